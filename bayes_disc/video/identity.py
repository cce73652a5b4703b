"""Marker identity: which 3-D point is which marker, frame by frame.

The markers form a rigid, scalene layout p_m (body frame, m), so the side lengths D_mn = |p_m − p_n|
tell the markers apart. Each frame:

1. **Candidates.** Every pair of usable blobs in two cameras is triangulated; pairs whose RMS
   reprojection error is ≤ ``reprojection_px`` are kept and extended greedily with the nearest blob of
   every other camera (accepted while the RMS stays ≤ ``reprojection_px``). Candidates are distinct
   view sets {(camera, blob)}.
2. **Hypotheses.** A hypothesis assigns each marker one candidate or none; candidates sharing a blob
   cannot both be used. Its cost (χ²-like, smaller is better) is

       Σ_m assigned [ n_m (rms_m / reprojection_sigma_px)² − view_bonus·n_m + missing_view_cost·g_m
                      + |X_m − X̂_m|² / σ̂_m² ]
       + Σ_(m,n) both assigned (|X_m − X_n| − D_mn)² / side_sigma² + miss_cost · (#unassigned),

   where g_m counts cameras with blobs in which the candidate projects into the image but no blob lies
   near it (negative evidence: ghosts of wrong pairings rarely have a blob in the other cameras),

   with X̂_m, σ̂_m the constant-velocity prediction (below) when there is one. All hypotheses are
   evaluated (vectorised) and the cheapest is taken.
3. **Ambiguity.** A marker stays unlabelled (NaN) in that frame if some other hypothesis, at a cost
   within ``ambiguity_margin`` of the best, puts it > ``swap_distance_m`` away or puts another marker
   where it is: a guess is never written (e.g. one or two markers seen and no prediction, so which is
   which is unknown).
4. **Prediction.** After each frame the tracker fits the rigid pose (R, c) to ≥ 3 labelled markers
   (Kabsch). From the last two poses (≤ ``max_pose_gap`` frames apart) it extrapolates with constant
   linear and angular velocity: X̂_m = exp([ω]ₓ Δ) R p_m + c + v Δ, σ̂ = ``prediction_sigma_m`` · Δ
   (Δ frames ahead, ≤ ``max_gap_frames``). With only two markers it falls back to each marker's own
   constant velocity (σ̂ = ``cv_sigma_m`` · Δ). Candidates farther than ``gate_sigma`` σ̂ from every
   prediction are ignored while tracking.

Gaps stay NaN; nothing is interpolated.

**Layout check.** Without a prediction only the side lengths tell the markers apart: a relabelling π
of a perfectly measured layout costs Σ_(m<n) (D_π(m)π(n) − D_mn)² / side_sigma² more than the true
labelling, so if that is below ``ambiguity_margin`` for some π the markers can never be identified
(an isosceles or equilateral triangle). :func:`layout_distinctness` gives the smallest such change
of the side lengths; the track configuration rejects layouts below
``side_sigma_m · √max(ambiguity_margin, 1)``.
"""
from __future__ import annotations

import itertools
from dataclasses import dataclass, field

import numpy as np

from .camera import Camera
from .triangulation import triangulate


@dataclass(frozen=True)
class IdentityConfig:
    """Identity and candidate settings (see module docstring for the symbols)."""

    reprojection_px: float = 2.0
    reprojection_sigma_px: float = 0.5
    side_sigma_m: float = 0.003
    prediction_sigma_m: float = 0.01
    cv_sigma_m: float = 0.03
    gate_sigma: float = 5.0
    miss_cost: float = 25.0
    view_bonus: float = 1.0
    missing_view_cost: float = 4.0
    ambiguity_margin: float = 9.0
    swap_distance_m: float = 0.02
    max_gap_frames: int = 5
    max_pose_gap: int = 2
    pixel_sigma: float = 0.1
    min_views: int = 2

    def __post_init__(self):
        for name in ("reprojection_px", "reprojection_sigma_px", "side_sigma_m", "prediction_sigma_m", "cv_sigma_m", "gate_sigma",
                     "swap_distance_m", "pixel_sigma"):
            if not getattr(self, name) > 0:
                raise ValueError(f"identity.{name} must be positive")
        if self.min_views < 2:
            raise ValueError("identity.min_views must be ≥ 2")


