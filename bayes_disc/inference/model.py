"""The statistical model: parameter vector, priors, simulated markers and the log-posterior.

θ = [10 coefficients, extra-term parameters, per flight: position (3) m, velocity (3) m/s, attitude
rotation vector (3) rad, body angular velocity (3) rad/s].
The attitude is q = q_ref ⊗ exp(ϑ) with q_ref the data-derived start: no singularity near the data.

Likelihood: independent Gaussian marker coordinates with one noise scale σ_f per flight, prior
p(σ_f) ∝ 1/σ_f (Jeffreys). σ_f is integrated out analytically,

    p(y_f | θ) = ∫ N(y_f | m_f(θ), σ_f² I) dσ_f/σ_f = ½ Γ(n_f/2) (π S_f)^(−n_f/2),   S_f = Σ residual²,

so the sampler explores θ alone (σ and θ are coupled: in ~60 dimensions that coupling alone makes the
joint posterior far from Gaussian), and σ_f is then drawn exactly from its conditional
σ_f² | θ, y ~ S_f / χ²_{n_f}: together an exact sample of the joint posterior p(θ, σ | y).
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from ..observation.explanations import DataExplanation, predicted_markers
from ..observation.markers import FlightObservation
from ..physics import COEFFICIENT_NAMES, Disc, Environment, SimulatorSettings, Term, simulate
from ..physics.frames import quat_from_rotvec, quat_multiply
from scipy.special import gammaln

from .priors import IC_SD, coefficient_prior

IC_NAMES = ("x", "y", "z", "vx", "vy", "vz", "th1", "th2", "th3", "wx", "wy", "wz")
IC_UNITS = ("m", "m", "m", "m/s", "m/s", "m/s", "rad", "rad", "rad", "rad/s", "rad/s", "rad/s")


@dataclass
class Problem:
    """Everything the log-posterior needs; built once per run."""

    flights: list[FlightObservation]
    marker_body: np.ndarray
    disc: Disc
    env: Environment
    prior_name: str
    terms: tuple[Term, ...] = ()
    explanations: tuple[DataExplanation, ...] = ()  # data explanations (marker geometry, timing)
    term_start: np.ndarray | None = None          # starting values of the extra-term parameters
    start_states: list[np.ndarray] = field(default_factory=list)  # data-derived (13,) per flight
    settings: SimulatorSettings = SimulatorSettings()
    rates: list[float] = field(default_factory=list)  # fixed integration rate per flight [rad/s]
    kernel_terms: tuple[Term, ...] = ()  # if set, a superset of ``terms`` to integrate with (absent ones off):
    #                                     one compiled kernel then serves many models (missing-physics search)

    def __post_init__(self):
        self.n_coef = len(COEFFICIENT_NAMES)
        self.marker_ids = tuple(self.flights[0].marker_ids) if self.flights else ()
        self.n_phys = sum(len(t.parameters) for t in self.terms)
        self.n_ext = self.n_phys + sum(len(p) for p in self._explanation_parameters())
        self.n_flights = len(self.flights)
        self.ic_start = self.n_coef + self.n_ext
        self.dim = self.ic_start + 12 * self.n_flights
        self.q_ref = [s[6:10] / np.linalg.norm(s[6:10]) for s in self.start_states]
        self._masks = [f.observed for f in self.flights]
        self._obs = [f.positions[f.observed] for f in self.flights]
        self.n_coords = np.array([3 * m.sum() for m in self._masks])
        mean, sd = self._prior_arrays()
        self.prior_mean, self.prior_sd = mean, sd

    # -- names ------------------------------------------------------------------------------------------
    def _explanation_parameters(self) -> list[tuple]:
        return [e.parameters_for(self.marker_ids) for e in self.explanations]

    @property
    def ext_parameters(self) -> list:
        """:class:`~bayes_disc.physics.TermParameter` of every extra parameter, in θ order."""
        return [p for t in self.terms for p in t.parameters] + [p for ps in self._explanation_parameters() for p in ps]

    @property
    def ext_names(self) -> list[str]:
        return [p.name for p in self.ext_parameters]

    @property
    def model_ids(self) -> list[str]:
        """SPEC ids of the model's extra physics terms and data explanations."""
        return [t.id for t in self.terms] + [e.id for e in self.explanations]

    @property
    def names(self) -> list[str]:
        out = list(COEFFICIENT_NAMES) + self.ext_names
        for f in self.flights:
            out += [f"{n}_{f.name}" for n in IC_NAMES]
        return out

    @property
    def sigma_names(self) -> list[str]:
        return [f"sigma_{f.name}" for f in self.flights]

    def ic_slice(self, k: int) -> slice:
        return slice(self.ic_start + 12 * k, self.ic_start + 12 * (k + 1))

    def flight_columns(self, k: int) -> np.ndarray:
        """Indices of θ that flight k's markers depend on (coefficients, extra terms, its own ICs)."""
        return np.r_[np.arange(self.ic_start), np.arange(self.ic_start + 12 * k, self.ic_start + 12 * (k + 1))]

    # -- priors -----------------------------------------------------------------------------------------
    def _prior_arrays(self):
        cp = coefficient_prior(self.prior_name)
        mean = np.zeros(self.dim)
        sd = np.zeros(self.dim)
        for i, n in enumerate(COEFFICIENT_NAMES):
            mean[i], sd[i] = cp.mean[n], cp.sd[n]
        for j, p in enumerate(self.ext_parameters, start=self.n_coef):
            mean[j], sd[j] = p.off_value, p.prior_sd
        ic_sd = np.repeat([IC_SD["position"], IC_SD["velocity"], IC_SD["attitude"], IC_SD["omega"]], 3)
        for k in range(self.n_flights):
            mean[self.ic_slice(k)] = self.state_to_ic(self.start_states[k], k)
            sd[self.ic_slice(k)] = ic_sd
        return mean, sd

    def log_prior(self, theta: np.ndarray) -> np.ndarray:
        theta = np.atleast_2d(theta)
        z = (theta - self.prior_mean) / self.prior_sd
        return -0.5 * np.sum(z * z, axis=1)

    def sample_prior(self, n: int, rng: np.random.Generator) -> np.ndarray:
        return self.prior_mean + self.prior_sd * rng.standard_normal((n, self.dim))

    # -- states -----------------------------------------------------------------------------------------
    def ic_to_state(self, ic: np.ndarray, k: int) -> np.ndarray:
        """(B, 12) initial-condition parameters of flight k → (B, 13) states."""
        ic = np.atleast_2d(ic)
        q = quat_multiply(self.q_ref[k], quat_from_rotvec(ic[:, 6:9]))
        return np.concatenate([ic[:, :6], q, ic[:, 9:12]], axis=1)

    def state_to_ic(self, state: np.ndarray, k: int) -> np.ndarray:
        from ..physics.frames import quat_to_rotvec
        qr = self.q_ref[k] * np.array([1, -1, -1, -1])
        rel = quat_multiply(qr, state[6:10])
        return np.concatenate([state[:6], quat_to_rotvec(rel), state[10:13]])

    # -- model ------------------------------------------------------------------------------------------
    def predict(self, theta: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
        """Markers (B, n, n_markers, 3) of flight k for θ (B, dim), and ok flags (B,)."""
        tr = self.simulate(theta, k, want_states=False)
        return tr.markers, tr.ok

    def simulate(self, theta: np.ndarray, k: int, want_states: bool = True):
        """The simulator's :class:`~bayes_disc.physics.simulator.Trajectories` of flight k for θ (B, dim)
        on the flight's sample times (markers include the data explanations)."""
        theta = np.atleast_2d(theta)
        f = self.flights[k]
        states = self.ic_to_state(theta[:, self.ic_slice(k)], k)
        ext = theta[:, self.n_coef: self.n_coef + self.n_phys] if self.n_phys else None
        terms = self.terms
        if self.kernel_terms:
            terms, ext = self.kernel_terms, self._kernel_extension(theta)
        settings = self.settings
        if self.rates:
            settings = SimulatorSettings(method=settings.method, step_factor=settings.step_factor,
                                         omega_cap=settings.omega_cap, speed_cap=settings.speed_cap,
                                         fixed_rate=self.rates[k])
        tr = simulate(states, theta[:, : self.n_coef], f.times, t0=f.times[0], disc=self.disc, env=self.env,
                      marker_body=self.marker_body, terms=terms, extension=ext, settings=settings,
                      want_states=want_states or bool(self.explanations))
        if self.explanations:
            tr = replace(tr, markers=self._explained_markers(theta, tr.states, f.times))
            if not want_states:
                tr = replace(tr, states=None)
        return tr

    def _kernel_extension(self, theta: np.ndarray) -> np.ndarray:
        """Parameters (B, n) of ``kernel_terms``: the model's own from θ, the others at their off values."""
        own = {t.id: self.n_coef + sum(len(u.parameters) for u in self.terms[:i]) for i, t in enumerate(self.terms)}
        missing = set(own) - {t.id for t in self.kernel_terms}
        if missing:
            raise ValueError(f"kernel_terms lacks the model's terms {sorted(missing)}")
        cols = []
        for t in self.kernel_terms:
            for i, par in enumerate(t.parameters):
                cols.append(theta[:, own[t.id] + i] if t.id in own else np.full(theta.shape[0], par.off_value))
        return np.column_stack(cols)

    def _explained_markers(self, theta: np.ndarray, states: np.ndarray, times: np.ndarray) -> np.ndarray:
        """Markers (B, n, m, 3) with the data explanations' body and timing offsets applied."""
        m = self.marker_body.shape[0]
        body, timing = None, None
        j = self.n_coef + self.n_phys
        for e, params in zip(self.explanations, self._explanation_parameters()):
            b, t = e.offsets(theta[:, j: j + len(params)], m)
            body = b if b is not None else body
            timing = t if t is not None else timing
            j += len(params)
        return predicted_markers(states, self.marker_body, body, timing, times)

    def residuals(self, theta: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
        """Observed-point residuals (B, n_coords_k) [m] (predicted − measured) and ok flags."""
        markers, ok = self.predict(theta, k)
        r = markers[:, self._masks[k]] - self._obs[k][None]
        return r.reshape(r.shape[0], -1), ok

    def sum_squares(self, theta: np.ndarray) -> np.ndarray:
        """S_f (B, n_flights) [m²]: summed squared marker residuals per flight; inf where a lane failed."""
        theta = np.atleast_2d(theta)
        out = np.empty((theta.shape[0], self.n_flights))
        for k in range(self.n_flights):
            r, ok = self.residuals(theta, k)
            ss = np.sum(r * r, axis=1)
            out[:, k] = np.where(ok & np.isfinite(ss), ss, np.inf)
        return out

    def log_likelihood_from_ss(self, ss: np.ndarray) -> np.ndarray:
        """Σ_f log p(y_f | θ) with σ_f integrated out (see module docstring)."""
        n = self.n_coords
        const = gammaln(n / 2) - np.log(2.0) - 0.5 * n * np.log(np.pi)
        return np.sum(const - 0.5 * n * np.log(ss), axis=1)

    def log_likelihood(self, theta: np.ndarray) -> np.ndarray:
        return self.log_likelihood_from_ss(self.sum_squares(theta))

    def log_prob_blobs(self, theta: np.ndarray) -> np.ndarray:
        """Vectorised log-posterior for emcee with blobs: rows (log p(θ | y), S_1 … S_F), shape (B, 1 + F)."""
        theta = np.atleast_2d(theta)
        ss = self.sum_squares(theta)
        lp = self.log_prior(theta) + self.log_likelihood_from_ss(ss)
        lp = np.where(np.isfinite(lp), lp, -np.inf)
        return np.column_stack([lp, ss])

    def log_prob(self, theta: np.ndarray) -> np.ndarray:
        """Vectorised log-posterior p(θ | y) (θ: (B, dim) → (B,))."""
        return self.log_prob_blobs(theta)[:, 0]

    def draw_sigma(self, ss: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """σ_f [m] drawn from σ_f² | θ, y ~ S_f / χ²_{n_f} for sum-of-squares ss (..., n_flights)."""
        return np.sqrt(ss / rng.chisquare(self.n_coords, size=ss.shape))

    def flight_rate(self, state: np.ndarray) -> float:
        """Integration rate for a flight: 1.25 × the fastest rate of its start (spin, nutation, aero)."""
        w = state[10:13]
        return 1.25 * max(np.linalg.norm(w), self.disc.Ia / self.disc.Id * abs(w[2]), 30.0)
