"""Public simulator interface: batches of (parameter set × initial state) on one flight's time grid.

Separated from the methods as in scipy.integrate: :func:`simulate` drives the compiled kernel
(:mod:`.kernel`), :func:`simulate_reference` the scipy DOP853 integrator of the readable equations
(:mod:`.equations`) for testing and benchmarking.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.integrate import solve_ivp

from .constants import Coefficients, Disc, Environment
from .equations import STATE_SIZE, marker_positions, state_derivative
from .kernel import (DEFAULT_METHOD, DEFAULT_STEP_FACTOR, LANES, LANES_SMALL, STATUS_OK, STATUS_TEXT, TABLEAUX,
                     get_kernel)
from .terms import Term


@dataclass(frozen=True)
class SimulatorSettings:
    """Integrator settings.

    method: Runge–Kutta tableau of :data:`.tableaux.TABLEAUX` (default ``vern7``: Verner's 9-stage 7th
    order; also ``dop853`` 12-stage 8th order, ``rk6`` Butcher 7-stage 6th order, ``rk4``); step_factor
    c: the substep is h ≤ c/ω_c (see :mod:`.kernel`), None for the method's default; omega_cap [rad/s]:
    lanes faster than this are flagged; speed_cap [m/s]: lanes faster than this are flagged; fixed_rate
    [rad/s]: if set, every substep is h = c / fixed_rate (a parameter-independent schedule, so results
    are smooth in the parameters) and lanes whose own rate exceeds rate_margin · fixed_rate are flagged.
    """

    method: str = DEFAULT_METHOD
    step_factor: float | None = None
    omega_cap: float = 5000.0
    speed_cap: float = 300.0
    fixed_rate: float | None = None
    rate_margin: float = 2.0

    def __post_init__(self):
        if self.method not in TABLEAUX:
            raise ValueError(f"unknown integration method {self.method!r}; known: {sorted(TABLEAUX)}")
        # the kernel's work is bounded by duration · cap / c substeps: keep every factor finite and positive
        if self.step_factor is not None and not (np.isfinite(self.step_factor) and self.step_factor > 0):
            raise ValueError(f"simulator step_factor must be a positive finite number or None, got "
                             f"{self.step_factor!r}")
        if self.fixed_rate is not None and not (np.isfinite(self.fixed_rate) and self.fixed_rate >= 0):
            raise ValueError(f"simulator fixed_rate must be a finite number ≥ 0 (0 or None: off), got "
                             f"{self.fixed_rate!r}")
        for name in ("omega_cap", "speed_cap", "rate_margin"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value > 0):
                raise ValueError(f"simulator {name} must be a positive finite number, got {value!r}")

    @property
    def c(self) -> float:
        return DEFAULT_STEP_FACTOR[self.method] if self.step_factor is None else float(self.step_factor)


@dataclass
class Trajectories:
    """Result of a batch simulation: lane b, sample i.

    states (B, n, 13) or None; markers (B, n, n_markers, 3) or None; status (B,) with 0 = ok;
    failed lanes hold NaN.
    """

    times: np.ndarray
    states: np.ndarray | None
    markers: np.ndarray | None
    status: np.ndarray

    @property
    def ok(self) -> np.ndarray:
        return self.status == STATUS_OK

    def failure_reasons(self) -> list[str]:
        return [STATUS_TEXT[int(s)] for s in self.status]


def _constants(disc: Disc, env: Environment) -> np.ndarray:
    return np.array([disc.mass, disc.Ia, disc.Id, disc.diameter, disc.area, env.rho, env.g], dtype=float)


def _as_batch(values, width: int, batch: int, name: str) -> np.ndarray:
    a = np.asarray(values, dtype=float)
    if a.ndim == 1:
        a = np.broadcast_to(a, (batch, a.shape[0]))
    if a.shape != (batch, width):
        raise ValueError(f"{name}: expected shape ({batch}, {width}) or ({width},), got {a.shape}")
    return np.ascontiguousarray(a)


def simulate(initial_states, coefficients, times, *, t0: float | None = None, disc: Disc = Disc(),
             env: Environment = Environment(), marker_body=None, terms: tuple[Term, ...] = (),
             extension=None, settings: SimulatorSettings = SimulatorSettings(),
             want_states: bool = True) -> Trajectories:
    """Simulate a batch of lanes on one time grid.

    initial_states: (B, 13) or (13,) states at time ``t0`` (default ``times[0]``); coefficients: (B, 10)
    or (10,) in :data:`COEFFICIENT_NAMES` order; times: (n,) non-decreasing output times ≥ t0 [s];
    marker_body: (n_markers, 3) body-frame marker positions [m] or None; terms/extension: extra physics
    terms and their parameters (B, n_ext) or (n_ext,).
    """
    times = np.ascontiguousarray(np.asarray(times, dtype=float).ravel())
    if times.size == 0:
        raise ValueError("times: need at least one output time")
    if not np.all(np.isfinite(times)) or np.any(np.diff(times) < 0):
        raise ValueError("times must be finite and non-decreasing")
    t0 = float(times[0]) if t0 is None else float(t0)
    if times[0] < t0:
        raise ValueError(f"times start at {times[0]} before t0 = {t0}")
    y0 = np.atleast_2d(np.asarray(initial_states, dtype=float))
    batch = y0.shape[0]
    y0 = _as_batch(y0, STATE_SIZE, batch, "initial_states")
    coef = _as_batch(coefficients if not isinstance(coefficients, Coefficients) else coefficients.as_array(),
                     10, batch, "coefficients")
    n_ext = sum(len(t.parameters) for t in terms)
    if extension is None:
        extension = np.array([p.off_value for t in terms for p in t.parameters], dtype=float)
    ext = np.asarray(extension, dtype=float)
    ext = _as_batch(ext if ext.ndim == 1 else ext.reshape(-1, n_ext), n_ext, batch,
                    "extension") if n_ext else np.zeros((batch, 0))
    mb = np.zeros((0, 3)) if marker_body is None else np.ascontiguousarray(np.asarray(marker_body, float))
    n = times.size
    out_states = np.empty((batch, n if want_states else 0, STATE_SIZE))
    out_markers = np.empty((batch, n if mb.shape[0] else 0, mb.shape[0], 3))
    status = np.zeros(batch, dtype=np.int64)
    # groups of 8 lanes for batches, of 4 for a few lanes (identical results either way)
    kernel = get_kernel(tuple(terms), settings.method, LANES_SMALL if batch <= LANES_SMALL else LANES)
    kernel(y0, coef, ext, _constants(disc, env), t0, times, mb, settings.c,
           settings.omega_cap, settings.speed_cap, settings.fixed_rate or 0.0, settings.rate_margin,
           out_states, out_markers, status)
    failed = status != STATUS_OK
    out_states[failed] = np.nan   # a failed lane is NaN over its whole trajectory
    out_markers[failed] = np.nan
    return Trajectories(times=times, states=out_states if want_states else None,
                        markers=out_markers if mb.shape[0] else None, status=status)


def simulate_reference(initial_state, coefficients: Coefficients, times, *, t0: float | None = None,
                       disc: Disc = Disc(), env: Environment = Environment(), marker_body=None,
                       terms: tuple[Term, ...] = (), extension=None, rtol: float = 1e-12,
                       atol: float = 1e-12) -> Trajectories:
    """One trajectory with scipy's DOP853 on the readable equations (slow; for tests and benchmarks)."""
    times = np.asarray(times, dtype=float)
    t0 = float(times[0]) if t0 is None else float(t0)
    if not isinstance(coefficients, Coefficients):
        coefficients = Coefficients.from_array(coefficients)
    sol = solve_ivp(state_derivative, (t0, float(times[-1])), np.asarray(initial_state, float),
                    method="DOP853", t_eval=times, rtol=rtol, atol=atol,
                    args=(coefficients, disc, env, tuple(terms), extension))
    ok = sol.success and sol.y.shape[1] == times.size
    states = sol.y.T[None] if ok else np.full((1, times.size, STATE_SIZE), np.nan)
    markers = marker_positions(states, marker_body) if marker_body is not None else None
    return Trajectories(times=times, states=states, markers=markers,
                        status=np.array([0 if ok else 1]))
