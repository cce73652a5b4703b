"""Physical plausibility of marker flights, checked before any fitting.

A marker file can parse cleanly and still make no physical sense: exported with y as the vertical axis,
time in milliseconds, or recorded with a marker layout other than the configured one. A fit of such data
gives confident nonsense (or minutes of sampling and a traceback), so :func:`check_flights` stops first
with an :class:`ImplausibleDataError` (a :class:`MarkerFileError`: file, line of the flight's first row,
flight, reason and the likely fix; exit status 2 from the command line). The checks, in order:

1. **Samples.** At least :data:`MIN_POSE_FRAMES` = 4 sample times with 3 or more markers seen (a pose
   needs 3 markers; a quadratic start fit needs 4 poses).
2. **Sample interval.** The median interval between sample times must lie in
   [:data:`MIN_INTERVAL_S`, :data:`MAX_INTERVAL_S`] = [1e-4, 0.1] s, i.e. 10 Hz to 10 kHz: slower cannot
   follow a spinning, wobbling disc, faster is beyond motion capture. An interval of 1–100 "s" is time in
   milliseconds (8.3 at 120 Hz), of 100 or more is microseconds.
3. **Marker layout.** For every pair of markers, the median over frames of their distance in the data
   must match the distance in the configured body layout within :data:`LAYOUT_TOL_M` + :data:`LAYOUT_TOL_REL`
   × distance (3 mm + 3 %). Marker noise (≤ 3 mm per coordinate) moves a median over tens of frames by
   well under 1 mm; a marker glued a few mm off its nominal spot (which the ``marker_geometry`` data
   explanation estimates, prior sd 5 mm) stays inside; another disc's layout, swapped or mislabelled ids
   (≥ 11 mm for the default layout) and other units (a constant ratio between all pairs) do not.
4. **Speed.** The centre's speed, from quadratic fits of the per-frame rigid poses (Kabsch) over
   windows of :data:`WINDOW_S` = 0.15 s, must stay below :data:`MAX_SPEED_M_S` = 60 m/s (the fastest
   throws reach about 40 m/s).
5. **Gravity along −z.** Under the flight model (docs/conventions.md) the aerodynamic acceleration A = a − G (a the
   centre's acceleration, G = −g ẑ) lies in the plane of the velocity v and the disc normal n: lift is
   perpendicular to v in that plane, drag along −v. Hence, in still air, A has no component along
   e = n × v / |n × v| and no component along +v (air cannot push the disc forward). The score
   s(G) = √median[(A·e)² + max(0, A·v̂)²] / g over the windows (the median ignores a gust or a window
   spoilt by dropouts) is ≈ 0 for the true gravity (< 0.01 g on noise-free synthetic flights, up to
   ≈ 0.1 g with 3 mm marker noise); a side force (C_Y = 0.05) or a 4 m/s wind gave at most 0.25 g on
   synthetic flights (speeds 5–30 m/s, α up to 60°, wobble). Gravity put along a horizontal axis lateral
   to the throw adds g·|cos| of the angle between that axis and the disc's lateral axis: 0.5–1.5 g on
   the same flights exported y-up (less while the disc is rolled near 45°). The data fail when
   s(−g ẑ) > :data:`MAX_GRAVITY_SCORE` = 0.35 g, and the message names the axis (±x, ±y, ±z) with the
   lowest score if it passes, e.g. a y-up export (gravity along −y). The simpler test "vertical
   acceleration ≈ −g" is not used: lift exceeds the weight in a fast throw (a_z ≈ +0.9 g at release for 14 m/s and α = 7°), so a level glide has
   a_z ≈ 0 just like the lateral axis of a y-up export. Limitation: gravity along the *downrange* axis
   is lateral to nothing and, with strong drag, may pass; the least-squares RMS check
   (:func:`bayes_disc.inference.fitting.fit_checks.check_fit_plausible`) stops such data before sampling.
   Flights with fewer than :data:`MIN_WINDOWS` windows are not checked for gravity.

Inertial data are not checked here yet.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .markers import FlightObservation, MarkerFileError

MIN_POSE_FRAMES = 4
MIN_INTERVAL_S = 1e-4
MAX_INTERVAL_S = 0.1
LAYOUT_TOL_M = 0.003
LAYOUT_TOL_REL = 0.03
MAX_SPEED_M_S = 60.0
WINDOW_S = 0.15
MIN_WINDOW_FRAMES = 5
MIN_WINDOWS = 2
MAX_GRAVITY_SCORE = 0.35
#: windows where the velocity is within this sine of the disc normal are not used (e undefined)
MIN_SIN_NORMAL_VELOCITY = 0.2


class ImplausibleDataError(MarkerFileError):
    """Marker data that parse but make no physical sense; the message names file, line, flight and cause."""

    def __init__(self, obs: FlightObservation, problem: str):
        self.flight = obs.name
        super().__init__(obs.source or "<data>", obs.line, f"flight {obs.name!r}: {problem}")


@dataclass(frozen=True)
class FramePoses:
    """Rigid poses of the frames with ≥ 3 markers seen: times (k,) [s], R (k, 3, 3) body→world, c (k, 3) [m]."""

    times: np.ndarray
    R: np.ndarray
    c: np.ndarray


def rigid_fits(body: np.ndarray, world: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Batched least-squares rigid transforms world ≈ c + R body (Kabsch, no scale).

    Parameters
    ----------
    body : ndarray (m, 3)
        Marker positions in the body frame [m].
    world : ndarray (k, m, 3)
        The same markers in k frames [m] (all seen).

    Returns
    -------
    R : ndarray (k, 3, 3)
        Rotations body → world.
    c : ndarray (k, 3)
        Positions of the body origin [m].
    """
    mb, mw = body.mean(axis=0), world.mean(axis=1)
    H = np.einsum("mi,kmj->kij", body - mb, world - mw[:, None])
    U, _, Vt = np.linalg.svd(H)
    V = np.swapaxes(Vt, 1, 2)
    d = np.sign(np.linalg.det(V @ np.swapaxes(U, 1, 2)))
    D = np.zeros((len(world), 3, 3))
    D[:, 0, 0] = D[:, 1, 1] = 1.0
    D[:, 2, 2] = d
    R = V @ D @ np.swapaxes(U, 1, 2)
    c = mw - np.einsum("kij,j->ki", R, mb)
    return R, c


