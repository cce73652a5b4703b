"""Gross errors in marker data: outlying points and label-swapped frames, judged by a mixture model.

Noise model ``robust`` (``noise.model: robust``). Given the residuals r_i = m_i(θ) − y_i [m] of a fit and
each point's inlier noise scale σ_i [m] (σ_f, or σ_f s_i / ḡ with per-point errors), every observed point is

    p(r_i) = (1 − π) N(r_i | 0, σ_i² I₃) + π N(r_i | 0, w² I₃),

π the share of points that are gross errors and w [m] their spread (isotropic normal: digitising slips of
centimetres to a marker spacing). A frame (sample time) is either as labelled (H₀, prior 1 − π_s) or has the
labels of one pair (j, l) of its observed markers exchanged (H_jl, prior π_s / n_pairs): under H_jl marker j
is compared with the observation labelled l and vice versa, each point again an inlier/outlier mixture. The
posterior probability of each hypothesis follows from Bayes' rule frame by frame; a point's outlier
probability is summed over the hypotheses. A swap explains two large residuals with two small ones, so it
beats "two outliers" by roughly (π_s/n_pairs) / π² times the ratio of the inlier to the outlier density
squared: a swap is recognised as a swap.

π, w and π_s are estimated for each flight (:func:`fit_mixture`): the maximum a posteriori values by EM
(Dempster et al. 1977), alternating the judgement above (E step) with

    π   = (Σ_i P(out_i) + a_π − 1) / (N + a_π + b_π − 2),                 π ~ Beta(a_π, b_π)
    w²  = (ν₀ w₀² + Σ_i P(out_i) |r_i|²) / (ν₀ + 3 Σ_i P(out_i) + 2),     w² ~ Scale-inv-χ²(ν₀, w₀²)
    π_s = (Σ_frames P(swapped) + a_π − 1) / (F + a_π + b_π − 2),          π_s ~ Beta(a_π, b_π)

(M step; N observed points, F frames with two or more of them; |r_i|² under each labelling, weighted by its
probability). The priors are centred on :data:`PRIOR_SHAPE` — π = π_s = 1 %, w = 5 cm — with the weight of
:data:`FRACTION_PRIOR_COUNT` = 200 points (frames) for the fractions and :data:`WIDTH_PRIOR_DOF` = 6
coordinates (two gross errors) for w, so that a flight without gross errors keeps small fractions
(2/(N + 200)) and w near 5 cm, while one with 10 % of them, or errors of decimetres, gets its own.
A 2 cm error at σ = 2 mm has a log-likelihood ratio of ~50 against the inlier, against log(π/(1−π)) ≈ −4.6
at π = 1 %: clear gross errors are flagged whatever π is; the estimate matters for the borderline ones, many
in a flight with many gross errors of a few σ.

Points and frames with probability > 0.5 are flagged; the fit then drops the outlying points and
restores the swapped labels (:func:`clean_flight`) and is repeated until the flags no longer change
(:mod:`bayes_disc.inference.fitting.robust`). The posterior sampled is then conditional on that classification.

The posterior averaged over every classification uses the mixture, at the flight's estimated π, w, π_s
(empirical Bayes), as the likelihood of the recording as given (:func:`mixture_log_likelihood`), with σ_f
integrated out under p(σ_f) ∝ 1/σ_f
(:func:`log_marginal_over_scale`):

    p(y | θ, σ) = Π_frames [ (1 − π_s) Π_i p(r_i | H₀) + Σ_(j,l) (π_s / n_pairs) Π_i p(r_i | H_jl) ],
    p(r_i | H) = (1 − π) |W_i| N(W_i r_i | 0, σ² I₃) + π N(r_i | 0, w² I₃),
    p(y | θ)   = ∫ p(y | θ, σ) dσ/σ,

W_i the observation's whitening (per-point errors, :mod:`.noise`; I without them), which travels with the
observation under a swap. :func:`bayes_disc.inference.fitting.robust.average_over_judgement` reweights the
conditional posterior's draws to it.
"""
from __future__ import annotations

