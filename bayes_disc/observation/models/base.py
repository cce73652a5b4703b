"""The contract every observation model fulfils (like ``scipy.integrate.OdeSolver``).

An observation model holds one flight's recordings of one kind and answers, for a batch of B parameter
vectors whose simulated trajectories are given:

* ``predict(trajectories, extra)``: the noise-free prediction of the recordings;
* ``residuals(prediction)``: predicted − measured on the observed entries, (B, n_res) in the data's unit;
* ``group_index`` (n_res,): the noise group of each residual (entries sharing one noise scale σ_g);
* ``log_likelihood(ss)``: log p(y | θ) from the per-group sums of squared residuals S_g (B, n_groups),
  with each σ_g integrated out under its Jeffreys prior p(σ_g) ∝ 1/σ_g (:func:`gaussian_marginal_loglik`);
* ``draw_noise(ss, rng, extra)``: σ_g drawn exactly from σ_g² | θ, y ~ S_g / χ²_{n_g}.

Correlated or unequal noise (residuals r ~ N(0, σ_g² C_g(φ)), φ the model's own parameters) enters through
a lower-triangular whitening map W with W C Wᵀ = I: ``whiten(residuals, extra)`` gives e = W r
(independent N(0, σ_g²)), ``log_diagonal(extra)`` the log of W's diagonal per residual and ``log_det(extra)``
(B, n_groups) the part of log |W| that depends on θ. Integrating σ_g out,

    p(y_g | θ) = |W_g| · ½ Γ(n_g/2) (π S_g)^(−n_g/2) = ½ Γ(n_g/2) (π S̃_g)^(−n_g/2),   S̃_g = |W_g|^(−2/n_g) S_g,

so the contract holds with the *effective* sums of squares S̃_g (:meth:`ObservationModel.effective_residuals`:
e scaled by |W_g|^(−1/n_g), Σ ẽ² = S̃_g). With no such map (the default) ẽ = r, S̃ = S. ``draw_noise``
then undoes the scaling: σ_g² = |W_g|^(2/n_g) S̃_g / χ²_{n_g}.

Optionally (diagnostics and the report) ``residual_series(trajectories, extra, prediction, conditions)``:
the model's residuals as named (n,) series in physical directions, with their standard errors per unit
noise scale, the noise group of each, and the flight's covariates on the series' time grid
(:class:`ResidualSeries`).

``times`` is the grid (s, starting at the flight's release or first sample) on which the flight must be
simulated for this model. It also names its noise groups (``noise_names``, the public names of the σ_g), the data explanations it
applies (``explanation_ids``: their parameters are shared by every flight and sit in the parameter
layout's extension block) and its own per-flight parameters (``parameters``: names, units, off values and
prior scales; none for markers). ``needs_states`` tells the simulator whether full states are required.
"""
from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass
from typing import ClassVar

import numpy as np
from scipy.special import gammaln

from ...physics import TermParameter


def gaussian_marginal_loglik(ss: np.ndarray, n: np.ndarray) -> np.ndarray:
    """log ∫ N(y | m, σ² I) dσ/σ = log Γ(n/2) − log 2 − (n/2) log(π S), summed over groups.

    Parameters
    ----------
    ss : (B, G) array
        Sums of squared residuals S_g per noise group [unit²].
    n : (G,) array
        Number of residuals in each group.

    Returns
    -------
    (B,) array
        Σ_g log p(y_g | θ) with σ_g integrated out.
    """
    n = np.asarray(n, float)
    const = gammaln(n / 2) - np.log(2.0) - 0.5 * n * np.log(np.pi)
    return np.sum(const - 0.5 * n * np.log(ss), axis=1)


#: covariates every :class:`ResidualSeries` carries (units: rad, m/s, rad/s, m, s)
COVARIATES = ("alpha", "speed", "spin", "height", "time")


