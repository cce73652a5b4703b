"""Noise models of marker positions: units the marker model (:class:`.markers.MarkerPositions`) delegates to.

The marker residuals of one flight, r = m(θ) − y [m], P observed points × 3 coordinates, are modelled as

    r ~ N(0, σ_f² C(φ)),    p(σ_f) ∝ 1/σ_f,

with C a correlation/shape matrix fixed by the data (per-point errors) and the unit's own per-flight
parameters φ (the AR(1) coefficient ρ_f). Every unit gives a lower-triangular whitening map W with
W C Wᵀ = I: the whitened residuals e = W r are independent N(0, σ_f²), and

    p(y | θ, σ_f) = |W| (2π σ_f²)^(−n/2) exp(−|e|² / (2σ_f²)),   n = 3P,
    p(y | θ)      = ∫ p(y | θ, σ_f) dσ_f/σ_f = |W| · ½ Γ(n/2) (π S)^(−n/2),   S = |e|²
                  = ½ Γ(n/2) (π S̃)^(−n/2),   S̃ = |W|^(−2/n) S.

So the observation-model contract (log-likelihood from per-group sums of squares, :mod:`.base`) holds
with the *effective* sum of squares S̃: the whitening normalised to unit determinant. log |W| is the sum
of the log-diagonal of W (:meth:`MarkerNoise.log_diagonal`); the part that depends on θ is
:meth:`MarkerNoise.log_det` (None when it is constant zero). Given θ, σ_f² | θ, y ~ S / χ²_n exactly.

Units (``noise.model`` in the run configuration):

* ``gaussian`` (:class:`WhiteNoise`): C = I (or the per-point shapes below), no parameter; with no
  per-point errors W = I and S̃ = S is the plain sum of squares (the model of Hummel & Hubbard 2002).
* ``ar1`` (:class:`AR1Noise`): each marker coordinate's (per-point whitened) residual series is a
  stationary AR(1) in the frame index with coefficient ρ_f ∈ (−1, 1): for consecutive observations of a
  marker k frames apart, z_i = ρ_f^k z_{i−1} + √(1 − ρ_f^{2k}) σ_f ε_i, ε_i ~ N(0, 1), the first of each
  series z ~ N(0, σ_f²) (σ_f is the marginal standard deviation). Exact likelihood with gaps:
  e_i = (z_i − ρ^k z_{i−1}) / √(1 − ρ^{2k}), log |W| = −½ Σ log(1 − ρ^{2k_i}) (per coordinate).
  Parameter ``rho`` (public ``rho_<flight>``, dimensionless), prior N(0, 0.5²) truncated to (−1, 1)
  (outside it the likelihood is zero).
* ``robust`` (:class:`RobustNoise`): the ``gaussian`` likelihood on the data cleaned of gross errors —
  points judged outliers are dropped and frames judged label-swapped restored by an inlier/outlier and
  swap mixture (:mod:`.outliers`, its π, w and π_s estimated per flight by EM, repeated with the fit until
  the judgement is stable); the sampled
  posterior is conditional on that judgement, and its draws are then reweighted to the posterior averaged
  over every judgement (:func:`.outliers.mixture_log_likelihood`,
  :func:`bayes_disc.inference.fitting.robust.average_over_judgement`).

Per-point errors (``noise.per_point``), :class:`PointScales`: a per-row ``sigma_m`` s_i [m] (the same for
x, y and z), or the covariance Σ_i [m²] (columns ``cov_xx … cov_zz`` written by ``bayes-disc track``),
shapes the noise point by point: r_i ~ N(0, σ_f² Σ_i / ḡ²) with ḡ [m] the geometric mean of the points'
σ (ḡ = exp(mean log s_i), or exp(mean ⅙ log det Σ_i)). Whitening: e_i = ḡ L_i⁻¹ r_i, Σ_i = L_i L_iᵀ
(Cholesky), or e_i = (ḡ / s_i) r_i. Because ḡ is the geometric mean, this part of W has unit
determinant; written with the dimensionless scale factor s_f = σ_f / ḡ the likelihood is
Π_i N(r_i | 0, s_f² Σ_i), including −Σ log of the per-point scales. σ_f [m] (``sigma_<flight>``) keeps its
meaning "noise of a typical point"; s_f = σ_f / ḡ says how far the stated errors are off (1: right).
"""
from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass, field
from typing import ClassVar

