"""The ``robust`` noise model's fit: judge gross errors, clean, refit, until the judgement is stable.

For every flight whose marker noise is ``robust`` (:class:`~bayes_disc.observation.models.noise.RobustNoise`)
the points and frames of the recording as given are judged at the current least-squares optimum by the
inlier/outlier and label-swap mixture of :mod:`bayes_disc.observation.models.outliers` (its π, w and π_s
estimated for the flight by EM, :func:`~bayes_disc.observation.models.outliers.fit_mixture`), with each point's
inlier scale σ_i = σ̂_f c_i: c_i the point's stated error relative to the flight's typical one (1 without
per-point errors) and σ̂_f the robust scale √(median_i |r_i / c_i|² / 2.366) (2.366: the median of χ²₃),
so that the gross errors being judged do not inflate it. Outlying points are removed and swapped labels
restored (:func:`~bayes_disc.observation.models.outliers.clean_flight`), the fit is refined on the cleaned
data, and this is repeated until the same points and frames are flagged twice running (at most
:data:`MAX_ROUNDS` times).

The sampler then explores the posterior on the cleaned data, conditional on that judgement.
:func:`average_over_judgement` turns its draws into the posterior averaged over every judgement — the
mixture itself, at each flight's estimated π, w, π_s, as the likelihood of the recording as given, σ_f integrated out
(:func:`~bayes_disc.observation.models.outliers.mixture_log_likelihood`) — by importance sampling:

    log w(θ) = Σ_f [log p_mix(y_f | θ) − log p_Gauss(y_f^clean | θ)]     (robust flights f; priors cancel)

with Pareto-smoothed weights (PSIS, Vehtari et al. 2024): where the Pareto k̂ of the weights is ≤ 0.7 the
weighted draws are the averaged posterior; above it the judgement matters more than importance sampling
from the conditional posterior can tell, and only the conditional posterior is reported.
"""
from __future__ import annotations

import json
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
from scipy.stats import chi2

from ...observation.models import MarkerPositions
from ...observation.models.noise import RobustNoise, WhiteNoise
from ...observation.models.outliers import (PRIOR_SHAPE, Classification, MixtureShape, clean_flight, fit_mixture,
                                            log_marginal_over_scale, mixture_log_likelihood)
from .leastsq import LeastSquaresResult, refine_least_squares
from ..model.problem import Problem

#: the judgement a run wrote (in its output folder)
FLAGGED = "flagged.json"
#: the posterior averaged over the judgement (:func:`average_over_judgement`), in the run's output folder
JUDGEMENT_AVERAGE = "judgement_average.json"
#: most posterior draws reweighted by :func:`average_over_judgement` (each costs one simulation of every robust
#: flight and its mixture likelihood at ~33 noise scales; PSIS's k̂ is reliable up to 1 − 1/log10(2000) ≈ 0.70)
JUDGEMENT_DRAWS = 2000
#: Pareto k̂ above which importance weights are not trusted (PSIS; Vehtari et al. 2024)
PARETO_K_MAX = 0.7
#: probability of a gross error above which a Gaussian-noise run is warned (stricter than the robust
#: model's flag at 0.5: with 10× noise on some points, a 3.5-sd residual of a noisy point reaches 0.5 now and
#: then, since the outlier spread, 5 cm, is then only five times its noise)
SUSPECT_PROBABILITY = 0.99
#: share of a flight's points judged gross errors above which the advice names varying noise instead
#: (the robust model's prior share of gross errors is 1 %)
MANY_SUSPECTS = 0.02
#: most judge–clean–refit rounds
MAX_ROUNDS = 5
_CHI2_3_MEDIAN = float(chi2.median(3))


def robust_flights(problem: Problem) -> list[tuple[int, MarkerPositions]]:
    """(flight index, marker model) of the flights with ``robust`` marker noise."""
    return [(k, c) for k, ch in enumerate(problem.channels) for c in ch if isinstance(c, MarkerPositions)
            and isinstance(c.noise, RobustNoise)]


def point_scales(model: MarkerPositions) -> np.ndarray:
    """(n, m) c_i: each observation's stated error relative to the flight's typical one (1 without them;
    with a covariance, the geometric mean of its Cholesky diagonal), NaN where unseen."""
    out = np.full(model.data.observed.shape, np.nan)
    ld = model.noise.log_diagonal(None)
    out[model.data.observed] = 1.0 if ld is None else np.exp(-ld.reshape(-1, 3).mean(axis=1))
    return out