@dataclass
class FrameLabels:
    """One frame's result for M markers: xyz (M, 3) [m] (NaN = not labelled), rms_px (M,), n_views (M,),
    cov (M, 3, 3) [m²], views (M, C) blob index per camera (−1 = not used), ambiguous (M,) bool."""

    xyz: np.ndarray
    rms_px: np.ndarray
    n_views: np.ndarray
    cov: np.ndarray
    views: np.ndarray
    ambiguous: np.ndarray

    @staticmethod
    def empty(M: int, C: int) -> "FrameLabels":
        return FrameLabels(np.full((M, 3), np.nan), np.full(M, np.nan), np.zeros(M, int),
                           np.full((M, 3, 3), np.nan), np.full((M, C), -1), np.zeros(M, bool))


@dataclass
class Candidates:
    """3-D candidates of a frame: views (K, C) blob index per camera (−1 unused), xyz (K, 3), rms_px (K,),
    n_views (K,), cov (K, 3, 3), n_missing (K,): cameras with blobs where the candidate should be
    visible but no blob is near its projection."""

    views: np.ndarray
    xyz: np.ndarray
    rms_px: np.ndarray
    n_views: np.ndarray
    cov: np.ndarray
    n_missing: np.ndarray = None

    def __len__(self):
        return len(self.views)


def _gather(blob_uv: list, views: np.ndarray) -> np.ndarray:
    """Per-blob arrays (n_c, ...) of each camera gathered for candidates' views (K, C) → (K, C, ...) (NaN
    where a view is unused)."""
    K, C = views.shape
    uv = np.full((K, C) + blob_uv[0].shape[1:], np.nan) if blob_uv else np.full((K, C, 2), np.nan)
    for c in range(C):
        sel = views[:, c] >= 0
        if sel.any():
            uv[sel, c] = blob_uv[c][views[sel, c]]
    return uv


def _gathered_cov(blob_cov, views):
    return None if blob_cov is None else _gather(blob_cov, views)


def build_candidates(cameras: list[Camera], blob_uv: list, cfg: IdentityConfig, predictions=None,
                     gate_m=None, blob_cov=None) -> Candidates:
    """Candidate 3-D points from usable blob centroids ``blob_uv[c]`` (n_c, 2) of each camera.

    predictions (M, 3) and gate_m (M,): when given, candidates farther than gate_m from every
    prediction are dropped (tracking mode). blob_cov: per camera (n_c, 2, 2) centroid covariances [px²]
    for the candidates' covariances (default: isotropic ``cfg.pixel_sigma``).
    """
    C = len(cameras)
    pairs = []
    for a, b in itertools.combinations(range(C), 2):
        na, nb = len(blob_uv[a]), len(blob_uv[b])
        if na == 0 or nb == 0:
            continue
        ia, ib = np.meshgrid(np.arange(na), np.arange(nb), indexing="ij")
        v = np.full((na * nb, C), -1)
        v[:, a] = ia.ravel()
        v[:, b] = ib.ravel()
        pairs.append(v)
    if not pairs:
        return _no_candidates(C)
    views = np.concatenate(pairs)
    tri = triangulate(cameras, _gather(blob_uv, views), pixel_sigma=cfg.pixel_sigma, iterations=4,
                      uv_cov=_gathered_cov(blob_cov, views))
    keep = np.isfinite(tri.rms_px) & (tri.rms_px <= cfg.reprojection_px)
    keep &= _in_front(cameras, tri.xyz, views)
    if predictions is not None:
        keep &= _near_prediction(tri.xyz, predictions, gate_m)
    views, X = views[keep], tri.xyz[keep]
    if len(views) == 0:
        return _no_candidates(C)
    # greedy extension with the nearest blob of the other cameras
    ext = views.copy()
    for c in range(C):
        if len(blob_uv[c]) == 0:
            continue
        free = ext[:, c] < 0
        if not free.any():
            continue
        p = cameras[c].project(X[free])
        d = np.linalg.norm(p[:, None, :] - blob_uv[c][None, :, :], axis=2)
        d = np.where(np.isfinite(d), d, np.inf)
        j = np.argmin(d, axis=1)
        close = d[np.arange(len(j)), j] <= 3 * cfg.reprojection_px
        idx = np.flatnonzero(free)[close]
        ext[idx, c] = j[close]
    grown = np.any(ext != views, axis=1)
    all_views = np.concatenate([views, ext[grown]])
    all_views = np.unique(all_views, axis=0)
    tri = triangulate(cameras, _gather(blob_uv, all_views), pixel_sigma=cfg.pixel_sigma,
                      uv_cov=_gathered_cov(blob_cov, all_views))
    ok = np.isfinite(tri.rms_px) & (tri.rms_px <= cfg.reprojection_px) & (tri.n_views >= cfg.min_views)
    ok &= _in_front(cameras, tri.xyz, all_views)
    if predictions is not None:
        ok &= _near_prediction(tri.xyz, predictions, gate_m)
    views, X = all_views[ok], tri.xyz[ok]
    missing = np.zeros(len(views), int)
    for c, cam in enumerate(cameras):
        if len(blob_uv[c]) == 0 or len(views) == 0:
            continue
        free = views[:, c] < 0
        if not free.any():
            continue
        p = cam.project(X[free])
        inside = np.all(np.isfinite(p), axis=1) & cam.in_image(p)
        d = np.min(np.linalg.norm(p[:, None, :] - blob_uv[c][None, :, :], axis=2), axis=1)
        missing[np.flatnonzero(free)[inside & ~(d <= 3 * cfg.reprojection_px)]] += 1
    return Candidates(views, X, tri.rms_px[ok], tri.n_views[ok], tri.cov[ok], missing)


