"""3-D marker positions (Hummel & Hubbard 2002): the first observation model.

Marker j of a flight is predicted at sample time t as

    m_j(t) = x(t + δ_j) + R(t + δ_j) (b_j + Δ_j)

x the centre of mass [m], R the body-to-world rotation, b_j the configured body position [m]; the body
offsets Δ_j [m] and timing offsets δ_j [s] are the data explanations ``marker_geometry`` and
``time_offset`` (:mod:`bayes_disc.observation.explanations`; zero unless the model includes them).
Every observed coordinate is y = m + ε with one noise scale σ_f [m] per flight (public name
``sigma_<flight>``), prior p(σ_f) ∝ 1/σ_f, integrated out analytically. By default ε ~ N(0, σ_f²)
independent; the flight's noise unit (:mod:`.noise`: per-point errors, AR(1) in time) may shape and
correlate it, whitening the residuals and adding its own per-flight parameters (e.g. ``rho_<flight>``).

Residual series (diagnostics): the residuals r = measured − predicted [m] are averaged over the markers
seen at each sample (r̄(t), standard error σ/√n_seen per component) and projected on two frames:

* flight path: along-track t̂ = v̂, lateral ŝ = (ẑ × v̂)/|ẑ × v̂| (to the left), normal n̂ = t̂ × ŝ (up);
* disc (velocity-aligned D frame of docs/conventions.md): d1, d2 (to the right), d3 = b3 (down through the disc).

The markers' spread about their mean carries the attitude residual: the small rotation δθ [rad] that
best maps the predicted lever arms p̃_j = p_j − p̄ onto the measured ones,

    δθ = (Σ_j |p̃_j|² I − p̃_j p̃_jᵀ)⁻¹ Σ_j p̃_j × (r_j − r̄),

projected as roll (about d1), pitch (about d2) and spin phase (about d3).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..explanations import DataExplanation, predicted_markers
from ..markers import FlightObservation
from ._marker_kernels import seen_sum_squares
from .base import ObservationModel, ResidualSeries
from .noise import MarkerNoise, marker_noise

#: the translation series of the marker model [m]
DIRECTIONS = ("along", "lateral", "normal", "d1", "d2", "d3")
#: the attitude series [rad]
ROTATIONS = ("roll", "pitch", "spin_phase")


def flight_axes(states: np.ndarray, conditions) -> dict:
    """Unit vectors (n, 3) of the flight-path frame (along, lateral, normal: ground-relative velocity) and
    the D frame (d1, d2, d3: air-relative, from ``conditions``, the
    :class:`~bayes_disc.physics.FlightConditions` of the same states) along states (n, 13)."""
    v = states[:, 3:6]
    t_hat = v / np.linalg.norm(v, axis=1, keepdims=True)
    s = np.cross(np.array([0.0, 0.0, 1.0]), t_hat)
    s_hat = s / np.linalg.norm(s, axis=1, keepdims=True)
    n_hat = np.cross(t_hat, s_hat)
    return {"along": t_hat, "lateral": s_hat, "normal": n_hat,
            "d1": conditions.d1[0], "d2": conditions.d2[0], "d3": conditions.d3[0]}


def attitude_residual(res: np.ndarray, arms: np.ndarray, seen: np.ndarray, axes: dict) -> tuple[dict, dict]:
    """Attitude residual δθ (module docstring) at samples where every marker is seen, projected on d1, d2,
    d3; and its standard error per unit marker noise.

    Parameters
    ----------
    res, arms : (n, m, 3) arrays
        Per-marker differences (zero where unseen) and predicted lever arms from the centre of mass [m].
    seen : (n, m) bool array
    axes : dict
        :func:`flight_axes` of the flight.

    Returns
    -------
    rot : dict
        {roll, pitch, spin_phase: (n,)} [rad], NaN unless every marker (at least 3) is seen.
    se : dict
        {same: (n,)} standard error per unit marker noise [rad/m].
    """
    n, m, _ = res.shape
    full = np.all(seen, axis=1) & (m >= 3)
    p = arms - arms.mean(axis=1, keepdims=True)
    d = res - res.mean(axis=1, keepdims=True)
    A = np.einsum("njc,njc->n", p, p)[:, None, None] * np.eye(3) - np.einsum("nji,njk->nik", p, p)
    b = np.cross(p, d).sum(axis=1)
    A = np.where(full[:, None, None], A, np.eye(3))
    theta = np.linalg.solve(A, b[..., None])[..., 0]
    Ainv = np.linalg.inv(A)
    rot, se = {}, {}
    for name, axis in zip(ROTATIONS, ("d1", "d2", "d3")):
        a = axes[axis]
        rot[name] = np.where(full, np.einsum("ni,ni->n", theta, a), np.nan)
        se[name] = np.sqrt(np.einsum("ni,nik,nk->n", a, Ainv, a))
    return rot, se


def marker_series(diff: np.ndarray, states: np.ndarray, markers: np.ndarray, seen: np.ndarray, conditions):
    """Series of a per-marker difference.

    Parameters
    ----------
    diff : (n, m, 3) array
        Per-marker difference [m] (finite where ``seen``).
    states : (n, 13) array
        Predicted states.
    markers : (n, m, 3) array
        Predicted markers [m].
    seen : (n, m) bool array
    conditions : FlightConditions
        Of the states.

    Returns
    -------
    r : (n, 3) array
        Marker mean r̄ [m] (NaN where nothing was seen).
    proj : dict
        {direction: (n,)} projections of r̄ [m].
    rot, rot_se : dict
        Attitude angles [rad] and their standard errors per unit noise (:func:`attitude_residual`).
    """
    n_seen = np.sum(seen, axis=1)
    total = np.sum(np.where(seen[..., None], diff, 0.0), axis=1)
    r = np.where(n_seen[:, None] > 0, total / np.maximum(n_seen, 1)[:, None], np.nan)
    axes = flight_axes(states, conditions)
    proj = {name: np.einsum("ni,ni->n", r, axis) for name, axis in axes.items()}
    rot, rot_se = attitude_residual(np.where(seen[..., None], diff, 0.0), markers - states[:, None, 0:3], seen, axes)
    return r, proj, rot, rot_se


@dataclass(eq=False)
class MarkerPositions(ObservationModel):
    """Marker positions of one flight.

    Parameters
    ----------
    data : FlightObservation
        The flight's sample times (n,) [s] and marker positions (n, m, 3) [m], NaN where unseen.
    marker_body : (m, 3) array
        Configured body-frame marker positions b_j [m], in the order of ``data.marker_ids``.
    explanations : tuple of DataExplanation
        Data explanations applied to the prediction, in parameter-layout order.
    noise_model : {"gaussian", "ar1"}
        The flight's noise unit (:mod:`.noise`).
    per_point : {"auto", "true", "false"}
        Per-point errors from ``sigma_m`` or the covariance columns (``auto``: when the file has them).
    """

    id = "markers"
    title = "3-D marker positions"
    equations = ("m_j(t) = x(t + δ_j) + R(t + δ_j)(b_j + Δ_j);  y = m + ε,  ε ~ N(0, σ_f² C)  [m],  C from the "
                 "flight's noise unit (I by default; :mod:`.noise`)")

    data: FlightObservation
    marker_body: np.ndarray
    explanations: tuple[DataExplanation, ...] = ()
    noise_model: str = "gaussian"
    per_point: str = "auto"
    noise: MarkerNoise = field(init=False, repr=False)
    _mask: np.ndarray = field(init=False, repr=False)
    _obs: np.ndarray = field(init=False, repr=False)
    _seen: np.ndarray = field(init=False, repr=False)     # flat (sample, marker) index of the observed points

    def __post_init__(self):
        self.flight = self.data.name
        self.times = self.data.times
        self._mask = self.data.observed
        self._obs = self.data.positions[self._mask]
        self._seen = np.flatnonzero(self._mask.ravel())
        self._groups = np.zeros(3 * int(self._mask.sum()), dtype=np.intp)
        self.noise = marker_noise(self.data, self.noise_model, self.per_point)

    def for_data(self, data: FlightObservation) -> "MarkerPositions":
        """The same model (explanations, noise settings) for other data of the flight (e.g. a window)."""
        return MarkerPositions(data, self.marker_body, self.explanations, self.noise_model, self.per_point)

    @property
    def parameters(self):
        """The noise unit's own parameters (e.g. ``rho`` of AR(1) noise)."""
        return self.noise.parameters

    def _own(self, extra: np.ndarray | None) -> np.ndarray | None:
        k = len(self.noise.parameters)
        return extra[:, extra.shape[1] - k:] if k else None

    def whiten(self, residuals, extra):
        return self.noise.whiten(residuals, self._own(extra))

    def log_diagonal(self, extra):
        return self.noise.log_diagonal(self._own(extra))

    def log_det(self, extra):
        ld = self.noise.log_det(self._own(extra))
        return None if ld is None else ld[:, None]

    @property
    def log_det_depends_on_parameters(self) -> bool:
        return bool(self.noise.parameters)

    def sample_noise(self, sigma: np.ndarray, extra: np.ndarray | None, rng: np.random.Generator) -> np.ndarray:
        """Noise draws (B, n, n_markers, 3) [m] on the whole sample grid for the flight's σ_f (B,) and the
        model's parameters ``extra`` (B, k) (:meth:`.noise.MarkerNoise.sample`)."""
        return self.noise.sample(sigma, self._own(extra), rng)

    @property
    def explanation_ids(self) -> tuple[str, ...]:
        return tuple(e.id for e in self.explanations)

    @property
    def needs_states(self) -> bool:
        return bool(self.explanations)

    @property
    def noise_names(self) -> tuple[str, ...]:
        return (f"sigma_{self.flight}",)

    @property
    def group_index(self) -> np.ndarray:
        return self._groups

    @property
    def noise_units(self) -> tuple[str, ...]:
        return ("m",)

    @property
    def nominal_noise(self) -> np.ndarray:
        return np.array([2e-3])          # m: motion capture 0.1–3 mm, video a few mm

    @property
    def n_coords(self) -> int:
        """Number of observed coordinates (3 per seen marker point)."""
        return self._groups.size

    def explanation_sizes(self) -> list[int]:
        """Number of parameters of each applied explanation."""
        return [len(e.parameters_for(self.data.marker_ids)) for e in self.explanations]

    def predict(self, trajectories, extra: np.ndarray | None) -> np.ndarray:
        """Markers (B, n, m, 3) [m]: the simulator's when no explanation applies, else recomputed from the
        states with the explanations' body and timing offsets."""
        if not self.explanations:
            return trajectories.markers
        m = self.marker_body.shape[0]
        body, timing, j = None, None, 0
        for e, size in zip(self.explanations, self.explanation_sizes()):
            b, t = e.offsets(extra[:, j: j + size], m)
            body = b if b is not None else body
            timing = t if t is not None else timing
            j += size
        return predicted_markers(trajectories.states, self.marker_body, body, timing, self.times)

    def residuals(self, prediction: np.ndarray) -> np.ndarray:
        B, n, m, _ = prediction.shape      # np.take on a precomputed index: ~3x faster than the boolean mask
        r = np.take(prediction.reshape(B, n * m, 3), self._seen, axis=1) - self._obs[None]
        return r.reshape(B, -1)

    def effective_sum_squares(self, prediction: np.ndarray, extra: np.ndarray | None) -> np.ndarray:
        """S̃ (B, 1): with independent noise of one size (W = I) Σ (m − y)² over the observed coordinates in one
        compiled pass (:func:`._marker_kernels.seen_sum_squares`); otherwise through the whitened residuals
        (:meth:`.base.ObservationModel.effective_sum_squares`)."""
        if not self.noise.white:
            return super().effective_sum_squares(prediction, extra)
        B, n, m, _ = prediction.shape
        flat = np.ascontiguousarray(prediction).reshape(B, n * m, 3)
        return seen_sum_squares(flat, self._seen, self._obs)[:, None]

    def residual_series(self, trajectories, extra, prediction, conditions, reference=None) -> ResidualSeries:
        """Marker mean projected on the flight-path and D frames [m] and the attitude residual [rad]
        (module docstring); contract: :meth:`.base.ObservationModel.residual_series`."""
        st, pred = trajectories.states[0], prediction[0]
        if reference is None:
            seen, ref = self._mask, self.data.positions
        else:
            seen, ref = np.ones(pred.shape[:2], bool), reference[0]
        n_seen = np.sum(seen, axis=1)
        diff = np.where(seen[..., None], ref - pred, 0.0)
        if reference is None and not self.noise.white:
            # the noise model's innovations per marker coordinate (AR(1) filtered, per-point standardised),
            # so that the series' whiteness tests see what the noise model does not explain
            diff[seen] = self.noise.whiten(diff[seen].reshape(1, -1), self._own(extra)).reshape(-1, 3)
        _, proj, rot, rot_se = marker_series(diff, st, pred, seen, conditions)
        names = DIRECTIONS + ROTATIONS
        cov = {"alpha": conditions.alpha[0], "speed": conditions.speed[0], "spin": st[:, 12],
               "height": st[:, 2], "time": self.times - self.times[0]}
        unit_se = {name: 1.0 / np.sqrt(np.maximum(n_seen, 1)) for name in DIRECTIONS} | rot_se
        return ResidualSeries(times=self.times, series=proj | rot, unit_se=unit_se,
                              groups={n: 0 for n in names}, units={n: "m" if n in DIRECTIONS else "rad" for n in names},
                              covariates=cov, primary=("along", "lateral", "normal"),
                              group_channels=(("markers", "m"),))
