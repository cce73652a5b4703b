"""Splitting and deblending of touching marker images by joint fits of pixel-integrated Gaussians.

Used by :mod:`.detection`: a component with two or more separate intensity peaks is split by a joint
least-squares fit of spots (centre, σ and flux each; :mod:`.psf`, compiled in :mod:`._kernels`), and the
centroids of blobs crowded by a neighbour are refined the same way. Each fit also gives the covariance of
its centres, (JᵀJ)⁻¹ s² with s² the mean square residual over the window's pixels (px²): a deblended
centroid carries the uncertainty of its fit, not that of an isolated blob.
"""
from __future__ import annotations

import cv2
import numpy as np

from ._kernels import fit_spots_lm
from .psf import pixel_integrals


def min_separation(u, v) -> float:
    """Smallest distance [px] between the points (u, v) (n,); inf for fewer than two."""
    d = np.hypot(u[:, None] - u[None, :], v[:, None] - v[None, :])
    d[np.diag_indices(len(u))] = np.inf
    return float(d.min()) if len(u) > 1 else float("inf")


def fit_spots(data, valid, origin, u0, v0, s0, f0, max_shift: float):
    """Least-squares fit of pixel-integrated Gaussians to ``data`` on ``valid`` pixels of a window whose
    top-left pixel is ``origin`` (frame coordinates).

    Parameters
    ----------
    data : ndarray (h, w)
        Background-subtracted window [DN].
    valid : ndarray of bool (h, w)
        Pixels that take part in the fit.
    origin : (int, int)
        Frame coordinates (x, y) of the window's top-left pixel.
    u0, v0, s0, f0 : ndarray (n,)
        Starting centres [px], widths σ [px] and fluxes [DN].
    max_shift : float
        Largest accepted move of a centre from its start [px].

    Returns
    -------
    tuple or None
        (u, v, σ, F, cov) with cov (n, 2, 2) the covariance of the centres [px²]; None when the fit fails,
        a centre moves more than ``max_shift`` or σ leaves [0.3, 10] px.
    """
    n = len(u0)
    if valid.sum() <= 4 * n:
        return None
    p0 = np.concatenate([u0, v0, np.log(s0), np.log(f0)]).astype(np.float64)
    try:
        p, ok = fit_spots_lm(np.ascontiguousarray(data, np.float64), np.ascontiguousarray(valid), int(origin[0]),
                             int(origin[1]), p0, 60)
    except Exception:  # noqa: BLE001 - singular normal equations inside the compiled kernel
        return None
    u, v, sg, fl = p[:n], p[n:2 * n], np.exp(p[2 * n:3 * n]), np.exp(p[3 * n:])
    if not (ok and np.all(np.isfinite(p)) and np.all(np.hypot(u - u0, v - v0) < max_shift)
            and np.all((sg > 0.3) & (sg < 10))):
        return None
    return u, v, sg, fl, centre_covariance(data, valid, origin, u, v, sg, fl)


def spot_jacobian(shape, valid, origin, u, v, sigma, flux) -> tuple[np.ndarray, np.ndarray]:
    """Model of spots (n,) on a window (``shape``, top-left pixel ``origin``) and its Jacobian: returns the
    model on the valid pixels (p,) [DN] and J (p, 4n) with respect to (u, v, ln σ, F) of each spot."""
    n = len(u)
    h, w = shape
    x0, y0 = int(origin[0]), int(origin[1])
    d = 1e-4

    def ax(c, s, first, count):
        return pixel_integrals(c, s, first, count)

    ex, ey = ax(u, sigma, x0, w), ax(v, sigma, y0, h)
    dex = (ax(u + d, sigma, x0, w) - ax(u - d, sigma, x0, w)) / (2 * d)
    dey = (ax(v + d, sigma, y0, h) - ax(v - d, sigma, y0, h)) / (2 * d)
    dsx = (ax(u, sigma * (1 + d), x0, w) - ax(u, sigma * (1 - d), x0, w)) / (2 * d)
    dsy = (ax(v, sigma * (1 + d), y0, h) - ax(v, sigma * (1 - d), y0, h)) / (2 * d)
    m = np.asarray(valid, bool).ravel()
    cols = []
    for s in range(n):
        cols += [flux[s] * np.outer(ey[s], dex[s]), flux[s] * np.outer(dey[s], ex[s]),
                 flux[s] * (np.outer(dsy[s], ex[s]) + np.outer(ey[s], dsx[s])), np.outer(ey[s], ex[s])]
    J = np.stack([c.ravel()[m] for c in cols], axis=1)
    model = sum(flux[s] * np.outer(ey[s], ex[s]) for s in range(n)).ravel()[m]
    return model, J


def centre_covariance(data, valid, origin, u, v, sigma, flux) -> np.ndarray:
    """Covariance (n, 2, 2) [px²] of fitted spot centres: the (u, v) block of (JᵀJ)⁻¹ s² for the model of
    :func:`fit_spots` at its solution, s² = Σ r² / (pixels − parameters) over the valid pixels."""
    n = len(u)
    model, J = spot_jacobian(np.shape(data), valid, origin, u, v, sigma, flux)
    r = model - np.asarray(data, float).ravel()[np.asarray(valid, bool).ravel()]
    dof = max(len(r) - 4 * n, 1)
    cov = np.linalg.pinv(J.T @ J) * (float(r @ r) / dof)
    out = np.empty((n, 2, 2))
    for s in range(n):
        idx = [4 * s, 4 * s + 1]
        out[s] = cov[np.ix_(idx, idx)]
    return out


