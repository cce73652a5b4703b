"""Gross errors in marker data: outlying points and label-swapped frames, judged by a mixture model.

Noise model ``robust`` (``noise.model: robust``). Given the residuals r_i = m_i(θ) − y_i [m] of a fit and
each point's inlier noise scale σ_i [m] (σ_f, or σ_f s_i / ḡ with per-point errors), every observed point is

    p(r_i) = (1 − π) N(r_i | 0, σ_i² I₃) + π N(r_i | 0, w² I₃),

π = :data:`OUTLIER_FRACTION` = 0.01 (prior probability that a point is a gross error) and
w = :data:`OUTLIER_WIDTH_M` = 0.05 m (spread of gross errors: digitising slips of centimetres to a marker
spacing). A frame (sample time) is either as labelled (H₀, prior 1 − π_s) or has the labels of one pair
(j, l) of its observed markers exchanged (H_jl, prior π_s / n_pairs, π_s = :data:`SWAP_FRACTION` = 0.01):
under H_jl marker j is compared with the observation labelled l and vice versa, each point again an
inlier/outlier mixture. The posterior probability of each hypothesis follows from Bayes' rule frame by
frame; a point's outlier probability is summed over the hypotheses. A swap explains two large residuals
with two small ones, so it beats "two outliers" by roughly (π_s/n_pairs) / π² times the ratio of the
inlier to the outlier density squared: a swap is recognised as a swap.

π, w and π_s are fixed, not estimated: with 1 % gross errors among ~10³ points there are ~10 to estimate π
from, and the judgement hardly depends on it — a 2 cm error at σ = 2 mm has a log-likelihood ratio of
~50 against the inlier, against log(π/(1−π)) ≈ −4.6 (a factor 10 in π shifts that by 2.3).

Points and frames with probability > 0.5 are flagged; the fit then drops the outlying points and
restores the swapped labels (:func:`clean_flight`) and is repeated until the flags no longer change
(:mod:`bayes_disc.inference.robust`). The posterior is then conditional on that classification.
"""
from __future__ import annotations

from dataclasses import dataclass, replace
from itertools import combinations

import numpy as np
from scipy.special import logsumexp

#: prior probability that a point is a gross error
OUTLIER_FRACTION = 0.01
#: spread [m] of gross errors (isotropic normal)
OUTLIER_WIDTH_M = 0.05
#: prior probability that a frame has two labels exchanged
SWAP_FRACTION = 0.01
#: posterior probability above which a point or frame is flagged
FLAG_PROBABILITY = 0.5


def _log_normal3(r: np.ndarray, s: np.ndarray) -> np.ndarray:
    """log N(r | 0, s² I₃) for r (..., 3) [m], s (...) [m]."""
    return -1.5 * np.log(2 * np.pi * s ** 2) - 0.5 * np.sum(r * r, axis=-1) / s ** 2


