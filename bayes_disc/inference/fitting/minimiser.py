"""The minimiser: Levenberg–Marquardt on the block-arrow normal equations (:mod:`.arrow`), each flight's initial
conditions eliminated by a Schur complement, so that a step costs time and memory linear in the number of
flights; with a step-length search along a step that gained less than predicted.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .arrow import ArrowJacobian
from ..model.problem import Problem
from .residuals import flight_residuals, jacobian_blocks


@dataclass
class Minimum:
    """A Levenberg–Marquardt optimum of the whitened objective (:func:`minimise`)."""

    x: np.ndarray            # (dim,) optimum (held entries as given)
    cost: float              # ½ Σ whitened residual² (prior included)
    nfev: int                # residual evaluations
    njev: int                # Jacobian evaluations
    status: int              # > 0 converged (1 gradient, 2 step, 3 cost, 4 decrement, 5 final step), 0 budget
                             # spent, −1 no descent
    message: str
    jacobian: ArrowJacobian | None = None   # over every parameter, the last computed (``keep_jacobian``)
    jacobian_x: np.ndarray | None = None    # (dim,) where it was computed: x, or one accepted step before it


#: Levenberg–Marquardt's stopping rule on the gradient: max |g_i · sd_i| (scale-free)
GTOL = 1e-10
#: Levenberg–Marquardt's initial damping μ₀ (relative to diag H, i.e. on the unit-diagonal scaled matrix) from a
#: start that may be far from the optimum. Madsen, Nielsen & Tingleff (2004, "Methods for non-linear least
#: squares problems", §3.2) advise μ₀ = τ · max diag, τ = 10⁻⁶ if x₀ is believed to be a good approximation
#: of the optimum, else 10⁻³ or even 1.
MU_FAR = 1e-3
#: μ₀ from a start next to an optimum (a profile point's conditional start, a converged fit refined with new
#: noise scales). The scaled information matrix has eigenvalues down to 2·10⁻⁶ along the ridges of the
#: synthetic benchmark (4 and 24 flights), so μ₀ = 10⁻³ damps the first steps along them ~500-fold, and μ
#: takes several Jacobians to fall below them (Nielsen's rule: at most ×1/3 per step): a fit started next to
#: its optimum (a profile fit) starts with μ₀ = 10⁻⁶, which needs fewer Jacobians and ends closer to the
#: constrained optimum.
MU_NEAR = 1e-6


def minimise(problem: Problem, x0: np.ndarray, sigma: np.ndarray, free: np.ndarray | None = None,
             max_nfev: int = 200, xtol: float = 1e-10, ftol: float = 1e-10, mu0: float = MU_FAR,
             dtol: float = 0.0, keep_jacobian: bool = False, line_search: bool = False,
             final_step: float = 0.0) -> Minimum:
    """Levenberg–Marquardt on ½ |whitened residuals|² with the block-arrow normal equations (:mod:`.arrow`):
    every step costs one Jacobian (one batched simulation per flight) and a Schur solve, both linear in the
    number of flights.

    Long: one Levenberg–Marquardt loop whose stopping rules share its state (x, μ, ν, the last Jacobian).

    Damping: (H + μ diag H) δ = −g, μ starting at ``mu0`` and updated by Nielsen's rule (× max(1/3,
    1 − (2ρ − 1)³) after a step with gain ratio ρ > 0; × ν, ν doubling, after a rejected one). With
    ``line_search``, where the cost at the full step shows the quadratic model mis-scaled along it, the cost
    is also evaluated at the parabola's minimum α*δ along the step (:func:`step_length`), and the lower point
    taken. Stops when
    the step is below ``xtol`` (relative, in prior-sd units), when an accepted step lowers the cost by less
    than ``ftol`` of it (with ρ > 1/4), when the scale-free gradient is below :data:`GTOL`, when the
    Gauss–Newton decrement ½ gᵀH⁻¹g (what the quadratic model still expects to gain) is at most ``dtol``, after
    one more step from a Jacobian whose decrement was at most ``final_step`` (if that step's gain matches the
    model's prediction to within ``dtol``), or after ``max_nfev`` residual evaluations.

    Parameters
    ----------
    problem : Problem
    x0 : (dim,) array
        Start.
    sigma : (n_groups,) array
        Noise scale per group, held fixed.
    free : (dim,) bool array, optional
        Parameters optimised (default: all); the others stay at their ``x0`` values.
    max_nfev : int
        Budget of residual evaluations.
    xtol, ftol : float
        Tolerances on the step and on the cost's decrease.
    mu0 : float
        Initial damping μ₀: :data:`MU_FAR` from a start that may be far from the optimum, :data:`MU_NEAR`
        from one next to it.
    dtol : float
        Tolerance on the Gauss–Newton decrement (units of the cost, ½ χ²); 0 (default): not used.
    keep_jacobian : bool
        Compute every Jacobian over all parameters (the held ones too: two more lanes per held column and
        flight) and solve with its ``free`` columns (:meth:`.arrow.ArrowJacobian.select`), so that the
        result carries the last Jacobian computed (``Minimum.jacobian``, at ``Minimum.jacobian_x``): at the
        fit's point, or one small step before it where the fit stopped on an accepted step (status 3: a
        gain below ``ftol``; status 5: the final step). A caller that needs the local covariance (a profile
        point) is spared one Jacobian.
    final_step : float
        Decrement (units of the cost) at or below which one more step ends the fit (status 5) without a
        Jacobian at its end, if the cost it gains is within ``dtol`` of the gain the model predicted (else
        the fit goes on as usual); 0 (default): not used; ignored unless ``dtol`` > 0. Where Gauss–Newton
        converges linearly (the residual curvature Σ r ∇²r it drops is large: profile fits on 24 flights,
        decrements falling ×0.3–0.6 per Jacobian), each further step costs a Jacobian for a gain below the
        digits the caller reads; the final step costs one residual evaluation.
    line_search : bool
        Correct the length of steps the model mis-scales (:func:`step_length`): for fits started next to an
        optimum, whose tail it shortens. Off by default: from a far start it changes the path, and with it
        which local optimum is reached (the two-flight problem of tests/test_arrow.py: 208.56 instead of
        207.99, each a true optimum).

    Returns
    -------
    Minimum
    """
    free = np.ones(x0.size, bool) if free is None else np.asarray(free, bool)
    x = np.asarray(x0, float).copy()
    sd = problem.prior_sd[free]

    def evaluate(z):
        parts = flight_residuals(z, problem, sigma)
        prior = (z - problem.prior_mean) / problem.prior_sd
        return parts, prior, 0.5 * float(sum(p @ p for p in parts) + prior @ prior)

    parts, prior, cost = evaluate(x)
    nfev, njev, mu, nu = 1, 0, float(mu0), 2.0
    status, message = 0, "evaluation budget spent"
    J = J_all = J_x = None
    while True:
        finishing = False
        if J is None:
            if keep_jacobian:
                J_all = jacobian_blocks(x, problem, sigma)
                J = J_all.select(free)
            else:
                J = jacobian_blocks(x, problem, sigma, free)
            J_x = x
            njev += 1
            H = J.information()
            g = J.gradient(parts, prior[free])
            if np.max(np.abs(g * sd), initial=0.0) < GTOL:
                status, message = 1, "gradient below tolerance"
                break
            if dtol > 0.0:
                gain = decrement(H, g)
                if gain <= dtol:
                    status, message = 4, "decrement below tolerance"
                    break
                finishing = gain <= final_step
        if nfev >= max_nfev:
            break
        try:
            step = H.solve(-g, mu)
        except np.linalg.LinAlgError:
            mu, nu = mu * nu, nu * 2
            if mu > 1e16:
                status, message = -1, "no positive-definite damped system"
                break
            continue
        if np.linalg.norm(step / sd) <= xtol * (np.linalg.norm(x[free] / sd) + xtol):
            status, message = 2, "step below tolerance"
            break
        trial = x.copy()
        trial[free] += step
        t_parts, t_prior, t_cost = evaluate(trial)
        nfev += 1
        predicted = 0.5 * float(-g @ step + mu * step @ (H.diagonal() * step))
        rho = (cost - t_cost) / predicted if predicted > 0 else -1.0
        length = step_length(cost, t_cost, float(g @ step)) if line_search and np.isfinite(t_cost) else None
        full = True                                # the trial point is the full step (its gain: ``predicted``)
        if length is not None:
            other = x.copy()
            other[free] += length * step
            o_parts, o_prior, o_cost = evaluate(other)
            nfev += 1
            if np.isfinite(o_cost) and o_cost < min(t_cost, cost):
                trial, t_parts, t_prior, t_cost = other, o_parts, o_prior, o_cost
                rho, full = max(rho, RHO_FLOOR), False   # μ still follows the full step's gain ratio
        if np.isfinite(t_cost) and rho > 0:
            small = cost - t_cost <= ftol * cost and rho > 0.25
            last = finishing and full and abs(cost - t_cost - predicted) <= dtol
            x, parts, prior, cost = trial, t_parts, t_prior, t_cost
            mu, nu = mu * max(1 / 3, 1 - (2 * rho - 1) ** 3), 2.0
            if small or last:
                status, message = (3, "cost decrease below tolerance") if small else (5, "final Gauss–Newton step")
                break
            J = None
        else:
            mu, nu = mu * nu, nu * 2
            if mu > 1e16:
                status, message = -1, "no step lowers the cost"
                break
    return Minimum(x=x, cost=cost, nfev=nfev, njev=njev, status=status, message=message, jacobian=J_all,
                   jacobian_x=J_x if J_all is not None else None)


#: bounds of the step-length factor of :func:`step_length`
STEP_LENGTH_BOUNDS = (0.1, 4.0)
#: :func:`step_length` proposes a factor only when it differs from 1 by more than this
STEP_LENGTH_TRIGGER = 0.25
#: the gain ratio credited to a step whose full length did not lower the cost but a shorter one did (Nielsen's
#: rule then roughly doubles μ, as after a poor step)
RHO_FLOOR = 1e-3


def step_length(cost: float, trial_cost: float, slope: float) -> float | None:
    """The factor α on a Levenberg–Marquardt step δ that minimises the parabola through the cost along it,

        f(α) = f(0) + α f'(0) + α² c,   c = f(1) − f(0) − f'(0),   α* = −f'(0) / (2c),

    with f(0) = ``cost``, f(1) = ``trial_cost`` and f'(0) = gᵀδ = ``slope``; None for a step that is not a
    descent direction or where α* is within :data:`STEP_LENGTH_TRIGGER` of 1 (the step is fine as it is); the
    upper bound where c ≤ 0 (the cost falls at least linearly along the step).

    Gauss–Newton drops the curvature Σ r_i ∇²r_i. Where that is large along the ridges of a joint fit, the full
    step lands far from the minimum along its own line: on bench_scale's 24-flight data of seed 19, the
    refinement's steps had gain ratios of 0.03–0.3 for 20 Jacobians (the curvature along them about twice the
    model's) and of 1.3–1.4 before that (each step going ~70 % of the way). One more residual evaluation (one
    lane per flight, ~1/45 of a Jacobian) at α* then does what the model could not: that refinement took 20
    Jacobians instead of 38, to the same optimum. α* is clipped to :data:`STEP_LENGTH_BOUNDS`.

    Parameters
    ----------
    cost, trial_cost : float
        ½ χ² at the current point and at the full step.
    slope : float
        Directional derivative gᵀδ of the cost along the step (< 0 for a descent step).

    Returns
    -------
    float or None
    """
    curvature = trial_cost - cost - slope
    if not slope < 0:
        return None
    if curvature <= 0:                      # the cost falls at least linearly along the step: the longest
        return STEP_LENGTH_BOUNDS[1]
    alpha = min(max(-slope / (2.0 * curvature), STEP_LENGTH_BOUNDS[0]), STEP_LENGTH_BOUNDS[1])
    return alpha if abs(alpha - 1.0) > STEP_LENGTH_TRIGGER else None


def decrement(H, g: np.ndarray) -> float:
    """The Gauss–Newton decrement ½ gᵀH⁻¹g: the cost decrease the quadratic model predicts for its full step
    (∞ where H is not positive definite).

    Parameters
    ----------
    H : ArrowMatrix
        Gauss–Newton information JᵀJ over the n unknowns.
    g : (n,) array
        Gradient Jᵀr.

    Returns
    -------
    float
    """
    try:
        return 0.5 * float(g @ H.solve(g))
    except np.linalg.LinAlgError:
        return np.inf
