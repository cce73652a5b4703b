"""The parameter layout: the one place that knows what every entry of θ is.

θ = [ the ten coefficients (docs/conventions.md) |
      extension: physics-term parameters, data-explanation parameters, then the parameters the
      observation models share across flights (e.g. the logger's position) |
      per flight f: initial conditions, then the flight's own observation-model parameters ]

Initial conditions (:class:`InitialConditions`) come in two kinds:

* ``full`` (flights with marker positions): position x, y, z [m], velocity vx, vy, vz [m/s] (world),
  attitude th1, th2, th3 [rad] (rotation vector relative to the data-derived start: q = q_ref ⊗ exp(ϑ)),
  body angular velocity wx, wy, wz [rad/s];
* ``inertial`` (flights seen by an inertial logger only: position and heading are unobservable and are
  not parameters): tilt1, tilt2 [rad] (the attitude R = exp([tilt1, tilt2, 0]×) R_level, R_level the
  level right-side-up disc with b1 along x), the air-relative velocity in body axes u1, u2, u3 [m/s]
  (v = R u; u3 > 0 is air meeting the underside), body angular velocity wx, wy, wz [rad/s].

Public names append ``_<flight>``.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ...physics import COEFFICIENT_NAMES, COEFFICIENT_UNITS, Term, TermParameter

IC_NAMES = ("x", "y", "z", "vx", "vy", "vz", "th1", "th2", "th3", "wx", "wy", "wz")
IC_UNITS = ("m", "m", "m", "m/s", "m/s", "m/s", "rad", "rad", "rad", "rad/s", "rad/s", "rad/s")


@dataclass(frozen=True)
class InitialConditions:
    """A kind of initial-condition parameters: names, units and prior scales (module docstring)."""

    kind: str
    names: tuple[str, ...]
    units: tuple[str, ...]
    prior_sd: tuple[float, ...]

    @property
    def size(self) -> int:
        return len(self.names)


FULL_IC = InitialConditions("full", IC_NAMES, IC_UNITS, (0.5,) * 3 + (5.0,) * 3 + (0.5,) * 3 + (30.0,) * 3)
INERTIAL_IC = InitialConditions("inertial", ("tilt1", "tilt2", "u1", "u2", "u3", "wx", "wy", "wz"),
                                ("rad", "rad", "m/s", "m/s", "m/s", "rad/s", "rad/s", "rad/s"),
                                (0.5, 0.5, 8.0, 8.0, 4.0, 30.0, 30.0, 30.0))
N_IC = FULL_IC.size


@dataclass(frozen=True)
class ParameterLayout:
    """Names, units and positions of θ's entries.

    Parameters
    ----------
    terms : tuple of Term
        Physics terms of the model, in θ order.
    explanation_parameters : tuple of TermParameter
        Parameters of the data explanations (shared by every flight), in θ order.
    flight_names : tuple of str
        The flights, in θ order.
    flight_parameters : tuple of tuple of TermParameter
        Each flight's own observation-model parameters (appended after its initial conditions).
    observation_parameters : tuple of TermParameter
        Observation-model parameters shared by all flights (after the explanations).
    flight_ic : tuple of InitialConditions
        Each flight's kind of initial conditions (default: all ``full``).
    """

    terms: tuple[Term, ...] = ()
    explanation_parameters: tuple[TermParameter, ...] = ()
    flight_names: tuple[str, ...] = ()
    flight_parameters: tuple[tuple[TermParameter, ...], ...] = ()
    observation_parameters: tuple[TermParameter, ...] = ()
    flight_ic: tuple[InitialConditions, ...] = ()
    _flight_start: tuple[int, ...] = field(init=False, repr=False)

    def __post_init__(self):
        if not self.flight_parameters:
            object.__setattr__(self, "flight_parameters", tuple(() for _ in self.flight_names))
        if not self.flight_ic:
            object.__setattr__(self, "flight_ic", tuple(FULL_IC for _ in self.flight_names))
        if len(self.flight_parameters) != len(self.flight_names) or len(self.flight_ic) != len(self.flight_names):
            raise ValueError("flight_parameters and flight_ic need one entry per flight")
        starts, j = [], self.ic_start
        for ic, own in zip(self.flight_ic, self.flight_parameters):
            starts.append(j)
            j += ic.size + len(own)
        object.__setattr__(self, "_flight_start", tuple(starts) + (j,))

    # -- sizes --------------------------------------------------------------------------------------------
    @property
    def n_coef(self) -> int:
        return len(COEFFICIENT_NAMES)

    @property
    def term_parameters(self) -> tuple[TermParameter, ...]:
        return tuple(p for t in self.terms for p in t.parameters)

    @property
    def n_phys(self) -> int:
        return len(self.term_parameters)

    @property
    def ext_parameters(self) -> tuple[TermParameter, ...]:
        """Every parameter of the extension block (terms, explanations, shared observation parameters)."""
        return self.term_parameters + self.explanation_parameters + self.observation_parameters

    @property
    def n_ext(self) -> int:
        return len(self.ext_parameters)

    @property
    def ic_start(self) -> int:
        """Index of the first per-flight entry (= number of shared entries)."""
        return self.n_coef + self.n_ext

    @property
    def n_flights(self) -> int:
        return len(self.flight_names)

    @property
    def dim(self) -> int:
        return self._flight_start[-1]

    # -- slices ---------------------------------------------------------------------------------------------
    @property
    def ext_slice(self) -> slice:
        return slice(self.n_coef, self.ic_start)

    @property
    def term_slice(self) -> slice:
        return slice(self.n_coef, self.n_coef + self.n_phys)

    @property
    def explanation_slice(self) -> slice:
        start = self.n_coef + self.n_phys
        return slice(start, start + len(self.explanation_parameters))

    @property
    def observation_slice(self) -> slice:
        """The observation models' shared parameters."""
        return slice(self.explanation_slice.stop, self.ic_start)

    def flight_slice(self, k: int) -> slice:
        """All of flight k's own entries (initial conditions, then observation-model parameters)."""
        return slice(self._flight_start[k], self._flight_start[k + 1])

    def ic_slice(self, k: int) -> slice:
        return slice(self._flight_start[k], self._flight_start[k] + self.flight_ic[k].size)

    def own_slice(self, k: int) -> slice:
        """Flight k's observation-model parameters."""
        return slice(self._flight_start[k] + self.flight_ic[k].size, self._flight_start[k + 1])

    def flight_columns(self, k: int) -> np.ndarray:
        """Indices of θ that flight k's predictions depend on (shared entries and its own)."""
        s = self.flight_slice(k)
        return np.r_[np.arange(self.ic_start), np.arange(s.start, s.stop)]

    # -- names and units ----------------------------------------------------------------------------------
    @property
    def ext_names(self) -> list[str]:
        return [p.name for p in self.ext_parameters]

    @property
    def names(self) -> list[str]:
        out = list(COEFFICIENT_NAMES) + self.ext_names
        for f, ic, own in zip(self.flight_names, self.flight_ic, self.flight_parameters):
            out += [f"{n}_{f}" for n in ic.names] + [f"{p.name}_{f}" for p in own]
        return out

    @property
    def units(self) -> list[str]:
        out = [COEFFICIENT_UNITS[n] for n in COEFFICIENT_NAMES] + [p.unit for p in self.ext_parameters]
        for ic, own in zip(self.flight_ic, self.flight_parameters):
            out += list(ic.units) + [p.unit for p in own]
        return out

    def index(self, name: str) -> int:
        """Position of the public parameter ``name`` in θ (KeyError naming the parameter if absent)."""
        try:
            return self.names.index(name)
        except ValueError:
            raise KeyError(f"no parameter {name!r} in this model") from None

    # -- vectors ------------------------------------------------------------------------------------------
    def off_values(self) -> np.ndarray:
        """(n_ext,) values that switch every extension parameter off."""
        return np.array([p.off_value for p in self.ext_parameters], float)

    def kernel_extension(self, theta: np.ndarray, kernel_terms: tuple[Term, ...]) -> np.ndarray:
        """Parameters (B, n) of ``kernel_terms`` (a superset of the model's terms, one compiled kernel for
        many models): the model's own from θ (B, dim), the others at their off values."""
        own, j = {}, self.n_coef
        for t in self.terms:
            own[t.id] = j
            j += len(t.parameters)
        missing = set(own) - {t.id for t in kernel_terms}
        if missing:
            raise ValueError(f"kernel_terms lacks the model's terms {sorted(missing)}")
        cols = []
        for t in kernel_terms:
            for i, par in enumerate(t.parameters):
                cols.append(theta[:, own[t.id] + i] if t.id in own else np.full(theta.shape[0], par.off_value))
        return np.column_stack(cols) if cols else np.zeros((theta.shape[0], 0))

    def transfer(self, theta: np.ndarray, source: "ParameterLayout", fill: np.ndarray) -> np.ndarray:
        """θ of ``source`` mapped into this layout (same flights): entries with the same public name
        copied, the others taken from ``fill`` (dim,) (e.g. a start vector)."""
        out = np.array(fill, float, copy=True)
        src = dict(zip(source.names, theta))
        for j, name in enumerate(self.names):
            if name in src:
                out[j] = src[name]
        return out
