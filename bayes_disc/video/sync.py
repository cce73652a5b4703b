"""Camera synchronisation from the footage itself.

**Integer frame offsets** (:func:`estimate_frame_offsets`). A camera's ``frame_offset`` k means its frame i
was exposed at reference frame i + k. For two cameras a, b and a candidate relative offset Δ = k_b − k_a,
frame i of a is paired with frame i + k_a − k_b of b, and every blob is compared with the epipolar lines
of the other camera's blobs: with x the undistorted normalised coordinates and E = [t]ₓ R the essential
matrix of the pair, the distance of x_b to the line E x_a, in pixels of b (× f_b), and the reverse. The
pair's cost at Δ is the mean over all blobs of min(d, τ)² / τ² (d: distance to the nearest line; τ =
``tau_px``, by default half the blobs' typical motion per frame, at least 3 px, so that a camera
exposed a fraction of a frame late still matches): close to 0 when the frames show the same instant,
close to 1 when they do not. The offsets of
cameras whose offset is not given minimise the sum of the pair costs over all pairs of cameras (weighted
by the blobs compared), with the given offsets fixed — or, when none is given, the first camera's
offset fixed at 0 (the reference frames are then that camera's frames). Every offset within
±``max_offset`` frames is tried (exhaustively for up to three free cameras, one camera at a time beyond).

**Sub-frame delays** (:func:`estimate_subframe`): a camera exposed δ frames after the reference instant
sees each marker where it was at f + δ; its labelled 2-D tracks are shifted back by −δ (quadratic
interpolation through the neighbouring frames, :mod:`.refine`) and δ is chosen to minimise the
reprojection χ² of all points (golden-section search in [−½, ½] per camera, cameras in turn, twice).
Its standard error is read from the curvature of the χ² (Δχ² = 1).
"""
from __future__ import annotations

import itertools
from dataclasses import dataclass, field

import numpy as np

from .camera import Camera


@dataclass
class SyncResult:
    """Frame offsets per camera: ``offsets`` {camera: k} (integer frames), ``subframe`` {camera: δ}
    [frames], ``subframe_se`` {camera: standard error of δ}, ``source`` {camera: ``config`` or
    ``estimated``}, ``cost`` {camera: (best, second best) summed pair cost per blob} and ``messages``
    (lines for the log)."""

    offsets: dict
    subframe: dict = field(default_factory=dict)
    subframe_se: dict = field(default_factory=dict)
    source: dict = field(default_factory=dict)
    cost: dict = field(default_factory=dict)
    messages: list = field(default_factory=list)

    def total(self, name: str) -> float:
        """A camera's offset in frames, integer part plus sub-frame delay."""
        return self.offsets[name] + self.subframe.get(name, 0.0)

    def as_dict(self) -> dict:
        """The offsets for the track metadata (JSON)."""
        return {n: {"frame_offset": int(self.offsets[n]), "subframe": round(float(self.subframe.get(n, 0.0)), 4),
                    "subframe_se": (round(float(self.subframe_se[n]), 4) if n in self.subframe_se else None),
                    "source": self.source.get(n, "config"),
                    "cost": [round(float(c), 4) for c in self.cost[n]] if n in self.cost else None}
                for n in self.offsets}


def _essential(a: Camera, b: Camera) -> np.ndarray:
    R = b.R @ a.R.T
    t = b.t - R @ a.t
    tx = np.array([[0, -t[2], t[1]], [t[2], 0, -t[0]], [-t[1], t[0], 0]])
    return tx @ R


def epipolar_distances(a: Camera, b: Camera, uv_a: np.ndarray, uv_b: np.ndarray) -> np.ndarray:
    """Symmetric epipolar distances (n_a, n_b) [px] between blobs uv_a (n_a, 2) of camera a and uv_b
    (n_b, 2) of camera b: the mean of the distance of each to the other's epipolar line, in its own
    camera's pixels (normalised distance × focal length)."""
    E = _essential(a, b)
    xa = np.c_[a.undistort_pixels(uv_a), np.ones(len(uv_a))]
    xb = np.c_[b.undistort_pixels(uv_b), np.ones(len(uv_b))]
    lb = xa @ E.T                      # lines in b (n_a, 3)
    la = xb @ E                        # lines in a (n_b, 3)
    alg = xb @ E @ xa.T                # x_bᵀ E x_a (n_b, n_a)
    db = np.abs(alg.T) / np.hypot(lb[:, 0], lb[:, 1])[:, None] * b.K[0, 0]
    da = np.abs(alg.T) / np.hypot(la[:, 0], la[:, 1])[None, :] * a.K[0, 0]
    return 0.5 * (da + db)


