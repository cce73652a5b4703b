"""The conditional reference prior of the initial conditions, computed: exact values of its log-density
g(c) = ½ Σ_f ln det I_xx,f(c, x̂_f(c)) and the quadratic surrogate the log-posterior adds
(:mod:`bayes_disc.inference.model.priors` says why).

At coefficients c every other parameter is refitted with c held (:func:`conditional_optimum`: the flights'
initial conditions, their observation-model parameters and any other shared ones, one Levenberg–Marquardt fit
from the least-squares covariance's linear prediction, :func:`.profile.conditional_start`); there the
Jacobian of every flight's residuals over its own initial conditions (whitened with the least-squares noise
scales, one batched simulation per flight) gives I_xx,f = J_fᵀ J_f (the block-arrow structure hands each
flight's block out directly, :mod:`.arrow`). The initial conditions' wide Gaussian priors are not part of
I_xx,f: the reference prior is the data's information.

:func:`build_ic_reference` computes g at a design of coefficient points in the least-squares metric
(:func:`.priors.reference_design`) and fits the surrogate by Huber's M-estimate (:data:`HUBER`: g is not smooth
everywhere, and values far from its trend must not bend the polynomial). A polynomial fitted to a fixed design
can still stand high between or beyond the design points where g does not (four short flights with AR(1)
noise: 14 nats above the exact g at 5.5–6 least-squares sds, where the posterior went), so it is then checked
where the posterior it makes will go: points drawn from the approximate posterior exp(−½|z|² + g̃(z)) in the
whitened coefficients z (the least-squares Gaussian, prior included, times the surrogate;
:func:`approximate_posterior_points`). Where g̃ is off the exact g there by more than :data:`REFINE_TOLERANCE`
rms, the points join the design and the surrogate is fitted again, up to :data:`REFINE_ROUNDS` times (points
drawn where the profile deviance exceeds :data:`MAX_DESIGN_DEVIANCE` are not checked: the likelihood leaves
the posterior no mass there). Finally the surrogate is measured at held-out points drawn as the random design
points are.

After sampling, :func:`check_at_draws` measures it where the posterior itself went: the exact g at a random
subset of the posterior's draws, and the posterior with the exact prior by importance weights exp(g − g̃) on those
draws (Pareto-smoothed, PSIS; Vehtari et al. 2024), whose coefficient means and sds are compared with the equally
weighted ones: shifts well under a tenth of a posterior sd say the surrogate's error does not move the intervals.
(On the demo the means and sds so compared agree between 200 and 1000 checked draws to 0.03 sd; the tail
quantiles scatter more, by up to 0.16 sd, and are reported, not judged.)
"""
from __future__ import annotations

from dataclasses import asdict, dataclass, replace

import numpy as np

from ..model.priors import ReferenceSurrogate, fit_reference_surrogate, reference_design, surrogate_accuracy
from ..model.problem import Problem
from .covariance import scaled_cholesky
from .leastsq import LeastSquaresResult
from .minimiser import MU_NEAR, Minimum, minimise
from .profile import DEVIANCE_TOL
from .residuals import jacobian_blocks, whitened_costs
from .robust import weighted_quantiles

#: design points along every whitened axis at these distances (least-squares sds) ...
AXIS_RADII = (3.0, 6.0)
#: ... and this many random points of N(0, RANDOM_SPREAD² I) (a posterior up to 1.3 times as wide as the
#: least-squares one); as many held-out points again check the fit (:data:`HELD_OUT`)
RANDOM_POINTS = 120
RANDOM_SPREAD = 1.3
#: held-out points drawn like the random design points
HELD_OUT = 30
#: trust radius of the surrogate (whitened units): beyond the farthest design points it stays at its value
#: on this sphere (:class:`.priors.ReferenceSurrogate`)
TRUST_RADIUS = 6.0
#: evaluation budget of one conditional fit (they start next to their optimum and take 2–4 Jacobians)
CONDITIONAL_NFEV = 40
#: rounds of the check at approximate-posterior points (module docstring), the points drawn in each, the
#: candidates they are resampled from (N(0, REFINE_SPREAD² I) in whitened units, importance-weighted) and the
#: rms error of g̃ at them [nats] that ends the refinement
REFINE_ROUNDS = 4
REFINE_POINTS = 12
REFINE_CANDIDATES = 4000
REFINE_SPREAD = 2.0
REFINE_TOLERANCE = 1.0
#: Huber's threshold of the surrogate's fit [nats] (:func:`.priors.fit_reference_surrogate`): g is not smooth
#: everywhere (a flight's information grows fast where its wobble turns unstable), and isolated values far from
#: the trend would bend a polynomial fitted by plain least squares
HUBER = 1.0
#: design and held-out points whose conditional optimum lies this far above the least-squares optimum (profile
#: deviance 2 Δcost) are left out of the fit and of the check: the posterior has no mass there (e^(−30) of the
#: optimum's density), and the simulations of such coefficients may fail (the demo, 6 sds down the
#: pitching-moment axis: a flight that cannot be simulated)
MAX_DESIGN_DEVIANCE = 60.0
#: posterior draws at which the surrogate is checked after sampling (:func:`check_at_draws`; one conditional fit
#: each, 0.02–0.05 s on the demo: fewer than the surrogate's design, so the check costs less than building it)
CHECK_DRAWS = 200
#: a shift of a coefficient's mean by more than this share of its posterior sd, or a change of its sd by more
#: than this share, when the check's draws are reweighted to the exact prior, is reported
CHECK_SHIFT_TOLERANCE = 0.1
#: Pareto k̂ above which the check's importance weights are not trusted (PSIS)
CHECK_PARETO_K_MAX = 0.7


