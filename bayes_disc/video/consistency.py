"""Checks of each triangulated marker against the rigid layout and against its neighbours in time.

A triangulated point X_fm [m] with covariance Σ_fm [m²] is tested twice:

* **Layout.** In a frame with ≥ 3 labelled markers, each side's length is compared with the layout's,
  z_mn = (|X_m − X_n| − D_mn) / √(gᵀ(Σ_m + Σ_n)g + σ_L²) (g: unit vector along the side, σ_L:
  ``layout_sigma_m``, how well the body positions are known). A side with |z| > ``z_max`` is bad; a
  marker all of whose sides are bad while some other side is good is the culprit. When every side is bad
  the culprit cannot be told and every marker of the frame is flagged.
* **Time.** The rigid pose (R, c) of the disc is fitted (Kabsch) in the frames f − 2 … f + 2 other than f
  that hold ≥ 3 markers consistent with the layout; with at least one such frame on each side and three
  in all, the pose at f is interpolated (c: least-squares quadratic in time; R: rotation vectors
  relative to the nearest pose, fitted linearly in time) and predicts X̂_fm = R p_m + c. The squared
  Mahalanobis distance e ᵀ (Σ_fm + s² I)⁻¹ e, e = X_fm − X̂_fm, is compared with the 1 − ``level``
  quantile of χ²(3); s [m], the error of the prediction itself, is set from the points of the ten
  neighbouring frames (the 90 % quantile of max(|e|² − tr Σ, 0) / 3 over them, divided by that of
  χ²(3)/3): the motion of a disc is predicted less well in some parts of a flight, and for some markers,
  than for others.

A flagged point is either kept with its covariance inflated by the disagreement, Σ + e eᵀ + s² I (for a
time flag) or Σ + Σ_bad sides (|X_m − X_n| − D_mn)² g gᵀ (for a layout flag) — its ellipsoid then reaches
the position its neighbours imply — or left out (``action: drop``). Either way the reason goes into the
output.
"""
from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np
from scipy.stats import chi2 as chi2_dist

from .identity import _rotmat, _rotvec, kabsch


@dataclass(frozen=True)
class CheckConfig:
    """Settings of the checks: action ``inflate`` or ``drop``; layout_sigma_m [m]; z_max for a side;
    level: false-alarm probability of the time test per point; enabled: run the checks at all."""

    action: str = "inflate"
    layout_sigma_m: float = 0.001
    z_max: float = 4.0
    level: float = 1e-4
    enabled: bool = True

    def __post_init__(self):
        if self.action not in ("inflate", "drop"):
            raise ValueError("checks.action must be 'inflate' or 'drop'")
        if not (self.layout_sigma_m >= 0 and self.z_max > 0 and 0 < self.level < 0.5):
            raise ValueError("checks: need layout_sigma_m ≥ 0, z_max > 0 and 0 < level < 0.5")


@dataclass
class CheckResult:
    """Per point (F, M): ``flag`` text ('' = passed), ``inflation`` (F, M, 3, 3) [m²] to add to the
    covariance, and the median scale s [m] of the time prediction."""

    flag: np.ndarray
    inflation: np.ndarray
    prediction_sigma: float


def layout_check(xyz: np.ndarray, cov: np.ndarray, layout: np.ndarray, cfg: CheckConfig):
    """Layout test of one frame: xyz (M, 3), cov (M, 3, 3). Returns (flagged (M,) bool, inflation
    (M, 3, 3), ambiguous: whether the culprit could not be told)."""
    M = len(layout)
    ok = np.all(np.isfinite(xyz), axis=1)
    flagged = np.zeros(M, bool)
    infl = np.zeros((M, 3, 3))
    if ok.sum() < 3:
        return flagged, infl, False
    D = np.linalg.norm(layout[:, None] - layout[None], axis=2)
    bad = {}
    for m, n in itertools.combinations(np.flatnonzero(ok), 2):
        v = xyz[m] - xyz[n]
        d = np.linalg.norm(v)
        g = v / d
        var = g @ (cov[m] + cov[n]) @ g + cfg.layout_sigma_m ** 2
        bad[(m, n)] = (abs(d - D[m, n]) / np.sqrt(var) > cfg.z_max, d - D[m, n], g)
    if not any(b[0] for b in bad.values()):
        return flagged, infl, False
    all_bad = all(b[0] for b in bad.values())
    for m in np.flatnonzero(ok):
        sides = [(k, b) for k, b in bad.items() if m in k]
        if all(b[0] for _, b in sides) and (all_bad or len(sides) < len(bad)):
            flagged[m] = True
            for _, (_, diff, g) in sides:
                infl[m] += diff * diff * np.outer(g, g)
    return flagged, infl, all_bad