def _no_candidates(C: int) -> Candidates:
    return Candidates(np.zeros((0, C), int), np.zeros((0, 3)), np.zeros(0), np.zeros(0, int), np.zeros((0, 3, 3)),
                      np.zeros(0, int))


def _in_front(cameras, X, views) -> np.ndarray:
    ok = np.all(np.isfinite(X), axis=1)
    for c, cam in enumerate(cameras):
        sel = views[:, c] >= 0
        if sel.any():
            z = cam.depth(np.where(np.isfinite(X[sel]), X[sel], 0))
            ok[sel] &= z > 0
    return ok


def _near_prediction(X, predictions, gate_m) -> np.ndarray:
    P = np.asarray(predictions, float)
    g = np.asarray(gate_m, float)
    valid = np.all(np.isfinite(P), axis=1)
    if not valid.any():
        return np.ones(len(X), bool)
    d = np.linalg.norm(X[:, None, :] - P[None, valid, :], axis=2)
    return np.any(d <= g[None, valid], axis=1)


def label_frame(cameras: list[Camera], blob_uv: list, layout: np.ndarray, cfg: IdentityConfig,
                predictions=None, pred_sigma=None, blob_cov=None) -> FrameLabels:
    """Label one frame. blob_uv: per camera, usable blob centroids (n_c, 2) [px]; layout (M, 3):
    body-frame marker positions [m]; predictions (M, 3) with NaN rows for markers without prediction,
    pred_sigma (M,) [m] (None: acquisition without prediction); blob_cov: per camera, the centroids'
    covariances (n_c, 2, 2) [px²] (default: isotropic ``cfg.pixel_sigma``).

    Long: acquisition and tracking share the candidate search and the assignment's bookkeeping."""
    M, C = len(layout), len(cameras)
    tracking = predictions is not None and np.any(np.all(np.isfinite(predictions), axis=1))
    gate = None
    full_prediction = tracking and bool(np.all(np.isfinite(predictions)))
    if full_prediction:
        gate = cfg.gate_sigma * np.asarray(pred_sigma, float)
    cands = build_candidates(cameras, blob_uv, cfg, predictions if full_prediction else None, gate, blob_cov)
    out = FrameLabels.empty(M, C)
    K = len(cands)
    if K == 0:
        return out
    D = np.linalg.norm(layout[:, None, :] - layout[None, :, :], axis=2)
    # unary costs U[m, k] for k in 0..K-1; index K = unassigned
    U = np.empty((M, K + 1))
    base = (cands.n_views * (cands.rms_px / cfg.reprojection_sigma_px) ** 2 - cfg.view_bonus * cands.n_views
            + cfg.missing_view_cost * cands.n_missing)
    U[:, :K] = base[None, :]
    U[:, K] = cfg.miss_cost
    allowed = np.ones((M, K), bool)
    if tracking:
        P = np.asarray(predictions, float)
        s = np.asarray(pred_sigma, float)
        for m in range(M):
            if np.all(np.isfinite(P[m])):
                d = np.linalg.norm(cands.xyz - P[m], axis=1)
                U[m, :K] += (d / s[m]) ** 2
                allowed[m] = d <= cfg.gate_sigma * s[m]
    # options per marker; with a prediction the unary costs rank the candidates and the enumeration keeps
    # the cheapest few, without one they are alike and all are kept (up to a bound)
    keep = min(12 if tracking else 40, max(3, int(2e5 ** (1.0 / M)) - 1))  # at most ~2·10⁵ hypotheses
    opts = []
    for m in range(M):
        ks = np.flatnonzero(allowed[m])
        if len(ks) > keep:
            ks = ks[np.argsort(U[m, ks], kind="stable")[:keep]]
        opts.append(np.append(ks, K))
    grid = np.stack(np.meshgrid(*opts, indexing="ij"), axis=-1).reshape(-1, M)
    cost = np.zeros(len(grid))
    for m in range(M):
        cost += U[m, grid[:, m]]
    valid = np.ones(len(grid), bool)
    # conflicts: same candidate or shared blob
    share = np.zeros((K + 1, K + 1), bool)
    V = cands.views
    for c in range(C):
        col = V[:, c]
        share[:K, :K] |= (col[:, None] == col[None, :]) & (col[:, None] >= 0)
    X = np.vstack([cands.xyz, np.full((1, 3), np.nan)])
    for m, n in itertools.combinations(range(M), 2):
        a, b = grid[:, m], grid[:, n]
        both = (a < K) & (b < K)
        valid &= ~(both & share[a, b])
        dist = np.linalg.norm(X[a] - X[b], axis=1)
        cost += np.where(both, ((dist - D[m, n]) / cfg.side_sigma_m) ** 2, 0.0)
    cost = np.where(valid, cost, np.inf)
    best = int(np.argmin(cost))
    if not np.isfinite(cost[best]):
        return out
    h = grid[best]
    # ambiguity: another hypothesis within the margin that puts marker m somewhere else
    pos = X[grid]  # (H, M, 3)
    for m in range(M):
        k = h[m]
        if k == K:
            continue
        d = np.linalg.norm(pos[:, m, :] - X[k], axis=1)
        rival = (grid[:, m] < K) & (d > cfg.swap_distance_m)          # m is somewhere else
        for n in range(M):                                               # or someone else is where m is
            if n != m:
                rival |= (grid[:, n] < K) & (np.linalg.norm(pos[:, n, :] - X[k], axis=1) <= cfg.swap_distance_m)
        if rival.any() and np.min(cost[rival]) < cost[best] + cfg.ambiguity_margin:
            out.ambiguous[m] = True
            continue
        out.xyz[m] = cands.xyz[k]
        out.rms_px[m] = cands.rms_px[k]
        out.n_views[m] = cands.n_views[k]
        out.cov[m] = cands.cov[k]
        out.views[m] = cands.views[k]
    return out