def _point_terms(r: np.ndarray, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(log p(r_i), log P(outlier_i | r_i)) of the inlier/outlier mixture; r (..., 3), s (...)."""
    a = np.log1p(-OUTLIER_FRACTION) + _log_normal3(r, s)
    b = np.log(OUTLIER_FRACTION) + _log_normal3(r, np.full_like(s, OUTLIER_WIDTH_M))
    total = np.logaddexp(a, b)
    return total, b - total


@dataclass
class Classification:
    """Outlier and swap probabilities of one flight's observed points and frames.

    Attributes
    ----------
    flight : str
    times : (n,) array
        Sample times [s].
    marker_ids : tuple of str
    outlier : (n, m) array
        Posterior probability that each observed point is a gross error (NaN where unobserved).
    pairs : list of (int, int)
        The marker pairs (j, l), j < l.
    swap : (n, n_pairs) array
        Posterior probability that the frame has the labels of pair (j, l) exchanged (0 where either is unseen).
    """

    flight: str
    times: np.ndarray
    marker_ids: tuple
    outlier: np.ndarray
    pairs: list
    swap: np.ndarray

    def swapped_frames(self) -> list[tuple[int, int, int, float]]:
        """(frame, j, l, probability) of every frame judged swapped (most probable pair > 0.5)."""
        out = []
        for i in np.flatnonzero(self.swap.max(axis=1, initial=0.0) > FLAG_PROBABILITY):
            p = int(np.argmax(self.swap[i]))
            out.append((int(i), *self.pairs[p], float(self.swap[i, p])))
        return out

    def outlier_points(self) -> list[tuple[int, int, float]]:
        """(frame, marker index, probability) of every point judged an outlier (> 0.5)."""
        i, j = np.nonzero(np.nan_to_num(self.outlier) > FLAG_PROBABILITY)
        return [(int(a), int(b), float(self.outlier[a, b])) for a, b in zip(i, j)]

    def records(self) -> dict:
        """The flags as JSON records: ``outliers`` [{flight, t, marker, probability}], ``swaps``
        [{flight, t, markers: [j, l], probability}]."""
        return {"outliers": [{"flight": self.flight, "t": float(self.times[i]), "marker": str(self.marker_ids[j]),
                              "probability": round(p, 4)} for i, j, p in self.outlier_points()],
                "swaps": [{"flight": self.flight, "t": float(self.times[i]),
                           "markers": [str(self.marker_ids[j]), str(self.marker_ids[l])], "probability": round(p, 4)}
                          for i, j, l, p in self.swapped_frames()]}


def classify(flight: str, times: np.ndarray, marker_ids, predicted: np.ndarray, observed: np.ndarray,
             point_sigma: np.ndarray) -> Classification:
    """Posterior outlier and swap probabilities of a flight's points and frames (module docstring).

    Parameters
    ----------
    flight : str
        Its name.
    times : (n,) array
        Sample times [s].
    marker_ids : sequence of str
    predicted : (n, m, 3) array
        The fit's markers [m].
    observed : (n, m, 3) array
        The data [m], NaN where unseen.
    point_sigma : (n, m) array
        Inlier noise scale σ_i of each observation [m] (belongs to the observation: it travels with a swap).

    Returns
    -------
    Classification
    """
    n, m, _ = observed.shape
    seen = np.all(np.isfinite(observed), axis=-1)
    s = np.where(seen, point_sigma, 1.0)
    r = np.where(seen[..., None], predicted - observed, 0.0)
    lp, lo = _point_terms(r, s)
    lp, lo = np.where(seen, lp, 0.0), np.where(seen, lo, -np.inf)
    pairs = list(combinations(range(m), 2))
    hyp = [np.log1p(-SWAP_FRACTION) + lp.sum(axis=1)]          # H0
    out_h = [lo]
    for j, l in pairs:
        both = seen[:, j] & seen[:, l]
        lps, los = lp.copy(), lo.copy()
        for a, b in ((j, l), (l, j)):                          # marker a compared with the observation labelled b
            t, o = _point_terms(predicted[:, a] - np.where(both[:, None], observed[:, b], 0.0), s[:, b])
            lps[:, a], los[:, a] = np.where(both, t, lps[:, a]), np.where(both, o, los[:, a])
        h = np.log(SWAP_FRACTION / len(pairs)) + lps.sum(axis=1)
        hyp.append(np.where(both, h, -np.inf))
        out_h.append(los)
    H = np.stack(hyp, axis=1)                                  # (n, 1 + n_pairs)
    post = np.exp(H - logsumexp(H, axis=1, keepdims=True))
    outlier = np.einsum("nh,hnm->nm", post, np.exp(np.stack(out_h)))
    return Classification(flight=flight, times=np.asarray(times), marker_ids=tuple(marker_ids),
                          outlier=np.where(seen, outlier, np.nan), pairs=pairs, swap=post[:, 1:])


def clean_flight(data, records: dict):
    """The flight with its swapped frames' labels restored and its outlying points removed (NaN).

    Outliers are judged under the frame's swap hypothesis, so a point of a restored frame that is still
    an outlier is removed as well.

    Parameters
    ----------
    data : FlightObservation
        The flight as recorded.
    records : dict
        :meth:`Classification.records` of the flight (or as read back from ``flagged.json``).

    Returns
    -------
    FlightObservation

    Raises
    ------
    ValueError
        If a record names a time or marker the flight does not have.
    """
    pos = data.positions.copy()
    sig = None if data.sigma is None else data.sigma.copy()
    cov = None if data.cov is None else data.cov.copy()
    ids = [str(m) for m in data.marker_ids]

    def frame(t):
        i = int(np.argmin(np.abs(data.times - t)))
        if abs(data.times[i] - t) > 1e-9 * max(1.0, abs(t)):
            raise ValueError(f"flight {data.name!r}: no sample at t = {t:g} s")
        return i

    def marker(mid):
        if mid not in ids:
            raise ValueError(f"flight {data.name!r}: no marker {mid!r}")
        return ids.index(mid)
    for rec in records.get("swaps", []):
        i, (j, l) = frame(rec["t"]), (marker(m) for m in rec["markers"])
        for arr in (pos, sig, cov):
            if arr is not None:
                arr[i, [j, l]] = arr[i, [l, j]]
    for rec in records.get("outliers", []):
        pos[frame(rec["t"]), marker(rec["marker"])] = np.nan
    return replace(data, positions=pos, sigma=sig, cov=cov)
