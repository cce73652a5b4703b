"""Second pass over the labelled views: sub-frame shifts, views that cannot be trusted, camera noise.

After labelling, every marker m at reference frame f has a view in some cameras c: a blob centroid
u_fmc [px] with its covariance C_fmc [px²] (:mod:`.detection`) and RMS width [px]. This pass

1. **shifts** the views of a camera exposed δ_c frames late (``frame_offset`` with a fraction, or an
   estimated sub-frame delay) back to the reference instants: the quadratic through the views at f − 1,
   f, f + 1 (seen at f − 1 + δ, f + δ, f + 1 + δ) is evaluated at f, i.e. at s = −δ, with Lagrange
   weights (s(s − 1)/2, 1 − s², s(s + 1)/2) — linear with one neighbour. The covariance follows the
   weights, plus the square of the interpolation error estimated from the third difference of the track
   (|Δ³u| |s(s² − 1)| / 6; for the line through two views, |Δ²u| |s(s − 1)| / 2, or half the shift
   without a second difference). A view without a neighbour cannot be shifted and is left out when
   |δ| ≥ 0.05;
2. **drops merged views**: where another labelled marker n projects within 2.5 (w_m + w_n) px of m's
   blob in camera c and n has no blob of its own there, the blob holds both markers' light and its
   centroid is neither's (reason ``overlap``);
3. **calibrates the pixel noise** of each camera: the blob covariances describe the read noise of the
   image around each blob; the shot noise needs the sensor's gain g (e⁻/DN), measured on the camera's
   own blobs (:func:`shot_noise`), and what they miss besides (calibration error, lens model, an
   imperfect timing) is a camera noise σ_c [px]. Each view's pixel covariance becomes
   C + α_c C_shot + σ_c² I (α_c = 1/g_c, C_shot the blob's shot-noise part per unit 1/g), with σ_c ≥ 0 the
   maximum-likelihood fit to the residuals of the camera's views (each residual Gaussian with covariance
   (1 − h/2) times that, h its leverage; views far outside left aside). Zero is a floor: the blob's own
   noise is never reduced;
4. **drops outlying views**: a point whose χ² exceeds the 99.9 % quantile of χ²(2n − 3) loses its view
   with the largest weighted residual (reason ``outlier``), and is triangulated again; a point seen by
   two cameras whose rays miss each other that badly is left out (``views disagree``).

Steps 2–4 are repeated until nothing changes (at most five times).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.stats import chi2 as chi2_dist

from .triangulation import Triangulation, triangulate


@dataclass
class Views:
    """Labelled views: uv (F, M, C, 2) [px] (NaN = none), cov (F, M, C, 2, 2) [px²], width (F, M, C) [px],
    cov_shot (F, M, C, 2, 2) the shot-noise covariance per unit 1/gain [px² DN]; notes (F, M) lists of
    reasons (text) collected by the passes."""

    uv: np.ndarray
    cov: np.ndarray
    width: np.ndarray
    notes: np.ndarray = None
    cov_shot: np.ndarray = None

    def __post_init__(self):
        if self.cov_shot is None:
            self.cov_shot = np.zeros(self.cov.shape)
        if self.notes is None:
            F, M = self.uv.shape[:2]
            self.notes = np.empty((F, M), object)
            for idx in np.ndindex(F, M):
                self.notes[idx] = []

    @staticmethod
    def empty(F: int, M: int, C: int) -> "Views":
        return Views(np.full((F, M, C, 2), np.nan), np.full((F, M, C, 2, 2), np.nan), np.full((F, M, C), np.nan))

    def copy(self) -> "Views":
        notes = np.empty(self.notes.shape, object)
        for idx in np.ndindex(self.notes.shape):
            notes[idx] = list(self.notes[idx])
        return Views(self.uv.copy(), self.cov.copy(), self.width.copy(), notes, self.cov_shot.copy())

    def drop(self, f: int, m: int, c: int, reason: str) -> None:
        self.uv[f, m, c] = np.nan
        self.cov[f, m, c] = np.nan
        self.cov_shot[f, m, c] = 0.0
        self.width[f, m, c] = np.nan
        self.notes[f, m].append(reason)

    @property
    def seen(self) -> np.ndarray:
        return np.all(np.isfinite(self.uv), axis=-1)


@dataclass
class Refined:
    """Result of :func:`refine`: the triangulation of every (frame, marker) (F·M points, frame-major),
    the views it used, the camera noise and counts of dropped views by reason."""

    tri: Triangulation
    views: Views
    noise: "CameraNoise"
    dropped: dict = field(default_factory=dict)


@dataclass
class CameraNoise:
    """What each camera adds to its blobs' own centroid covariances: C + α_c C_shot + σ_c² I, with σ_c
    [px] (C,) and α_c = 1 / gain [DN per e⁻] (C,) scaling the shot-noise part."""

    sigma: np.ndarray
    alpha: np.ndarray

    @staticmethod
    def zero(C: int) -> "CameraNoise":
        return CameraNoise(np.zeros(C), np.zeros(C))

    def covariances(self, views: "Views") -> np.ndarray:
        """Total pixel covariance of every view (F, M, C, 2, 2) [px²]."""
        return (views.cov + self.alpha[None, None, :, None, None] * views.cov_shot
                + self.sigma[None, None, :, None, None] ** 2 * np.eye(2))


# ---------------------------------------------------------------------------------------------------
# sub-frame shift
# ---------------------------------------------------------------------------------------------------
def shift_camera(views: Views, c: int, delta: float, names=None) -> None:
    """Shift camera c's views from the instants f + δ to f (in place; see the module docstring)."""
    if abs(delta) < 1e-9:
        return
    uv, cov, shot = views.uv[:, :, c].copy(), views.cov[:, :, c].copy(), views.cov_shot[:, :, c].copy()
    F, M = uv.shape[:2]
    ok = np.all(np.isfinite(uv), axis=-1)
    s = -delta
    label = names[c] if names is not None else str(c)
    for m in range(M):
        for f in np.flatnonzero(ok[:, m]):
            prev = f > 0 and ok[f - 1, m]
            nxt = f + 1 < F and ok[f + 1, m]
            if prev and nxt:
                w = {f - 1: s * (s - 1) / 2, f: 1 - s * s, f + 1: s * (s + 1) / 2}
                err = _interpolation_error(uv[:, m], ok[:, m], f, s)
            elif prev or nxt:
                g = f - 1 if prev else f + 1
                a = s / (g - f)                     # linear through f and g, evaluated at f + s
                w = {f: 1 - a, g: a}
                err = _linear_error(uv[:, m], ok[:, m], f, g, a)
            else:
                if abs(delta) >= 0.05:
                    views.drop(f, m, c, f"{label}: no neighbouring view for the sub-frame shift")
                continue
            views.uv[f, m, c] = sum(wk * uv[k, m] for k, wk in w.items())
            var = sum(wk * wk * cov[k, m] for k, wk in w.items())
            views.cov[f, m, c] = var + np.diag(err ** 2)
            views.cov_shot[f, m, c] = sum(wk * wk * shot[k, m] for k, wk in w.items())