def _poses(xyz: np.ndarray, usable: np.ndarray, layout: np.ndarray) -> dict:
    """{frame: (R, c)} for frames with ≥ 3 usable markers."""
    out = {}
    for f in range(len(xyz)):
        ok = usable[f]
        if ok.sum() >= 3:
            R, c, _ = kabsch(layout[ok], xyz[f, ok])
            out[f] = (R, c)
    return out


def predict_from_neighbours(poses: dict, f: int, layout: np.ndarray, half: int = 2):
    """Marker positions (M, 3) at frame f interpolated from the poses of frames f ± 1 … f ± half, or
    None without a pose on each side and three in all."""
    near = [k for k in range(f - half, f + half + 1) if k != f and k in poses]
    if len(near) < 3 or not any(k < f for k in near) or not any(k > f for k in near):
        return None
    t = np.array(near, float) - f
    C = np.array([poses[k][1] for k in near])
    c_f = np.linalg.lstsq(np.vander(t, 3), C, rcond=None)[0][-1]
    k0 = min(near, key=lambda k: abs(k - f))
    R0 = poses[k0][0]
    rv = np.array([_rotvec(poses[k][0] @ R0.T) for k in near])
    B = np.vander(t, 2)
    phi_f = np.linalg.lstsq(B, rv, rcond=None)[0][-1]
    return layout @ (_rotmat(phi_f) @ R0).T + c_f


def _local_sigma(errs: dict, f: int, half: int = 5) -> float:
    """Scale s [m] of the time prediction around frame f: from the points of frames f − half … f + half other
    than f, s² = q₉₀(max(|e|² − tr Σ, 0) / 3) / 2.08 (2.08: the 90 % quantile of χ²(3)/3; the upper
    quantile, because the prediction is worse for a marker far from the disc's centre); 0 with fewer than
    4 points."""
    vals = [max(float(e @ e - np.trace(S)), 0.0) / 3 for k in range(f - half, f + half + 1) if k != f
            for e, S in errs.get(k, [])]
    if len(vals) < 4:
        return 0.0
    return float(np.sqrt(np.quantile(vals, 0.9) / 2.08))


def check_points(xyz: np.ndarray, cov: np.ndarray, layout: np.ndarray, cfg: CheckConfig) -> CheckResult:
    """Layout and time checks of every point: xyz (F, M, 3) [m], cov (F, M, 3, 3) [m²] (module docstring)."""
    F, M = xyz.shape[:2]
    flag = np.full((F, M), "", dtype=object)
    infl = np.zeros((F, M, 3, 3))
    if not cfg.enabled:
        return CheckResult(flag, infl, 0.0)
    ok = np.all(np.isfinite(xyz), axis=2)
    usable = ok.copy()
    for f in range(F):
        bad, add, ambiguous = layout_check(xyz[f], cov[f], layout, cfg)
        for m in np.flatnonzero(bad):
            flag[f, m] = "layout (culprit unclear)" if ambiguous else "layout"
            infl[f, m] += add[m]
            usable[f, m] = False
        if ambiguous:
            usable[f] = False
    poses = _poses(xyz, usable, layout)
    preds, errs = {}, {}
    for f in range(F):
        if not ok[f].any():
            continue
        X = predict_from_neighbours(poses, f, layout)
        if X is None:
            continue
        preds[f] = X
        errs[f] = [(xyz[f, m] - X[m], cov[f, m]) for m in np.flatnonzero(ok[f] & usable[f])]
    limit = chi2_dist.ppf(1 - cfg.level, 3)
    scales = []
    for f, X in preds.items():
        s = _local_sigma(errs, f)
        scales.append(s)
        for m in np.flatnonzero(ok[f]):
            e = xyz[f, m] - X[m]
            q = e @ np.linalg.solve(cov[f, m] + s * s * np.eye(3), e)
            if q > limit:
                flag[f, m] = (flag[f, m] + "; " if flag[f, m] else "") + f"time (χ² {q:.0f})"
                infl[f, m] += np.outer(e, e) + s * s * np.eye(3)
    return CheckResult(flag, infl, float(np.median(scales)) if scales else 0.0)