def judge(problem: Problem, theta: np.ndarray, k: int, model: MarkerPositions, data) -> Classification:
    """The mixture's judgement of flight k's recording ``data`` (as given) at θ, its π, w, π_s estimated
    (:func:`~bayes_disc.observation.models.outliers.fit_mixture`)."""
    pred, ok = problem.predict(theta[None], k)
    if not ok[0]:
        raise RuntimeError(f"flight {data.name!r}: the fit no longer simulates; cannot judge outliers")
    c = point_scales(model)
    seen = data.observed
    r2 = np.sum((pred[0] - data.positions) ** 2, axis=-1)[seen] / c[seen] ** 2
    sigma = np.sqrt(np.median(r2) / _CHI2_3_MEDIAN)
    return fit_mixture(data.name, data.times, data.marker_ids, pred[0], data.positions, sigma * c)


def suspected_gross_errors(problem: Problem, theta: np.ndarray) -> dict:
    """The mixture's judgement (:func:`judge`) of the marker flights with white Gaussian noise (per-point
    errors included; not ``robust``, whose gross errors are handled, nor AR(1)) at θ: what a Gaussian
    likelihood would let pull the fit.

    Parameters
    ----------
    problem : Problem
        The run's problem.
    theta : ndarray, shape (problem.dim,)
        Its least-squares optimum.

    Returns
    -------
    dict
        {flight: {"outliers": n, "swaps": n, "points": observed points}} for the flights where any point or
        frame is judged a gross error with probability ≥ :data:`SUSPECT_PROBABILITY`; empty when none is.
    """
    out = {}
    for k, ch in enumerate(problem.channels):
        for c in ch:
            if isinstance(c, MarkerPositions) and type(c.noise) is WhiteNoise:
                rec = judge(problem, theta, k, c, c.data).records()
                n_out, n_swap = (sum(r["probability"] >= SUSPECT_PROBABILITY for r in rec[key])
                                 for key in ("outliers", "swaps"))
                if n_out or n_swap:
                    out[c.flight] = {"outliers": int(n_out), "swaps": int(n_swap),
                                     "points": int(c.data.observed.sum())}
    return out


def gross_error_advice(suspects: dict) -> str | None:
    """One sentence for the user when :func:`suspected_gross_errors` found any: what, where, and the fix.

    Parameters
    ----------
    suspects : dict
        Its result.

    Returns
    -------
    str or None
        None when nothing is suspected.
    """
    if not suspects:
        return None
    where = "; ".join(f"{f}: {v['outliers']} point(s) as gross errors, {v['swaps']} frame(s) as swapped labels"
                      for f, v in suspects.items())
    text = (f"the data look as if they hold gross errors ({where}; judged at the least-squares fit by the "
            "inlier/outlier/swap mixture). A Gaussian likelihood lets them pull the coefficients, and its "
            "intervals do not widen for it: set `noise: {model: robust}` (for all flights, or per flight under "
            "flight_options) to have them judged, listed and left out (docs/configuration.md)")
    many = [f for f, v in suspects.items() if v["outliers"] > MANY_SUSPECTS * v["points"]]
    if many:
        text += (f". In {', '.join(many)} so many points are suspect (more than {MANY_SUSPECTS:.0%} of the flight) "
                 "that the noise more likely varies along the flight than slips occurred: give each point its "
                 "error (a `sigma_m` column or the covariances `track` writes, with `noise: {per_point: true}`)")
    return text


def robust_refit(problem: Problem, ls: LeastSquaresResult, max_nfev: int = 200, progress=None):
    """Judge, clean and refit until the flags are stable (module docstring).

    Parameters
    ----------
    problem : Problem
        The run's problem on the data as recorded.
    ls : LeastSquaresResult
        Its least-squares optimum.
    max_nfev : int
        Evaluation budget of each refinement.
    progress : callable, optional
        ``progress(round, n_outliers, n_swaps)`` after each judgement.

    Returns
    -------
    problem : Problem
        On the cleaned data.
    ls : LeastSquaresResult
        Its optimum.
    flags : dict
        {flight: :meth:`Classification.records`} of the last judgement.
    """

    def flagged(records: dict) -> dict:
        """What a judgement flags: its outlying points and swapped frames (not π, w or the probabilities)."""
        return {f: ([(o["t"], o["marker"]) for o in r["outliers"]], [(w["t"], w["markers"]) for w in r["swaps"]])
                for f, r in records.items()}
    flights = robust_flights(problem)
    if not flights:
        return problem, ls, {}
    current, previous, flags = problem, None, {}
    for i in range(MAX_ROUNDS):
        flags = {c.flight: judge(current, ls.theta, k, c, c.data).records() for k, c in flights}
        if progress is not None:
            progress(i + 1, sum(len(f["outliers"]) for f in flags.values()), sum(len(f["swaps"]) for f in flags.values()))
        if previous is not None and flagged(flags) == flagged(previous):
            break
        current = problem.with_marker_data({c.flight: clean_flight(c.data, flags[c.flight]) for _, c in flights})
        ls = refine_least_squares(current, ls.theta, max_nfev=max_nfev)
        previous = flags
    return current, ls, flags