def pair_cost(a: Camera, b: Camera, blobs_a: dict, blobs_b: dict, delta: int, tau_px: float) -> tuple[float, int]:
    """Cost (mean truncated squared distance / τ², see the module docstring) and number of blobs compared
    when frame i of camera a shows the instant of frame i − ``delta`` of camera b (Δ = k_b − k_a).
    blobs_a, blobs_b: {camera frame: blob centroids (n, 2) [px]}."""
    total, count = 0.0, 0
    for i, ua in blobs_a.items():
        ub = blobs_b.get(i - delta)
        if ub is None or len(ua) == 0 or len(ub) == 0:
            continue
        d = np.minimum(epipolar_distances(a, b, ua, ub), tau_px)
        total += float(np.sum(d.min(axis=1) ** 2) + np.sum(d.min(axis=0) ** 2)) / tau_px ** 2
        count += len(ua) + len(ub)
    return (total / count if count else np.inf), count


def typical_motion(blobs: list) -> float:
    """Median image motion [px/frame] of the blobs: over cameras and consecutive frames holding the same
    number of blobs, the distance the centre of the blobs moved (0 when no frames compare)."""
    steps = []
    for per_camera in blobs:
        for i, u in per_camera.items():
            v = per_camera.get(i + 1)
            if v is not None and len(u) and len(u) == len(v):
                steps.append(float(np.linalg.norm(v.mean(axis=0) - u.mean(axis=0))))
    return float(np.median(steps)) if steps else 0.0


def estimate_frame_offsets(cameras: list, names: list, blobs: list, given: dict, max_offset: int = 10,
                           tau_px: float = 3.0, min_blobs: int = 12) -> SyncResult:
    """Integer frame offsets of the cameras whose offset is not given.

    Parameters
    ----------
    cameras : list of Camera
    names : list of str
        Camera names, in the order of ``cameras``.
    blobs : list of dict
        Per camera {camera frame: usable blob centroids (n, 2) [px]}.
    given : dict
        {camera name: frame offset} from the configuration (the others are estimated).
    max_offset : int
        Offsets (relative to the fixed cameras) tried: −max_offset … +max_offset frames.
    tau_px : float
        Truncation of the epipolar distance [px].
    min_blobs : int
        A pairing of two cameras that compares fewer blobs than this does not count.

    Returns
    -------
    SyncResult
    """
    C = len(cameras)
    fixed = {c: int(given[n]) for c, n in enumerate(names) if n in given}
    if not fixed:
        fixed = {0: 0}
    free = [c for c in range(C) if c not in fixed]
    result = SyncResult(offsets={names[c]: k for c, k in fixed.items()},
                        source={names[c]: ("config" if names[c] in given else "reference") for c in fixed})
    if not free:
        return result
    span = max_offset + max((abs(k) for k in fixed.values()), default=0)
    table = {}
    for a, b in itertools.combinations(range(C), 2):
        if a in fixed and b in fixed:
            continue
        for d in range(-2 * span, 2 * span + 1):
            cost, n = pair_cost(cameras[a], cameras[b], blobs[a], blobs[b], d, tau_px)
            table[(a, b, d)] = (cost, n) if n >= min_blobs else (np.inf, 0)
    ref = int(np.median(list(fixed.values())))
    choices = range(ref - max_offset, ref + max_offset + 1)

    def pairs(assign: dict, camera=None):
        for a, b in itertools.combinations(range(C), 2):
            if (a in fixed and b in fixed) or (camera is not None and camera not in (a, b)):
                continue
            yield table[(a, b, assign[b] - assign[a])]

    def total(assign: dict) -> float:
        num = den = 0.0
        for cost, n in pairs(assign):
            if n and np.isfinite(cost):
                num += cost * n
                den += n
        return num / den if den else np.inf

    scored = _search(free, fixed, choices, total)
    best_assign, best = scored[0]
    for c in free:
        alt = [s for a, s in scored if a[c] != best_assign[c]]
        second = min(alt) if alt else np.inf
        result.offsets[names[c]] = int(best_assign[c])
        result.source[names[c]] = "estimated"
        result.cost[names[c]] = (best, second)
        if not any(n for _, n in pairs(best_assign, c)):
            raise ValueError(f"camera {names[c]}: no frames overlap with the other cameras' for any offset within "
                             f"±{max_offset}; give its frame_offset")
        note = "" if second - best > 0.1 else " (weakly determined: the next best offset fits almost as well)"
        result.messages.append(f"camera {names[c]}: frame offset {best_assign[c]} estimated from the footage "
                               f"(epipolar cost {best:.3f}, next best {second:.3f}){note}")
    return result