def frame_poses(obs: FlightObservation, marker_body: np.ndarray) -> FramePoses:
    """Poses of every frame with ≥ 3 markers seen (frames batched by which markers are seen).

    Parameters
    ----------
    obs : FlightObservation
        The flight.
    marker_body : ndarray (m, 3)
        Configured body positions [m] in ``obs.marker_ids`` order.

    Returns
    -------
    FramePoses
        In time order.
    """
    seen = obs.observed
    use = np.flatnonzero(seen.sum(axis=1) >= 3)
    R = np.empty((use.size, 3, 3))
    c = np.empty((use.size, 3))
    patterns, inverse = np.unique(seen[use], axis=0, return_inverse=True)
    for p, pattern in enumerate(patterns):
        rows = np.flatnonzero(inverse.ravel() == p)
        k = np.flatnonzero(pattern)
        R[rows], c[rows] = rigid_fits(marker_body[k], obs.positions[use[rows]][:, k])
    return FramePoses(obs.times[use], R, c)


@dataclass(frozen=True)
class Kinematics:
    """Centre velocity v (w, 3) [m/s], acceleration a (w, 3) [m/s²] and disc normal n (w, 3) at the
    middle of w windows."""

    v: np.ndarray
    a: np.ndarray
    n: np.ndarray


def window_kinematics(poses: FramePoses, window_s: float = WINDOW_S) -> Kinematics:
    """Quadratic fits of the pose centres over windows of ``window_s`` overlapping by half (windows with
    fewer than :data:`MIN_WINDOW_FRAMES` frames are left out; a flight shorter than ``window_s`` is one window).

    Parameters
    ----------
    poses : FramePoses
        Per-frame poses.
    window_s : float
        Window length [s].

    Returns
    -------
    Kinematics
        One row per window (possibly none for a short flight).
    """
    t = poses.times
    v, a, n = [], [], []
    if t.size >= MIN_WINDOW_FRAMES and t[-1] - t[0] < window_s:
        window_s = float(t[-1] - t[0])  # a short flight is one window
    start = 0
    while start < t.size and t[start] + window_s <= t[-1] + 1e-9:
        end = int(np.searchsorted(t, t[start] + window_s + 1e-9, side="right"))
        if end - start >= MIN_WINDOW_FRAMES:
            tt = t[start:end]
            mid = 0.5 * (tt[0] + tt[-1])
            coef = np.polynomial.polynomial.polyfit(tt - mid, poses.c[start:end], 2)
            v.append(coef[1])
            a.append(2.0 * coef[2])
            n.append(poses.R[start + int(np.argmin(np.abs(tt - mid))), :, 2])
        start = int(np.searchsorted(t, t[start] + 0.5 * window_s, side="left"))
    empty = np.zeros((0, 3))
    return Kinematics(np.array(v) if v else empty, np.array(a) if a else empty, np.array(n) if n else empty)