import numpy as np

from ...physics import TermParameter
from .outliers import OUTLIER_FRACTION, OUTLIER_WIDTH_M, SWAP_FRACTION

#: ``noise.model`` values
NOISE_MODELS = ("gaussian", "ar1", "robust")
#: ``noise.per_point`` values
PER_POINT = ("auto", "true", "false")


# ------------------------------------------------------------------------------------------------ per point
@dataclass(frozen=True)
class PointScales:
    """Per-point noise shapes of one flight's observed points (module docstring).

    Parameters
    ----------
    source : str
        ``"sigma_m"`` or ``"covariance"``: where the shapes come from.
    reference : float
        ḡ [m], the geometric mean of the points' σ.
    scale : (P,) array or None
        ḡ / s_i (``sigma_m``).
    whiten_matrix : (P, 3, 3) array or None
        ḡ L_i⁻¹ (covariance).
    """

    source: str
    reference: float
    scale: np.ndarray | None = None
    whiten_matrix: np.ndarray | None = None

    @classmethod
    def from_sigma(cls, sigma: np.ndarray) -> "PointScales":
        """From per-point standard deviations s_i (P,) [m], each > 0 and finite."""
        sigma = np.asarray(sigma, float)
        g = float(np.exp(np.mean(np.log(sigma))))
        return cls("sigma_m", g, scale=g / sigma)

    @classmethod
    def from_covariance(cls, cov: np.ndarray) -> "PointScales":
        """From per-point covariances Σ_i (P, 3, 3) [m²], each symmetric positive definite."""
        L = np.linalg.cholesky(np.asarray(cov, float))
        logdet = 2.0 * np.sum(np.log(np.diagonal(L, axis1=1, axis2=2)), axis=1)    # log det Σ_i
        g = float(np.exp(np.mean(logdet) / 6.0))
        return cls("covariance", g, whiten_matrix=g * np.linalg.inv(L))

    def apply(self, r: np.ndarray) -> np.ndarray:
        """Whitened residuals e_i (B, P, 3) of r (B, P, 3) [m] (still in m: scaled by ḡ)."""
        if self.scale is not None:
            return r * self.scale[None, :, None]
        return np.einsum("pij,bpj->bpi", self.whiten_matrix, r)

    def unapply(self, e: np.ndarray) -> np.ndarray:
        """Inverse of :meth:`apply`: r (B, P, 3) from e (B, P, 3)."""
        if self.scale is not None:
            return e / self.scale[None, :, None]
        return np.einsum("pij,bpj->bpi", np.linalg.inv(self.whiten_matrix), e)

    def matrices(self) -> np.ndarray:
        """(P, 3, 3) the per-point whitening maps W_i (e_i = W_i r_i; :meth:`apply`)."""
        if self.scale is not None:
            return self.scale[:, None, None] * np.eye(3)
        return self.whiten_matrix

    def log_diagonal(self) -> np.ndarray:
        """(P, 3) log of the diagonal of the per-point whitening (sums to 0 up to rounding)."""
        if self.scale is not None:
            return np.repeat(np.log(self.scale)[:, None], 3, axis=1)
        return np.log(np.diagonal(self.whiten_matrix, axis1=1, axis2=2))