def _search(free: list, fixed: dict, choices, total) -> list:
    """Assignments of offsets to the free cameras with their total cost, best first: exhaustive for up to
    three free cameras, else one camera at a time (each against those already placed)."""
    if len(free) <= 3:
        out = []
        for combo in itertools.product(choices, repeat=len(free)):
            assign = dict(fixed)
            assign.update(zip(free, combo))
            out.append((assign, total(assign)))
        return sorted(out, key=lambda x: x[1])
    assign = dict(fixed)
    for c in free:
        best = min(choices, key=lambda k: total({**assign, c: k, **{o: assign.get(o, k) for o in free}}))
        assign[c] = best
    variants = [(assign, total(assign))]
    for c in free:
        for k in choices:
            if k != assign[c]:
                variants.append(({**assign, c: k}, total({**assign, c: k})))
    return sorted(variants, key=lambda x: x[1])


def centre_velocity(blobs: dict, i: int) -> np.ndarray:
    """Image velocity [px/frame] of the centre of a camera's blobs around its frame i: central difference
    of the centres in frames i ± 1, else a one-sided one; zero when no two neighbouring frames hold the
    same number of blobs. blobs: {camera frame: centroids (n, 2)}."""
    def centre(k):
        u = blobs.get(k)
        return (None, 0) if u is None or len(u) == 0 else (u.mean(axis=0), len(u))

    (a, na), (c, nc), (b, nb) = centre(i - 1), centre(i), centre(i + 1)
    if a is not None and b is not None and na == nb:
        return (b - a) / 2
    if c is not None and b is not None and nc == nb:
        return b - c
    if a is not None and c is not None and na == nc:
        return c - a
    return np.zeros(2)


def _match(u: np.ndarray, other, shift: np.ndarray, radius: float) -> np.ndarray:
    """For each blob u (n, 2), the blob of ``other`` (k, 2) nearest to u + shift if within ``radius``
    and that blob's nearest in return (mutual); NaN rows otherwise."""
    out = np.full(u.shape, np.nan)
    if other is None or len(other) == 0 or len(u) == 0:
        return out
    d = np.linalg.norm((u + shift)[:, None] - other[None], axis=2)
    j = np.argmin(d, axis=1)
    back = np.argmin(d, axis=0)
    ok = (d[np.arange(len(u)), j] < radius) & (back[j] == np.arange(len(u)))
    out[ok] = other[j[ok]]
    return out