@dataclass
class ResidualSeries:
    """One observation model's residuals of one flight as named series (diagnostics and the report).

    Attributes
    ----------
    times : (n,) array
        Times of the series [s], on the model's clock: the recorded sample times for markers, since
        release for inertial logs (the ``time`` covariate always counts from the flight's start).
    series : dict
        {name: (n,) array} reference − prediction (by default measured − predicted) in physical
        directions, in the unit ``units[name]``; NaN where the data have nothing.
    unit_se : dict
        {name: (n,) array} standard error of each sample per unit noise scale σ of its group.
    groups : dict
        {name: int} the model's noise group (index into ``noise_names``) whose σ scales the series.
    units : dict
        {name: str} unit of each series ("m", "rad", "rad/s", "m/s²").
    covariates : dict
        {name: (n,) array} the flight's α [rad], air speed [m/s], spin r [rad/s], height z [m] and time [s]
        along the predicted trajectory, on ``times`` (names: :data:`COVARIATES`).
    primary : tuple of str
        The series whose whitened squares locate the strongest structure (peak window).
    group_channels : tuple of (str, str)
        Per noise group of the model: the recorded quantity it belongs to ("markers", "gyro", "acc") and
        its unit — the channels of the per-flight RMS.
    """

    times: np.ndarray
    series: dict
    unit_se: dict
    groups: dict
    units: dict
    covariates: dict
    primary: tuple
    group_channels: tuple


