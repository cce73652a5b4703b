"""N-view triangulation: linear DLT on undistorted coordinates, then Gauss–Newton on pixel errors.

For a point seen at pixels u_c in cameras c (with distortion), the linear step solves, in ideal
normalised coordinates x_c = (x, y) of each view and the camera matrices [R_c | t_c],

    x · (r3ᵀ X + t3) − (r1ᵀ X + t1) = 0,   y · (r3ᵀ X + t3) − (r2ᵀ X + t2) = 0

for homogeneous X by SVD. Gauss–Newton then minimises Σ_c |π_c(X) − u_c|² (π_c: full projection with
distortion, px) with the analytic Jacobian J_c = ∂π_c/∂X. With pixel noise σ (px, isotropic,
independent), the covariance of X is Σ = σ² (Σ_c J_cᵀ J_c)⁻¹ [m²].

Everything is vectorised over points; a point may be seen by any subset of cameras (missing views are
NaN in the input).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .camera import Camera


@dataclass
class Triangulation:
    """xyz (P, 3) [m] (NaN where fewer than ``min_views``); rms_px (P,): RMS over views of the
    reprojection error norm; n_views (P,); cov (P, 3, 3) [m²]; residuals (P, C, 2) [px] (NaN for
    missing views); chi2 (P,): Σ_c r_cᵀ W_c r_c, the residuals weighted by the inverse pixel covariances
    (with an isotropic σ: Σ |r|² / σ²); leverage (P, C): tr(W_c J_c cov J_cᵀ), the share of a view's two
    residual dimensions taken by the fit (its residual has 2 − leverage degrees of freedom)."""

    xyz: np.ndarray
    rms_px: np.ndarray
    n_views: np.ndarray
    cov: np.ndarray
    residuals: np.ndarray
    chi2: np.ndarray = None
    leverage: np.ndarray = None


def triangulate_linear(cameras: list[Camera], uv: np.ndarray) -> np.ndarray:
    """Linear N-view triangulation of pixels uv (P, C, 2) (NaN = not seen). Returns (P, 3) (NaN where
    fewer than two views)."""
    uv = np.asarray(uv, float)
    P_, C = uv.shape[:2]
    A = np.zeros((P_, 2 * C, 4))
    seen = np.all(np.isfinite(uv), axis=-1)
    for c, cam in enumerate(cameras):
        ok = seen[:, c]
        if not ok.any():
            continue
        x = cam.undistort_pixels(uv[ok, c])
        Rt = np.hstack([cam.R, cam.t[:, None]])
        A[ok, 2 * c] = x[:, 0:1] * Rt[2] - Rt[0]
        A[ok, 2 * c + 1] = x[:, 1:2] * Rt[2] - Rt[1]
    n = seen.sum(axis=1)
    out = np.full((P_, 3), np.nan)
    good = n >= 2
    if good.any():
        # rows scaled to unit norm for conditioning
        Ag = A[good]
        norms = np.linalg.norm(Ag, axis=2, keepdims=True)
        Ag = np.divide(Ag, norms, out=np.zeros_like(Ag), where=norms > 0)
        _, _, Vt = np.linalg.svd(Ag)
        h = Vt[:, -1, :]
        with np.errstate(divide="ignore", invalid="ignore"):
            out[good] = h[:, :3] / h[:, 3:4]
    return out


def _weights(uv_cov, seen, pixel_sigma: float) -> np.ndarray:
    """Per-view weight matrices W (P, C, 2, 2) = inverse pixel covariances (isotropic 1/σ² without them)."""
    P_, C = seen.shape
    if uv_cov is None:
        W = np.zeros((P_, C, 2, 2))
        W[..., 0, 0] = W[..., 1, 1] = 1.0 / pixel_sigma ** 2
        return W
    cov = np.asarray(uv_cov, float)
    if cov.shape != (P_, C, 2, 2):
        raise ValueError(f"uv_cov must have shape ({P_}, {C}, 2, 2), got {cov.shape}")
    W = np.zeros((P_, C, 2, 2))
    good = seen & np.all(np.isfinite(cov), axis=(2, 3))
    if good.any():
        W[good] = np.linalg.inv(cov[good])
    return W


def _gauss_newton(cameras, uv, W, X, active, seen, iterations: int, tol: float):
    """Weighted Gauss–Newton on the active points (X updated in place). Returns the normal matrices
    Σ Jᵀ W J (P, 3, 3), the residuals (P, C, 2) [px] and the Jacobians (P, C, 2, 3) at the final X."""
    P_, C = seen.shape
    JTJ = np.zeros((P_, 3, 3))
    res = np.full((P_, C, 2), np.nan)
    jac = np.zeros((P_, C, 2, 3))
    converged = False
    for it in range(iterations + 1):
        # residuals and normal equations at the current X (the last pass only refreshes them)
        JTJ[:] = 0
        JTr = np.zeros((P_, 3))
        for c, cam in enumerate(cameras):
            ok = active & seen[:, c]
            if not ok.any():
                continue
            p, J = cam.project_jacobian(X[ok])
            r = p - uv[ok, c]
            res[ok, c] = r
            bad = ~np.all(np.isfinite(r), axis=1)
            if bad.any():  # behind the camera: drop the view from this iteration
                r[bad] = 0
                J[bad] = 0
            jac[ok, c] = J
            WJ = W[ok, c] @ J
            JTJ[ok] += np.einsum("pki,pkj->pij", J, WJ)
            JTr[ok] += np.einsum("pki,pk->pi", WJ, r)
        if it == iterations or converged:
            break
        idx = np.flatnonzero(active)
        if idx.size == 0:
            break
        try:
            step = np.linalg.solve(JTJ[idx], -JTr[idx][..., None])[..., 0]
        except np.linalg.LinAlgError:
            step = np.stack([np.linalg.lstsq(a, -b, rcond=None)[0] for a, b in zip(JTJ[idx], JTr[idx])])
        X[idx] += step
        converged = bool(np.max(np.abs(step)) < tol)
    return JTJ, res, jac


def triangulate(cameras: list[Camera], uv, *, pixel_sigma: float = 0.1, uv_cov=None, min_views: int = 2,
                iterations: int = 10, tol: float = 1e-10) -> Triangulation:
    """Triangulate pixels uv (P, C, 2) seen by ``cameras`` (NaN = not seen).

    Parameters
    ----------
    cameras : list of Camera
        The C cameras.
    uv : array_like (P, C, 2)
        Observed pixels (NaN = not seen).
    pixel_sigma : float
        Isotropic centroid standard deviation [px] used when ``uv_cov`` is not given.
    uv_cov : array_like (P, C, 2, 2), optional
        Covariance of each observed pixel [px²]; the fit then minimises Σ rᵀ W r with W = uv_cov⁻¹ and the
        point covariance is (Σ Jᵀ W J)⁻¹.
    min_views : int
        Views needed for a point (≥ 2).

    Returns
    -------
    Triangulation
    """
    uv = np.asarray(uv, float)
    if uv.ndim != 3 or uv.shape[1] != len(cameras) or uv.shape[2] != 2:
        raise ValueError(f"uv must have shape (points, {len(cameras)}, 2), got {uv.shape}")
    P_, C = uv.shape[:2]
    seen = np.all(np.isfinite(uv), axis=-1)
    W = _weights(uv_cov, seen, pixel_sigma)
    n_views = seen.sum(axis=1)
    X = triangulate_linear(cameras, uv)
    active = (n_views >= max(2, min_views)) & np.all(np.isfinite(X), axis=1)
    JTJ, res, jac = _gauss_newton(cameras, uv, W, X, active, seen, iterations, tol)
    rms = np.full(P_, np.nan)
    chi2 = np.full(P_, np.nan)
    with np.errstate(invalid="ignore"):
        sq = np.nansum(np.sum(res ** 2, axis=2), axis=1)
        rms[active] = np.sqrt(sq[active] / n_views[active])
        rr = np.where(np.isfinite(res), res, 0.0)
        chi2[active] = np.einsum("pci,pcij,pcj->p", rr, W, rr)[active]
    cov = np.full((P_, 3, 3), np.nan)
    if active.any():
        try:
            cov[active] = np.linalg.inv(JTJ[active])
        except np.linalg.LinAlgError:
            for i in np.flatnonzero(active):
                cov[i] = np.linalg.pinv(JTJ[i])
    lev = np.zeros((P_, C))
    if active.any():
        a = np.flatnonzero(active)
        JS = np.einsum("pcki,pij->pckj", jac[a], cov[a])            # J Σ
        lev[a] = np.einsum("pckj,pclj,pclk->pc", JS, jac[a], W[a])   # tr(W J Σ Jᵀ)
    lev[~seen] = 0.0
    X[~active] = np.nan
    res[~active] = np.nan
    chi2[~active] = np.nan
    return Triangulation(X, rms, np.where(active, n_views, 0), cov, res, chi2, lev)