def layout_distinctness(layout) -> float:
    """Smallest change of the side lengths [m] under a relabelling of the markers:
    min over permutations π ≠ identity of sqrt(Σ_(m<n) (D_π(m)π(n) − D_mn)²), D_mn = |p_m − p_n|.

    0 for a layout with a symmetry (isosceles or equilateral triangle): its markers cannot be told
    apart by side lengths. layout (M, 3) body positions [m]; NaN for M > 7 (not evaluated) or M < 2.
    """
    P = np.asarray(layout, float).reshape(-1, 3)
    M = len(P)
    if M < 2 or M > 7:
        return float("nan")
    D = np.linalg.norm(P[:, None, :] - P[None, :, :], axis=2)
    iu = np.triu_indices(M, 1)
    best = np.inf
    for perm in itertools.permutations(range(M)):
        if perm == tuple(range(M)):
            continue
        pi = np.asarray(perm)
        best = min(best, float(np.sqrt(np.sum((D[pi[:, None], pi[None, :]][iu] - D[iu]) ** 2))))
    return best


def kabsch(body: np.ndarray, world: np.ndarray):
    """Rigid fit world ≈ R body + c for ≥ 3 corresponding points (rows); returns R (3, 3), c (3,), RMS [m]."""
    bc, wc = body.mean(axis=0), world.mean(axis=0)
    H = (body - bc).T @ (world - wc)
    U, _, Vt = np.linalg.svd(H)
    d = np.sign(np.linalg.det(Vt.T @ U.T))
    R = Vt.T @ np.diag([1, 1, d]) @ U.T
    c = wc - R @ bc
    rms = float(np.sqrt(np.mean(np.sum((body @ R.T + c - world) ** 2, axis=1))))
    return R, c, rms