def peaks(S: np.ndarray, own: np.ndarray) -> list:
    """Separate intensity peaks inside a blob, as window (x, y): local maxima of the 3×3-smoothed image
    ≥ 30 % of the highest, ≥ 3 px apart and with a valley in the image (< 80 % of the lower maximum)
    between them. ``[None]`` when there is only one."""
    if own.sum() < 6:
        return [None]
    Sm = cv2.blur(S, (3, 3))
    mx = cv2.dilate(Sm, np.ones((3, 3), np.uint8))
    top = Sm[own].max()
    cand = ((Sm >= mx) & own & (Sm >= 0.3 * top)).astype(np.uint8)
    n, lab = cv2.connectedComponents(cand, connectivity=8)  # a plateau of maxima is one peak
    if n <= 2:
        return [None]
    xs, ys = [], []
    for k in range(1, n):
        yy, xx = np.nonzero(lab == k)
        j = int(np.argmax(Sm[yy, xx]))
        xs.append(xx[j])
        ys.append(yy[j])
    xs, ys = np.array(xs), np.array(ys)
    centres = []
    for i in np.argsort(-Sm[ys, xs], kind="stable"):  # greedy: brightest first
        p = (float(xs[i]), float(ys[i]))
        if all(np.hypot(p[0] - c[0], p[1] - c[1]) >= 3.0 and valley(S, p, c) for c in centres):
            centres.append(p)
    return centres


def valley(S: np.ndarray, a, b, depth: float = 0.8) -> bool:
    """True if the intensity dips below ``depth`` × the lower of two maxima somewhere between them
    (two blobs), False for a ridge or plateau (a motion streak, a saturated top)."""
    n = int(np.ceil(2 * np.hypot(a[0] - b[0], a[1] - b[1]))) + 1
    t = np.linspace(0.0, 1.0, n)
    xs = np.rint(a[0] + t * (b[0] - a[0])).astype(int)
    ys = np.rint(a[1] + t * (b[1] - a[1])).astype(int)
    low = min(S[int(a[1]), int(a[0])], S[int(b[1]), int(b[0])])
    return bool(S[ys, xs].min() < depth * low)


def deblend_groups(signal, labels, uv: np.ndarray, cov: np.ndarray, info: list, x_off: int, y_off: int) -> None:
    """Refine the centroids of crowded blobs by a joint fit over the union of their windows (in place).

    signal, labels: the region's background-subtracted image and component labels; uv (n, 2) and cov
    (n, 2, 2): the blobs' centroids [px] and covariances [px²] (frame coordinates); info: per blob
    (label, window (x0, y0, x1, y1), local background, σ estimate, neighbour labels); x_off, y_off: the
    region's offset in the frame. Groups of 2–6 blobs linked as neighbours are fitted together, other
    components getting zero weight; the fit is accepted when it converges with every centre within
    1.5 px of its centroid and σ in [0.3, 10] px. The covariance of an accepted centre is the fit's plus
    the square of a quarter of the move the fit made: a correction is only as certain as the model of
    the neighbour's tail.
    """
    label_to_idx = {inf[0]: i for i, inf in enumerate(info) if inf[0] > 0}
    parent = list(range(len(info)))

    def find(i):
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    for i, inf in enumerate(info):
        for lab in inf[4]:
            j = label_to_idx.get(lab)
            if j is not None:
                parent[find(i)] = find(j)
    groups: dict = {}
    for i in range(len(info)):
        if info[i][0] > 0:
            groups.setdefault(find(i), []).append(i)
    for members in groups.values():
        if len(members) < 2 or len(members) > 6:
            continue
        x0 = min(info[i][1][0] for i in members)
        y0 = min(info[i][1][1] for i in members)
        x1 = max(info[i][1][2] for i in members)
        y1 = max(info[i][1][3] for i in members)
        data = signal[y0:y1, x0:x1].astype(np.float64) - float(np.mean([info[i][2] for i in members]))
        L = labels[y0:y1, x0:x1]
        valid = (L == 0) | np.isin(L, [info[i][0] for i in members])
        u0, v0 = uv[members, 0].copy(), uv[members, 1].copy()
        s0 = np.array([info[i][3] for i in members])
        f0 = np.array([max(float(data[L == info[i][0]].sum()), 1.0) for i in members])
        fit = fit_spots(data, valid, (x0 + x_off, y0 + y_off), u0, v0, s0, f0, 1.5)
        if fit is None:
            continue
        move = np.stack([fit[0] - u0, fit[1] - v0], axis=1)
        for k, i in enumerate(members):
            cov[i] = fit[4][k] + 0.25 * np.outer(move[k], move[k])
        uv[members, 0] = fit[0]
        uv[members, 1] = fit[1]