def _linear_error(track: np.ndarray, ok: np.ndarray, f: int, g: int, a: float) -> np.ndarray:
    """Error [px] per axis of the line through the views at f and g evaluated at f + a (g − f):
    |Δ²u| |a (a − 1)| / 2 from the second difference of three consecutive views f, g, 2g − f, or, without
    them, half the shift |a| |u_g − u_f| / 2."""
    h = 2 * g - f
    if 0 <= h < len(track) and ok[h]:
        d2 = track[h] - 2 * track[g] + track[f]
        return np.abs(d2) * abs(a * (a - 1)) / 2
    return np.abs(track[g] - track[f]) * abs(a) / 2


def _interpolation_error(track: np.ndarray, ok: np.ndarray, f: int, s: float) -> np.ndarray:
    """|Δ³u| |s(s² − 1)| / 6 per axis [px] from four consecutive views around f (zero without them)."""
    F = len(track)
    for a in (f - 2, f - 1):
        if a >= 0 and a + 3 < F and ok[a:a + 4].all():
            d3 = track[a + 3] - 3 * track[a + 2] + 3 * track[a + 1] - track[a]
            return np.abs(d3) * abs(s * (s * s - 1)) / 6 + 0.0
    return np.zeros(2)


def shifted(views: Views, delays: dict, names=None) -> Views:
    """A copy of ``views`` with each camera c in ``delays`` shifted by its δ_c [frames]."""
    out = views.copy()
    for c, d in delays.items():
        shift_camera(out, c, d, names)
    return out


