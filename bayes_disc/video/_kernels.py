"""Compiled kernel: Levenberg–Marquardt fit of pixel-integrated Gaussian spots (see :mod:`.psf`).

Parameters per spot s: centre (u_s, v_s) [px], ln σ_s, ln F_s; the model on a window whose top-left
pixel is (x0, y0) is Σ_s F_s e(x; u_s, σ_s) e(y; v_s, σ_s). Only pixels with ``valid`` count.
"""
from __future__ import annotations

import math

import numba as nb
import numpy as np

_SQRT2 = math.sqrt(2.0)
_INV_SQRT2PI = 1.0 / math.sqrt(2.0 * math.pi)


@nb.njit(cache=True)
def _axis(n, first, c, s, e, de_dc, de_dls):
    for i in range(n):
        x = first + i
        a = (x + 0.5 - c) / s
        b = (x - 0.5 - c) / s
        pa = math.exp(-0.5 * a * a) * _INV_SQRT2PI
        pb = math.exp(-0.5 * b * b) * _INV_SQRT2PI
        e[i] = 0.5 * (math.erf(a / _SQRT2) - math.erf(b / _SQRT2))
        de_dc[i] = -(pa - pb) / s
        de_dls[i] = -(a * pa - b * pb)


@nb.njit(cache=True)
def _model(data, valid, x0, y0, p, n, J, r):
    """Residuals r (model − data) and Jacobian J on the valid pixels; returns the sum of squares."""
    h, w = data.shape
    ex = np.empty((n, w))
    dex = np.empty((n, w))
    dexl = np.empty((n, w))
    ey = np.empty((n, h))
    dey = np.empty((n, h))
    deyl = np.empty((n, h))
    for s in range(n):
        sg = math.exp(p[2 * n + s])
        _axis(w, x0, p[s], sg, ex[s], dex[s], dexl[s])
        _axis(h, y0, p[n + s], sg, ey[s], dey[s], deyl[s])
    k = 0
    ss = 0.0
    for yi in range(h):
        for xi in range(w):
            if not valid[yi, xi]:
                continue
            m = 0.0
            for s in range(n):
                f = math.exp(p[3 * n + s])
                g = ey[s, yi] * ex[s, xi]
                m += f * g
                J[k, s] = f * ey[s, yi] * dex[s, xi]
                J[k, n + s] = f * dey[s, yi] * ex[s, xi]
                J[k, 2 * n + s] = f * (deyl[s, yi] * ex[s, xi] + ey[s, yi] * dexl[s, xi])
                J[k, 3 * n + s] = f * g
            r[k] = m - data[yi, xi]
            ss += r[k] * r[k]
            k += 1
    return ss


@nb.njit(cache=True)
def fit_spots_lm(data, valid, x0, y0, p0, max_iter):
    """LM fit; returns (parameters, converged)."""
    n = p0.size // 4
    npar = p0.size
    npix = 0
    for yi in range(data.shape[0]):
        for xi in range(data.shape[1]):
            if valid[yi, xi]:
                npix += 1
    J = np.empty((npix, npar))
    r = np.empty(npix)
    Jt = np.empty((npix, npar))
    rt = np.empty(npix)
    p = p0.copy()
    cost = _model(data, valid, x0, y0, p, n, J, r)
    lam = 1e-3
    converged = False
    for it in range(max_iter):
        A = J.T @ J
        g = J.T @ r
        improved = False
        for _ in range(12):
            M = A.copy()
            for i in range(npar):
                M[i, i] += lam * max(A[i, i], 1e-12)
            step = np.linalg.solve(M, -g)
            pt = p + step
            # keep σ and flux in a sane range while iterating
            for s in range(n):
                pt[2 * n + s] = min(max(pt[2 * n + s], -3.0), 4.0)
                pt[3 * n + s] = min(max(pt[3 * n + s], -20.0), 30.0)
            ct = _model(data, valid, x0, y0, pt, n, Jt, rt)
            if ct < cost:
                small = np.max(np.abs(step)) < 1e-9 or (cost - ct) < 1e-12 * max(cost, 1e-30)
                p = pt
                cost = ct
                J[:, :] = Jt
                r[:] = rt
                lam = max(lam / 3.0, 1e-12)
                improved = True
                if small:
                    converged = True
                break
            lam *= 4.0
        if not improved or converged:
            converged = converged or not improved
            break
    return p, converged