def apply_flags(problem: Problem, flags: dict) -> Problem:
    """The problem with saved flags (``flagged.json``) applied to its robust flights' recordings (resume)."""
    return problem.with_marker_data({c.flight: clean_flight(c.data, flags.get(c.flight, {}))
                                     for _, c in robust_flights(problem)})


def with_saved_flags(problem: Problem, run_dir) -> Problem:
    """The problem a finished (or interrupted) run sampled: its robust flights cleaned as the run's
    ``flagged.json`` says (unchanged without robust flights).

    Parameters
    ----------
    problem : Problem
        Rebuilt from the run's configuration (data as recorded).
    run_dir : str or Path
        The run's output folder.

    Returns
    -------
    Problem

    Raises
    ------
    FileNotFoundError
        If the problem has robust flights but the folder has no ``flagged.json``.
    """
    if not robust_flights(problem):
        return problem
    path = Path(run_dir) / FLAGGED
    if not path.is_file():
        raise FileNotFoundError(f"{path}: missing; the run's robust flights were cleaned as it lists (re-run sample)")
    return apply_flags(problem, json.loads(path.read_text()))


# ------------------------------------------------------------------------------ averaged over the judgement
def observation_whitening(model: MarkerPositions) -> np.ndarray | None:
    """(n, m, 3, 3) W_i of every point of the flight's grid (I where unseen; per-point errors), None when
    the flight has no per-point errors (W = I)."""
    points = model.noise.points
    if points is None:
        return None
    n, m = model.data.observed.shape
    W = np.broadcast_to(np.eye(3), (n, m, 3, 3)).copy()
    W[model.data.observed] = points.matrices()
    return W


def judgement_log_weights(raw: Problem, clean: Problem, theta: np.ndarray, ss: np.ndarray,
                          shapes: dict, batch: int = 64) -> np.ndarray:
    """log w(θ) = Σ_f [log p_mix(y_f | θ) − log p_Gauss(y_f^clean | θ)] over the robust flights (module
    docstring) of draws sampled on the cleaned data.

    Parameters
    ----------
    raw : Problem
        The run's problem on the data as recorded.
    clean : Problem
        The problem that was sampled (robust flights cleaned as judged; :func:`robust_refit`).
    theta : (B, dim) array
        Draws.
    ss : (B, n_groups) array
        Their effective sums of squares S̃_g in ``clean`` (the sampler's blobs).
    shapes : dict
        {flight: MixtureShape}, each robust flight's π, w, π_s (:func:`mixture_shapes` of ``flagged.json``).
    batch : int
        Draws simulated at once.

    Returns
    -------
    (B,) array
        −inf where a draw's simulation fails.
    """
    theta = np.atleast_2d(theta)
    out = np.zeros(theta.shape[0])
    for k, model in robust_flights(raw):
        j = raw.channels[k].index(model)
        g = clean.channel_groups(k)[j]
        clean_model = clean.channels[k][j]
        out -= clean_model.log_likelihood(ss[:, g])
        n_clean = int(clean_model.group_sizes[0])
        W, obs = observation_whitening(model), model.data.positions
        if model.flight not in shapes:
            raise KeyError(f"flight {model.flight!r}: no judgement (π, w, π_s) in the run's {FLAGGED}")
        sh = shapes[model.flight]
        for start in range(0, theta.shape[0], batch):
            rows = slice(start, start + batch)
            pred, ok = raw.predict(theta[rows], k)
            centre = 0.5 * np.log(ss[rows, g.start] / n_clean)
            part = log_marginal_over_scale(lambda u, r: mixture_log_likelihood(
                pred[r], obs, W, u, sh.outlier_fraction, sh.width, sh.swap_fraction),
                                           np.where(ok, centre, 0.0), model.n_coords)
            out[rows] += np.where(ok, part, -np.inf)
    return out


def weighted_quantiles(x: np.ndarray, w: np.ndarray, q) -> np.ndarray:
    """Quantiles ``q`` of draws ``x`` (S,) with normalised weights ``w`` (S,): the weighted empirical CDF,
    each draw at the midpoint of its weight's step, interpolated linearly (equal weights: the usual
    Hazen quantiles)."""
    order = np.argsort(x)
    xs, ws = x[order], w[order]
    cdf = np.cumsum(ws) - 0.5 * ws
    return np.interp(q, cdf, xs)


