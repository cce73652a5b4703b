"""Joint least squares over all flights (the MAP with the noise scales held fixed): several starts,
best kept, then Gauss–Newton (Cramér–Rao) covariance and condition number. Seeds the sampler.

The minimiser (:func:`minimise`) is Levenberg–Marquardt on the block-arrow normal equations
(:mod:`.arrow`): each flight's initial conditions are eliminated by a Schur complement, so a step costs
time and memory linear in the number of flights. The dense forms (:func:`whitened_jacobian`,
:func:`covariance_from_jacobian`) remain for small problems (one flight, a learned correction's design)."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ...physics import literature_coefficients
from .arrow import ArrowJacobian
from .fit_checks import check_fit_plausible
from ..model.problem import Problem

FAILED_RESIDUAL = 1e3  # whitened residual standing in for a failed simulation


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

    def noise(self) -> dict:
        """{sigma name: {"value", "unit"}}: every noise group's residual RMS at the optimum."""
        return {n: {"value": float(s), "unit": u} for n, s, u in zip(self.sigma_names, self.sigma, self.sigma_units)}

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


def _steps(problem: Problem, x: np.ndarray) -> np.ndarray:
    """Finite-difference steps: 1e-4 of each parameter's prior scale (shrunk where the residuals are not
    linear over it: :func:`jacobian_blocks`)."""
    return 1e-4 * problem.prior_sd


#: a Jacobian column is recomputed with a step ten times smaller while its one-sided differences disagree by
#: more than this share of their mean: |d⁺ − d⁻| > NONLINEARITY_MAX · |d⁺ + d⁻|/2 (central differences are
#: then off by a comparable share; on the inertial logs of runs/flatball CRr's default step was 138 of its
#: conditional sds, the gradient pointed uphill and least squares stalled with lower costs within reach)
NONLINEARITY_MAX = 0.05
#: at most this many tenfold reductions of a column's step
STEP_REDUCTIONS = 4


def _flight_columns(x: np.ndarray, problem: Problem, sigma: np.ndarray, k: int, cols: np.ndarray,
                    h: np.ndarray, centre: np.ndarray | None = None):
    """Flight k's whitened residual derivatives along θ columns ``cols`` (c,) with steps ``h`` (c,).

    Parameters
    ----------
    centre : (n_k,) array, optional
        Flight k's effective residuals at x; if None they are simulated in the same batch (one more lane).

    Returns
    -------
    d : (c, n_k) array
        Central differences (a column whose lanes' simulation failed is zero).
    bend, slope : (c,) arrays
        |d⁺ − d⁻|² and |d⁺ + d⁻|²/4 summed over the rows, d± the one-sided differences (zero for a failed
        column, or where the centre's simulation failed).
    centre : (n_k,) array or None
        The residuals at x (None if that simulation failed).
    """
    w = sigma[problem.residual_groups(k)]
    if cols.size == 0:
        return np.zeros((0, w.size)), np.zeros(0), np.zeros(0), centre
    lanes = np.repeat(x[None], 2 * cols.size + (centre is None), axis=0)
    lanes[np.arange(cols.size), cols] += h
    lanes[cols.size + np.arange(cols.size), cols] -= h
    r, ok = problem.noise_residuals(lanes, k)
    if centre is None:
        centre = r[-1] if ok[-1] else None
    plus, minus = r[: cols.size], r[cols.size: 2 * cols.size]
    good = ok[: cols.size] & ok[cols.size: 2 * cols.size]
    d = (plus - minus) / (2 * h)[:, None] / w
    d[~good] = 0.0
    bend, slope = np.zeros(cols.size), np.zeros(cols.size)
    if centre is not None:
        dp, dm = (plus - centre) / w, (centre - minus) / w
        bend[good] = np.sum((dp - dm)[good] ** 2, axis=1)
        slope[good] = np.sum((0.5 * (dp + dm))[good] ** 2, axis=1)
    return d, bend, slope, centre