from dataclasses import dataclass, replace
from itertools import combinations

import numpy as np
from scipy.special import logsumexp

from ._outlier_kernels import mixture_frames

#: prior centre of π, the share of points that are gross errors
OUTLIER_FRACTION = 0.01
#: prior centre of w [m], the spread of gross errors (isotropic normal)
OUTLIER_WIDTH_M = 0.05
#: prior centre of π_s, the share of frames with two labels exchanged
SWAP_FRACTION = 0.01
#: posterior probability above which a point or frame is flagged
FLAG_PROBABILITY = 0.5
#: weight of the Beta priors of π and π_s in points (frames): a_π + b_π − 2
FRACTION_PRIOR_COUNT = 200.0
#: degrees of freedom ν₀ of the scaled-inverse-χ² prior of w² (coordinates: two gross errors)
WIDTH_PRIOR_DOF = 6.0
#: most EM iterations of :func:`fit_mixture`, and its tolerance on the relative change of π, w and π_s
EM_MAX_ITER = 100
EM_TOL = 1e-6


@dataclass(frozen=True)
class MixtureShape:
    """The inlier/outlier/swap mixture's π, w [m] and π_s (module docstring).

    Attributes
    ----------
    outlier_fraction : float
        π, prior probability that a point is a gross error.
    width : float
        w [m], the spread of gross errors.
    swap_fraction : float
        π_s, prior probability that a frame has the labels of one pair exchanged.
    """

    outlier_fraction: float = OUTLIER_FRACTION
    width: float = OUTLIER_WIDTH_M
    swap_fraction: float = SWAP_FRACTION

    def __post_init__(self):
        for name, v in (("outlier_fraction", self.outlier_fraction), ("swap_fraction", self.swap_fraction)):
            if not 0.0 <= v < 1.0:
                raise ValueError(f"MixtureShape: {name} must lie in [0, 1), got {v!r}")
        if not self.width > 0.0:
            raise ValueError(f"MixtureShape: width must be > 0 m, got {self.width!r}")

    def record(self) -> dict:
        """As JSON: {outlier_fraction, outlier_width_m, swap_fraction} (4 significant digits)."""
        return {"outlier_fraction": float(f"{self.outlier_fraction:.4g}"),
                "outlier_width_m": float(f"{self.width:.4g}"), "swap_fraction": float(f"{self.swap_fraction:.4g}")}

    @classmethod
    def from_record(cls, rec: dict) -> "MixtureShape":
        """Inverse of :meth:`record`."""
        return cls(rec["outlier_fraction"], rec["outlier_width_m"], rec["swap_fraction"])


#: the priors' centre, and the shape a judgement uses unless told otherwise
PRIOR_SHAPE = MixtureShape()


def _log_normal3(r: np.ndarray, s: np.ndarray) -> np.ndarray:
    """log N(r | 0, s² I₃) for r (..., 3) [m], s (...) [m]."""
    return -1.5 * np.log(2 * np.pi * s ** 2) - 0.5 * np.sum(r * r, axis=-1) / s ** 2


def _point_terms(r: np.ndarray, s: np.ndarray, shape: MixtureShape) -> tuple[np.ndarray, np.ndarray]:
    """(log p(r_i), log P(outlier_i | r_i)) of the inlier/outlier mixture; r (..., 3), s (...)."""
    with np.errstate(divide="ignore"):                                  # π = 0: no gross errors
        a = np.log1p(-shape.outlier_fraction) + _log_normal3(r, s)
        b = np.log(shape.outlier_fraction) + _log_normal3(r, np.full_like(s, shape.width))
    total = np.logaddexp(a, b)
    return total, b - total