# ---------------------------------------------------------------------------------------------------
# triangulation with camera noise
# ---------------------------------------------------------------------------------------------------
def triangulate_views(cameras: list, views: Views, noise: CameraNoise, min_views: int = 2) -> Triangulation:
    """Triangulate every (frame, marker) from its views with the covariances of ``noise``."""
    C = views.uv.shape[2]
    return triangulate(cameras, views.uv.reshape(-1, C, 2), uv_cov=noise.covariances(views).reshape(-1, C, 2, 2),
                       min_views=min_views)


def _view_ratios(tri: Triangulation, views: Views, noise: CameraNoise) -> np.ndarray:
    """Per view rᵀ W r / (2 − h) (P, C) with the covariances of ``noise`` (NaN where no view)."""
    P, C = tri.residuals.shape[:2]
    cov = noise.covariances(views).reshape(P, C, 2, 2)
    r = tri.residuals
    ok = np.all(np.isfinite(r), axis=-1) & np.all(np.isfinite(cov), axis=(2, 3))
    out = np.full((P, C), np.nan)
    if ok.any():
        q = np.einsum("vi,vij,vj->v", r[ok], np.linalg.inv(cov[ok]), r[ok])
        out[ok] = q / np.maximum(2.0 - tri.leverage[ok], 0.05)
    return out


def camera_noise(tri: Triangulation, views: Views, start: CameraNoise, cap: float = 30.0) -> CameraNoise:
    """Fit each camera's noise σ_c ≥ 0 [px] to the residuals of its views (module docstring, step 3).

    Each view's residual r is taken as Gaussian with covariance (1 − h/2)(C + α C_shot + σ² I) (h: its
    leverage, so that the expected rᵀ W r is 2 − h; α fixed, from :func:`shot_noise`); σ² maximises the
    likelihood over the views with rᵀ W r < ``cap`` at the current fit (outliers left aside; three rounds)."""
    from scipy.optimize import minimize_scalar

    P, C = tri.residuals.shape[:2]
    sig = start.sigma.copy()
    r = tri.residuals
    base = (views.cov + start.alpha[None, None, :, None, None] * views.cov_shot).reshape(P, C, 2, 2)
    for c in range(C):
        ok = np.all(np.isfinite(r[:, c]), axis=-1) & (tri.n_views >= 2)
        if ok.sum() < 5:
            continue
        rc, cc = r[ok, c], base[ok, c]
        k = np.clip(1.0 - tri.leverage[ok, c] / 2, 0.025, 1.0)[:, None, None]

        def parts(y):
            S = k * (cc + np.exp(y) * np.eye(2))
            return np.einsum("vi,vij,vj->v", rc, np.linalg.inv(S), rc), np.linalg.slogdet(S)[1]

        y = np.log(max(sig[c] ** 2, 1e-6))
        for _ in range(3):
            keep = parts(y)[0] < cap
            if keep.sum() < 5:
                break
            y = minimize_scalar(lambda z: float(np.sum(np.add(*parts(z))[keep])), bounds=(-30.0, 6.0),
                                method="bounded").x
        sig[c] = float(np.sqrt(np.exp(y))) if y > -29 else 0.0
    return CameraNoise(sig, start.alpha.copy())


def shot_noise(stats: np.ndarray) -> np.ndarray:
    """1/gain [DN per e⁻] per camera from pooled blob statistics (C, 2) = (Σ m (r² − σ_b²), Σ m²) of
    :class:`.detection.Blobs` (zero where the scatter shows no shot noise)."""
    stats = np.asarray(stats, float)
    with np.errstate(divide="ignore", invalid="ignore"):
        a = np.where(stats[:, 1] > 0, stats[:, 0] / stats[:, 1], 0.0)
    return np.maximum(a, 0.0)