def _flight_whitened(X: np.ndarray, problem: Problem, sigma: np.ndarray, k: int) -> np.ndarray:
    """Flight k's whitened effective residuals (B, n_k) of the points X (B, dim), one batched simulation; a
    point whose simulation failed (or gave a non-finite residual) has every residual FAILED_RESIDUAL."""
    r, ok = problem.noise_residuals(X, k)
    r = r / sigma[problem.residual_groups(k)]
    good = ok & np.all(np.isfinite(r), axis=1)
    return np.where(good[:, None], r, FAILED_RESIDUAL)


def flight_residuals(x: np.ndarray, problem: Problem, sigma: np.ndarray) -> list[np.ndarray]:
    """Every flight's whitened effective residuals (n_k,) at x (FAILED_RESIDUAL where its simulation failed)."""
    return [_flight_whitened(x[None], problem, sigma, k)[0] for k in range(problem.n_flights)]


def whitened_costs(X: np.ndarray, problem: Problem, sigma: np.ndarray) -> np.ndarray:
    """½ |whitened residuals|² of several points at once: one batched simulation per flight.

    Parameters
    ----------
    X : (B, dim) array
        Points.
    problem : Problem
    sigma : (n_groups,) array
        Noise scale per group.

    Returns
    -------
    (B,) array
        Each point's ½ Σ r² of :func:`whitened_residuals` (a flight whose simulation failed counts its
        residuals as FAILED_RESIDUAL).
    """
    X = np.atleast_2d(X)
    out = 0.5 * np.sum(np.square((X - problem.prior_mean) / problem.prior_sd), axis=1)
    for k in range(problem.n_flights):
        out += 0.5 * np.sum(np.square(_flight_whitened(X, problem, sigma, k)), axis=1)
    return out


def whitened_residuals(x: np.ndarray, problem: Problem, sigma: np.ndarray) -> np.ndarray:
    """Every flight's effective residuals (:meth:`Problem.noise_residuals`) divided by their group's σ, then
    the prior's standardised deviations: ½ |·|² is the negative log-posterior with σ fixed."""
    return np.concatenate(flight_residuals(x, problem, sigma) + [(x - problem.prior_mean) / problem.prior_sd])


def jacobian_blocks(x: np.ndarray, problem: Problem, sigma: np.ndarray, free: np.ndarray | None = None) -> ArrowJacobian:
    """The whitened Jacobian in block-arrow form (:mod:`.arrow`) over the ``free`` parameters (default:
    all): central differences, one batched simulation per flight (2 lanes per free parameter it depends on,
    and one at x).

    Steps start at :func:`_steps`; a column whose one-sided differences disagree by more than
    :data:`NONLINEARITY_MAX` of their mean (summed over the flights) is recomputed with a step ten times
    smaller, at most :data:`STEP_REDUCTIONS` times: a parameter the data pin down to far less than its
    prior scale (CRr on the inertial logs: 7·10⁻⁹ against a 10⁻⁶ step) then still gets a derivative, not a
    secant across a bend. Where no column bends the result is the plain central difference.

    Parameters
    ----------
    x : (dim,) array
        Where.
    problem : Problem
    sigma : (n_groups,) array
        Noise scale per group.
    free : (dim,) bool array, optional
        Parameters that are unknowns; the unknowns are numbered in θ order among the free ones.

    Returns
    -------
    ArrowJacobian
        Shared unknowns: the free entries before the first flight's; block k: flight k's free entries.
    """
    free = np.ones(x.size, bool) if free is None else np.asarray(free, bool)
    position = np.cumsum(free) - 1                  # θ index -> unknown index
    h = _steps(problem, x).copy()
    shared_cols = np.flatnonzero(free[: problem.ic_start])
    cols = [np.r_[shared_cols, problem.layout.flight_slice(k).start + np.flatnonzero(free[problem.layout.flight_slice(k)])]
            for k in range(problem.n_flights)]
    blocks, centres, bend, slope = [], [], np.zeros(x.size), np.zeros(x.size)
    for k in range(problem.n_flights):
        d, b, m, centre = _flight_columns(x, problem, sigma, k, cols[k], h[cols[k]])
        blocks.append(d)
        centres.append(centre)
        np.add.at(bend, cols[k], b)
        np.add.at(slope, cols[k], m)
    # columns whose residuals bend over the step: recompute them (every flight they enter) with smaller steps
    for _ in range(STEP_REDUCTIONS):
        bent = np.flatnonzero(np.sqrt(bend) > NONLINEARITY_MAX * np.sqrt(slope))
        if bent.size == 0:
            break
        h[bent] /= 10.0
        bend[bent], slope[bent] = 0.0, 0.0
        for k in range(problem.n_flights):
            redo = np.flatnonzero(np.isin(cols[k], bent))
            if redo.size == 0 or centres[k] is None:
                continue
            d, b, m, _ = _flight_columns(x, problem, sigma, k, cols[k][redo], h[cols[k][redo]], centres[k])
            blocks[k][redo] = d
            np.add.at(bend, cols[k][redo], b)
            np.add.at(slope, cols[k][redo], m)
    own = [position[c[shared_cols.size:]] for c in cols]
    return ArrowJacobian(shared=position[shared_cols], own=tuple(own),
                         blocks=tuple(np.ascontiguousarray(d.T) for d in blocks), prior=1.0 / problem.prior_sd[free])


