"""3-D marker positions (Hummel & Hubbard 2002): the first observation model.

Marker j of a flight is predicted at sample time t as

    m_j(t) = x(t + δ_j) + R(t + δ_j) (b_j + Δ_j)

x the centre of mass [m], R the body-to-world rotation, b_j the configured body position [m]; the body
offsets Δ_j [m] and timing offsets δ_j [s] are the data explanations ``marker_geometry`` and
``time_offset`` (:mod:`bayes_disc.observation.explanations`; zero unless the model includes them).
Every observed coordinate is y = m + ε, ε ~ N(0, σ_f²) independent, with one noise scale σ_f [m] per
flight (public name ``sigma_<flight>``), prior p(σ_f) ∝ 1/σ_f, integrated out analytically.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..explanations import DataExplanation, predicted_markers
from ..markers import FlightObservation
from .base import ObservationModel


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
    """

    id = "markers"
    title = "3-D marker positions"
    equations = "m_j(t) = x(t + δ_j) + R(t + δ_j)(b_j + Δ_j);  y = m + ε,  ε ~ N(0, σ_f² I)  [m]"

    data: FlightObservation
    marker_body: np.ndarray
    explanations: tuple[DataExplanation, ...] = ()
    _mask: np.ndarray = field(init=False, repr=False)
    _obs: np.ndarray = field(init=False, repr=False)

    def __post_init__(self):
        self.flight = self.data.name
        self.times = self.data.times
        self._mask = self.data.observed
        self._obs = self.data.positions[self._mask]
        self._groups = np.zeros(3 * int(self._mask.sum()), dtype=np.intp)

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
        r = prediction[:, self._mask] - self._obs[None]
        return r.reshape(r.shape[0], -1)