def _rotvec(R):
    """Rotation vector (axis·angle) of R."""
    cos = np.clip((np.trace(R) - 1) / 2, -1, 1)
    ang = np.arccos(cos)
    if ang < 1e-12:
        return np.zeros(3)
    w = np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])
    if np.pi - ang < 1e-6:  # near π: axis from the symmetric part
        B = (R + np.eye(3)) / 2
        axis = np.sqrt(np.clip(np.diag(B), 0, None))
        i = int(np.argmax(axis))
        axis = B[i] / axis[i]
        return axis / np.linalg.norm(axis) * ang
    return w / (2 * np.sin(ang)) * ang


def _rotmat(rv):
    ang = np.linalg.norm(rv)
    if ang < 1e-12:
        return np.eye(3)
    k = rv / ang
    Kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(ang) * Kx + (1 - np.cos(ang)) * Kx @ Kx


@dataclass
class Tracker:
    """Constant-velocity predictor of the marker positions (rigid pose when ≥ 3 markers are known)."""

    layout: np.ndarray
    cfg: IdentityConfig
    poses: list = field(default_factory=list)      # (frame, R, c)
    points: list = field(default_factory=list)     # (frame, xyz (M, 3))

    def update(self, frame: int, xyz: np.ndarray) -> None:
        xyz = np.asarray(xyz, float)
        seen = np.all(np.isfinite(xyz), axis=1)
        if seen.sum() >= 1:
            self.points.append((frame, xyz.copy()))
            self.points = self.points[-3:]
        if seen.sum() >= 3:
            R, c, rms = kabsch(self.layout[seen], xyz[seen])
            if rms < 5 * self.cfg.side_sigma_m:
                self.poses.append((frame, R, c))
                self.poses = self.poses[-2:]

    def predict(self, frame: int):
        """Predicted positions (M, 3) (NaN rows where unknown) and σ (M,) [m], or (None, None)."""
        M = len(self.layout)
        if len(self.poses) == 2:
            (f2, R2, c2), (f1, R1, c1) = self.poses
            ahead = frame - f1
            if 0 < f1 - f2 <= self.cfg.max_pose_gap and 0 < ahead <= self.cfg.max_gap_frames:
                w = _rotvec(R1 @ R2.T) / (f1 - f2)
                R = _rotmat(w * ahead) @ R1
                c = c1 + (c1 - c2) / (f1 - f2) * ahead
                return self.layout @ R.T + c, np.full(M, self.cfg.prediction_sigma_m * ahead)
        if len(self.points) >= 2:
            (f2, X2), (f1, X1) = self.points[-2], self.points[-1]
            ahead = frame - f1
            if 0 < f1 - f2 <= self.cfg.max_pose_gap and 0 < ahead <= self.cfg.max_gap_frames:
                pred = X1 + (X1 - X2) / (f1 - f2) * ahead
                if np.any(np.all(np.isfinite(pred), axis=1)):
                    return pred, np.full(M, self.cfg.cv_sigma_m * ahead)
        return None, None