@dataclass
class Classification:
    """Outlier and swap probabilities of one flight's observed points and frames.

    Attributes
    ----------
    flight : str
    times : (n,) array
        Sample times [s].
    marker_ids : tuple of str
    outlier : (n, m) array
        Posterior probability that each observed point is a gross error (NaN where unobserved).
    pairs : list of (int, int)
        The marker pairs (j, l), j < l.
    swap : (n, n_pairs) array
        Posterior probability that the frame has the labels of pair (j, l) exchanged (0 where either is unseen).
    shape : MixtureShape
        The π, w, π_s judged with.
    outlier_r2 : (n, m) array
        Σ_H P(H) P(out_i | H) |r_i(H)|² [m²]: each point's squared residual weighted by its probability of
        being a gross error, summed over the frame's labellings (the M step's statistic; NaN where unseen).
    """

    flight: str
    times: np.ndarray
    marker_ids: tuple
    outlier: np.ndarray
    pairs: list
    swap: np.ndarray
    shape: MixtureShape = PRIOR_SHAPE
    outlier_r2: np.ndarray | None = None

    def swapped_frames(self) -> list[tuple[int, int, int, float]]:
        """(frame, j, l, probability) of every frame judged swapped (most probable pair > 0.5)."""
        out = []
        for i in np.flatnonzero(self.swap.max(axis=1, initial=0.0) > FLAG_PROBABILITY):
            p = int(np.argmax(self.swap[i]))
            out.append((int(i), *self.pairs[p], float(self.swap[i, p])))
        return out

    def outlier_points(self) -> list[tuple[int, int, float]]:
        """(frame, marker index, probability) of every point judged an outlier (> 0.5)."""
        i, j = np.nonzero(np.nan_to_num(self.outlier) > FLAG_PROBABILITY)
        return [(int(a), int(b), float(self.outlier[a, b])) for a, b in zip(i, j)]

    def records(self) -> dict:
        """The flags as JSON records: ``outliers`` [{flight, t, marker, probability}], ``swaps``
        [{flight, t, markers: [j, l], probability}], and ``mixture`` (:meth:`MixtureShape.record`)."""
        return {"mixture": self.shape.record(),
                "outliers": [{"flight": self.flight, "t": float(self.times[i]), "marker": str(self.marker_ids[j]),
                              "probability": round(p, 4)} for i, j, p in self.outlier_points()],
                "swaps": [{"flight": self.flight, "t": float(self.times[i]),
                           "markers": [str(self.marker_ids[j]), str(self.marker_ids[l])], "probability": round(p, 4)}
                          for i, j, l, p in self.swapped_frames()]}


def classify(flight: str, times: np.ndarray, marker_ids, predicted: np.ndarray, observed: np.ndarray,
             point_sigma: np.ndarray, shape: MixtureShape = PRIOR_SHAPE) -> Classification:
    """Posterior outlier and swap probabilities of a flight's points and frames at given π, w, π_s (module
    docstring; the E step of :func:`fit_mixture`).

    Parameters
    ----------
    flight : str
        Its name.
    times : (n,) array
        Sample times [s].
    marker_ids : sequence of str
    predicted : (n, m, 3) array
        The fit's markers [m].
    observed : (n, m, 3) array
        The data [m], NaN where unseen.
    point_sigma : (n, m) array
        Inlier noise scale σ_i of each observation [m] (belongs to the observation: it travels with a swap).
    shape : MixtureShape
        π, w [m] and π_s.

    Returns
    -------
    Classification
    """
    n, m, _ = observed.shape
    seen = np.all(np.isfinite(observed), axis=-1)
    s = np.where(seen, point_sigma, 1.0)
    r = np.where(seen[..., None], predicted - observed, 0.0)
    lp, lo = _point_terms(r, s, shape)
    lp, lo = np.where(seen, lp, 0.0), np.where(seen, lo, -np.inf)
    pairs = list(combinations(range(m), 2))
    with np.errstate(divide="ignore"):                          # π_s = 0: labels as given
        log_h0, log_pair = np.log1p(-shape.swap_fraction), np.log(shape.swap_fraction / max(len(pairs), 1))
    hyp, out_h, r2_h = [log_h0 + lp.sum(axis=1)], [lo], [np.sum(r * r, axis=-1)]      # H0
    for j, l in pairs:
        both = seen[:, j] & seen[:, l]
        lps, los, r2s = lp.copy(), lo.copy(), r2_h[0].copy()
        for a, b in ((j, l), (l, j)):                          # marker a compared with the observation labelled b
            d = predicted[:, a] - np.where(both[:, None], observed[:, b], 0.0)
            t, o = _point_terms(d, s[:, b], shape)
            lps[:, a], los[:, a] = np.where(both, t, lps[:, a]), np.where(both, o, los[:, a])
            r2s[:, a] = np.where(both, np.sum(d * d, axis=-1), r2s[:, a])
        hyp.append(np.where(both, log_pair + lps.sum(axis=1), -np.inf))
        out_h.append(los)
        r2_h.append(r2s)
    H = np.stack(hyp, axis=1)                                  # (n, 1 + n_pairs)
    post = np.exp(H - logsumexp(H, axis=1, keepdims=True))
    p_out = np.exp(np.stack(out_h))                            # (1 + n_pairs, n, m)
    outlier = np.einsum("nh,hnm->nm", post, p_out)
    outlier_r2 = np.einsum("nh,hnm->nm", post, p_out * np.stack(r2_h))
    return Classification(flight=flight, times=np.asarray(times), marker_ids=tuple(marker_ids),
                          outlier=np.where(seen, outlier, np.nan), pairs=pairs, swap=post[:, 1:], shape=shape,
                          outlier_r2=np.where(seen, outlier_r2, np.nan))