class ObservationModel(ABC):
    """One flight's recordings of one kind, and how the flight model predicts them (module docstring)."""

    #: registry id (``observation.registry``)
    id: ClassVar[str]
    #: one-line title
    title: ClassVar[str]
    #: the measurement equations, symbols and units
    equations: ClassVar[str]

    flight: str
    times: np.ndarray

    @property
    def parameters(self) -> tuple[TermParameter, ...]:
        """This flight's own parameters of the model (appended to the flight's initial conditions)."""
        return ()

    @property
    def shared_parameters(self) -> tuple[TermParameter, ...]:
        """Parameters of the model shared by every flight it observes (e.g. where a logger sits); they
        appear once in the parameter layout's extension block."""
        return ()

    @property
    def explanation_ids(self) -> tuple[str, ...]:
        """Ids of the data explanations this model applies (their parameters are shared by all flights)."""
        return ()

    @property
    def needs_states(self) -> bool:
        return True

    @property
    @abstractmethod
    def noise_names(self) -> tuple[str, ...]:
        """Public names of the noise scales σ_g, one per group."""

    @property
    @abstractmethod
    def group_index(self) -> np.ndarray:
        """(n_res,) noise group of each residual."""

    @property
    @abstractmethod
    def noise_units(self) -> tuple[str, ...]:
        """Unit of each noise group's scale (the data's unit)."""

    @property
    @abstractmethod
    def nominal_noise(self) -> np.ndarray:
        """(n_groups,) a plausible noise scale per group, in the data's unit: the weights of the first
        least-squares pass (before each group's RMS replaces them)."""

    @property
    def group_sizes(self) -> np.ndarray:
        """(n_groups,) number of residuals per noise group."""
        return np.bincount(self.group_index, minlength=len(self.noise_names))

    @abstractmethod
    def predict(self, trajectories, extra: np.ndarray | None) -> np.ndarray:
        """Noise-free prediction from :class:`~bayes_disc.physics.Trajectories` (batch B) and the values
        (B, k) of the explanation and own parameters (``None`` when there are none)."""

    @abstractmethod
    def residuals(self, prediction: np.ndarray) -> np.ndarray:
        """(B, n_res) predicted − measured on the observed entries."""

    def residual_series(self, trajectories, extra: np.ndarray | None, prediction: np.ndarray, conditions,
                        reference: np.ndarray | None = None) -> ResidualSeries:
        """Optional: the residuals as named series for diagnostics and the report.

        Parameters
        ----------
        trajectories : Trajectories
            One parameter vector's simulation (B = 1) on :attr:`times`, states included.
        extra : (1, k) array or None
            The values of the model's explanation and own parameters (as for :meth:`predict`).
        prediction : array
            :meth:`predict` of ``trajectories`` and ``extra`` (leading axis B = 1).
        conditions : FlightConditions
            Air-relative flight conditions along ``trajectories.states[0]`` (on :attr:`times`).
        reference : array, optional
            Another prediction (same shape as ``prediction``) to difference against instead of the
            measured data (the effect of a term: reference − prediction, every entry used).

        Returns
        -------
        ResidualSeries
        """
        raise NotImplementedError(f"observation model {self.id!r} gives no residual series")

    def whiten(self, residuals: np.ndarray, extra: np.ndarray | None) -> np.ndarray:
        """e = W r (B, n_res): residuals whitened to independent N(0, σ_g²) (module docstring); the
        default W = I returns ``residuals`` itself. ``extra`` as for :meth:`predict`."""
        return residuals

    def log_diagonal(self, extra: np.ndarray | None) -> np.ndarray | None:
        """(B or 1, n_res) log of W's diagonal entry of each residual (pointwise log-Jacobian), None for W = I."""
        return None

    def log_det(self, extra: np.ndarray | None) -> np.ndarray | None:
        """(B, n_groups) the part of log |W_g| that depends on θ; None when there is none."""
        return None

    def effective_residuals(self, residuals: np.ndarray, extra: np.ndarray | None) -> np.ndarray:
        """ẽ (B, n_res): whitened residuals scaled by |W_g|^(−1/n_g), so that Σ_g ẽ² = S̃_g and
        p(y | θ) = :func:`gaussian_marginal_loglik` (S̃) exactly (module docstring); ``residuals`` itself
        when W = I."""
        e = self.whiten(residuals, extra)
        ld = self.log_det(extra)
        if ld is None:
            return e
        return e * np.exp(-ld / self.group_sizes)[:, self.group_index]

    def sum_squares(self, residuals: np.ndarray) -> np.ndarray:
        """(B, n_groups) sums of squared residuals per noise group."""
        G = len(self.noise_names)
        if G == 1:
            return np.sum(residuals * residuals, axis=1)[:, None]
        out = np.zeros((residuals.shape[0], G))
        for g in range(G):
            r = residuals[:, self.group_index == g]
            out[:, g] = np.sum(r * r, axis=1)
        return out

    def effective_sum_squares(self, prediction: np.ndarray, extra: np.ndarray | None) -> np.ndarray:
        """S̃_g (B, n_groups) of a prediction: :meth:`sum_squares` of the :meth:`effective_residuals` of its
        :meth:`residuals`. The likelihood needs only these sums; a model may compute them without the
        residual arrays (:class:`.markers.MarkerPositions` for independent noise of one size)."""
        return self.sum_squares(self.effective_residuals(self.residuals(prediction), extra))

    def log_likelihood(self, ss: np.ndarray) -> np.ndarray:
        """(B,) log p(y | θ) with every σ_g integrated out (Jeffreys prior), from ss (B, n_groups)."""
        return gaussian_marginal_loglik(ss, self.group_sizes)

    def draw_noise(self, ss: np.ndarray, rng: np.random.Generator, extra: np.ndarray | None = None) -> np.ndarray:
        """σ_g drawn from σ_g² | θ, y ~ S_g / χ²_{n_g}, S_g = |W_g|^(2/n_g) S̃_g.

        Parameters
        ----------
        ss : (B, n_groups) array
            Effective sums of squares S̃_g (the sampler's blobs).
        rng : numpy.random.Generator
        extra : (B, k) array, optional
            The model's parameters of each draw (as for :meth:`predict`); needed when :meth:`log_det`
            depends on them.

        Returns
        -------
        (B, n_groups) array
            σ_g in the data's unit.
        """
        sigma = np.sqrt(ss / rng.chisquare(self.group_sizes, size=ss.shape))
        if not self.log_det_depends_on_parameters:
            return sigma
        if extra is None:
            raise ValueError(f"observation model {self.id!r}: drawing σ needs each draw's parameter values (extra)")
        return sigma * np.exp(self.log_det(extra) / self.group_sizes)

    @property
    def log_det_depends_on_parameters(self) -> bool:
        """Whether :meth:`log_det` depends on the model's own parameters (then σ draws need them)."""
        return False