def gravity_score(kin: Kinematics, gravity: np.ndarray) -> float:
    """√median[(A·e)² + max(0, A·v̂)²] [m/s²] of the aerodynamic acceleration A = a − ``gravity`` (module
    docstring, check 5); NaN if no window has a usable velocity."""
    speed = np.linalg.norm(kin.v, axis=1)
    vhat = kin.v / np.maximum(speed, 1e-12)[:, None]
    cross = np.cross(kin.n, vhat)
    sin = np.linalg.norm(cross, axis=1)
    ok = (speed > 1e-6) & (sin > MIN_SIN_NORMAL_VELOCITY)
    if not ok.any():
        return float("nan")
    e = cross[ok] / sin[ok, None]
    A = kin.a[ok] - gravity
    lateral = np.einsum("ki,ki->k", A, e)
    forward = np.maximum(np.einsum("ki,ki->k", A, vhat[ok]), 0.0)
    return float(np.sqrt(np.median(lateral ** 2 + forward ** 2)))


AXES = {"+x": (0, 1.0), "-x": (0, -1.0), "+y": (1, 1.0), "-y": (1, -1.0), "+z": (2, 1.0), "-z": (2, -1.0)}

FIXES = {
    "-y": "the data look like a y-up export (gravity acts along −y): swap the y and z columns and negate the "
          "new y to stay right-handed (x, y, z) → (x, −z, y)",
    "+y": "the vertical axis is y pointing down: swap the y and z columns and negate the new z, "
          "(x, y, z) → (x, z, −y)",
    "-x": "the vertical axis is x: rotate the data so that z points up (docs/conventions.md)",
    "+x": "the vertical axis is x pointing down: rotate the data so that z points up (docs/conventions.md)",
    "+z": "z points down: negate z and y to stay right-handed, (x, y, z) → (x, −y, −z)",
}


def check_samples(obs: FlightObservation) -> None:
    """Check 1: at least :data:`MIN_POSE_FRAMES` sample times with ≥ 3 markers seen."""
    frames = int((obs.observed.sum(axis=1) >= 3).sum())
    if obs.times.size == 1:
        raise ImplausibleDataError(obs, f"has only 1 sample (t = {obs.times[0]:g} s); a flight needs at least "
                                   f"{MIN_POSE_FRAMES} samples with 3 markers seen")
    if frames < MIN_POSE_FRAMES:
        raise ImplausibleDataError(obs, f"has only {frames} sample(s) with 3 or more markers seen "
                                   f"(of {obs.times.size}); at least {MIN_POSE_FRAMES} are needed")


def check_interval(obs: FlightObservation) -> None:
    """Check 2: median sample interval in [:data:`MIN_INTERVAL_S`, :data:`MAX_INTERVAL_S`] s."""
    dt = float(np.median(np.diff(obs.times)))
    if MIN_INTERVAL_S <= dt <= MAX_INTERVAL_S:
        return
    if 1.0 <= dt < 100.0:
        why = f"time looks like milliseconds ({1e3 / dt:.0f} Hz if so): give seconds (docs/data-formats.md)"
    elif dt >= 100.0:
        why = f"time looks like microseconds ({1e6 / dt:.0f} Hz if so): give seconds (docs/data-formats.md)"
    else:
        why = "check the unit of the time column: docs/data-formats.md asks for seconds"
    raise ImplausibleDataError(obs, f"median sample interval {dt:.4g} s is outside [{MIN_INTERVAL_S:g}, "
                               f"{MAX_INTERVAL_S:g}] s (10 Hz to 10 kHz): {why}")