# ------------------------------------------------------------------------------------------------ units
@dataclass(eq=False)
class MarkerNoise(ABC):
    """A noise model of one flight's observed marker points (module docstring).

    Parameters
    ----------
    points : PointScales or None
        Per-point noise shapes (None: every coordinate alike).
    observed : (n, m) bool array or None
        The flight's observed points on its sample grid (the order of the residuals; :meth:`sample`).
    """

    id: ClassVar[str]
    title: ClassVar[str]
    equations: ClassVar[str]

    points: PointScales | None = None
    observed: np.ndarray | None = None

    @property
    def white(self) -> bool:
        """True when W = I (independent noise of one size: the residuals are used as they are)."""
        return False

    @property
    def parameters(self) -> tuple[TermParameter, ...]:
        """The unit's own per-flight parameters φ (appended to the flight's initial conditions)."""
        return ()

    def describe(self) -> dict:
        """What the flight's noise model is, for summary.json and the log."""
        return {"model": self.id, "per_point": None if self.points is None else self.points.source,
                "reference_sigma_m": None if self.points is None else self.points.reference,
                "parameters": [p.name for p in self.parameters]}

    def _points(self, r: np.ndarray) -> np.ndarray:
        """(B, P, 3) per-point whitened residuals of r (B, 3P)."""
        z = r.reshape(r.shape[0], -1, 3)
        return z if self.points is None else self.points.apply(z)

    @abstractmethod
    def whiten(self, r: np.ndarray, own: np.ndarray | None) -> np.ndarray:
        """e = W r: (B, 3P) whitened residuals (independent N(0, σ_f²)) of r (B, 3P) [m], for the unit's own
        parameters ``own`` (B, k) (None when it has none); NaN where φ is outside its domain."""

    def log_diagonal(self, own: np.ndarray | None) -> np.ndarray | None:
        """(B, 3P) log of W's diagonal entry of each residual (the pointwise log-Jacobian), or None for W = I."""
        if self.points is None:
            return None
        return self.points.log_diagonal().reshape(1, -1)

    def log_det(self, own: np.ndarray | None) -> np.ndarray | None:
        """(B,) the θ-dependent part of log |W| (None: log |W| = 0, as for the per-point shapes)."""
        return None

    @abstractmethod
    def sample(self, sigma: np.ndarray, own: np.ndarray | None, rng: np.random.Generator) -> np.ndarray:
        """Noise draws (B, n, m, 3) [m] on the flight's whole sample grid (``observed.shape``), for scales
        σ_f (B,) and own parameters (B, k); per-point shapes where a point was observed, ḡ elsewhere."""


@dataclass(eq=False)
class WhiteNoise(MarkerNoise):
    """Independent Gaussian noise, one scale σ_f per flight, optionally shaped per point (module docstring)."""

    id = "gaussian"
    title = "independent Gaussian marker noise"
    equations = ("y_i = m_i(θ) + ε_i,  ε_i ~ N(0, σ_f² I₃)  [m];  with per-point errors "
                 "ε_i ~ N(0, σ_f² Σ_i / ḡ²),  ḡ = geometric mean of the points' σ  [m]")

    @property
    def white(self) -> bool:
        return self.points is None

    def whiten(self, r, own):
        if self.points is None:
            return r
        return self._points(r).reshape(r.shape[0], -1)

    def sample(self, sigma, own, rng):
        eps = sigma[:, None, None, None] * rng.standard_normal((sigma.size, *self.observed.shape, 3))
        return _shape_points(eps, self.points, self.observed)


@dataclass(eq=False)
class RobustNoise(WhiteNoise):
    """``gaussian`` noise on data cleaned of outlying points and label swaps (:mod:`.outliers`)."""

    id = "robust"
    title = "Gaussian marker noise after removing outliers and label swaps"
    equations = ("judged: p(r_i) = (1 − π) N(0, σ_i² I₃) + π N(0, w² I₃); frames: labels as given (1 − π_s) or "
                 "one pair exchanged (π_s); π, w, π_s estimated per flight by EM (priors centred on 0.01, 0.05 m, "
                 "0.01); fitted: the gaussian model on the cleaned data")

    def describe(self) -> dict:
        return super().describe() | {"prior_outlier_fraction": OUTLIER_FRACTION, "prior_outlier_width_m": OUTLIER_WIDTH_M,
                                     "prior_swap_fraction": SWAP_FRACTION,
                                     "estimated": "per flight, flagged.json → mixture"}


def _shape_points(eps: np.ndarray, points: PointScales | None, observed: np.ndarray | None) -> np.ndarray:
    """Per-point shapes applied to unit-shaped noise (B, n, m, 3) at the observed points."""
    if points is None:
        return eps
    out = eps.copy()
    out[:, observed] = points.unapply(eps[:, observed])
    return out