def estimate_shape(c: Classification, prior: MixtureShape = PRIOR_SHAPE) -> MixtureShape:
    """The M step of :func:`fit_mixture`: the MAP π, w, π_s given a judgement's probabilities (module docstring).

    Parameters
    ----------
    c : Classification
        A judgement (:func:`classify`).
    prior : MixtureShape
        The priors' centre.

    Returns
    -------
    MixtureShape
    """
    seen = np.isfinite(c.outlier)
    n_points = float(seen.sum())
    n_frames = float(np.sum(seen.sum(axis=1) >= 2))
    p_out = float(np.sum(c.outlier[seen]))
    a = 1.0 + FRACTION_PRIOR_COUNT * prior.outlier_fraction          # Beta(a, b), a + b − 2 = count
    pi = (p_out + a - 1.0) / (n_points + FRACTION_PRIOR_COUNT)
    a_s = 1.0 + FRACTION_PRIOR_COUNT * prior.swap_fraction
    pi_s = (float(c.swap.sum()) + a_s - 1.0) / (n_frames + FRACTION_PRIOR_COUNT)
    w2 = ((WIDTH_PRIOR_DOF * prior.width ** 2 + float(np.sum(c.outlier_r2[seen])))
          / (WIDTH_PRIOR_DOF + 3.0 * p_out + 2.0))
    return MixtureShape(pi, float(np.sqrt(w2)), pi_s)


def fit_mixture(flight: str, times: np.ndarray, marker_ids, predicted: np.ndarray, observed: np.ndarray,
                point_sigma: np.ndarray, prior: MixtureShape = PRIOR_SHAPE) -> Classification:
    """The judgement of a flight's points and frames with π, w and π_s estimated (EM; module docstring).

    Starts from the priors' centre and alternates :func:`classify` and :func:`estimate_shape` until π, w and
    π_s change by less than :data:`EM_TOL` relatively (each EM step raises the posterior of π, w, π_s).

    Parameters
    ----------
    flight, times, marker_ids, predicted, observed, point_sigma
        As for :func:`classify`.
    prior : MixtureShape
        The priors' centre.

    Returns
    -------
    Classification
        The judgement at the estimated shape (its ``shape``).

    Raises
    ------
    RuntimeError
        If EM has not converged after :data:`EM_MAX_ITER` iterations.
    """
    shape = prior
    for _ in range(EM_MAX_ITER):
        c = classify(flight, times, marker_ids, predicted, observed, point_sigma, shape)
        new = estimate_shape(c, prior)
        old_v = np.array([shape.outlier_fraction, shape.width, shape.swap_fraction])
        new_v = np.array([new.outlier_fraction, new.width, new.swap_fraction])
        shape = new
        if np.all(np.abs(new_v - old_v) <= EM_TOL * old_v):
            return classify(flight, times, marker_ids, predicted, observed, point_sigma, shape)
    raise RuntimeError(f"flight {flight!r}: the outlier mixture's π, w, π_s not converged after {EM_MAX_ITER} "
                       "EM iterations")


