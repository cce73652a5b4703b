"""Compiled loop of :func:`.outliers.mixture_log_likelihood`: every frame's label hypotheses and every point's
inlier/outlier mixture at every noise scale of every prediction. In numpy the (B, n, m, Q) temporaries of
each hypothesis cost ~15 ms per draw and flight; here a frame costs m + 2·n_pairs log-sums per scale (a swap
of j and l changes only their two terms), with no temporary array.
"""
from __future__ import annotations

import math

import numba as nb
import numpy as np


@nb.njit(cache=True)
def _logaddexp(a, b):
    if a < b:
        a, b = b, a
    if b == -np.inf:
        return a
    return a + math.log1p(math.exp(b - a))


@nb.njit(cache=True)
def mixture_frames(e2, r2, log_w, seen, log_sigma, log_inlier, log_outlier, inv_width2, log_as_given, log_pair):
    """Σ over frames of log p(frame | θ, σ) (the inlier/outlier/swap mixture) for each prediction and scale.

    Parameters
    ----------
    e2 : (B, n, m, m) array
        |W_l (m_a − y_l)|² [m²] of marker a's prediction against the observation labelled l (whitened).
    r2 : (B, n, m, m) array
        |m_a − y_l|² [m²], not whitened.
    log_w : (n, m) array
        log |W_l| of each observation.
    seen : (n, m) bool array
        Observed points.
    log_sigma : (B, Q) array
        ln σ at which to evaluate.
    log_inlier : float
        ln(1 − π) − 1.5 ln 2π.
    log_outlier : float
        ln π − 1.5 ln(2π w²).
    inv_width2 : float
        1 / w² [m⁻²].
    log_as_given, log_pair : float
        ln(1 − π_s) and ln(π_s / n_pairs).

    Returns
    -------
    (B, Q) array
    """
    B, n, m, _ = e2.shape
    Q = log_sigma.shape[1]
    out = np.zeros((B, Q))
    t = np.empty((m, m))
    hyp = np.empty(1 + m * (m - 1) // 2)
    for b in range(B):
        for q in range(Q):
            u = log_sigma[b, q]
            iv = math.exp(-2.0 * u)
            c_in = log_inlier - 3.0 * u
            total = 0.0
            for i in range(n):
                for a in range(m):
                    for l in range(m):
                        if seen[i, l]:
                            t[a, l] = _logaddexp(c_in + log_w[i, l] - 0.5 * e2[b, i, a, l] * iv,
                                                 log_outlier - 0.5 * r2[b, i, a, l] * inv_width2)
                        else:
                            t[a, l] = 0.0
                given = 0.0
                for a in range(m):
                    given += t[a, a]
                hyp[0] = log_as_given + given
                h = 1
                top = hyp[0]
                for j in range(m):
                    for l in range(j + 1, m):
                        if seen[i, j] and seen[i, l]:
                            hyp[h] = log_pair + given - t[j, j] - t[l, l] + t[j, l] + t[l, j]
                        else:
                            hyp[h] = -np.inf
                        if hyp[h] > top:
                            top = hyp[h]
                        h += 1
                s = 0.0
                for k in range(h):
                    s += math.exp(hyp[k] - top)
                total += top + math.log(s)
            out[b, q] = total
    return out
