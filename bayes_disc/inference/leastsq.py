"""Joint least squares over all flights (the MAP with the noise scales held fixed): several starts,
best kept, then Gauss–Newton (Cramér–Rao) covariance and condition number. Seeds the sampler."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from ..physics import literature_coefficients
from .fit_checks import check_fit_plausible
from .model import Problem

FAILED_RESIDUAL = 1e3  # whitened residual standing in for a failed simulation


@dataclass
class LeastSquaresResult:
    theta: np.ndarray            # (dim,) optimum
    sigma: np.ndarray            # (n_groups,) noise scale per noise group (per flight for markers) [m]: residual RMS
    cov: np.ndarray              # (dim, dim) Gauss–Newton covariance (prior included)
    cost: float                  # ½ Σ whitened residual² at the optimum
    condition_number: float      # of the scale-free (correlation-normalised) information matrix
    start_costs: list            # final cost of every start
    nfev: int
    message: str
    names: list
    flight_names: list

    def to_dict(self) -> dict:
        sd = np.sqrt(np.diag(self.cov))
        return {
            "cost": self.cost, "condition_number": self.condition_number, "nfev": self.nfev,
            "message": self.message, "start_costs": self.start_costs,
            "rms_mm": {n: float(r * 1e3) for n, r in zip(self.flight_names, self.sigma)},
            "parameters": {n: {"value": float(v), "sd": float(s)} for n, v, s in zip(self.names, self.theta, sd)},
        }


def _steps(problem: Problem, x: np.ndarray) -> np.ndarray:
    """Finite-difference steps: 1e-4 of each parameter's prior scale."""
    return 1e-4 * problem.prior_sd


def whitened_residuals(x: np.ndarray, problem: Problem, sigma: np.ndarray) -> np.ndarray:
    """Every flight's effective residuals (:meth:`Problem.noise_residuals`) divided by their group's σ, then
    the prior's standardised deviations: ½ |·|² is the negative log-posterior with σ fixed."""
    parts = []
    theta = x[None]
    for k in range(problem.n_flights):
        r, ok = problem.noise_residuals(theta, k)
        r = r[0] / sigma[problem.residual_groups(k)]
        if not ok[0] or not np.all(np.isfinite(r)):
            r = np.full(r.shape, FAILED_RESIDUAL)
        parts.append(r)
    parts.append((x - problem.prior_mean) / problem.prior_sd)
    return np.concatenate(parts)


def whitened_jacobian(x: np.ndarray, problem: Problem, sigma: np.ndarray, free: np.ndarray | None = None) -> np.ndarray:
    """Central differences, one batched simulation per flight (2 lanes per parameter it depends on); with
    ``free`` (dim,) bool, the columns of held parameters are zero (not computed)."""
    h = _steps(problem, x)
    rows = []
    n_x = x.size
    for k in range(problem.n_flights):
        cols = problem.flight_columns(k)
        if free is not None:
            cols = cols[free[cols]]
        lanes = np.repeat(x[None], 2 * cols.size, axis=0)
        lanes[np.arange(cols.size), cols] += h[cols]
        lanes[cols.size + np.arange(cols.size), cols] -= h[cols]
        r, ok = problem.noise_residuals(lanes, k)
        d = (r[: cols.size] - r[cols.size:]) / (2 * h[cols])[:, None] / sigma[problem.residual_groups(k)]
        d[~(ok[: cols.size] & ok[cols.size:])] = 0.0
        J = np.zeros((r.shape[1], n_x))
        J[:, cols] = d.T
        rows.append(J)
    rows.append(np.diag(1.0 / problem.prior_sd))
    return np.vstack(rows)


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