def whitened_jacobian(x: np.ndarray, problem: Problem, sigma: np.ndarray, free: np.ndarray | None = None) -> np.ndarray:
    """The dense whitened Jacobian (data rows, then one prior row per parameter), for small problems:
    :func:`jacobian_blocks` scattered into a matrix; with ``free`` (dim,) bool, the columns of held
    parameters are zero (not computed)."""
    free_mask = np.ones(x.size, bool) if free is None else np.asarray(free, bool)
    Jf = jacobian_blocks(x, problem, sigma, free_mask).dense()
    J = np.zeros((Jf.shape[0] - int(free_mask.sum()) + x.size, x.size))
    n_data = Jf.shape[0] - int(free_mask.sum())
    J[:n_data, free_mask] = Jf[:n_data]
    J[n_data:] = np.diag(1.0 / problem.prior_sd)
    return J


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
#: takes several Jacobians to fall below them (Nielsen's rule: at most ×1/3 per step). Profile fits took 4.2
#: and 6.6 Jacobians each at 4 and 24 flights with 10⁻³, 3.0 and 3.1 with 10⁻⁶, and ended closer to the
#: constrained optimum (``benchmarks/bench_profile_fits.py``).
MU_NEAR = 1e-6


def minimise(problem: Problem, x0: np.ndarray, sigma: np.ndarray, free: np.ndarray | None = None,
             max_nfev: int = 200, xtol: float = 1e-10, ftol: float = 1e-10, mu0: float = MU_FAR,
             dtol: float = 0.0, keep_jacobian: bool = False, line_search: bool = False,
             final_step: float = 0.0) -> Minimum:
    """Levenberg–Marquardt on ½ |whitened residuals|² with the block-arrow normal equations (:mod:`.arrow`):
    every step costs one Jacobian (one batched simulation per flight) and a Schur solve, both linear in the
    number of flights.

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


def covariance_at(J: ArrowJacobian, free: np.ndarray) -> np.ndarray:
    """(dim, dim) Gauss–Newton covariance (JᵀJ)⁻¹ from a block Jacobian over the ``free`` parameters (held
    parameters' rows and columns zero)."""
    cov = np.zeros((free.size, free.size))
    cov[np.ix_(free, free)] = J.information().inverse()
    return cov


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
                              sigma_names=list(problem.sigma_names), sigma_units=list(problem.noise_units))


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