def _moments(x: np.ndarray, w: np.ndarray) -> dict:
    mean = float(np.sum(w * x))
    q05, q50, q95 = weighted_quantiles(x, w, [0.05, 0.5, 0.95])
    return {"mean": mean, "sd": float(np.sqrt(np.sum(w * (x - mean) ** 2))), "q05": float(q05),
            "q50": float(q50), "q95": float(q95)}


@dataclass
class JudgementAverage:
    """The posterior averaged over the judgement of gross errors, beside the conditional one (module docstring).

    Attributes
    ----------
    draws : int
        Posterior draws reweighted (a random subset of the run's).
    failed : int
        Draws whose simulation failed (weight 0).
    pareto_k : float
        PSIS shape k̂ of the weights.
    ess : float
        Effective sample size of the smoothed weights, 1 / Σ w².
    reliable : bool
        k̂ ≤ :data:`PARETO_K_MAX`: the ``averaged`` summaries are the averaged posterior's.
    conditional, averaged : dict
        {parameter: {mean, sd, q05, q50, q95}} of the same draws, equally weighted (the posterior given the
        judgement) and with the smoothed weights (averaged over the judgement; empty when not ``reliable``).
    """

    draws: int
    failed: int
    pareto_k: float
    ess: float
    reliable: bool
    conditional: dict
    averaged: dict

    def to_dict(self) -> dict:
        return asdict(self) | {"pareto_k_max": PARETO_K_MAX,
                               "method": "PSIS importance sampling of the conditional posterior's draws to the "
                                         "inlier/outlier/swap mixture likelihood, σ integrated out"}

    def lines(self) -> list[str]:
        """Log lines: the weights' diagnostics, then one line per parameter whose sd or median changes."""
        head = (f"averaged over the judgement: {self.draws} draws reweighted, Pareto k̂ {self.pareto_k:.2f}, "
                f"ESS {self.ess:.0f}")
        if not self.reliable:
            return [head + f" — k̂ above {PARETO_K_MAX}: the weights cannot be trusted; the posterior reported is "
                           "conditional on the judgement"]
        out = [head]
        for name, c in self.conditional.items():
            a = self.averaged[name]
            out.append(f"  {name}: median {c['q50']:.5g} → {a['q50']:.5g}, sd {c['sd']:.3g} → {a['sd']:.3g} "
                       f"(×{a['sd'] / c['sd']:.3f})")
        return out


def mixture_shapes(flags: dict) -> dict:
    """{flight: MixtureShape} of a judgement's records (``flagged.json``). Runs from before π, w and π_s were
    estimated wrote no ``mixture``: they were judged at the priors' centre, which is returned for them."""
    return {f: MixtureShape.from_record(r["mixture"]) if "mixture" in r else PRIOR_SHAPE for f, r in flags.items()}


def average_over_judgement(raw: Problem, clean: Problem, theta: np.ndarray, ss: np.ndarray, names: list[str],
                           rng: np.random.Generator, flags: dict, draws: int = JUDGEMENT_DRAWS) -> JudgementAverage:
    """The posterior averaged over the judgement of outliers and swaps, from the conditional posterior's draws.

    Parameters
    ----------
    raw, clean : Problem
        As for :func:`judgement_log_weights`.
    theta : (S, dim) array
        The run's posterior draws (on ``clean``).
    ss : (S, n_groups) array
        Their effective sums of squares (the sampler's blobs).
    names : list of str
        Parameters to summarise.
    rng : numpy.random.Generator
        Picks the draws reweighted.
    flags : dict
        The judgement (:func:`robust_refit`, ``flagged.json``): each robust flight's π, w, π_s.
    draws : int
        At most this many draws.

    Returns
    -------
    JudgementAverage
    """
    import arviz as az
    pick = np.sort(rng.choice(theta.shape[0], size=min(draws, theta.shape[0]), replace=False))
    th, lw = theta[pick], judgement_log_weights(raw, clean, theta[pick], ss[pick], mixture_shapes(flags))
    keep = np.isfinite(lw)                                      # a failed simulation: weight 0
    failed, th, lw = int(np.sum(~keep)), th[keep], lw[keep]
    smoothed, k = az.psislw(lw - np.max(lw))
    w = np.exp(smoothed - np.logaddexp.reduce(smoothed))
    k = float(k)
    reliable = bool(k <= PARETO_K_MAX)
    idx = [clean.names.index(n) for n in names]
    equal = np.full(th.shape[0], 1.0 / th.shape[0])
    conditional = {n: _moments(th[:, i], equal) for n, i in zip(names, idx)}
    averaged = {n: _moments(th[:, i], w) for n, i in zip(names, idx)} if reliable else {}
    return JudgementAverage(draws=int(th.shape[0]), failed=failed, pareto_k=k, ess=float(1.0 / np.sum(w * w)),
                            reliable=reliable, conditional=conditional, averaged=averaged)