def ic_log_determinants(problem: Problem, theta: np.ndarray, sigma: np.ndarray) -> np.ndarray:
    """½ ln det I_xx,f at θ for every flight f: I_xx,f = J_fᵀ J_f over its initial conditions.

    Parameters
    ----------
    problem : Problem
    theta : (dim,) array
    sigma : (n_groups,) array
        Noise scale per group (whitens the residuals).

    Returns
    -------
    (n_flights,) array
        [nats]; −inf for a flight whose initial conditions are not all informed (a singular block).
    """
    free = np.zeros(problem.dim, bool)
    for k in range(problem.n_flights):
        free[problem.ic_slice(k)] = True
    J = jacobian_blocks(theta, problem, sigma, free)
    out = np.empty(problem.n_flights)
    for k, block in enumerate(J.blocks):
        info = block.T @ block                  # the block has no shared columns: only its own
        d = np.sqrt(np.diag(info))
        if not np.all(d > 0):
            out[k] = -np.inf
            continue
        sign, log_det = np.linalg.slogdet(info / np.outer(d, d))
        out[k] = 0.5 * (log_det + 2.0 * np.sum(np.log(d))) if sign > 0 else -np.inf
    return out


def conditional_optimum(problem: Problem, ls: LeastSquaresResult, c: np.ndarray, held: np.ndarray | None = None,
                        max_nfev: int = CONDITIONAL_NFEV) -> Minimum:
    """The optimum of every parameter but the coefficients ``held``, which stay at ``c``.

    Parameters
    ----------
    problem : Problem
    ls : LeastSquaresResult
        The least-squares optimum, its noise scales (held) and covariance (for the start).
    c : (len(held),) array
        The held coefficients' values.
    held : (k,) int array, optional
        Their indices (default: all ``problem.n_coef`` coefficients).
    max_nfev : int
        Evaluation budget (:data:`CONDITIONAL_NFEV`: next to the optimum, 2–4 Jacobians).

    Returns
    -------
    Minimum
        ``x`` (dim,) the held coefficients at ``c`` and every other parameter at its optimum given them; its
        ``status`` is 0 where the budget stopped the fit (used where it stopped: next to the optimum when the
        start is, and :func:`build_ic_reference`'s held-out check measures the result).

    Raises
    ------
    RuntimeError
        The fit failed (no step lowered the cost, or no positive-definite damped system).
    """
    held = np.arange(problem.n_coef) if held is None else np.asarray(held, int)
    c = np.asarray(c, float)
    S = ls.cov[np.ix_(held, held)]
    start = ls.theta + ls.cov[:, held] @ np.linalg.solve(S, c - ls.theta[held])    # the Laplace conditional mean
    start[held] = c
    kept = ls.theta.copy()
    kept[held] = c
    x0 = min((start, kept), key=lambda x: float(whitened_costs(x, problem, ls.sigma)[0]))
    free = np.ones(problem.dim, bool)
    free[held] = False
    cost0 = max(float(ls.cost), 1e-300)
    res = minimise(problem, x0, ls.sigma, free=free, max_nfev=max_nfev, mu0=MU_NEAR,
                   ftol=0.5 * DEVIANCE_TOL / cost0, dtol=0.25 * DEVIANCE_TOL)
    if res.status < 0:
        raise RuntimeError(f"the conditional fit at {np.round(c, 5).tolist()} failed: {res.message}")
    return res


