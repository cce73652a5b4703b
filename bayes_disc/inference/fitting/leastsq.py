"""Joint least squares over all flights (the MAP with the noise scales held fixed): several starts,
best kept, then Gauss–Newton (Cramér–Rao) covariance and condition number. Seeds the sampler.

On many flights the starts are fitted on the most informative few (:func:`informative_flights`) and the
other flights joined to the best one (:func:`join_flights`). The minimiser is :func:`.minimiser.minimise`
(Levenberg–Marquardt on the block-arrow normal equations), the residuals and Jacobians are those of
:mod:`.residuals`, the covariance that of :mod:`.covariance`."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ...physics import literature_coefficients
from .arrow import ArrowJacobian
from .fit_checks import check_fit_plausible
from ..model.problem import Problem
from .covariance import covariance_at
from .minimiser import MU_FAR, MU_NEAR, Minimum, minimise
from .residuals import jacobian_blocks, whitened_residuals


@dataclass
class LeastSquaresResult:
    theta: np.ndarray            # (dim,) optimum
    sigma: np.ndarray            # (n_groups,) noise scale per noise group (per flight for markers) [m]: residual RMS
    cov: np.ndarray              # (dim, dim) Gauss–Newton covariance (prior included)
    cost: float                  # ½ Σ whitened residual² at the optimum
    condition_number: float      # of the scale-free (correlation-normalised) information matrix
    start_costs: list            # cost where every start stopped (nominal noise; within START_DECREMENT of its optimum)
    nfev: int
    message: str
    names: list
    flight_names: list
    sigma_names: list            # (n_groups,) public name of every noise group's σ (``sigma_<flight>`` for markers)
    sigma_units: list            # (n_groups,) its unit ("m", "rad/s", "m/s²")
    start_flights: list = field(default_factory=list)   # flights the starts were fitted on (empty: all of them)
    lower_optima: list = field(default_factory=list)    # profile points below an earlier optimum it was refitted from
    sigma_counts: list = field(default_factory=list)    # (n_groups,) residuals in every noise group (empty: not known)

    def noise(self) -> dict:
        """{sigma name: {"value", "unit", "n"}}: every noise group's residual RMS at the optimum and its number
        of residuals (``n`` only when ``sigma_counts`` is known). With ``n``, two fits of the same data compare
        by their σ-profiled log-likelihood difference Σ_g n_g ln(σ_g,1/σ_g,2)."""
        counts = self.sigma_counts or [None] * len(self.sigma_names)
        return {n: {"value": float(s), "unit": u, **({"n": int(c)} if c is not None else {})}
                for n, s, u, c in zip(self.sigma_names, self.sigma, self.sigma_units, counts)}

    def marker_rms_mm(self) -> dict:
        """{flight: RMS [mm]} of the marker noise groups (``sigma_<flight>``, unit m)."""
        return {n[len("sigma_"):]: float(s * 1e3) for n, s, u in zip(self.sigma_names, self.sigma, self.sigma_units)
                if u == "m"}

    def to_dict(self) -> dict:
        sd = np.sqrt(np.diag(self.cov))
        return {
            "cost": self.cost, "condition_number": self.condition_number, "nfev": self.nfev,
            "message": self.message, "start_costs": self.start_costs, "start_flights": self.start_flights,
            "lower_optima": self.lower_optima,
            "rms_mm": self.marker_rms_mm(), "noise": self.noise(),
            "parameters": {n: {"value": float(v), "sd": float(s)} for n, v, s in zip(self.names, self.theta, sd)},
        }


def noise_text(noise: dict) -> str:
    """"a 1.52 mm, gyro_axial_b 0.0127 rad/s, …": a ``noise`` dict ({sigma name: {"value", "unit"}},
    :meth:`LeastSquaresResult.noise`) as one line, marker groups in mm."""
    return ", ".join(f"{n[len('sigma_'):]} {1e3 * v['value']:.2f} mm" if v["unit"] == "m"
                     else f"{n[len('sigma_'):]} {v['value']:.3g} {v['unit']}" for n, v in noise.items())


def _starts(problem: Problem, n: int, rng: np.random.Generator) -> list[np.ndarray]:
    base = problem.start_vector()
    out = []
    for key in ("potts_crowther", "hummel2002"):
        x = base.copy()
        x[: problem.n_coef] = literature_coefficients(key).as_array()
        out.append(x)
    if problem.prior_name != "potts_crowther":
        out.insert(0, base.copy())
    while len(out) < n:
        x = out[len(out) % 2].copy()
        x[: problem.n_coef] *= 1 + 0.3 * rng.standard_normal(problem.n_coef)
        out.append(x)
    return out[:n]


#: a least-squares start stops once the Gauss–Newton decrement is at most this (½ χ² units): near enough its
#: optimum to rank the starts, after which only the best is refined (:func:`refine_least_squares`)
START_DECREMENT = 0.1
#: each round of :func:`refine_least_squares` stops once the Gauss–Newton decrement is at most this (or on the
#: tight step and cost tolerances, 10⁻¹²). Without it the rounds spent most of their Jacobians on digits: on
#: bench_scale's 12-flight data of seed 19, 58 and 23 Jacobians, the cost settled to 10⁻⁴ after ~20; with
#: it 35 and 2, the optimum within 0.011 sd of the fully converged one and the cost within 1.1·10⁻⁴ (a
#: tenth of the profile fits' deviance tolerance); at 24 flights of seeds 18 and 19, 0.004 and 0.006 sd
REFINE_DECREMENT = 1e-5


#: with more flights than this, the least-squares starts are fitted on this many of them, the most informative
#: (:func:`informative_flights`), and the other flights are then joined to the best start (:func:`join_flights`)
START_FLIGHTS = 4


def informative_flights(J: ArrowJacobian, n: int) -> list[int]:
    """The n blocks (flights) that together say most about the shared parameters: a greedy D-optimal choice,
    each pick maximising ln det(P_s² + Σ_chosen S_k) (S_k: :meth:`.arrow.ArrowJacobian.block_schur`, a
    flight's information about the coefficients with its own initial conditions unknown).

    Parameters
    ----------
    J : ArrowJacobian
        Whitened Jacobian over every parameter (e.g. at the start vector).
    n : int
        Blocks to choose.

    Returns
    -------
    list of int
        Block indices, ascending.
    """
    S = J.block_schur()
    M = np.diag(J.prior[J.shared] ** 2)
    chosen: list[int] = []
    for _ in range(min(n, len(S))):
        scores = [-np.inf if k in chosen else _log_det(M + Sk) for k, Sk in enumerate(S)]
        k = int(np.argmax(scores))
        chosen.append(k)
        M = M + S[k]
    return sorted(chosen)


def _start_noise(problem: Problem, sigma0: float | None) -> np.ndarray:
    """Noise scale per group during the starts: ``sigma0`` for every group, or each model's nominal noise."""
    return problem.nominal_noise if sigma0 is None else np.full(problem.n_groups, sigma0)


def _log_det(M: np.ndarray) -> float:
    """ln det of a symmetric positive-definite matrix in scale-free form (−∞ if not positive definite)."""
    d = np.sqrt(np.where(np.diag(M) > 0, np.diag(M), 1.0))
    sign, value = np.linalg.slogdet(M / np.outer(d, d))
    return float(value + 2.0 * np.sum(np.log(d))) if sign > 0 else -np.inf


def join_flights(problem: Problem, part: Problem, x_part: np.ndarray, sigma0: float | None = None,
                 max_nfev: int = 200) -> Minimum:
    """From an optimum ``x_part`` of some of the flights (``part``, :meth:`Problem.select_flights`) to one of
    all of them: every other flight's own block fitted alone with the shared parameters held (one flight's
    simulations per step), then all together from there (little damping, :data:`MU_NEAR`, and step-length
    corrections: the start is next to the optimum), each to :data:`START_DECREMENT`.

    On bench_scale's 24-flight data of seed 19 (starts on 4 flights), each other flight's fit took 3–7
    Jacobians of that flight, the joint fit 4, and least squares in all (:func:`fit_least_squares`) reached the
    optimum of four starts on all 24 flights to 0.0005 sd with 1228 flight-Jacobians instead of 4128.

    Parameters
    ----------
    problem : Problem
        All flights.
    part : Problem
        Some of them, with the same model.
    x_part : (part.dim,) array
        Optimum of ``part``.
    sigma0 : float, optional
        Noise scale of every group (default: the nominal noise).
    max_nfev : int
        Evaluation budget of each fit.

    Returns
    -------
    Minimum
        The joint fit (``nfev``: every fit's evaluations).
    """
    x = problem.layout.transfer(x_part, part.layout, problem.start_vector())
    done = {f.name for f in part.flights}
    nfev = 0
    for k, flight in enumerate(problem.flights):
        if flight.name in done:
            continue
        one = problem.subset(k)
        free = np.zeros(one.dim, bool)
        free[one.layout.flight_slice(0)] = True
        res = minimise(one, one.layout.transfer(x, problem.layout, one.start_vector()), _start_noise(one, sigma0),
                       free=free, max_nfev=max_nfev, dtol=START_DECREMENT)
        x = problem.layout.transfer(res.x, one.layout, x)
        nfev += res.nfev
    joint = minimise(problem, x, _start_noise(problem, sigma0), max_nfev=max_nfev, mu0=MU_NEAR, dtol=START_DECREMENT,
                     line_search=True)
    joint.nfev += nfev
    return joint


def fit_least_squares(problem: Problem, starts: int = 4, max_nfev: int = 200, seed: int = 0,
                      sigma0: float | None = None, progress=None) -> LeastSquaresResult:
    """Joint least squares from several starts, each to within :data:`START_DECREMENT` of its optimum; the
    best is refined with per-flight noise scales, to the full tolerance.

    With more than :data:`START_FLIGHTS` flights the starts are fitted on the :data:`START_FLIGHTS` most
    informative ones (:func:`informative_flights`, from the Jacobian at the start vector), and the others are
    joined to the best start (:func:`join_flights`) before the refinement: the starts' cost no longer grows with
    the flights.

    Parameters
    ----------
    problem : Problem
        The run's statistical problem.
    starts : int
        Number of starts (the data-derived start, the literature coefficient sets, perturbations).
    max_nfev : int
        Evaluation budget of each fit.
    seed : int
        Seed of the perturbed starts.
    sigma0 : float, optional
        Noise scale assumed for every group during the starts (default: each observation model's
        nominal noise, e.g. 2 mm for markers).
    progress : callable, optional
        Called as ``progress(done, total, cost)`` after each start (``cost``: its final ½ Σ whitened
        residual²), and ``progress(total, total, None)`` before the other flights are joined and the best
        start refined.

    Returns
    -------
    LeastSquaresResult
        The optimum, noise scales [m], covariance, cost and condition number; ``start_flights`` the flights
        the starts were fitted on (empty: all).
    """
    rng = np.random.default_rng(seed)
    part, chosen = problem, []
    if problem.n_flights > START_FLIGHTS:
        J = jacobian_blocks(problem.start_vector(), problem, _start_noise(problem, sigma0))
        chosen = informative_flights(J, START_FLIGHTS)
        part = problem.select_flights(chosen)
    sigma = _start_noise(part, sigma0)
    results = []
    x0s = _starts(part, starts, rng)
    for i, x0 in enumerate(x0s):
        res = minimise(part, x0, sigma, max_nfev=max_nfev, dtol=START_DECREMENT)
        results.append(res)
        if progress is not None:
            progress(i + 1, len(x0s), float(res.cost))
    if progress is not None:
        progress(len(x0s), len(x0s), None)
    best = min(results, key=lambda r: r.cost)
    nfev = int(sum(r.nfev for r in results))
    if part is not problem:
        best = join_flights(problem, part, best.x, sigma0, max_nfev)
        nfev += best.nfev
    # a converged start is next to the optimum the new noise scales move: little damping at first
    near = best.status > 0
    out = refine_least_squares(problem, best.x, max_nfev=max_nfev, mu0=MU_NEAR if near else MU_FAR, line_search=near)
    out.start_costs = [float(r.cost) for r in results]
    out.start_flights = [problem.flights[k].name for k in chosen]
    out.nfev += nfev
    check_fit_plausible(out, problem)  # an RMS far above any marker noise stops here, before sampling
    return out


def refine_least_squares(problem: Problem, x0: np.ndarray, max_nfev: int = 200, rounds: int = 2,
                         free: np.ndarray | None = None, mu0: float = MU_FAR,
                         line_search: bool = False) -> LeastSquaresResult:
    """From x0: estimate each flight's σ from its residuals and refit (``rounds`` times, each until the
    Gauss–Newton decrement is at most :data:`REFINE_DECREMENT`), then the Gauss–Newton covariance at the
    optimum.

    Parameters
    ----------
    problem : Problem
    x0 : (dim,) array
        Start.
    max_nfev : int
        Evaluation budget of each round.
    rounds : int
        σ re-estimations.
    free : (dim,) bool array, optional
        Parameters fitted; the others are held at their ``x0`` values (their covariance rows and columns
        are zero). Default: all.
    mu0 : float
        Initial damping of every round (:func:`minimise`): :data:`MU_NEAR` when x0 is a converged optimum.
    line_search : bool
        Step-length corrections in every round (:func:`minimise`): when x0 is a converged optimum.

    Returns
    -------
    LeastSquaresResult
    """
    x, nfev, res = np.asarray(x0, float).copy(), 0, None
    free = np.ones(x.size, bool) if free is None else np.asarray(free, bool)
    for _ in range(rounds):
        res = minimise(problem, x, _rms(problem, x), free=free, max_nfev=max_nfev, xtol=1e-12, ftol=1e-12, mu0=mu0,
                       dtol=REFINE_DECREMENT, line_search=line_search)
        x, nfev = res.x, nfev + res.nfev
    sigma = _rms(problem, x)
    J = jacobian_blocks(x, problem, sigma, free)
    cov = covariance_at(J, free)
    cost = float(0.5 * np.sum(whitened_residuals(x, problem, sigma) ** 2))
    return LeastSquaresResult(theta=x, sigma=sigma, cov=cov, cost=cost, condition_number=J.information().condition_number(),
                              start_costs=[], nfev=int(nfev), message=res.message if res else "",
                              names=problem.names, flight_names=[f.name for f in problem.flights],
                              sigma_names=list(problem.sigma_names), sigma_units=list(problem.noise_units),
                              sigma_counts=[int(n) for n in problem.n_coords])


def refit_from_lower(problem: Problem, ls: LeastSquaresResult, x: np.ndarray, found: dict,
                     max_nfev: int = 200) -> LeastSquaresResult:
    """The least squares refitted from x, a point of lower cost than ``ls``'s optimum (a profile point,
    :class:`.profile.LowerOptimum`): ``ls`` was not the lowest point (a local optimum that every start ended
    in, or a refinement that stopped short of its optimum).

    Parameters
    ----------
    problem : Problem
    ls : LeastSquaresResult
        The optimum found before.
    x : (dim,) array
        The lower point (every parameter).
    found : dict
        What found it (``profile``, ``t``, ``deviance``), recorded in ``lower_optima`` with ``earlier_cost``:
        the earlier optimum's cost with the new noise scales, to compare with the new ``cost``.
    max_nfev : int
        Evaluation budget of each refinement round.

    Returns
    -------
    LeastSquaresResult
        Refined from x (:func:`refine_least_squares`, next to an optimum); the starts' record, the evaluations
        and the earlier ``lower_optima`` carried over.
    """
    out = refine_least_squares(problem, x, max_nfev=max_nfev, mu0=MU_NEAR, line_search=True)
    out.start_costs, out.start_flights, out.nfev = ls.start_costs, ls.start_flights, out.nfev + ls.nfev
    earlier = 0.5 * float(np.sum(np.square(whitened_residuals(ls.theta, problem, out.sigma))))
    out.lower_optima = [*ls.lower_optima, {**found, "earlier_cost": earlier}]
    check_fit_plausible(out, problem)
    return out


def _rms(problem: Problem, x: np.ndarray) -> np.ndarray:
    """(n_groups,) effective residual RMS per noise group at x (5 × nominal where the simulation failed)."""
    out = np.empty(problem.n_groups)
    theta = x[None]
    for k in range(problem.n_flights):
        r, ok = problem.noise_residuals(theta, k)
        g = problem.residual_groups(k)
        ms = np.bincount(g, weights=r[0] ** 2, minlength=problem.n_groups) / np.maximum(
            np.bincount(g, minlength=problem.n_groups), 1)
        groups = problem.flight_groups(k)
        out[groups] = np.sqrt(ms[groups]) if ok[0] and np.all(np.isfinite(ms[groups])) else 5 * problem.nominal_noise[groups]
    return np.maximum(out, 5e-3 * problem.nominal_noise)


