"""Newton–Euler equations of the spinning disc (docs/conventions.md, Hummel & Hubbard 2002 eqs. 1–2).

Readable numpy reference of the model; the compiled simulator (:mod:`bayes_disc.physics.kernel`)
implements the same equations for batches and is tested against this module.

State vector y (13): centre-of-mass position r_W [m] (3), velocity v_W [m/s] (3), attitude quaternion
q = (w, x, y, z) body→world (4), body-frame angular velocity ω_B [rad/s] (3).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .constants import Coefficients, Disc, Environment
from .frames import quat_to_matrix, velocity_frame

STATE_SIZE = 13
POS, VEL, QUAT, OMEGA = slice(0, 3), slice(3, 6), slice(6, 10), slice(10, 13)


@dataclass(frozen=True)
class Loads:
    """Aerodynamic force F_W [N] and moment M_W [N m] (world frame) with the flight context."""

    force: np.ndarray
    moment: np.ndarray
    alpha: float
    speed: float
    pqr: np.ndarray


def aerodynamic_loads(y, coefficients: Coefficients, disc: Disc, env: Environment,
                      terms=(), extension=None, t: float = 0.0) -> Loads:
    """Forces and moments of docs/conventions.md (plus any extra ``terms`` with parameters ``extension``)."""
    c = coefficients
    extension = np.zeros(0) if extension is None else np.asarray(extension, dtype=float)
    E = extension
    R = quat_to_matrix(y[QUAT])
    b3 = R[:, 2]
    wind = np.zeros(3)
    off = 0
    for term in terms:
        if term.air is not None:
            wind += np.array(term.air(E, off, t, y[0], y[1], y[2]))
        off += len(term.parameters)
    v_air = y[VEL] - wind
    D = velocity_frame(v_air, b3)
    alpha, speed = D.alpha, D.speed
    Q = 0.5 * env.rho * speed**2                      # dynamic pressure [Pa]
    A, d = disc.area, disc.diameter
    omega_W = R @ y[OMEGA]
    p, q, r = omega_W @ D.d1, omega_W @ D.d2, omega_W @ D.d3
    v_hat = v_air / speed if speed > 0 else np.zeros(3)
    lift = (c.CL0 + c.CLa * alpha) * Q * A                 # along d2 × v̂_a
    drag = (c.CD0 + c.CDa * alpha**2) * Q * A              # along −v̂_a
    roll = (c.CRr * r + c.CRp * p) * Q * A * d             # about d1
    pitch = (c.CM0 + c.CMa * alpha + c.CMq * q) * Q * A * d  # about d2, positive nose up
    spin = c.CNr * r * Q * A * d                           # about d3
    F = lift * np.cross(D.d2, v_hat) - drag * v_hat
    M = roll * D.d1 + pitch * D.d2 + spin * D.d3
    d1_body = R.T @ D.d1                                 # (cos β, sin β, 0): the airflow's azimuth in the disc
    ctx = (t, y[0], y[1], y[2], speed, alpha, Q, *v_air, *D.d1, *D.d2, *D.d3, p, q, r,
           A, d, disc.mass, env.rho, disc.Ia, disc.Id, d1_body[0], d1_body[1])
    off = 0
    for term in terms:
        if term.loads is not None:
            extra = np.array(term.loads(E, off, ctx))
            F = F + extra[:3]
            M = M + extra[3:]
        off += len(term.parameters)
    return Loads(force=F, moment=M, alpha=alpha, speed=speed, pqr=np.array([p, q, r]))


def state_derivative(t, y, coefficients: Coefficients, disc: Disc, env: Environment,
                     terms=(), extension=None) -> np.ndarray:
    """dy/dt of the rigid axisymmetric disc.

    m dv/dt = F − m g ẑ                                   (Newton)
    I dω_B/dt + ω_B × I ω_B = M_B,  I = diag(Id, Id, Ia)   (Euler, body frame)
    dq/dt = ½ q ⊗ (0, ω_B)                                (attitude kinematics)
    """
    y = np.asarray(y, dtype=float)
    loads = aerodynamic_loads(y, coefficients, disc, env, terms, extension, t)
    R = quat_to_matrix(y[QUAT])
    I = np.array([disc.Id, disc.Id, disc.Ia])
    w = y[OMEGA]
    M_B = R.T @ loads.moment
    dv = loads.force / disc.mass - np.array([0.0, 0.0, env.g])
    dw = (M_B - np.cross(w, I * w)) / I
    qw, qx, qy, qz = y[QUAT] / np.linalg.norm(y[QUAT])
    ox, oy, oz = w
    dq = 0.5 * np.array([
        -qx * ox - qy * oy - qz * oz,
        qw * ox + qy * oz - qz * oy,
        qw * oy - qx * oz + qz * ox,
        qw * oz + qx * oy - qy * ox,
    ])
    return np.concatenate([y[VEL], dv, dq, dw])


def marker_positions(states: np.ndarray, marker_body: np.ndarray) -> np.ndarray:
    """World positions (..., n_markers, 3) of body-frame markers for states (..., 13): r + R(q) m_B."""
    states = np.asarray(states, dtype=float)
    R = quat_to_matrix(states[..., QUAT])
    return states[..., None, POS] + np.einsum("...ij,mj->...mi", R, np.asarray(marker_body, float))


def kinetic_energy(y, disc: Disc) -> float:
    """T = ½ m |v|² + ½ ω_B·I ω_B [J]."""
    w = y[OMEGA]
    return 0.5 * disc.mass * y[VEL] @ y[VEL] + 0.5 * (disc.Id * (w[0]**2 + w[1]**2) + disc.Ia * w[2]**2)


def angular_momentum_world(y, disc: Disc) -> np.ndarray:
    """H_W = R(q) I ω_B [kg m²/s] about the centre of mass."""
    R = quat_to_matrix(y[QUAT])
    return R @ (np.array([disc.Id, disc.Id, disc.Ia]) * y[OMEGA])

