"""Data explanations: ways the recordings, rather than the flight physics, can disagree with the model.

Each explanation is one small unit like a physics term (:class:`bayes_disc.physics.Term`): an id,
title, equations and parameters with units and prior scales, plus ``apply``, which turns simulated
states into predicted marker positions. The model then predicts marker j at sample time t as

    m_j(t) = x(t + δ_j) + R(t + δ_j) (b_j + Δ_j)

with x the centre of mass [m], R the body-to-world rotation, b_j the configured body position of the
marker [m], Δ_j its body-frame offset (``marker_geometry``) and δ_j its timing offset [s]
(``time_offset``). Over the few milliseconds of a timing offset the motion is advanced as

    x(t + δ) = x + v δ + ½ a δ²,    R(t + δ) = R · exp([ω_B δ + ½ ω̇_B δ²]×)

(ω_B the body angular velocity [rad/s]; a = dv/dt and ω̇_B from the sampled states by central
differences; the neglected terms are O(δ³)). A timing offset common to all markers is absorbed by the initial conditions,
so only the offsets of markers 2…m relative to marker 1 are parameters.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from ..physics import TermParameter
from ..physics.frames import quat_from_rotvec, quat_multiply, quat_to_matrix


@dataclass(frozen=True)
class DataExplanation:
    """A data explanation: id, title, equations, its parameters for given marker ids, and ``offsets``
    mapping parameter values (B, k) to (Δ (B, m, 3) body offsets [m], δ (B, m) timing offsets [s])."""

    id: str
    title: str
    equations: str
    parameters_for: Callable[[tuple], tuple[TermParameter, ...]]
    offsets: Callable[[np.ndarray, int], tuple[np.ndarray | None, np.ndarray | None]]


def _geometry_parameters(marker_ids: tuple) -> tuple[TermParameter, ...]:
    return tuple(TermParameter(f"marker_{axis}_{m}", "m", f"body-frame {axis} offset of marker {m}", prior_sd=0.005)
                 for m in marker_ids for axis in ("b1", "b2", "b3"))


def _geometry_offsets(values: np.ndarray, n_markers: int):
    return values.reshape(values.shape[0], n_markers, 3), None


MARKER_GEOMETRY = DataExplanation(
    id="marker_geometry",
    title="Marker body positions differ from the configured ones",
    equations="m_j = x + R (b_j + Δ_j),  Δ_j = (Δ_j1, Δ_j2, Δ_j3) body frame [m]",
    parameters_for=_geometry_parameters,
    offsets=_geometry_offsets,
)


def _timing_parameters(marker_ids: tuple) -> tuple[TermParameter, ...]:
    return tuple(TermParameter(f"dt_{m}", "s", f"timing offset of marker {m} relative to marker {marker_ids[0]}",
                               prior_sd=0.002) for m in marker_ids[1:])


def _timing_offsets(values: np.ndarray, n_markers: int):
    return None, np.concatenate([np.zeros((values.shape[0], 1)), values], axis=1)


TIME_OFFSET = DataExplanation(
    id="time_offset",
    title="Markers recorded at slightly different times (unsynchronised cameras or digitising)",
    equations="m_j(t) = x(t + δ_j) + R(t + δ_j) b_j,  δ_1 = 0",
    parameters_for=_timing_parameters,
    offsets=_timing_offsets,
)

EXPLANATIONS: dict[str, DataExplanation] = {e.id: e for e in (MARKER_GEOMETRY, TIME_OFFSET)}


def predicted_markers(states: np.ndarray, marker_body: np.ndarray, body_offset: np.ndarray | None,
                      time_offset: np.ndarray | None, times: np.ndarray | None = None) -> np.ndarray:
    """Markers (B, n, m, 3) [m] from states (B, n, 13) at ``times`` (n,) [s], body positions b (m, 3), body
    offsets Δ (B, m, 3) and timing offsets δ (B, m) [s] (either may be None; times are needed with δ)."""
    B, n, _ = states.shape
    m = marker_body.shape[0]
    body = np.broadcast_to(marker_body, (B, m, 3)) if body_offset is None else marker_body[None] + body_offset
    x, v, q, w = states[..., 0:3], states[..., 3:6], states[..., 6:10], states[..., 10:13]
    if time_offset is None:
        R = quat_to_matrix(q.reshape(-1, 4)).reshape(B, n, 3, 3)
        return x[:, :, None, :] + np.einsum("bnij,bmj->bnmi", R, body)
    out = np.empty((B, n, m, 3))
    a = np.gradient(v, times, axis=1, edge_order=2) if n > 2 else np.zeros_like(v)
    w_dot = np.gradient(w, times, axis=1, edge_order=2) if n > 2 else np.zeros_like(w)
    for j in range(m):
        dt = time_offset[:, j][:, None, None]                               # (B, 1, 1)
        xj = x + v * dt + 0.5 * a * dt ** 2
        qj = quat_multiply(q.reshape(-1, 4), quat_from_rotvec((w * dt + 0.5 * w_dot * dt ** 2).reshape(-1, 3)))
        R = quat_to_matrix(qj).reshape(B, n, 3, 3)
        out[:, :, j] = xj + np.einsum("bnij,bj->bni", R, body[:, j])
    return out
