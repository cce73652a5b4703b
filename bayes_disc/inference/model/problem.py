"""The statistical model: priors, simulated flights, the observation models and the log-posterior.

θ is laid out by :class:`.layout.ParameterLayout` (coefficients, extension parameters, per flight its
initial conditions and observation-model parameters). The attitude is q = q_ref ⊗ exp(ϑ) with q_ref the
data-derived start: no singularity near the data.

Likelihood: every flight carries one or more observation models (:mod:`bayes_disc.observation.models`);
the log-likelihood is their sum. Each model's noise groups have one scale σ_g with the Jeffreys prior
p(σ_g) ∝ 1/σ_g. For the marker model (one group per flight) σ_f is integrated out analytically,

    p(y_f | θ) = ∫ N(y_f | m_f(θ), σ_f² I) dσ_f/σ_f = ½ Γ(n_f/2) (π S_f)^(−n_f/2),   S_f = Σ residual²,

so the sampler explores θ alone (σ and θ are coupled: in ~60 dimensions that coupling alone makes the
joint posterior far from Gaussian), and σ_f is then drawn exactly from its conditional
σ_f² | θ, y ~ S_f / χ²_{n_f}: together an exact sample of the joint posterior p(θ, σ | y).

A flight's noise unit may shape or correlate the noise (per-point errors, AR(1) in time:
:mod:`bayes_disc.observation.models.noise`); then S_f is the *effective* sum of squares S̃_f of the
whitened residuals (:meth:`ObservationModel.effective_residuals`), and the formula above still holds
exactly. The sampler's blobs are the S̃_g; :meth:`Problem.draw_sigma` needs θ as well when a unit's
whitening depends on its parameters (ρ_f).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ...observation.explanations import DataExplanation
from ...observation.markers import FlightObservation
from ...observation.models import MarkerPositions, ObservationModel
from ...physics import COEFFICIENT_NAMES, Disc, Environment, SimulatorSettings, Term, flight_conditions, simulate
from ...physics.frames import matrix_to_quat, quat_from_rotvec, quat_multiply, quat_to_matrix, quat_to_rotvec
from .layout import FULL_IC, IC_NAMES, INERTIAL_IC, ParameterLayout
from .priors import ReferenceSurrogate, coefficient_prior

#: body→world rotation of the level right-side-up disc (b1 along x, b3 down): the inertial ICs' reference
R_LEVEL = np.diag([1.0, -1.0, -1.0])
#: release height [m] of flights seen by an inertial logger only (unobservable; matters only with terms
#: that depend on height)
INERTIAL_RELEASE_HEIGHT = 1.0

__all__ = ["Problem", "IC_NAMES", "shared_observation_parameters"]


def shared_observation_parameters(channels) -> dict:
    """{name: TermParameter} of the parameters the observation models share across flights, in first-seen
    order: one θ entry per name, read by every model that declares it (e.g. the logger's mount by every
    inertial throw, the field only by throws whose magnetometer is used).

    Parameters
    ----------
    channels : iterable of iterables of ObservationModel
        Per flight, its observation models.

    Returns
    -------
    dict
        Raises ValueError when two models declare one name differently (unit, prior).
    """
    out: dict = {}
    for ch in channels:
        for c in ch:
            for q in c.shared_parameters:
                if out.setdefault(q.name, q) != q:
                    raise ValueError(f"shared parameter {q.name!r} is declared differently by two observation models")
    return out


@dataclass
class Problem:
    """Everything the log-posterior needs; complete when constructed.

    Parameters
    ----------
    flights : list
        One record per flight with a ``name``: marker recordings (:class:`FlightObservation`, sample times
        (n,) [s], positions (n, m, 3) [m]) or any other data record when ``observations`` are given.
    marker_body : (m, 3) array
        Configured body-frame marker positions [m].
    disc, env : Disc, Environment
        Constants of the flight model.
    prior_name : str
        Coefficient prior (``potts_crowther`` or ``weak``).
    terms : tuple of Term
        Extra physics terms of the model.
    explanations : tuple of DataExplanation
        Data explanations of the recordings (marker geometry, timing).
    start_states : list of (13,) arrays
        Data-derived start state of every flight (centres the initial-condition priors).
    term_start : (n_ext,) array, optional
        Starting values of the extension parameters; default: the values that switch them off.
    settings : SimulatorSettings
        Integrator settings.
    rates : list of float, optional
        Fixed integration rate per flight [rad/s]; default: :meth:`flight_rate` of each start state.
    kernel_terms : tuple of Term
        If set, a superset of ``terms`` to integrate with (absent ones off): one compiled kernel then
        serves many models (missing-physics search).
    observations : list of tuple of ObservationModel, optional
        Per flight, its observation models (each predicts from the flight simulated on its own grid
        ``times``); default: one :class:`MarkerPositions` per flight, with the explanations. A flight with
        no marker model gets the ``inertial`` initial conditions (:mod:`.layout`).
    own_start : list of arrays, optional
        Per flight, starting values of its own observation-model parameters (default: their off values).
    ic_reference : ReferenceSurrogate, optional
        The conditional reference prior of the initial conditions (:mod:`.priors`): its log-density g̃(c) of
        the coefficients is added to :meth:`log_prior`; None (default): the wide Gaussians alone. A problem
        derived for other flights or data (:meth:`subset`, :meth:`with_marker_data` …) does not carry it.
    """

    flights: list[FlightObservation]
    marker_body: np.ndarray
    disc: Disc
    env: Environment
    prior_name: str
    terms: tuple[Term, ...] = ()
    explanations: tuple[DataExplanation, ...] = ()
    start_states: list[np.ndarray] = field(default_factory=list)
    term_start: np.ndarray | None = None
    settings: SimulatorSettings = SimulatorSettings()
    rates: list[float] | None = None
    kernel_terms: tuple[Term, ...] = ()
    observations: list[tuple[ObservationModel, ...]] | None = None
    own_start: list[np.ndarray] | None = None
    ic_reference: ReferenceSurrogate | None = None

    def __post_init__(self):
        if len(self.start_states) != len(self.flights):
            raise ValueError(f"{len(self.flights)} flights but {len(self.start_states)} start states")
        if self.observations is None:
            self.observations = [(MarkerPositions(f, self.marker_body, tuple(self.explanations)),)
                                 for f in self.flights]
        if len(self.observations) != len(self.flights) or not all(self.observations):
            raise ValueError("observations needs at least one observation model per flight")
        self.channels: list[tuple[ObservationModel, ...]] = [tuple(ch) for ch in self.observations]
        markers = [c for ch in self.channels for c in ch if isinstance(c, MarkerPositions)]
        self.marker_ids = tuple(markers[0].data.marker_ids) if markers else ()
        expl = tuple(p for e in self.explanations for p in e.parameters_for(self.marker_ids))
        shared = shared_observation_parameters(self.channels)
        self.layout = ParameterLayout(
            terms=tuple(self.terms), explanation_parameters=expl,
            observation_parameters=tuple(shared.values()),
            flight_names=tuple(f.name for f in self.flights),
            flight_parameters=tuple(tuple(p for c in ch for p in c.parameters) for ch in self.channels),
            flight_ic=tuple(FULL_IC if any(isinstance(c, MarkerPositions) for c in ch) else INERTIAL_IC
                            for ch in self.channels))
        L = self.layout
        self.n_coef, self.n_phys, self.n_ext = L.n_coef, L.n_phys, L.n_ext
        self.n_flights, self.ic_start, self.dim = L.n_flights, L.ic_start, L.dim
        self.term_start = L.off_values() if self.term_start is None else np.asarray(self.term_start, float)
        if self.term_start.shape != (self.n_ext,):
            raise ValueError(f"term_start has shape {self.term_start.shape}, the model has {self.n_ext} "
                             "extension parameters")
        if self.rates is None:
            self.rates = [self.flight_rate(s) for s in self.start_states]
        self.q_ref = [s[6:10] / np.linalg.norm(s[6:10]) for s in self.start_states]
        # θ columns each channel reads besides the flight's ICs: its shared parameters (by name), then its own
        at = {name: L.observation_slice.start + i for i, name in enumerate(shared)}
        expl_cols = np.arange(L.explanation_slice.start, L.explanation_slice.stop)
        self._columns = []
        for k, ch in enumerate(self.channels):
            per, o = [], L.own_slice(k).start
            for c in ch:
                base = expl_cols if isinstance(c, MarkerPositions) else np.zeros(0, np.intp)
                mine = np.array([at[q.name] for q in c.shared_parameters], np.intp)
                per.append(np.r_[base, mine, np.arange(o, o + len(c.parameters))].astype(np.intp))
                o += len(c.parameters)
            self._columns.append(per)
        # noise groups: every channel's, in flight order; _groups[k][c] = slice of channel c of flight k
        self.noise_names, self._groups, sizes, g = [], [], [], 0
        for ch in self.channels:
            per = []
            for c in ch:
                per.append(slice(g, g + len(c.noise_names)))
                self.noise_names += list(c.noise_names)
                sizes += list(c.group_sizes)
                g += len(c.noise_names)
            self._groups.append(per)
        self.n_coords = np.array(sizes)
        self.nominal_noise = np.concatenate([c.nominal_noise for ch in self.channels for c in ch])
        self.noise_units = [u for ch in self.channels for c in ch for u in c.noise_units]
        self._residual_groups = [np.concatenate([c.group_index + s.start for c, s in zip(ch, per)])
                                 for ch, per in zip(self.channels, self._groups)]
        self.prior_mean, self.prior_sd = self._prior_arrays()

    # -- names (asked of the layout) -------------------------------------------------------------------
    @property
    def ext_parameters(self) -> list:
        """:class:`~bayes_disc.physics.TermParameter` of every extension parameter, in θ order."""
        return list(self.layout.ext_parameters)

    @property
    def ext_names(self) -> list[str]:
        return self.layout.ext_names

    @property
    def model_ids(self) -> list[str]:
        """Ids of the model's extra physics terms and data explanations."""
        return [t.id for t in self.terms] + [e.id for e in self.explanations]

    @property
    def names(self) -> list[str]:
        return self.layout.names

    @property
    def sigma_names(self) -> list[str]:
        """Public names of the noise scales (one per noise group; ``sigma_<flight>`` for markers)."""
        return list(self.noise_names)

    @property
    def n_groups(self) -> int:
        return len(self.noise_names)

    def ic_slice(self, k: int) -> slice:
        return self.layout.ic_slice(k)

    def flight_columns(self, k: int) -> np.ndarray:
        """Indices of θ that flight k's predictions depend on (shared entries and its own)."""
        return self.layout.flight_columns(k)

    def residual_groups(self, k: int) -> np.ndarray:
        """(n_res_k,) noise-group index (into :attr:`sigma_names`) of each of flight k's residuals."""
        return self._residual_groups[k]

    def channel_columns(self, k: int) -> list[np.ndarray]:
        """Per observation model of flight k, the θ indices of the parameters it reads besides the flight's
        initial conditions (explanations or shared parameters, then its own)."""
        return list(self._columns[k])

    def channel_groups(self, k: int) -> list[slice]:
        """Per observation model of flight k, the slice of its noise groups in :attr:`sigma_names`."""
        return list(self._groups[k])

    def flight_groups(self, k: int) -> np.ndarray:
        """Indices of flight k's noise groups."""
        return np.arange(self._groups[k][0].start, self._groups[k][-1].stop)

    def subset(self, k: int, flight: FlightObservation | None = None) -> "Problem":
        """The problem of flight k alone (optionally with its recording replaced, e.g. a window), with the
        same model, settings and integration rate; a replaced recording keeps the marker model's noise
        settings and drops the flight's other channels)."""
        if flight is None:
            return self.select_flights([k])
        marker = next((c for c in self.channels[k] if isinstance(c, MarkerPositions)), None)
        observations = None if marker is None else [(marker.for_data(flight),)]
        own = None if marker is None or not self.own_start else [self.own_start[k][: len(marker.parameters)]]
        return Problem(flights=[flight], marker_body=self.marker_body,
                       disc=self.disc, env=self.env, prior_name=self.prior_name, terms=self.terms,
                       explanations=self.explanations, start_states=[self.start_states[k]],
                       term_start=self.term_start, settings=self.settings, rates=[self.rates[k]],
                       kernel_terms=self.kernel_terms, observations=observations, own_start=own)

    def select_flights(self, ks) -> "Problem":
        """The problem of flights ``ks`` (indices, in that order) alone, with the same model, settings,
        integration rates and observation models (θ entries map by name: :meth:`.layout.ParameterLayout.transfer`)."""
        ks = [int(k) for k in ks]
        return Problem(flights=[self.flights[k] for k in ks], marker_body=self.marker_body, disc=self.disc, env=self.env,
                       prior_name=self.prior_name, terms=self.terms, explanations=self.explanations,
                       start_states=[self.start_states[k] for k in ks], term_start=self.term_start,
                       settings=self.settings, rates=[self.rates[k] for k in ks], kernel_terms=self.kernel_terms,
                       observations=[self.channels[k] for k in ks],
                       own_start=None if not self.own_start else [self.own_start[k] for k in ks])

    def with_marker_data(self, flights: dict) -> "Problem":
        """The same problem with some flights' marker recordings replaced ({name: FlightObservation} on the
        same sample grid, e.g. cleaned of outliers): same parameters, starts and noise settings."""
        unknown = sorted(set(flights) - {f.name for f in self.flights})
        if unknown:
            raise KeyError(f"no flight(s) {unknown} in the problem")
        records = [flights.get(f.name, f) if isinstance(f, FlightObservation) else f for f in self.flights]
        observations = [tuple(c.for_data(flights[c.flight]) if isinstance(c, MarkerPositions) and c.flight in flights
                              else c for c in ch) for ch in self.channels]
        return Problem(flights=records, marker_body=self.marker_body, disc=self.disc, env=self.env,
                       prior_name=self.prior_name, terms=self.terms, explanations=self.explanations,
                       start_states=self.start_states, term_start=self.term_start, settings=self.settings,
                       rates=self.rates, kernel_terms=self.kernel_terms, observations=observations,
                       own_start=self.own_start)

    def with_marker_noise(self, noise: dict) -> "Problem":
        """The same problem with some flights' marker noise models replaced.

        Parameters
        ----------
        noise : dict
            {flight name: (model, per_point)} (:func:`~bayes_disc.observation.models.noise.marker_noise`).

        Returns
        -------
        Problem
            Same data, model and starts; a replaced model's own parameters (e.g. ``rho``) start at their off
            values, the flight's other channels keep theirs.

        Raises
        ------
        ValueError
            For a flight without markers, or a noise model its data do not allow (naming the flight).
        """
        x0 = self.start_vector()
        own = [x0[self.layout.own_slice(k)] for k in range(self.n_flights)]
        observations = []
        for k, (f, ch) in enumerate(zip(self.flights, self.channels)):
            if f.name not in noise:
                observations.append(ch)
                continue
            marker = next((c for c in ch if isinstance(c, MarkerPositions)), None)
            if marker is None:
                raise ValueError(f"flight {f.name!r} has no marker recording: its noise model is its sensors'")
            model, per_point = noise[f.name]
            new = MarkerPositions(marker.data, marker.marker_body, marker.explanations, model, per_point)
            own[k] = np.r_[[p.off_value for p in new.parameters], own[k][len(marker.parameters):]]
            observations.append(tuple(new if c is marker else c for c in ch))
        return Problem(flights=self.flights, marker_body=self.marker_body, disc=self.disc, env=self.env,
                       prior_name=self.prior_name, terms=self.terms, explanations=self.explanations,
                       start_states=self.start_states, term_start=self.term_start, settings=self.settings,
                       rates=self.rates, kernel_terms=self.kernel_terms, observations=observations,
                       own_start=own)

    def start_vector(self) -> np.ndarray:
        """(dim,) prior means with the extension parameters at their starting values."""
        x = self.prior_mean.copy()
        x[self.layout.ext_slice] = self.term_start
        for k, own in enumerate(self.own_start or []):
            x[self.layout.own_slice(k)] = own
        return x

    # -- priors -----------------------------------------------------------------------------------------
    def _prior_arrays(self):
        cp = coefficient_prior(self.prior_name)
        L = self.layout
        mean = np.zeros(self.dim)
        sd = np.zeros(self.dim)
        for i, n in enumerate(COEFFICIENT_NAMES):
            mean[i], sd[i] = cp.mean[n], cp.sd[n]
        for j, p in enumerate(L.ext_parameters, start=self.n_coef):
            mean[j], sd[j] = p.prior_centre, p.prior_sd
        for k in range(self.n_flights):
            mean[L.ic_slice(k)] = self.state_to_ic(self.start_states[k], k)
            sd[L.ic_slice(k)] = L.flight_ic[k].prior_sd
            own = L.own_slice(k)
            mean[own] = [p.off_value for p in L.flight_parameters[k]]
            sd[own] = [p.prior_sd for p in L.flight_parameters[k]]
        return mean, sd

    def log_prior(self, theta: np.ndarray) -> np.ndarray:
        """(B,) log-prior of θ (B, dim), up to a constant: the independent Gaussians, plus the conditional
        reference prior's g̃(c) of the coefficients when the problem carries one (:attr:`ic_reference`)."""
        theta = np.atleast_2d(theta)
        z = (theta - self.prior_mean) / self.prior_sd
        out = -0.5 * np.sum(z * z, axis=1)
        if self.ic_reference is not None:
            out = out + self.ic_reference(theta[:, : self.n_coef])
        return out

    def with_ic_reference(self, surrogate: ReferenceSurrogate | None) -> "Problem":
        """The same problem with the conditional reference prior ``surrogate`` (None: without one)."""
        from dataclasses import replace
        return replace(self, ic_reference=surrogate)

    def sample_prior(self, n: int, rng: np.random.Generator) -> np.ndarray:
        return self.prior_mean + self.prior_sd * rng.standard_normal((n, self.dim))

    # -- states -----------------------------------------------------------------------------------------
    def ic_to_state(self, ic: np.ndarray, k: int) -> np.ndarray:
        """(B, n_ic) initial-condition parameters of flight k → (B, 13) states (:mod:`.layout`)."""
        ic = np.atleast_2d(ic)
        if self.layout.flight_ic[k] == INERTIAL_IC:          # equality: survives pickling (worker processes)
            tilt = np.concatenate([ic[:, 0:2], np.zeros((ic.shape[0], 1))], axis=1)
            R = quat_to_matrix(quat_from_rotvec(tilt)) @ R_LEVEL
            v = np.einsum("bij,bj->bi", R, ic[:, 2:5])
            x = np.broadcast_to([0.0, 0.0, INERTIAL_RELEASE_HEIGHT], v.shape)
            return np.concatenate([x, v, matrix_to_quat(R), ic[:, 5:8]], axis=1)
        q = quat_multiply(self.q_ref[k], quat_from_rotvec(ic[:, 6:9]))
        return np.concatenate([ic[:, :6], q, ic[:, 9:12]], axis=1)

    def state_to_ic(self, state: np.ndarray, k: int) -> np.ndarray:
        """(13,) state of flight k → its initial-condition parameters (for ``inertial`` flights the state
        is first turned about the vertical so that R = exp([tilt1, tilt2, 0]×) R_level)."""
        if self.layout.flight_ic[k] == INERTIAL_IC:          # equality: survives pickling (worker processes)
            R = quat_to_matrix(state[6:10])
            M = R @ R_LEVEL.T
            psi = np.arctan2(M[1, 0] - M[0, 1], M[0, 0] + M[1, 1])
            c, s = np.cos(psi), np.sin(psi)
            T = np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]]) @ M
            tilt = quat_to_rotvec(matrix_to_quat(T))[:2]
            return np.concatenate([tilt, R.T @ state[3:6], state[10:13]])
        qr = self.q_ref[k] * np.array([1, -1, -1, -1])
        rel = quat_multiply(qr, state[6:10])
        return np.concatenate([state[:6], quat_to_rotvec(rel), state[10:13]])

    # -- model ------------------------------------------------------------------------------------------
    def predict(self, theta: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
        """Markers (B, n, n_markers, 3) of flight k for θ (B, dim), and ok flags (B,)."""
        tr = self.simulate(theta, k, want_states=False)
        return tr.markers, tr.ok

    def _run(self, theta: np.ndarray, k: int, want_states: bool, times: np.ndarray | None = None):
        """The simulator's raw Trajectories of flight k on ``times`` (default: its first channel's grid)."""
        times = self.channels[k][0].times if times is None else times
        states = self.ic_to_state(theta[:, self.ic_slice(k)], k)
        terms, ext = self.terms, (theta[:, self.layout.term_slice] if self.n_phys else None)
        if self.kernel_terms:
            terms, ext = self.kernel_terms, self.layout.kernel_extension(theta, self.kernel_terms)
        settings = SimulatorSettings(method=self.settings.method, step_factor=self.settings.step_factor,
                                     omega_cap=self.settings.omega_cap, speed_cap=self.settings.speed_cap,
                                     fixed_rate=self.rates[k])
        need = want_states or any(c.needs_states for c in self.channels[k] if c.times is times)
        return simulate(states, theta[:, : self.n_coef], times, t0=times[0], disc=self.disc, env=self.env,
                        marker_body=self.marker_body, terms=terms, extension=ext, settings=settings,
                        want_states=need)

    def channel_predictions(self, theta: np.ndarray, k: int):
        """[(channel, prediction)] of flight k and the ok flags (B,): one simulation per distinct grid."""
        runs, out, ok = {}, [], np.ones(theta.shape[0], bool)
        for c, cols in zip(self.channels[k], self._columns[k]):
            key = id(c.times)
            if key not in runs:
                runs[key] = self._run(theta, k, want_states=False, times=c.times)
                ok &= runs[key].ok
            out.append((c, c.predict(runs[key], theta[:, cols] if cols.size else None)))
        return out, ok

    def simulate(self, theta: np.ndarray, k: int, want_states: bool = True):
        """The simulator's :class:`~bayes_disc.physics.simulator.Trajectories` of flight k for θ (B, dim)
        on its first channel's grid (for marker flights the sample times; markers as the marker model
        predicts them, explanations included)."""
        from dataclasses import replace
        theta = np.atleast_2d(theta)
        tr = self._run(theta, k, want_states)
        if self.explanations and isinstance(self.channels[k][0], MarkerPositions):
            tr = replace(tr, markers=self.channels[k][0].predict(tr, theta[:, self._columns[k][0]]))
        if not want_states and tr.states is not None:
            tr = replace(tr, states=None)
        return tr

    def conditions(self, states: np.ndarray, theta: np.ndarray, k: int):
        """Air-relative flight conditions (:class:`~bayes_disc.physics.FlightConditions`: v_a, air speed, D
        frame, α, p, q, r) of flight k along ``states`` ((n, 13) or (B, n, 13)) for θ ((dim,) or (B, dim)):
        the model's wind terms included."""
        return flight_conditions(states, self.channels[k][0].times, self.terms, theta[..., self.layout.term_slice])

    def residuals(self, theta: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
        """Residuals (B, n_res_k) (predicted − measured, every channel of flight k, each in its data's
        unit) and ok flags (B,)."""
        theta = np.atleast_2d(theta)
        preds, ok = self.channel_predictions(theta, k)
        parts = [c.residuals(p) for c, p in preds]
        return (parts[0] if len(parts) == 1 else np.concatenate(parts, axis=1)), ok

    def noise_residuals(self, theta: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
        """Effective residuals ẽ (B, n_res_k) of flight k (every channel's residuals whitened by its noise
        unit and scaled so that Σ_g ẽ² = S̃_g, :meth:`ObservationModel.effective_residuals`; the residuals
        themselves for independent noise of one size) and ok flags (B,): least squares fits these."""
        theta = np.atleast_2d(theta)
        preds, ok = self.channel_predictions(theta, k)
        parts = [c.effective_residuals(c.residuals(p), self._extra(theta, k, j)) for j, (c, p) in enumerate(preds)]
        return (parts[0] if len(parts) == 1 else np.concatenate(parts, axis=1)), ok

    def _extra(self, theta: np.ndarray, k: int, j: int) -> np.ndarray | None:
        """θ columns (B, k) channel j of flight k reads besides the initial conditions (None if none)."""
        cols = self._columns[k][j]
        return theta[:, cols] if cols.size else None

    def flight_sum_squares(self, theta: np.ndarray, k: int) -> np.ndarray:
        """S̃_g (B, n_groups_k) of flight k's noise groups (:meth:`flight_groups`): one batched simulation of
        that flight alone; inf where a lane failed."""
        theta = np.atleast_2d(theta)
        base = self._groups[k][0].start
        out = np.empty((theta.shape[0], self.flight_groups(k).size))
        preds, ok = self.channel_predictions(theta, k)
        for j, ((c, p), g) in enumerate(zip(preds, self._groups[k])):
            ss = c.effective_sum_squares(p, self._extra(theta, k, j))
            out[:, g.start - base: g.stop - base] = np.where(ok[:, None] & np.isfinite(ss), ss, np.inf)
        return out

    def flight_log_likelihood(self, ss: np.ndarray, k: int) -> np.ndarray:
        """(B,) log p(y_k | θ) of flight k alone from its S̃_g (B, n_groups_k), every noise scale integrated
        out: the likelihood factorises over flights (each flight's noise groups are its own)."""
        base = self._groups[k][0].start
        return sum(c.log_likelihood(ss[:, g.start - base: g.stop - base]) for c, g in zip(self.channels[k], self._groups[k]))

    def sum_squares(self, theta: np.ndarray) -> np.ndarray:
        """S̃_g (B, n_groups): effective summed squared residuals per noise group (the plain sums of squares
        for independent noise of one size); inf where a lane failed."""
        theta = np.atleast_2d(theta)
        out = np.empty((theta.shape[0], self.n_groups))
        for k in range(self.n_flights):
            out[:, self.flight_groups(k)] = self.flight_sum_squares(theta, k)
        return out

    def log_likelihood_from_ss(self, ss: np.ndarray) -> np.ndarray:
        """Σ over flights and channels of log p(y | θ), every noise scale integrated out."""
        return sum(self.flight_log_likelihood(ss[:, self.flight_groups(k)], k) for k in range(self.n_flights))

    def log_likelihood(self, theta: np.ndarray) -> np.ndarray:
        return self.log_likelihood_from_ss(self.sum_squares(theta))

    def log_prob_blobs(self, theta: np.ndarray) -> np.ndarray:
        """Vectorised log-posterior for emcee with blobs: rows (log p(θ | y), S_1 … S_G), shape (B, 1 + G)."""
        theta = np.atleast_2d(theta)
        ss = self.sum_squares(theta)
        lp = self.log_prior(theta) + self.log_likelihood_from_ss(ss)
        lp = np.where(np.isfinite(lp), lp, -np.inf)
        return np.column_stack([lp, ss])

    def log_prob(self, theta: np.ndarray) -> np.ndarray:
        """Vectorised log-posterior p(θ | y) (θ: (B, dim) → (B,))."""
        return self.log_prob_blobs(theta)[:, 0]

    def draw_sigma(self, ss: np.ndarray, rng: np.random.Generator, theta: np.ndarray | None = None) -> np.ndarray:
        """Noise scales drawn from their exact conditionals given θ.

        Parameters
        ----------
        ss : (B, n_groups) array
            Effective sums of squares S̃_g of B draws (the sampler's blobs).
        rng : numpy.random.Generator
        theta : (B, dim) array, optional
            The draws themselves; required when a noise unit's whitening depends on its parameters (AR(1)).

        Returns
        -------
        (B, n_groups) array
            σ_g in each group's unit.
        """
        out = np.empty_like(ss)
        for k, (ch, per) in enumerate(zip(self.channels, self._groups)):
            for j, (c, g) in enumerate(zip(ch, per)):
                extra = None if theta is None else self._extra(np.atleast_2d(theta), k, j)
                out[..., g] = c.draw_noise(ss[..., g], rng, extra)
        return out

    def flight_rate(self, state: np.ndarray) -> float:
        """Integration rate for a flight: 1.25 × the fastest rate of its start (spin, nutation, aero)."""
        w = state[10:13]
        return 1.25 * max(np.linalg.norm(w), self.disc.Ia / self.disc.Id * abs(w[2]), 30.0)