def fit_least_squares(problem: Problem, starts: int = 4, max_nfev: int = 200, seed: int = 0,
                      sigma0: float | None = None, progress=None) -> LeastSquaresResult:
    """Joint least squares from several starts; the best is refined with per-flight noise scales.

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
        residual²), and ``progress(total, total, None)`` before the final refinement.

    Returns
    -------
    LeastSquaresResult
        The optimum, noise scales [m], covariance, cost and condition number.
    """
    rng = np.random.default_rng(seed)
    sigma = problem.nominal_noise if sigma0 is None else np.full(problem.n_groups, sigma0)
    results = []
    x0s = _starts(problem, starts, rng)
    for i, x0 in enumerate(x0s):
        res = least_squares(whitened_residuals, x0, jac=whitened_jacobian, args=(problem, sigma), method="trf",
                            x_scale=problem.prior_sd, max_nfev=max_nfev, xtol=1e-10, ftol=1e-10)
        results.append(res)
        if progress is not None:
            progress(i + 1, len(x0s), float(res.cost))
    if progress is not None:
        progress(len(x0s), len(x0s), None)
    best = min(results, key=lambda r: r.cost)
    out = refine_least_squares(problem, best.x, max_nfev=max_nfev)
    out.start_costs = [float(r.cost) for r in results]
    out.nfev += int(sum(r.nfev for r in results))
    check_fit_plausible(out, problem)  # an RMS far above any marker noise stops here, before sampling
    return out


def refine_least_squares(problem: Problem, x0: np.ndarray, max_nfev: int = 200, rounds: int = 2,
                         free: np.ndarray | None = None) -> LeastSquaresResult:
    """From x0: estimate each flight's σ from its residuals and refit (``rounds`` times), then the
    Gauss–Newton covariance at the optimum.

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

    Returns
    -------
    LeastSquaresResult
    """
    x, nfev, res = np.asarray(x0, float).copy(), 0, None
    free = np.ones(x.size, bool) if free is None else np.asarray(free, bool)

    def full(xf):
        out = x.copy()
        out[free] = xf
        return out

    for _ in range(rounds):
        sigma = _rms(problem, x)
        res = least_squares(lambda xf, s=sigma: whitened_residuals(full(xf), problem, s), x[free],
                            jac=lambda xf, s=sigma: whitened_jacobian(full(xf), problem, s, free)[:, free],
                            method="trf", x_scale=problem.prior_sd[free], max_nfev=max_nfev, xtol=1e-12, ftol=1e-12)
        x, nfev = full(res.x), nfev + res.nfev
    sigma = _rms(problem, x)
    J = whitened_jacobian(x, problem, sigma, free)[:, free]
    cov = np.zeros((x.size, x.size))
    cov[np.ix_(free, free)] = covariance_from_jacobian(J)
    cost = float(0.5 * np.sum(whitened_residuals(x, problem, sigma) ** 2))
    return LeastSquaresResult(theta=x, sigma=sigma, cov=cov, cost=cost, condition_number=condition_number(J),
                              start_costs=[], nfev=int(nfev), message=str(res.message) if res else "",
                              names=problem.names, flight_names=[f.name for f in problem.flights])


def _scaled_information(J: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Fisher information F = JᵀJ of whitened residuals, scaled to unit diagonal (entries of F span ~12
    decades: CNr ~ 1e−5 beside positions ~ 1 m); returns (F / d dᵀ, d)."""
    F = J.T @ J
    d = np.sqrt(np.diag(F))
    return F / np.outer(d, d), d


def covariance_from_jacobian(J: np.ndarray) -> np.ndarray:
    """Gauss–Newton (Cramér–Rao) covariance (JᵀJ)⁻¹ of the whitened residual Jacobian J (prior rows
    included), inverted in scale-free form."""
    Fn, d = _scaled_information(J)
    return np.linalg.pinv(Fn) / np.outer(d, d)


def condition_number(J: np.ndarray) -> float:
    """Condition number of the scale-free information matrix."""
    ev = np.linalg.eigvalsh(_scaled_information(J)[0])
    return float(ev[-1] / max(ev[0], 1e-300))


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


