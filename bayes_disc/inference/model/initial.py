"""Initial conditions from the data alone: per-frame disc pose from the marker triangle, then position,
velocity, attitude and angular velocity (spin included) at the flight's first sample time."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...observation.markers import FlightObservation
from ...physics.frames import matrix_to_quat, quat_from_rotvec, quat_multiply, quat_to_rotvec


def rigid_fit(body: np.ndarray, world: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """Least-squares rigid transform world ≈ c + R body (Kabsch/Umeyama without scale).

    Returns R (3, 3), c (3,) [m] and the RMS fit residual [m]."""
    mb, mw = body.mean(axis=0), world.mean(axis=0)
    H = (body - mb).T @ (world - mw)
    U, _, Vt = np.linalg.svd(H)
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(Vt.T @ U.T))])
    R = Vt.T @ D @ U.T
    c = mw - R @ mb
    rms = float(np.sqrt(np.mean(np.sum((world - (c + body @ R.T)) ** 2, axis=1))))
    return R, c, rms


@dataclass(frozen=True)
class Poses:
    """Per-frame poses where ≥ 3 markers are seen: times (k,), R (k, 3, 3), centre c (k, 3), fit RMS (k,)."""

    times: np.ndarray
    R: np.ndarray
    c: np.ndarray
    rms: np.ndarray


def frame_poses(obs: FlightObservation, marker_body: np.ndarray) -> Poses:
    seen = obs.observed
    t, Rs, cs, rms = [], [], [], []
    for i in range(obs.times.size):
        k = np.flatnonzero(seen[i])
        if k.size < 3:
            continue
        R, c, e = rigid_fit(marker_body[k], obs.positions[i, k])
        t.append(obs.times[i])
        Rs.append(R)
        cs.append(c)
        rms.append(e)
    if len(t) < 4:
        raise ValueError(f"flight {obs.name!r}: fewer than 4 frames with 3 markers; cannot estimate a start")
    return Poses(np.array(t), np.array(Rs), np.array(cs), np.array(rms))


def initial_state_from_data(obs: FlightObservation, marker_body: np.ndarray, window_s: float = 0.1) -> np.ndarray:
    """State (13,) at ``obs.times[0]`` from the first ``window_s`` of poses.

    Position and velocity: quadratic fit of the pose centres. Body angular velocity: the mean of the
    body-frame rotation vectors log(R_kᵀ R_{k+1}) / Δt (valid while the spin is below π·rate). Attitude:
    the first pose carried back to t0 with that angular velocity."""
    poses = frame_poses(obs, marker_body)
    t0 = obs.times[0]
    use = poses.times <= poses.times[0] + window_s
    if use.sum() < 4:
        use = np.arange(poses.times.size) < 4
    tt = poses.times[use] - t0
    deg = 2 if use.sum() >= 5 else 1
    coef = np.polynomial.polynomial.polyfit(tt, poses.c[use], deg)
    pos0 = coef[0]
    vel0 = coef[1]
    Ru = poses.R[use]
    rel = np.einsum("kji,kjl->kil", Ru[:-1], Ru[1:])  # R_kᵀ R_{k+1}
    dt = np.diff(tt)
    rv = quat_to_rotvec(matrix_to_quat(rel)) / dt[:, None]
    omega_b = np.median(rv, axis=0)
    q_first = matrix_to_quat(Ru[0])
    q0 = quat_multiply(q_first, quat_from_rotvec(-omega_b * tt[0]))
    return np.concatenate([pos0, vel0, q0, omega_b])
