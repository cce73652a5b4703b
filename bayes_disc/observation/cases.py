"""Simulation cases in the format of ``shared/reference/NAME.json`` (docs/conventions.md)."""
from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..physics import Coefficients, Disc, Environment, simulate
from .markers import FlightObservation, MarkerTable, table_from_flights


class CaseFileError(ValueError):
    """A case file that cannot be used; the message names the file and the problem."""


@dataclass(frozen=True)
class Case:
    """A single simulated flight: constants, coefficients, markers (body frame, m), initial state."""

    name: str
    disc: Disc
    env: Environment
    coefficients: Coefficients
    marker_body: np.ndarray
    initial_state: np.ndarray
    sample_rate_hz: float
    duration_s: float

    @property
    def times(self) -> np.ndarray:
        """Sample times k / rate for k = 0 … round(duration · rate) [s]."""
        n = int(round(self.duration_s * self.sample_rate_hz))
        return np.arange(n + 1) / self.sample_rate_hz

    @property
    def marker_ids(self) -> tuple[str, ...]:
        return tuple(str(i) for i in range(len(self.marker_body)))


def load_case(path) -> Case:
    path = Path(path)
    try:
        J = json.loads(path.read_text())
    except FileNotFoundError:
        raise CaseFileError(f"{path}: file not found") from None
    except json.JSONDecodeError as e:
        raise CaseFileError(f"{path}:{e.lineno}: not valid JSON ({e.msg})") from None
    try:
        d = J.get("disc", {})
        disc = Disc(mass=d.get("m", Disc.mass), Ia=d.get("Ia", Disc.Ia), Id=d.get("Id", Disc.Id),
                    diameter=d.get("d", Disc.diameter), area=d.get("A", Disc.area))
        env = Environment(rho=d.get("rho", Environment.rho), g=d.get("g", Environment.g))
        coef = Coefficients.from_mapping(J["coefficients"])
        mb = np.asarray(J["marker_body_positions_m"], float)
        ic = J["initial_state"]
        y0 = np.concatenate([ic["position_m"], ic["velocity_m_s"], ic["quaternion_wxyz_body_to_world"],
                             ic["omega_body_rad_s"]]).astype(float)
        rate, duration = float(J["sample_rate_hz"]), float(J["duration_s"])
    except KeyError as e:
        raise CaseFileError(f"{path}: missing key {e.args[0]!r}") from None
    except (TypeError, ValueError) as e:
        raise CaseFileError(f"{path}: {e}") from None
    if mb.ndim != 2 or mb.shape[1] != 3 or len(mb) < 3:
        raise CaseFileError(f"{path}: marker_body_positions_m must be a list of ≥3 [x, y, z]")
    if y0.shape != (13,) or not np.all(np.isfinite(y0)):
        raise CaseFileError(f"{path}: initial_state must give 3+3+4+3 finite numbers")
    if not (rate > 0 and duration > 0):
        raise CaseFileError(f"{path}: sample_rate_hz and duration_s must be positive")
    return Case(name=path.stem, disc=disc, env=env, coefficients=coef, marker_body=mb, initial_state=y0,
                sample_rate_hz=rate, duration_s=duration)


def simulate_case(case: Case) -> tuple[MarkerTable, np.ndarray]:
    """Marker table (docs/data-formats.md) and states (n, 13) of a case."""
    tr = simulate(case.initial_state, case.coefficients.as_array(), case.times, disc=case.disc,
                  env=case.env, marker_body=case.marker_body)
    if not tr.ok[0]:
        raise CaseFileError(f"case {case.name}: simulation failed: {tr.failure_reasons()[0]}")
    obs = FlightObservation(name=case.name, source="", times=case.times, marker_ids=case.marker_ids,
                            positions=tr.markers[0])
    return table_from_flights([obs]), tr.states[0]