@dataclass(eq=False)
class AR1Noise(MarkerNoise):
    """AR(1) noise in time per marker coordinate, coefficient ρ_f per flight (module docstring).

    Parameters
    ----------
    points : PointScales or None
        Per-point shapes (applied before the AR(1) filter).
    frame : (P,) int array
        Frame index of each observed point (time / frame interval).
    previous : (P,) int array
        Index of the same marker's previous observed point (−1 for the first of its series).
    observed : (n, m) bool array
        Observed points of the grid.
    frames : (n,) int array
        Frame index of every sample time of the grid.
    """

    id = "ar1"
    title = "AR(1) marker noise in time"
    equations = ("z_i = ρ_f^k z_(i−1) + √(1 − ρ_f^(2k)) σ_f ε_i,  ε_i ~ N(0, 1),  z_first ~ N(0, σ_f²),  "
                 "k = frames between consecutive observations of a marker  [z in m]")

    frame: np.ndarray = field(default_factory=lambda: np.zeros(0, np.intp))
    previous: np.ndarray = field(default_factory=lambda: np.zeros(0, np.intp))
    frames: np.ndarray | None = None

    def __post_init__(self):
        has = self.previous >= 0
        self._has = has
        self._prev = self.previous[has]
        self._gap = (self.frame[has] - self.frame[self._prev]).astype(float)
        if np.any(self._gap < 1):
            raise ValueError("AR(1) noise: a marker is seen twice in one frame")

    @property
    def parameters(self):
        return (TermParameter("rho", "1", "AR(1) coefficient of the marker noise per frame; prior N(0, 0.5²) "
                              "truncated to (−1, 1)", off_value=0.0, prior_sd=0.5),)

    def _coefficients(self, own: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(B, P_has) ρ^k and √(1 − ρ^{2k}) (NaN for |ρ| ≥ 1)."""
        rho = own[:, 0]
        rho = np.where(np.abs(rho) < 1.0, rho, np.nan)
        a = np.sign(rho)[:, None] ** self._gap[None] * np.abs(rho)[:, None] ** self._gap[None]
        return a, np.sqrt(1.0 - a * a)

    def whiten(self, r, own):
        z = self._points(r)
        a, s = self._coefficients(own)
        e = z.copy()
        e[:, self._has] = (z[:, self._has] - a[..., None] * z[:, self._prev]) / s[..., None]
        return e.reshape(r.shape[0], -1)

    def log_diagonal(self, own):
        a, s = self._coefficients(own)
        out = np.zeros((own.shape[0], self.frame.size, 3))
        if self.points is not None:
            out += self.points.log_diagonal()[None]
        out[:, self._has] -= np.log(s)[..., None]
        return out.reshape(own.shape[0], -1)

    def log_det(self, own):
        a, s = self._coefficients(own)
        return -3.0 * np.sum(np.log(s), axis=1)

    def sample(self, sigma, own, rng):
        frames, B, n = self.frames, sigma.size, self.frames.size
        rho = own[:, 0]
        eps = rng.standard_normal((B, *self.observed.shape, 3))
        z = np.empty_like(eps)
        z[:, 0] = eps[:, 0]
        for i in range(1, n):
            a = np.sign(rho) ** (frames[i] - frames[i - 1]) * np.abs(rho) ** (frames[i] - frames[i - 1])
            z[:, i] = a[:, None, None] * z[:, i - 1] + np.sqrt(1 - a * a)[:, None, None] * eps[:, i]
        return _shape_points(sigma[:, None, None, None] * z, self.points, self.observed)


# ------------------------------------------------------------------------------------------------ building
def frame_index(times: np.ndarray, flight: str) -> np.ndarray:
    """Frame index (n,) of sample times (n,) [s]: (t − t₀)/Δt rounded, Δt the smallest time step.

    Raises
    ------
    ValueError
        If a time lies more than 0.1 frame off the grid (AR(1) noise needs a frame clock).
    """
    dt = float(np.min(np.diff(times))) if times.size > 1 else 1.0
    f = (times - times[0]) / dt
    k = np.rint(f)
    off = np.abs(f - k)
    if np.any(off > 0.1):
        i = int(np.argmax(off))
        raise ValueError(f"flight {flight!r}: AR(1) noise needs samples on a regular frame grid; t = {times[i]:g} s "
                         f"is {off[i]:.2f} frame off the grid of step {dt:g} s")
    return k.astype(np.intp)


def previous_points(observed: np.ndarray) -> np.ndarray:
    """For the observed points (time-major order of ``np.nonzero(observed)``), the index of the same
    marker's previous observed point, −1 for the first; observed (n, m) bool → (P,) int."""
    ti, mi = np.nonzero(observed)
    prev = np.full(ti.size, -1, np.intp)
    last = np.full(observed.shape[1], -1, np.intp)
    for p, j in enumerate(mi):
        prev[p] = last[j]
        last[j] = p
    return prev


def point_scales(data, per_point: str) -> PointScales | None:
    """The per-point shapes of a flight's marker data, as ``per_point`` asks.

    Parameters
    ----------
    data : FlightObservation
        The flight (``sigma`` (n, m) [m] from a ``sigma_m`` column, ``cov`` (n, m, 3, 3) [m²] from the
        covariance columns; the covariance wins when both are given).
    per_point : {"auto", "true", "false"}
        ``auto``: use them when the file has them; ``true``: required; ``false``: ignored.

    Returns
    -------
    PointScales or None

    Raises
    ------
    ValueError
        ``per_point`` unknown; ``true`` without the columns; a value missing, non-positive or not positive
        definite at an observed point (naming the flight, time and marker).
    """
    if per_point not in PER_POINT:
        raise ValueError(f"noise.per_point: unknown value {per_point!r} (choices: {', '.join(PER_POINT)})")
    cov, sigma = getattr(data, "cov", None), data.sigma
    if per_point == "false" or (cov is None and sigma is None):
        if per_point == "true":
            raise ValueError(f"flight {data.name!r}: noise.per_point is true but the marker file has neither a "
                             "sigma_m column nor the covariance columns cov_xx … cov_zz")
        return None
    seen = data.observed
    ti, mi = np.nonzero(seen)
    if cov is not None:
        c = cov[seen]
        ok = np.all(np.isfinite(c), axis=(1, 2)) & (np.linalg.eigvalsh(np.where(np.isfinite(c), c, 0.0))[:, 0] > 0)
        what = "covariance (cov_xx … cov_zz) missing or not positive definite"
    else:
        c = sigma[seen]
        ok = np.isfinite(c) & (c > 0)
        what = "sigma_m missing or not positive"
    if not np.all(ok):
        p = int(np.argmin(ok))
        raise ValueError(f"flight {data.name!r}: {what} at t = {data.times[ti[p]]:g} s, marker "
                         f"{data.marker_ids[mi[p]]!r} (per-point errors need one at every observed point; "
                         "set noise.per_point: false to ignore them)")
    return PointScales.from_covariance(c) if cov is not None else PointScales.from_sigma(c)


def marker_noise(data, model: str = "gaussian", per_point: str = "auto") -> MarkerNoise:
    """The noise unit of one flight's marker data.

    Parameters
    ----------
    data : FlightObservation
        The flight's marker data.
    model : {"gaussian", "ar1", "robust"}
        The noise model (module docstring).
    per_point : {"auto", "true", "false"}
        Per-point errors (:func:`point_scales`).

    Returns
    -------
    MarkerNoise

    Raises
    ------
    ValueError
        For an unknown ``model`` or ``per_point`` (naming the key) or unusable per-point data.
    """
    if model not in NOISE_MODELS:
        raise ValueError(f"noise.model: unknown value {model!r} (choices: {', '.join(NOISE_MODELS)})")
    points = point_scales(data, per_point)
    seen = data.observed
    if model in ("gaussian", "robust"):
        return (WhiteNoise if model == "gaussian" else RobustNoise)(points=points, observed=seen)
    frames = frame_index(data.times, data.name)
    ti, _ = np.nonzero(seen)
    return AR1Noise(points=points, frame=frames[ti], previous=previous_points(seen), observed=seen, frames=frames)
