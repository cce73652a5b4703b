"""Joint statements about the coefficients from the profile likelihood: the deviance of a set of values,

    W(c_H) = 2 [cost(c_H, x̂(c_H)) − cost(θ̂)],

for a subset H of the coefficients held at the values c_H, every other parameter re-optimised (the other
coefficients, every flight's initial conditions, its observation-model parameters and any extra-term
parameters; the noise scales held at the least squares', as along the profile paths). The cost is the negative
log-posterior of the least squares: data and coefficient prior, the objective of the profile paths and of the
profile intervals (:mod:`.profile_interval`).

W is the likelihood-ratio statistic. At the true values it is χ² with |H| degrees of freedom when the profile
likelihood's joint regions are calibrated, and then

    R₉₀ = {c_H : W(c_H) ≤ χ²_|H|(0.9)}

is a 90 % joint region. For a Gaussian likelihood W is the Mahalanobis distance² of c_H under the least-squares
covariance; along a curved valley (the pitching-moment trio) it follows the valley. Its calibration at fixed
truths of varied four-flight designs is measured by ``benchmarks/bench_profile_coverage.py``.

:func:`literature_tests` puts every published coefficient set to this test, each on the coefficients it gives.
A set whose held values reach a lower cost than θ̂ shows that θ̂ was not the lowest point:
:func:`literature_tests_through_lowest` then refits the least squares from that set's conditional optimum and
tests again, as the profile paths do with a lower point (:func:`.profile.profiles_through_lowest`).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

import numpy as np
from scipy.stats import chi2

from ...physics.constants import LITERATURE
from ..model.problem import Problem
from .leastsq import LeastSquaresResult, refit_from_lower
from .profile import LOWER_OPTIMUM_DEVIANCE, MAX_LOWER_REFITS
from .reference import conditional_optimum
from .residuals import whitened_costs

#: the joint region's level
JOINT_LEVEL = 0.9
#: evaluation budget of one joint test's fit (values far from the optimum take a few hundred evaluations, not a
#: profile point's few)
JOINT_NFEV = 1000


def p_text(p: float) -> str:
    """A p-value as the log and the report print it: "p < 0.001", else "p = 0.012" (two significant digits)."""
    return "p < 0.001" if p < 1e-3 else f"p = {p:.2g}"


@dataclass(frozen=True)
class JointTest:
    """The profile deviance of a set of coefficient values (:func:`profile_deviance`)."""

    values: dict        # {name: value} held
    deviance: float     # W (negative where the fit went below the optimum: :attr:`below_optimum`)
    converged: bool     # False: the fit stopped at its budget, and W is an upper bound
    #: the conditional optimum x̂(c_H) (every parameter; not written to summary.json)
    x: np.ndarray | None = field(default=None, repr=False, compare=False)

    @property
    def dof(self) -> int:
        return len(self.values)

    @property
    def p_value(self) -> float:
        """P(χ²_dof ≥ W)."""
        return float(chi2.sf(self.deviance, self.dof))

    @property
    def below_optimum(self) -> bool:
        """The fit with the values held reached a lower cost than the least-squares optimum (by more than
        :data:`.profile.LOWER_OPTIMUM_DEVIANCE` in W): the optimum was not the lowest point, these values fit
        better, and W is no χ² statistic."""
        return self.deviance < -LOWER_OPTIMUM_DEVIANCE

    @property
    def inside(self) -> bool:
        """Whether the values lie inside the joint region R₉₀ (at :data:`JOINT_LEVEL`)."""
        return self.deviance <= float(chi2.ppf(JOINT_LEVEL, self.dof))

    def to_dict(self) -> dict:
        return {"values": self.values, "deviance": round(self.deviance, 3), "dof": self.dof,
                "p_value": self.p_value, "inside_90": self.inside, "converged": self.converged,
                "below_optimum": self.below_optimum}


def profile_deviance(problem: Problem, ls: LeastSquaresResult, values: dict,
                     max_nfev: int = JOINT_NFEV) -> JointTest:
    """W of the coefficient values ``values`` (module docstring).

    Parameters
    ----------
    problem : Problem
    ls : LeastSquaresResult
        The least-squares optimum θ̂ (the lowest point: the one the profile paths went through), its noise
        scales and covariance.
    values : dict
        {coefficient name: value}, in the coefficients' units; any subset of ``problem.names[:n_coef]``.
    max_nfev : int
        Evaluation budget of the conditional fit.

    Returns
    -------
    JointTest
    """
    coef = list(problem.names[:problem.n_coef])
    unknown = sorted(set(values) - set(coef))
    if unknown or not values:
        raise ValueError(f"a joint test holds coefficients of the model ({', '.join(coef)}); given "
                         f"{', '.join(unknown) or 'none'}")
    held = np.array([coef.index(n) for n in values])
    res = conditional_optimum(problem, ls, np.array([float(values[n]) for n in values]), held, max_nfev=max_nfev)
    deviance = 2.0 * (float(whitened_costs(res.x, problem, ls.sigma)[0]) - float(ls.cost))
    return JointTest({n: float(v) for n, v in values.items()}, deviance, res.status > 0, np.asarray(res.x))


def literature_tests(problem: Problem, ls: LeastSquaresResult, sets: dict | None = None) -> dict[str, JointTest]:
    """Every published set (:data:`bayes_disc.physics.constants.LITERATURE`) tested on the coefficients it gives.

    Parameters
    ----------
    problem : Problem
    ls : LeastSquaresResult
        The least-squares optimum.
    sets : dict, optional
        {key: {coefficient name: value}} to test instead of the published sets.

    Returns
    -------
    dict
        {set key: JointTest}; a set that gives none of the model's coefficients is left out.
    """
    coef = set(problem.names[:problem.n_coef])
    sets = {key: lit.values for key, lit in LITERATURE.items()} if sets is None else sets
    out = {}
    for key, given in sets.items():
        values = {n: v for n, v in given.items() if n in coef}
        if values:
            out[key] = profile_deviance(problem, ls, values)
    return out


def literature_tests_through_lowest(problem: Problem, ls: LeastSquaresResult, max_nfev: int = 200,
                                    sets: dict | None = None, on_refit: Callable | None = None
                                    ) -> tuple[dict[str, JointTest], LeastSquaresResult]:
    """:func:`literature_tests`, after refitting the least squares from the conditional optimum of any set whose
    held values fit better than the optimum (the lowest such set first; at most
    :data:`.profile.MAX_LOWER_REFITS` refits, after which a set may still be below: :attr:`JointTest.below_optimum`).

    Parameters
    ----------
    problem : Problem
    ls : LeastSquaresResult
        The least-squares optimum found before.
    max_nfev : int
        Evaluation budget of each refinement round of a refit.
    sets : dict, optional
        As in :func:`literature_tests`.
    on_refit : callable, optional
        Called as ``on_refit(key, test, ls)`` after each refit: the set, its test against the earlier optimum
        and the new result.

    Returns
    -------
    tests : dict
        {set key: JointTest} against the returned optimum.
    ls : LeastSquaresResult
        ``ls`` itself, or its last refit (``lower_optima`` records each, with ``joint_test``: the set's key).
    """
    for attempt in range(MAX_LOWER_REFITS + 1):
        tests = literature_tests(problem, ls, sets)
        below = {k: t for k, t in tests.items() if t.below_optimum}
        if not below or attempt == MAX_LOWER_REFITS:
            return tests, ls
        key, test = min(below.items(), key=lambda kt: kt[1].deviance)
        ls = refit_from_lower(problem, ls, test.x, max_nfev=max_nfev,
                              found={"joint_test": key, "deviance": float(test.deviance)})
        if on_refit is not None:
            on_refit(key, test, ls)
    raise AssertionError("unreachable: the last attempt returns")