def check_layout(obs: FlightObservation, marker_body: np.ndarray) -> None:
    """Check 3: pairwise marker distances in the data (median over frames) against the configured layout."""
    seen = obs.observed
    ids = obs.marker_ids
    pairs = []
    for i in range(len(ids)):
        for j in range(i + 1, len(ids)):
            both = seen[:, i] & seen[:, j]
            if both.sum() == 0:
                continue
            data = float(np.median(np.linalg.norm(obs.positions[both, i] - obs.positions[both, j], axis=1)))
            layout = float(np.linalg.norm(marker_body[i] - marker_body[j]))
            pairs.append((ids[i], ids[j], data, layout))
    bad = [p for p in pairs if abs(p[2] - p[3]) > LAYOUT_TOL_M + LAYOUT_TOL_REL * p[3]]
    if not bad:
        return
    ratios = np.array([d / lay for _, _, d, lay in pairs if lay > 0])
    if ratios.size == len(pairs) and len(pairs) >= 3 and np.ptp(ratios) < 0.05 * np.median(ratios):
        raise ImplausibleDataError(obs, f"all marker distances are {np.median(ratios):.3g}× those of the configured "
                                   "layout: the config's markers and the data use different units (both metres)")
    a, b, d, lay = max(bad, key=lambda p: abs(p[2] - p[3]) - LAYOUT_TOL_REL * p[3])
    raise ImplausibleDataError(obs, f"markers {a!r} and {b!r} are {d * 1e3:.1f} mm apart in the data (median) but "
                               f"{lay * 1e3:.1f} mm in the configured layout: wrong layout in the config's "
                               "'markers', or marker ids swapped or mislabelled")


def check_speed(obs: FlightObservation, kin: Kinematics) -> None:
    """Check 4: the centre's speed below :data:`MAX_SPEED_M_S`."""
    if not kin.v.size:
        return
    speed = float(np.linalg.norm(kin.v, axis=1).max())
    if speed > MAX_SPEED_M_S:
        raise ImplausibleDataError(obs, f"the disc's centre moves at up to {speed:.3g} m/s (more than "
                                   f"{MAX_SPEED_M_S:g} m/s, faster than any throw): check the units of time "
                                   "(s) and positions (m)")


def check_gravity(obs: FlightObservation, kin: Kinematics, g: float) -> None:
    """Check 5: the accelerations agree with gravity along −z (module docstring)."""
    if kin.v.shape[0] < MIN_WINDOWS:
        return
    scores = {}
    for name, (axis, sign) in AXES.items():
        G = np.zeros(3)
        G[axis] = sign * g
        scores[name] = gravity_score(kin, G)
    s = scores["-z"]
    if not np.isfinite(s) or s <= MAX_GRAVITY_SCORE * g:
        return
    best = min((k for k in scores if k != "-z" and np.isfinite(scores[k])), key=scores.get, default=None)
    msg = (f"the accelerations do not fit gravity along −z (docs/conventions.md: z up): the aerodynamic force "
           f"would need "
           f"{s / g:.2f} g along the disc's side or pushing it forward (a disc's is near 0)")
    if best is not None and scores[best] <= MAX_GRAVITY_SCORE * g and scores[best] < 0.5 * s:
        msg += f"; with gravity along {best} it would be {scores[best] / g:.2f} g: {FIXES[best]}"
    raise ImplausibleDataError(obs, msg)


def check_flight(obs: FlightObservation, marker_body: np.ndarray, g: float) -> None:
    """All checks of the module docstring on one flight.

    Parameters
    ----------
    obs : FlightObservation
        The flight (as it will be fitted, i.e. after any time window).
    marker_body : ndarray (m, 3)
        Configured body positions [m] in ``obs.marker_ids`` order.
    g : float
        Gravitational acceleration [m/s²].

    Raises
    ------
    ImplausibleDataError
        The first failed check, with its likely cause and fix.
    """
    check_samples(obs)
    check_interval(obs)
    check_layout(obs, marker_body)
    kin = window_kinematics(frame_poses(obs, marker_body))
    check_speed(obs, kin)
    check_gravity(obs, kin, g)


def check_flights(flights, marker_body: np.ndarray, g: float) -> None:
    """:func:`check_flight` on every flight, in order (see there)."""
    for obs in flights:
        check_flight(obs, np.asarray(marker_body, float), g)