def exact_log_reference(problem: Problem, ls: LeastSquaresResult, c: np.ndarray) -> tuple[float, float]:
    """g(c) = ½ Σ_f ln det I_xx,f(c, x̂_f(c)) [nats]: the conditional reference prior's log-density at the
    coefficients ``c`` (n_coef,), computed exactly (:func:`conditional_optimum`, :func:`ic_log_determinants`),
    and the profile deviance 2 [cost(c, x̂(c)) − cost(θ̂)] there (noise scales held at the least squares').

    Returns
    -------
    g : float
        −inf where a flight's block is singular.
    deviance : float
    """
    x = conditional_optimum(problem, ls, c).x
    deviance = 2.0 * (float(whitened_costs(x, problem, ls.sigma)[0]) - float(ls.cost))
    return float(np.sum(ic_log_determinants(problem, x, ls.sigma))), deviance


def approximate_posterior_points(surrogate: ReferenceSurrogate, factor: np.ndarray, k: int,
                                 rng: np.random.Generator) -> np.ndarray:
    """Up to ``k`` distinct coefficient points drawn from the approximate posterior q(z) ∝ exp(−½|z|² + g̃(z)),
    z the whitened coefficients (the least-squares Gaussian, prior included, times the surrogate prior), by
    importance resampling of :data:`REFINE_CANDIDATES` draws of N(0, :data:`REFINE_SPREAD`² I).

    Parameters
    ----------
    surrogate : ReferenceSurrogate
    factor : (n, n) array
        L, the coefficients' scaled Cholesky factor (z = L⁻¹ (c − ĉ)).
    k : int
    rng : numpy.random.Generator

    Returns
    -------
    (m, n) array, m ≤ k
        Coefficient values (their units); a candidate drawn more than once appears once.
    """
    n = factor.shape[0]
    z = REFINE_SPREAD * rng.standard_normal((REFINE_CANDIDATES, n))
    c = surrogate.centre + z @ factor.T
    r2 = np.sum(z * z, axis=1)
    log_w = -0.5 * r2 * (1.0 - 1.0 / REFINE_SPREAD ** 2) + surrogate(c)
    w = np.exp(log_w - log_w.max())
    pick = np.unique(rng.choice(REFINE_CANDIDATES, size=k, p=w / w.sum()))   # a point drawn twice counts once
    return c[pick]