def mixture_log_likelihood(predicted: np.ndarray, observed: np.ndarray, whiten: np.ndarray | None,
                           log_sigma: np.ndarray, outlier_fraction: float = OUTLIER_FRACTION,
                           width: float = OUTLIER_WIDTH_M, swap_fraction: float = SWAP_FRACTION) -> np.ndarray:
    """log p(y | θ, σ) of one flight's recording as given under the inlier/outlier/swap mixture (module
    docstring), for B predictions at Q noise scales each.

    Parameters
    ----------
    predicted : (B, n, m, 3) array
        Predicted markers [m].
    observed : (n, m, 3) array
        The recording [m], NaN where unseen.
    whiten : (n, m, 3, 3) array or None
        W_i of each observation (e = W_i r is N(0, σ² I₃) for an inlier; per-point errors), None for I.
    log_sigma : (B, Q) array
        ln σ [ln m] at which to evaluate, per prediction.
    outlier_fraction, width, swap_fraction : float
        π, w [m] and π_s.

    Returns
    -------
    (B, Q) array
    """
    B, n, m, _ = predicted.shape
    seen = np.all(np.isfinite(observed), axis=-1)                       # (n, m)
    obs = np.where(seen[..., None], observed, 0.0)
    r = predicted[:, :, :, None, :] - obs[None, :, None, :, :]         # (B, n, a, l, 3): marker a vs label l
    r2 = np.sum(r * r, axis=-1)
    if whiten is None:
        e2, log_w = r2, np.zeros((n, m))
    else:
        e = np.einsum("nlij,bnalj->bnali", whiten, r)
        e2, log_w = np.sum(e * e, axis=-1), np.linalg.slogdet(whiten)[1]
    n_pairs = max(m * (m - 1) // 2, 1)
    with np.errstate(divide="ignore"):                                  # π or π_s = 0: the Gaussian limit
        logs = (np.log1p(-outlier_fraction) - 1.5 * np.log(2 * np.pi),
                np.log(outlier_fraction) - 1.5 * np.log(2 * np.pi * width ** 2),
                np.log1p(-swap_fraction), np.log(swap_fraction / n_pairs))
    return mixture_frames(np.ascontiguousarray(e2), np.ascontiguousarray(r2), log_w, seen,
                          np.ascontiguousarray(log_sigma, dtype=float), logs[0], logs[1], 1.0 / width ** 2,
                          logs[2], logs[3])


#: nodes of the trapezoid rule in ln σ (:func:`log_marginal_over_scale`), and its half-width in units of the
#: Gaussian likelihood's sd in ln σ, 1/√(2N): node spacing 0.5 of it, at which the rule's error for a
#: Gaussian integrand is ~e^(−79); with the peak within one sd of the centre the range leaves out < e^(−24)
SCALE_NODES = 33
SCALE_HALF_WIDTH = 8.0


def log_marginal_over_scale(log_lik, centre: np.ndarray, n_coords: int, max_moves: int = 12) -> np.ndarray:
    """log ∫ p(y | θ, σ) dσ/σ = log ∫ p(y | θ, e^u) du by the trapezoid rule in u = ln σ.

    The nodes span ± :data:`SCALE_HALF_WIDTH` / √(2N) (N = ``n_coords``: the width of a Gaussian
    likelihood's peak in ln σ is 1/√(2N)) around a centre. The rule is applied once the highest node is
    within one such width of the centre (≥ 7 widths of the peak on either side); otherwise the grid moves
    to the highest node, and where that node is an end of the grid the next grid is 4× wider (coarse) until
    the peak is bracketed, then narrow again.

    Parameters
    ----------
    log_lik : callable
        ``log_lik(u, rows)``: log p(y | θ, σ) (b, Q) of the predictions ``rows`` (b,) at ln σ = u (b, Q).
    centre : (B,) array
        A first guess of the peak in ln σ (e.g. ½ ln(S/N) of a Gaussian fit).
    n_coords : int
        Number of observed coordinates N.
    max_moves : int
        Most moves of a grid.

    Returns
    -------
    (B,) array
        −inf where the likelihood is zero at every node.

    Raises
    ------
    RuntimeError
        If a peak is not centred after ``max_moves`` moves.
    """
    offsets = np.linspace(-1.0, 1.0, SCALE_NODES) * SCALE_HALF_WIDTH / np.sqrt(2.0 * n_coords)
    mid = SCALE_NODES // 2
    weights = np.full(SCALE_NODES, np.log(offsets[1] - offsets[0]))
    weights[[0, -1]] -= np.log(2.0)
    centre = np.asarray(centre, float).copy()
    span = np.ones(centre.size)
    out = np.full(centre.size, np.nan)
    todo = np.arange(centre.size)
    for _ in range(max_moves + 1):
        u = centre[todo, None] + span[todo, None] * offsets[None]
        ll = log_lik(u, todo)
        peak = np.argmax(ll, axis=1)
        done = ~np.isfinite(ll.max(axis=1)) | ((span[todo] == 1.0) & (np.abs(peak - mid) <= 2))
        with np.errstate(invalid="ignore"):
            out[todo[done]] = logsumexp(ll[done] + weights, axis=1)
        rest = ~done
        edge = rest & ((peak == 0) | (peak == SCALE_NODES - 1))
        centre[todo[rest]] = u[rest, peak[rest]]
        span[todo[edge]] *= 4.0
        span[todo[rest & ~edge]] = 1.0
        todo = todo[rest]
        if todo.size == 0:
            return out
    raise RuntimeError(f"log_marginal_over_scale: the likelihood's peak in ln σ not centred for {todo.size} "
                       f"prediction(s) after {max_moves} moves")


def clean_flight(data, records: dict):
    """The flight with its swapped frames' labels restored and its outlying points removed (NaN).

    Outliers are judged under the frame's swap hypothesis, so a point of a restored frame that is still
    an outlier is removed as well.

    Parameters
    ----------
    data : FlightObservation
        The flight as recorded.
    records : dict
        :meth:`Classification.records` of the flight (or as read back from ``flagged.json``).

    Returns
    -------
    FlightObservation

    Raises
    ------
    ValueError
        If a record names a time or marker the flight does not have.
    """
    pos = data.positions.copy()
    sig = None if data.sigma is None else data.sigma.copy()
    cov = None if data.cov is None else data.cov.copy()
    ids = [str(m) for m in data.marker_ids]

    def frame(t):
        i = int(np.argmin(np.abs(data.times - t)))
        if abs(data.times[i] - t) > 1e-9 * max(1.0, abs(t)):
            raise ValueError(f"flight {data.name!r}: no sample at t = {t:g} s")
        return i

    def marker(mid):
        if mid not in ids:
            raise ValueError(f"flight {data.name!r}: no marker {mid!r}")
        return ids.index(mid)
    for rec in records.get("swaps", []):
        i, (j, l) = frame(rec["t"]), (marker(m) for m in rec["markers"])
        for arr in (pos, sig, cov):
            if arr is not None:
                arr[i, [j, l]] = arr[i, [l, j]]
    for rec in records.get("outliers", []):
        pos[frame(rec["t"]), marker(rec["marker"])] = np.nan
    return replace(data, positions=pos, sigma=sig, cov=cov)
