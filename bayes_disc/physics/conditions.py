"""Flight conditions along simulated trajectories, air-relative as the model sees them (docs/conventions.md).

One definition of the air-relative velocity, the D frame, the angle of attack and the rates p, q, r
for every caller (diagnostics, report, synthetic data): the wind of the model's terms (their ``air``
hooks, :mod:`.terms`) is subtracted exactly as the integrator does, so α here is the α of the forces.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .frames import quat_to_matrix


@dataclass(frozen=True)
class FlightConditions:
    """Air-relative flight conditions of B trajectories at n samples.

    Attributes
    ----------
    v_air : numpy.ndarray, shape (B, n, 3)
        Air-relative velocity v − wind [m/s], world axes.
    speed : numpy.ndarray, shape (B, n)
        |v_air| [m/s].
    d1, d2, d3 : numpy.ndarray, shape (B, n, 3)
        D frame (world components); d1 is zero where v_air is along b3.
    alpha : numpy.ndarray, shape (B, n)
        Angle of attack atan2(v_a·d3, v_a·d1) [rad].
    pqr : numpy.ndarray, shape (B, n, 3)
        Rates ω·d1, ω·d2, ω·d3 [rad/s].
    """

    v_air: np.ndarray
    speed: np.ndarray
    d1: np.ndarray
    d2: np.ndarray
    d3: np.ndarray
    alpha: np.ndarray
    pqr: np.ndarray


def wind_velocity(states: np.ndarray, times: np.ndarray, terms=(), extension=None) -> np.ndarray:
    """Σ of the terms' wind velocities [m/s] at every sample.

    Parameters
    ----------
    states : numpy.ndarray, shape (B, n, 13)
    times : numpy.ndarray, shape (n,)
        Sample times [s].
    terms : tuple of Term
    extension : numpy.ndarray, shape (B, n_ext) or (n_ext,), optional
        The terms' parameters (default: their off values).

    Returns
    -------
    numpy.ndarray, shape (B, n, 3)
    """
    states = np.asarray(states, dtype=float)
    B, n = states.shape[:2]
    n_ext = sum(len(t.parameters) for t in terms)
    if extension is None:
        extension = np.array([p.off_value for t in terms for p in t.parameters], dtype=float)
    ext = np.broadcast_to(np.asarray(extension, dtype=float).reshape(-1, n_ext), (B, n_ext)) if n_ext else None
    wind = np.zeros((B, n, 3))
    off = 0
    for term in terms:
        if term.air is not None:
            for b in range(B):
                E = np.ascontiguousarray(ext[b])
                for i in range(n):
                    x, y, z = states[b, i, :3]
                    wind[b, i] += term.air(E, off, float(times[i]), x, y, z)
        off += len(term.parameters)
    return wind


def flight_conditions(states: np.ndarray, times: np.ndarray, terms=(), extension=None) -> FlightConditions:
    """Air-relative velocity, D frame, α and p, q, r along trajectories (module docstring).

    Parameters
    ----------
    states : numpy.ndarray, shape (B, n, 13) or (n, 13)
        States (position [m], velocity [m/s], quaternion body→world, body ω [rad/s]).
    times : numpy.ndarray, shape (n,)
        Sample times [s].
    terms : tuple of Term
        The model's extra terms (only their ``air`` hooks matter here).
    extension : numpy.ndarray, shape (B, n_ext) or (n_ext,), optional
        The terms' parameters (default: their off values).

    Returns
    -------
    FlightConditions
        Arrays shaped (B, n, …); for (n, 13) input B = 1.
    """
    states = np.asarray(states, dtype=float)
    if states.ndim == 2:
        states = states[None]
    va = states[..., 3:6] - wind_velocity(states, np.asarray(times, dtype=float), terms, extension)
    R = quat_to_matrix(states[..., 6:10])
    d3 = R[..., :, 2]
    perp = va - np.sum(va * d3, axis=-1, keepdims=True) * d3
    norm = np.linalg.norm(perp, axis=-1, keepdims=True)
    d1 = np.divide(perp, norm, out=np.zeros_like(perp), where=norm > 0)
    d2 = np.cross(d3, d1)
    alpha = np.arctan2(np.sum(va * d3, axis=-1), np.sum(va * d1, axis=-1))
    omega = np.einsum("...ij,...j->...i", R, states[..., 10:13])
    pqr = np.stack([np.sum(omega * d, axis=-1) for d in (d1, d2, d3)], axis=-1)
    return FlightConditions(v_air=va, speed=np.linalg.norm(va, axis=-1), d1=d1, d2=d2, d3=d3, alpha=alpha,
                            pqr=pqr)