def _exact_values(problem: Problem, ls: LeastSquaresResult, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(m,) exact g and (m,) profile deviance at coefficient points (m, n_coef) (:func:`exact_log_reference`)."""
    out = np.array([exact_log_reference(problem, ls, c) for c in points], float).reshape(-1, 2)
    return out[:, 0], out[:, 1]


def build_ic_reference(problem: Problem, ls: LeastSquaresResult, seed: int) -> ReferenceSurrogate:
    """The surrogate of g fitted to exact values at a design of coefficient points, refined where its
    approximate posterior goes and measured at held-out ones (module docstring).

    Parameters
    ----------
    problem : Problem
    ls : LeastSquaresResult
        The least-squares optimum: the design is centred on it and scaled by its coefficients' covariance.
    seed : int
        Seed of the random design, refinement and held-out points.

    Returns
    -------
    ReferenceSurrogate
        ``accuracy``: :func:`.priors.surrogate_accuracy` at the held-out points, with ``design_points`` (fitted,
        refinement points included), ``left_out`` (points beyond :data:`MAX_DESIGN_DEVIANCE`),
        ``refinement_rounds`` (rounds that added points) and ``posterior_rms_error`` (the rms error of g̃ at
        the last round's approximate-posterior points [nats]).

    Raises
    ------
    RuntimeError
        A conditional fit failed, or g is not finite at a point within :data:`MAX_DESIGN_DEVIANCE` (a flight
        whose initial conditions the data do not all inform there).
    ValueError
        The points left do not fix the quadratic (:func:`.priors.fit_reference_surrogate`).
    """
    n = problem.n_coef
    rng = np.random.default_rng([seed, 7411])
    L = scaled_cholesky(ls.cov[:n, :n])   # the coefficients' metric (floored where it is numerically singular)
    design = ls.theta[:n] + reference_design(n, AXIS_RADII, RANDOM_POINTS, RANDOM_SPREAD, rng) @ L.T
    held = ls.theta[:n] + RANDOM_SPREAD * rng.standard_normal((HELD_OUT, n)) @ L.T
    values, deviance = _exact_values(problem, ls, design)
    points, values, left_out = _kept(design, values, deviance)
    surrogate = fit_reference_surrogate(points, values, ls.theta[:n], L, TRUST_RADIUS, HUBER)
    rounds, error = 0, np.inf
    for _ in range(REFINE_ROUNDS):
        new = approximate_posterior_points(surrogate, L, REFINE_POINTS, rng)
        new_values, new_deviance = _exact_values(problem, ls, new)
        near = new_deviance <= MAX_DESIGN_DEVIANCE
        e = surrogate(new[near]) - new_values[near]
        error = float(np.sqrt(np.mean(e * e))) if e.size else 0.0
        if error <= REFINE_TOLERANCE:
            break
        kept, kept_values, out = _kept(new, new_values, new_deviance)
        points, values, left_out = np.vstack([points, kept]), np.concatenate([values, kept_values]), left_out + out
        surrogate = fit_reference_surrogate(points, values, ls.theta[:n], L, TRUST_RADIUS, HUBER)
        rounds += 1
    held_values, held_deviance = _exact_values(problem, ls, held)
    check, check_values, out = _kept(held, held_values, held_deviance)
    accuracy = {**surrogate_accuracy(surrogate, check, check_values), "design_points": int(len(points)),
                "left_out": left_out + out, "refinement_rounds": rounds, "posterior_rms_error": error}
    return replace(surrogate, accuracy=accuracy)


def _kept(points: np.ndarray, values: np.ndarray, deviance: np.ndarray) -> tuple[np.ndarray, np.ndarray, int]:
    """The points within :data:`MAX_DESIGN_DEVIANCE` and their exact g, and how many were left out.

    Raises
    ------
    RuntimeError
        g is not finite at a point kept.
    """
    keep = deviance <= MAX_DESIGN_DEVIANCE
    if not np.all(np.isfinite(values[keep])):
        raise RuntimeError("the initial conditions' information is singular at some design points: the "
                           "reference prior is undefined there")
    return points[keep], values[keep], int((~keep).sum())


@dataclass
class SurrogateCheck:
    """The surrogate g̃ against the exact g at posterior draws (:func:`check_at_draws`).

    Attributes
    ----------
    draws : int
        Posterior draws checked (a random subset of the run's).
    singular : int
        Of them, draws where a flight's information is singular: the exact prior's density is zero there, so
        their weight is zero.
    failed : int
        Draws whose conditional fit failed: left out of the check.
    rms_error, max_error : float
        rms and largest |g̃ − g| at them [nats], each relative to the mean difference (a constant offset does
        not change the posterior).
    pareto_k : float or None
        PSIS shape k̂ of the weights exp(g − g̃); None where they are all equal.
    ess : float
        Effective sample size of the smoothed weights, 1 / Σ w².
    mean_shift : dict
        {coefficient: (weighted − equal mean) / equal sd} over the checked draws.
    sd_ratio : dict
        {coefficient: weighted sd / equal sd}.
    quantile_shift : dict
        {coefficient: largest |weighted − equal| of its 5 %, 50 % and 95 % quantiles / equal sd}.
    reweighted : dict
        {coefficient: {q05, q50, q95}} of the checked draws weighted to the exact prior (its units); empty when
        the weights are not :attr:`reliable`.
    """

    draws: int
    singular: int
    failed: int
    rms_error: float
    max_error: float
    pareto_k: float | None
    ess: float
    mean_shift: dict
    sd_ratio: dict
    quantile_shift: dict
    reweighted: dict

    @property
    def largest_shift(self) -> float:
        """max over coefficients of |mean shift| [posterior sds] and |sd ratio − 1|."""
        return max(max(abs(v) for v in self.mean_shift.values()),
                   max(abs(v - 1.0) for v in self.sd_ratio.values()))

    @property
    def reliable(self) -> bool:
        """The weights can be trusted (k̂ ≤ :data:`CHECK_PARETO_K_MAX` or all equal)."""
        return _trusted(self.pareto_k)

    @property
    def moves_intervals(self) -> bool:
        """The exact prior would move some coefficient's mean by more than :data:`CHECK_SHIFT_TOLERANCE` of its
        posterior sd or change its sd by more than that share, or the weights cannot say (not :attr:`reliable`)."""
        return not self.reliable or self.largest_shift > CHECK_SHIFT_TOLERANCE

    def to_dict(self) -> dict:
        return asdict(self) | {"largest_shift": self.largest_shift, "moves_intervals": self.moves_intervals,
                               "shift_tolerance": CHECK_SHIFT_TOLERANCE, "pareto_k_max": CHECK_PARETO_K_MAX}

    def text(self) -> str:
        """One line for the log."""
        k = "weights equal" if self.pareto_k is None else f"Pareto k̂ {self.pareto_k:.2f}"
        k += f"; {self.singular} draws singular, weight zero" if self.singular else ""
        k += f"; {self.failed} conditional fits failed, left out" if self.failed else ""
        return (f"at {self.draws} posterior draws the surrogate is within {self.rms_error:.2f} nats rms "
                f"({self.max_error:.2f} max) of the exact reference prior; reweighting them to the exact prior "
                f"moves the coefficients' means and sds by at most {self.largest_shift:.2f} posterior sd ({k})")


def check_at_draws(problem: Problem, ls: LeastSquaresResult, surrogate: ReferenceSurrogate, theta: np.ndarray,
                   rng: np.random.Generator, names: list[str], draws: int = CHECK_DRAWS) -> SurrogateCheck:
    """The surrogate checked where the posterior went (module docstring).

    Parameters
    ----------
    problem : Problem
        The problem sampled (only its likelihood is read: the surrogate it may carry does not enter g).
    ls : LeastSquaresResult
        The least-squares optimum the surrogate was built at (the conditional fits start from its covariance's
        prediction).
    surrogate : ReferenceSurrogate
        The surrogate the posterior was sampled with.
    theta : (S, dim) array
        The run's posterior draws.
    rng : numpy.random.Generator
        Picks the draws checked.
    names : list of str
        The coefficients (the first len(names) columns of ``theta``).
    draws : int
        At most this many draws.

    Returns
    -------
    SurrogateCheck

    Raises
    ------
    RuntimeError
        Every checked draw's conditional fit failed or is singular (nothing to weigh).
    """
    import arviz as az
    n = problem.n_coef
    pick = np.sort(rng.choice(theta.shape[0], size=min(draws, theta.shape[0]), replace=False))
    c = theta[pick, :n]
    exact = np.array([_exact_or_nan(problem, ls, ci) for ci in c])
    failed = np.isnan(exact)
    c, exact = c[~failed], exact[~failed]
    finite = np.isfinite(exact)                       # −inf: a singular flight, the exact prior's density is zero
    if not np.any(finite):
        raise RuntimeError(f"the reference prior could not be checked: at {int(failed.sum())} of {len(pick)} "
                           "posterior draws the conditional fit failed, at the others the information is singular")
    log_w = exact[finite] - surrogate(c[finite])
    e = log_w - log_w.mean()
    w = np.zeros(c.shape[0])
    if np.ptp(log_w) > 1e-9:
        smoothed, k = az.psislw(log_w - log_w.max())
        w[finite], k = np.exp(smoothed - np.logaddexp.reduce(smoothed)), float(k)
    else:
        w[finite], k = 1.0 / np.sum(finite), None
    mean, sd = c.mean(axis=0), c.std(axis=0)
    w_mean = w @ c
    w_sd = np.sqrt(w @ (c - w_mean) ** 2)
    equal = np.full(c.shape[0], 1.0 / c.shape[0])
    q = [0.05, 0.5, 0.95]
    shift = [np.max(np.abs(weighted_quantiles(c[:, i], w, q) - weighted_quantiles(c[:, i], equal, q))) / sd[i]
             for i in range(n)]
    reweighted = {m: dict(zip(("q05", "q50", "q95"), weighted_quantiles(c[:, i], w, q).tolist()))
                  for i, m in enumerate(names)} if _trusted(k) else {}
    return SurrogateCheck(draws=int(len(pick)), singular=int(np.sum(~finite)), failed=int(failed.sum()),
                          rms_error=float(np.sqrt(np.mean(e * e))),
                          max_error=float(np.max(np.abs(e))), pareto_k=k, ess=float(1.0 / np.sum(w * w)),
                          mean_shift=dict(zip(names, ((w_mean - mean) / sd).tolist())),
                          sd_ratio=dict(zip(names, (w_sd / sd).tolist())),
                          quantile_shift=dict(zip(names, np.asarray(shift, float).tolist())),
                          reweighted=reweighted)


def _exact_or_nan(problem: Problem, ls: LeastSquaresResult, c: np.ndarray) -> float:
    """g at coefficients ``c`` (:func:`exact_log_reference`; −inf where a flight's information is singular), NaN
    where the conditional fit fails."""
    try:
        return exact_log_reference(problem, ls, c)[0]
    except RuntimeError:
        return float("nan")


def _trusted(pareto_k: float | None) -> bool:
    """Importance weights with this Pareto k̂ can be trusted (None: all equal)."""
    return pareto_k is None or pareto_k <= CHECK_PARETO_K_MAX