# ---------------------------------------------------------------------------------------------------
# views that cannot be trusted
# ---------------------------------------------------------------------------------------------------
def drop_overlaps(cameras: list, views: Views, xyz: np.ndarray, names) -> int:
    """Drop views whose blob holds another labelled marker's light (module docstring, step 2); returns
    the number dropped. xyz (F, M, 3) [m]: the current points."""
    F, M, C = views.uv.shape[:3]
    n = 0
    seen = views.seen
    for c, cam in enumerate(cameras):
        proj = cam.project(xyz.reshape(-1, 3)).reshape(F, M, 2)
        for f in range(F):
            for m in np.flatnonzero(seen[f, :, c]):
                for o in range(M):
                    if o == m or seen[f, o, c] or not np.all(np.isfinite(proj[f, o])):
                        continue
                    # the other marker is as wide as this one in this camera (both at about the same range)
                    if np.linalg.norm(proj[f, o] - views.uv[f, m, c]) < 5.0 * views.width[f, m, c]:
                        views.drop(f, m, c, f"{names[c]}: overlap with marker {o}")
                        n += 1
                        break
    return n


def drop_outliers(tri: Triangulation, views: Views, noise: CameraNoise, names, level: float = 0.999) -> tuple[int, int]:
    """Drop the worst view of every point whose χ² exceeds the ``level`` quantile of χ²(2n − 3); a
    two-view point is left out altogether. Returns (views dropped, points left out)."""
    F, M, C = views.uv.shape[:3]
    ratios = _view_ratios(tri, views, noise)
    n_view = n_point = 0
    for p in np.flatnonzero(tri.n_views >= 2):
        n = int(tri.n_views[p])
        if not tri.chi2[p] > chi2_dist.ppf(level, 2 * n - 3):
            continue
        f, m = divmod(p, M)
        if n >= 3:
            c = int(np.nanargmax(ratios[p]))
            views.drop(f, m, c, f"{names[c]}: outlier (χ² {tri.chi2[p]:.0f} with {n} views)")
            n_view += 1
        else:
            for c in np.flatnonzero(views.seen[f, m]):
                views.drop(f, m, c, f"{names[c]}: views disagree (χ² {tri.chi2[p]:.0f} with 2 views)")
            n_point += 1
    return n_view, n_point


def refine(cameras: list, views: Views, names, noise: CameraNoise | None = None, calibrate: bool = True,
           min_views: int = 2, level: float = 0.999, max_passes: int = 5) -> Refined:
    """Steps 2–4 of the module docstring on views already shifted to the reference instants.

    noise: starting (or, without ``calibrate``, fixed) camera noise; level: the χ² quantile beyond which
    a point's worst view is left out."""
    C = len(cameras)
    F, M = views.uv.shape[:2]
    views = views.copy()
    noise = CameraNoise.zero(C) if noise is None else noise
    dropped = {"overlap": 0, "outlier": 0, "views disagree": 0}
    for _ in range(max_passes):
        tri = triangulate_views(cameras, views, noise, min_views)
        n_overlap = drop_overlaps(cameras, views, tri.xyz.reshape(F, M, 3), names)
        if n_overlap:
            tri = triangulate_views(cameras, views, noise, min_views)
        if calibrate:
            for _ in range(6):     # the residuals and leverages change with the weights: to the fixed point
                new = camera_noise(tri, views, noise)
                tri = triangulate_views(cameras, views, new, min_views)
                done = np.all(np.abs(new.sigma - noise.sigma) <= 0.01 * new.sigma + 1e-4)
                noise = new
                if done:
                    break
        n_out, n_pts = drop_outliers(tri, views, noise, names, level)
        dropped["overlap"] += n_overlap
        dropped["outlier"] += n_out
        dropped["views disagree"] += n_pts
        if n_overlap == n_out == n_pts == 0:
            break
    tri = triangulate_views(cameras, views, noise, min_views)
    return Refined(tri, views, noise, dropped)