def moved_blobs(blobs: dict, delay: float) -> dict:
    """A camera's blobs exposed ``delay`` frames late, moved to the reference instants before any marker
    is labelled: each blob is matched with the nearest blob of the previous and next frames (after the
    motion of the blobs' centre, :func:`centre_velocity`; mutual nearest, within half the smallest
    distance between the frame's blobs) and the quadratic through the three (linear through two) is
    evaluated at −delay; an unmatched blob moves by −delay × the centre's velocity."""
    if abs(delay) < 1e-9:
        return blobs
    s = -delay
    out = {}
    for i, u in blobs.items():
        if len(u) == 0:
            out[i] = u
            continue
        v = centre_velocity(blobs, i)
        sep = np.linalg.norm(u[:, None] - u[None], axis=2) + np.eye(len(u)) * 1e9
        radius = max(1.0, 0.5 * float(sep.min())) if len(u) > 1 else 10.0
        prev, nxt = _match(u, blobs.get(i - 1), -v, radius), _match(u, blobs.get(i + 1), v, radius)
        both = np.all(np.isfinite(prev), axis=1) & np.all(np.isfinite(nxt), axis=1)
        res = u + s * v
        res[both] = (s * (s - 1) / 2) * prev[both] + (1 - s * s) * u[both] + (s * (s + 1) / 2) * nxt[both]
        only_n = ~both & np.all(np.isfinite(nxt), axis=1)
        res[only_n] = u[only_n] + s * (nxt[only_n] - u[only_n])
        only_p = ~both & ~only_n & np.all(np.isfinite(prev), axis=1)
        res[only_p] = u[only_p] - s * (prev[only_p] - u[only_p])
        out[i] = res
    return out


def coarse_subframe(cameras: list, names: list, blobs: list, offsets: dict, free: list, tau_px: float,
                    step: float = 0.05) -> dict:
    """First guess of the sub-frame delays {camera index: δ} of the cameras in ``free`` before any marker
    is labelled: each camera's blobs are moved by −δ × their centre's velocity (:func:`moved_blobs`) and
    δ is chosen on a grid of ``step`` in [−½, ½] to minimise the pair costs against the other cameras
    (cameras in turn, twice)."""
    C = len(cameras)
    delays = {c: 0.0 for c in range(C)}
    grid = np.arange(-0.5, 0.5 + 1e-9, step)
    for _ in range(2):
        for c in free:
            def cost(d):
                moved = moved_blobs(blobs[c], d)
                num = den = 0.0
                for o in range(C):
                    if o == c:
                        continue
                    other = moved_blobs(blobs[o], delays[o])
                    k = offsets[names[c]] - offsets[names[o]]
                    val, n = pair_cost(cameras[o], cameras[c], other, moved, k, tau_px)
                    if n and np.isfinite(val):
                        num += val * n
                        den += n
                return num / den if den else np.inf
            delays[c] = float(min(grid, key=cost))
    return delays


def golden_minimum(fun, lo: float, hi: float, tol: float = 1e-3) -> float:
    """Minimiser of a unimodal function on [lo, hi] by golden-section search (to ``tol``)."""
    g = (np.sqrt(5.0) - 1) / 2
    a, b = lo, hi
    c, d = b - g * (b - a), a + g * (b - a)
    fc, fd = fun(c), fun(d)
    while b - a > tol:
        if fc < fd:
            b, d, fd = d, c, fc
            c = b - g * (b - a)
            fc = fun(c)
        else:
            a, c, fc = c, d, fd
            d = a + g * (b - a)
            fd = fun(d)
    return 0.5 * (a + b)


def estimate_subframe(chi2_of, free: list, start: dict, sweeps: int = 2) -> tuple[dict, dict]:
    """Sub-frame delays of the cameras in ``free`` minimising ``chi2_of(delays)`` ({camera index: δ} →
    total reprojection χ²), starting from ``start``; cameras in turn, ``sweeps`` times. Returns the
    delays and their standard errors (from a parabola through the χ² at δ̂ ± 0.05: Δχ² = 1)."""
    delays = dict(start)
    for _ in range(sweeps):
        for c in free:
            delays[c] = golden_minimum(lambda d: chi2_of({**delays, c: d}), -0.5, 0.5)
    se = {}
    h = 0.05
    for c in free:
        f0 = chi2_of(delays)
        fp, fm = chi2_of({**delays, c: delays[c] + h}), chi2_of({**delays, c: delays[c] - h})
        curv = (fp + fm - 2 * f0) / (2 * h * h)       # χ² ≈ f0 + curv (δ − δ̂)²
        se[c] = float(1 / np.sqrt(curv)) if curv > 0 else float("inf")
    return delays, se
