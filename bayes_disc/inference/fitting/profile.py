"""Profile-likelihood paths of single parameters through the least-squares optimum.

For a parameter θ_i held at values stepping away from the optimum θ̂, every other parameter is
re-optimised (the same whitened least-squares objective and block-arrow Levenberg–Marquardt as
:mod:`.leastsq`, noise scales fixed at their least-squares values):

    θ*(v) = argmin_{θ: θ_i = v} ½ Σ_f |r_f(θ)/σ_f|² + ½ |(θ − μ_prior)/sd_prior|²,
    deviance D(v) = 2 [cost(θ*(v)) − cost(θ̂)]        (χ²₁-like; D = t² for a Gaussian posterior)

The path θ*(v) follows the posterior's ridge: where the posterior is a thin curved valley (a weakly
identified combination such as CM0 + CMq·q̄ with the flights' wobble initial conditions), the Laplace
approximation at θ̂ is far too narrow and the path shows where the mass really lies. At every point the
local Gauss–Newton covariance is kept, so the path can seed a ridge proposal for the sampler
(:mod:`.sampler`) and profile verdicts for identifiability.

Where the valley widens along the path, the posterior's marginal of θ_i is not the profile likelihood
but the Laplace marginal along it,

    ln g(v) = −D(v)/2 + ½ ln|S(v)| + const,     S(v) = Cov(θ_−i | θ_i = v) of the local covariance,

which can keep rising while D does (24 synthetic flights: the marginal of CMq has its median where D ≈ 13
and 5 % of its mass beyond the end of a path that stopped at D = 18). A side therefore goes on past
``max_deviance`` while ln g has fallen by less than ``max_deviance``/2 from its highest value on that side
(at most :data:`EXTENDED_POINTS` points; :func:`side_done`), so that the ridge proposal built on it covers
the marginal's mass. The same holds where the profile stays flat but ln g rises (the valley widens faster
than the deviance grows): a flat side goes on past :data:`MAX_POINTS` once ln g has risen by more than
:data:`MARGINAL_RISE` along it, until it has fallen by ``max_deviance``/2 from its best.

A path that reaches a lower cost than θ̂ (deviance below −:data:`LOWER_OPTIMUM_DEVIANCE`) shows θ̂ not to be the
lowest point (a local optimum, or a fit that stopped short of it); :func:`profile_paths` can then stop
(:class:`LowerOptimum`) so that the least squares are refitted from that point and the paths start again
(:func:`profiles_through_lowest`).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from ...physics.parallel import mp_context
from .arrow import ArrowJacobian
from .minimiser import MU_NEAR, minimise
from .leastsq import LeastSquaresResult, refit_from_lower
from .residuals import jacobian_blocks, whitened_costs
from ..model.problem import Problem

#: the path stops past this profile deviance (≈ 3.5 σ for a Gaussian)
MAX_DEVIANCE = 12.0
#: at most this many points on each side of the optimum where the profile is flat (deviance ≤ MAX_DEVIANCE)
MAX_POINTS = 6
#: at most this many points on a side that goes on because the Laplace marginal ln g has not yet fallen
EXTENDED_POINTS = 12
#: a flat side (deviance ≤ MAX_DEVIANCE) goes on past MAX_POINTS when ln g has risen by more than this along
#: it: the marginal's mass lies away from the optimum (12 synthetic flights, seed 19 of ``bench_scale.py``: CMq's
#: profile deviance 2.7 after six points on its low side while ln g rose by 36, the walkers 11 Laplace sds out)
MARGINAL_RISE = 1.0
#: a profile fit stops when a step lowers the deviance by less than this (the deviances are read to ~0.01; the
#: relative tolerance of a full fit would spend the evaluation budget on digits no verdict uses)
DEVIANCE_TOL = 1e-3
#: a profile fit also stops once the Gauss–Newton decrement ½ gᵀH⁻¹g is at most this (cost units), on the point
#: whose Jacobian it has just computed, which then gives the point's covariance. The decrement is the quadratic
#: model's one-step gain and falls short of what a slow ridge still holds: a quarter of DEVIANCE_TOL keeps the
#: points of a 24-flight campaign within DEVIANCE_TOL of a tight refit
DECREMENT_TOL = 0.25 * DEVIANCE_TOL
#: a profile fit whose Gauss–Newton decrement is at most this (cost units; deviance 5·10⁻³) takes one more step
#: and stops there if the step gains what the model predicted, to DECREMENT_TOL (:func:`.minimiser.minimise`'s
#: ``final_step``); the point's covariance then comes from the Jacobian one step before it. With many flights the
#: Gauss–Newton iteration converges linearly near a profile point (decrements ×0.3–0.6 per Jacobian on 24 flights,
#: ×10⁻³ on 4: the residual curvature it drops grows with the ridges), so the last Jacobians bought digits no
#: verdict reads; the deviances then fall short of a tight refit by at most a few 10⁻³, and the covariance one step
#: away differs by under 1 % in its sds.
FINAL_DECREMENT = 10.0 * DECREMENT_TOL
#: a point whose deviance exceeds this multiple of the stopping deviance is a failed fit or a cliff: it
#: still bounds the profile but is not ``ok`` (not used as a posterior approximation)
FAILED_DEVIANCE_FACTOR = 4.0
#: a point whose deviance is below −LOWER_OPTIMUM_DEVIANCE has a lower cost than the least-squares optimum the
#: paths start from (the profile fits are accurate to ~10⁻³, the optimum's refinement to 10⁻⁵): that optimum was
#: not the lowest point (a local optimum, or a fit that stopped short of it), and the side stops there
#: (:class:`LowerOptimum`). On seed 19's 12 flights of ``benchmarks/bench_scale.py`` the least squares ended in a
#: mode 2.0 deviance units above another (CM0, CMa, CMq 2.9, 2.1, 3.0 Laplace sds away; the straight line
#: between the two crosses a barrier of D ≈ 360), which the profiles of CM0 (D = −0.62 at t = −1.8) and CMa
#: (D = −1.95 at t = +1.8) reach along the ridge. From the local optimum five profile fits crawled toward it to
#: their budget, 673 Jacobians in all; from the lower one, 366 and none at its budget. On the real throws of
#: runs/flatball, imu_offset_z's profile reached D = −0.16 at t = −1 (a refinement that had stopped short)
LOWER_OPTIMUM_DEVIANCE = 0.1


#: least-squares refits from a lower point a profile found (:func:`profiles_through_lowest`) before the paths are
#: taken as they come
MAX_LOWER_REFITS = 2


class LowerOptimum(Exception):
    """A profile fit found a point below the least-squares optimum the paths started from
    (:func:`profile_paths` with ``stop_on_lower``): the least squares should be refitted from ``point.theta``.

    Attributes
    ----------
    name : str
        The profiled parameter.
    point : ProfilePoint
        The lowest point of that side (deviance < −:data:`LOWER_OPTIMUM_DEVIANCE`).
    """

    def __init__(self, name: str, point: "ProfilePoint"):
        super().__init__(f"the profile of {name} reached below the least-squares optimum "
                         f"(deviance {point.deviance:.2f} at t = {point.t:+.2f})")
        self.name, self.point = name, point


@dataclass
class ProfilePoint:
    """One point of a profile path: θ_i = ``value``, the other parameters optimised."""

    value: float
    theta: np.ndarray      # (dim,) constrained optimum
    deviance: float        # 2 Δcost relative to the least-squares optimum
    cov: np.ndarray        # (dim, dim) local Gauss–Newton covariance at ``theta``
    t: float               # (value − θ̂_i) / sd_i, sd_i the Laplace sd at the optimum
    ok: bool = True


@dataclass
class ProfileSide:
    """One side of a profile path (:func:`profile_side`): its points, moving away from θ̂, and the work of
    every fit on it, a failed last fit included."""

    points: list           # ProfilePoint, in the order they were fitted (the optimum not among them)
    njev: int = 0          # Jacobians (each one batched simulation per flight)
    nfev: int = 0          # residual evaluations (each one simulation per flight), the fits' batched starts included


@dataclass
class ProfilePath:
    """Profile of parameter ``index`` (``name``): points sorted by value, the optimum included (t = 0)."""

    index: int
    name: str
    points: list
    njev: int = 0          # Jacobians of its fits, both sides (:class:`ProfileSide`)
    nfev: int = 0          # their residual evaluations

    @property
    def t(self) -> np.ndarray:
        return np.array([p.t for p in self.points])

    @property
    def deviance(self) -> np.ndarray:
        return np.array([p.deviance for p in self.points])

    def gaussian_misfit(self) -> float:
        """Largest departure from a Gaussian profile over the path's ``ok`` points: max |D − t²| / (1 + t²/4)
        (0 for an exactly Gaussian posterior; > 1 when the Laplace approximation misleads)."""
        ok = np.array([p.ok for p in self.points], bool)
        t, D = self.t[ok], self.deviance[ok]
        return float(np.max(np.abs(D - t * t) / (1.0 + t * t / 4.0))) if t.size else 0.0

    def halfwidth(self, level: float = 1.0) -> float:
        """Half the distance between the values where the deviance crosses ``level`` on either side (linear
        interpolation of √D; the outermost point where a side never crosses): the profile's "1 σ" for
        level 1, which a curved or flat-topped posterior makes wider than the Laplace sd."""
        v, D = np.array([p.value for p in self.points]), self.deviance
        c = int(np.argmin(D))
        ends = []
        for side in (1, -1):
            j = c
            while 0 <= j + side < v.size and D[j + side] < level:
                j += side
            if 0 <= j + side < v.size:
                a, b = np.sqrt(max(D[j], 0.0)), np.sqrt(D[j + side])
                f = (np.sqrt(level) - a) / (b - a) if b > a else 1.0
                ends.append(v[j] + f * (v[j + side] - v[j]))
            else:
                ends.append(v[j])
        return float(abs(ends[0] - ends[1]) / 2)

    def classify(self, threshold: float = 3.84) -> str:
        """``bounded`` (deviance exceeds ``threshold`` on both sides), ``one-sided`` or ``flat``."""
        t, D = self.t, self.deviance
        up = bool(np.any(D[t > 0] > threshold))
        down = bool(np.any(D[t < 0] > threshold))
        return "bounded" if up and down else ("one-sided" if up or down else "flat")


def conditional_log_volume(cov: np.ndarray, index: int) -> float:
    """½ ln|S|, S = Cov(θ_−i | θ_i) = Σ_−i,−i − Σ_−i,i Σ_i,−i / Σ_ii: the Laplace marginal's volume term,
    ½ (ln|Σ| − ln Σ_ii), with the determinant of the correlation matrix (scales from 1e−7 to 1).

    Parameters
    ----------
    cov : (dim, dim) array
        Local Gauss–Newton covariance.
    index : int
        The profiled parameter i.

    Returns
    -------
    float
    """
    d = np.sqrt(np.diag(cov))
    sign, log_det = np.linalg.slogdet(cov / np.outer(d, d))
    if sign <= 0:
        return -np.inf
    return 0.5 * (log_det + 2.0 * np.sum(np.log(d)) - np.log(cov[index, index]))


def side_done(n_points: int, deviance: float, log_g: float, best: float, max_deviance: float = MAX_DEVIANCE,
              max_points: int = MAX_POINTS, extended_points: int = EXTENDED_POINTS) -> bool:
    """Whether a side of a profile path stops after its latest point.

    Parameters
    ----------
    n_points : int
        Points on this side so far, the latest included.
    deviance : float
        The latest point's profile deviance D.
    log_g : float
        The latest point's Laplace marginal ln g = −D/2 + ½ ln|S| (relative to the optimum's).
    best : float
        The highest ln g on this side so far (the optimum's, 0, included).
    max_deviance, max_points, extended_points
        As in :func:`profile_path`.

    Returns
    -------
    bool
        True past ``FAILED_DEVIANCE_FACTOR`` · ``max_deviance`` (a cliff or a failed fit); after
        ``max_points`` points while D ≤ ``max_deviance`` (a flat profile) unless ln g has risen by more
        than :data:`MARGINAL_RISE` on this side (``best``) and not yet fallen by ``max_deviance``/2 from
        it; once D > ``max_deviance`` and ln g < ``best`` − ``max_deviance``/2 (the marginal has fallen
        too); always after max(``max_points``, ``extended_points``).
    """
    if deviance > FAILED_DEVIANCE_FACTOR * max_deviance or n_points >= max(max_points, extended_points):
        return True
    fallen = log_g < best - 0.5 * max_deviance
    if deviance <= max_deviance:
        return n_points >= max_points and (best <= MARGINAL_RISE or fallen)
    return fallen


def conditional_start(x: np.ndarray, cov: np.ndarray, index: int, value: float) -> np.ndarray:
    """Where the other parameters' optimum moves when θ_i moves from x_i to ``value``, to first order: the
    conditional mean of the local Gaussian, x + Σ_·i / Σ_ii · (value − x_i) (θ_i = ``value`` exactly).

    Parameters
    ----------
    x : (dim,) array
        A point of the path (its constrained optimum).
    cov : (dim, dim) array
        The local Gauss–Newton covariance there.
    index : int
        The profiled parameter i.
    value : float
        Its next value.

    Returns
    -------
    (dim,) array
    """
    out = x + cov[:, index] / cov[index, index] * (value - x[index])
    out[index] = value
    return out


def bent_start(x: np.ndarray, cov: np.ndarray, index: int, value: float, miss: np.ndarray,
               ratio: float) -> np.ndarray:
    """:func:`conditional_start` corrected for the path's curvature: the previous step's miss (where that step's
    constrained optimum lay, less its conditional start) scaled by the square of the steps' ratio. A linear
    prediction along a smooth path θ*(v) misses by ½ θ*''(v) h² over a step h, so the last miss m over a step h'
    predicts the next one as m (h/h')²:

        x₀ = x + Σ_·i / Σ_ii · (value − x_i) + m · ratio²,    ratio = h / h'.

    Parameters
    ----------
    x : (dim,) array
        The last point of the path.
    cov : (dim, dim) array
        Its local covariance.
    index : int
        The profiled parameter i.
    value : float
        Its next value.
    miss : (dim,) array
        The last point less the conditional start it was fitted from (zero at i).
    ratio : float
        The next step over the last one.

    Returns
    -------
    (dim,) array
        θ_i = ``value`` exactly.
    """
    out = conditional_start(x, cov, index, value) + miss * ratio ** 2
    out[index] = value
    return out


class FixedFit(NamedTuple):
    """One profile point's fit (:func:`_fixed_fit`)."""

    x: np.ndarray             # (dim,) θ*, the constrained optimum (θ_i = value)
    cost: float               # ½ Σ whitened residual² there
    ok: bool                  # converged
    J: ArrowJacobian | None   # whitened Jacobian over every parameter at θ* or one small step before it
    njev: int                 # Jacobians computed (one batched simulation per flight each)
    nfev: int                 # residual evaluations, the starts' batched one included


def _fixed_fit(problem: Problem, sigma: np.ndarray, x0: np.ndarray, cov0: np.ndarray, index: int, value: float,
               max_nfev: int, cost0: float, mu0: float = MU_NEAR, dtol: float = DECREMENT_TOL,
               bent: np.ndarray | None = None, final: float = FINAL_DECREMENT) -> FixedFit:
    """Optimum of every parameter but ``index`` (held at ``value``) (:class:`FixedFit`), with J the whitened
    Jacobian over every parameter (:class:`.arrow.ArrowJacobian`, for the point's covariance) at θ* or one
    small step before it.

    The fit starts from the best (lowest cost) of x0 with θ_i set to ``value``, :func:`conditional_start`
    (x0, cov0) and, when given, ``bent`` (:func:`bent_start`): the conditional start about halves the
    Jacobians per fit on the campaign benchmark (``benchmarks/bench_scale.py``), the bent one saves about
    another eighth, and the held start guards a curved ridge where the predictions overshoot. The starts are
    next to the constrained optimum, so the fit starts with little damping ``mu0`` (:data:`.minimiser.MU_NEAR`). It stops when the Gauss–Newton decrement (the cost decrease its quadratic model
    still expects) is at most ``dtol`` — the Jacobian there is the point's own, so none is computed twice —;
    after one more step from a decrement at most ``final`` whose gain is as predicted (to ``dtol``); and
    when a step lowers the deviance 2 Δcost by less than :data:`DEVIANCE_TOL` (``cost0``: the optimum's cost,
    which turns it into the minimiser's relative tolerance). In these last two cases J is the fit's last
    Jacobian, one small step before θ* (:data:`FINAL_DECREMENT`). J is None after a failed fit. ``dtol`` = 0:
    the last rule alone, J computed at θ*."""
    free = np.ones(x0.size, bool)
    free[index] = False
    held = x0.copy()
    held[index] = value
    starts = [held, conditional_start(x0, cov0, index, value)] + ([bent] if bent is not None else [])
    x = starts[int(np.argmin(whitened_costs(np.array(starts), problem, sigma)))]
    ftol = 0.5 * DEVIANCE_TOL / max(cost0, 1e-300)
    res = minimise(problem, x, sigma, free=free, max_nfev=max_nfev, ftol=ftol, mu0=mu0, dtol=dtol,
                   keep_jacobian=dtol > 0, final_step=final)
    ok = res.status > 0
    J = None if not ok else res.jacobian if res.jacobian is not None else jacobian_blocks(res.x, problem, sigma)
    njev = res.njev + int(ok and res.jacobian is None)
    return FixedFit(res.x, float(res.cost), ok, J, njev, res.nfev + 1)


def profile_side(problem: Problem, theta_hat: np.ndarray, sigma: np.ndarray, cov_hat: np.ndarray, index: int,
                 side: float, max_deviance: float = MAX_DEVIANCE, max_points: int = MAX_POINTS,
                 max_nfev: int = 40, extended_points: int = EXTENDED_POINTS,
                 mu0: float = MU_NEAR, dtol: float = DECREMENT_TOL,
                 final: float = FINAL_DECREMENT) -> ProfileSide:
    """The points on one side (``side`` = +1: values above θ̂_i, −1: below) of parameter ``index``'s profile
    through the least-squares optimum ``theta_hat`` (noise ``sigma``, covariance ``cov_hat``).

    Steps are one local sd of θ_i (from the local covariance, at least half the optimum's sd), each fit
    started from the previous point moved along its local covariance, corrected for the path's curvature
    from the second point on (:func:`_fixed_fit`, :func:`bent_start`). The side stops
    when a fit fails, past ``FAILED_DEVIANCE_FACTOR`` · ``max_deviance``, after ``max_points`` points while
    the deviance stays below ``max_deviance``, and past ``max_deviance`` once the Laplace marginal ln g
    (module docstring) has fallen by ``max_deviance``/2 from its highest value on that side, or after
    ``extended_points`` points (:func:`side_done`); and at a point below the optimum (deviance
    < −:data:`LOWER_OPTIMUM_DEVIANCE`: θ̂ was not the lowest point). The two sides start from θ̂ and do not
    depend on each other. ``mu0`` is every fit's initial damping (:func:`.minimiser.minimise`), ``dtol`` its
    decrement tolerance (:func:`_fixed_fit`).

    Returns
    -------
    ProfileSide
        The points in the order they were fitted (moving away from θ̂; the optimum itself is not among them)
        and the work of every fit.
    """
    cost0 = float(whitened_costs(theta_hat, problem, sigma)[0])
    sd0 = float(np.sqrt(cov_hat[index, index]))
    volume0 = conditional_log_volume(cov_hat, index)
    out = ProfileSide(points=[])
    x, cov, step, best = theta_hat.copy(), cov_hat, sd0, 0.0
    miss = last_step = None
    for k in range(max(max_points, extended_points)):
        value = float(x[index] + side * step)
        bent = None if miss is None else bent_start(x, cov, index, value, miss, step / last_step)
        fit = _fixed_fit(problem, sigma, x, cov, index, value, max_nfev, cost0, mu0, dtol, bent, final)
        out.njev, out.nfev = out.njev + fit.njev, out.nfev + fit.nfev
        if not (fit.ok and np.isfinite(fit.cost)):
            break
        x_new = fit.x
        miss, last_step = x_new - conditional_start(x, cov, index, value), step
        cov = fit.J.information().inverse()
        dev = 2.0 * (fit.cost - cost0)
        out.points.append(ProfilePoint(value=value, theta=x_new, deviance=dev, cov=cov,
                                       t=(value - theta_hat[index]) / sd0,
                                       ok=dev <= FAILED_DEVIANCE_FACTOR * max_deviance))
        log_g = -0.5 * dev + conditional_log_volume(cov, index) - volume0
        best = max(best, log_g)
        if dev < -LOWER_OPTIMUM_DEVIANCE or side_done(k + 1, dev, log_g, best, max_deviance, max_points,
                                                       extended_points):
            break
        x, step = x_new, max(float(np.sqrt(cov[index, index])), 0.5 * sd0)
    return out


def join_sides(problem: Problem, theta_hat: np.ndarray, cov_hat: np.ndarray, index: int,
               sides: list[ProfileSide]) -> ProfilePath:
    """The profile path of parameter ``index``: the optimum (t = 0) and the points of its sides
    (:func:`profile_side`), sorted by value, with the sides' work."""
    centre = ProfilePoint(value=float(theta_hat[index]), theta=theta_hat.copy(), deviance=0.0, cov=cov_hat, t=0.0)
    points = sorted([centre, *(p for side in sides for p in side.points)], key=lambda p: p.value)
    return ProfilePath(index=index, name=problem.names[index], points=points, njev=sum(s.njev for s in sides),
                       nfev=sum(s.nfev for s in sides))


def profile_path(problem: Problem, theta_hat: np.ndarray, sigma: np.ndarray, cov_hat: np.ndarray, index: int,
                 **kwargs) -> ProfilePath:
    """Profile of parameter ``index`` through the least-squares optimum ``theta_hat``: both sides
    (:func:`profile_side`, whose keyword arguments ``kwargs`` are) joined at the optimum."""
    sides = [profile_side(problem, theta_hat, sigma, cov_hat, index, side, **kwargs) for side in (1.0, -1.0)]
    return join_sides(problem, theta_hat, cov_hat, index, sides)


_POOL: dict = {}


def _init_profile_worker(data: dict) -> None:
    _POOL.update(data)


def _side_task(task: tuple[int, float]) -> ProfileSide:
    a = _POOL
    return profile_side(a["problem"], a["theta"], a["sigma"], a["cov"], task[0], task[1], **a["kwargs"])


def lowest_point(points: list[ProfilePoint]) -> ProfilePoint | None:
    """The lowest point with a deviance below −:data:`LOWER_OPTIMUM_DEVIANCE` (a lower cost than the optimum the
    path started from), or None."""
    below = [p for p in points if p.deviance < -LOWER_OPTIMUM_DEVIANCE]
    return min(below, key=lambda p: p.deviance) if below else None


def ridge_first(cov: np.ndarray, indices) -> list[int]:
    """``indices`` by decreasing variance inflation Σ_ii (Σ⁻¹)_ii (how much the other parameters widen θ_i's
    Laplace sd; the scale-free correlation matrix inverted): the parameters on the posterior's ridges, whose
    sides are the longest and slowest (up to 18 points instead of 4–5, and the crawling fits), come first.

    Parameters
    ----------
    cov : (dim, dim) array
        Gauss–Newton covariance at the optimum (held parameters: zero rows and columns, inflation 0).
    indices : iterable of int
        Parameters to order.

    Returns
    -------
    list of int
        Ties keep the order of ``indices``.
    """
    d = np.sqrt(np.maximum(np.diag(cov), 0.0))
    live = d > 0                                    # held parameters have zero rows and columns
    inflation = np.zeros(d.size)
    inflation[live] = np.diag(np.linalg.inv(cov[np.ix_(live, live)] / np.outer(d[live], d[live])))
    return sorted(indices, key=lambda i: -inflation[i])


def profile_paths(problem: Problem, theta_hat: np.ndarray, sigma: np.ndarray, cov_hat: np.ndarray, indices,
                  processes: int = 1, progress=None, stop_on_lower: bool = False, **kwargs) -> list[ProfilePath]:
    """Profiles of several parameters, in ``processes`` forked worker processes (independent fits).

    Each side of each path is one task (:func:`profile_side`), so that no worker is left waiting on one long
    path (a side that runs on past the deviance limit, :func:`side_done`, is up to 12 fits). The paths are the
    same as :func:`profile_path`'s. The tasks go out ridge parameters first (:func:`ridge_first`): the longest
    sides start first, so that the workers finish together, and a lower optimum, which the ridges lead to, is
    found early.

    Parameters
    ----------
    problem : Problem
        The run's statistical problem.
    theta_hat : ndarray, shape (dim,)
        The least-squares optimum.
    sigma : ndarray, shape (n_groups,)
        Noise scale per noise group [m], held fixed.
    cov_hat : ndarray, shape (dim, dim)
        Gauss–Newton covariance at the optimum.
    indices : iterable of int
        Parameters to profile.
    processes : int
        Worker processes.
    progress : callable, optional
        Called as ``progress(path, done, total)`` after each profile is finished (in the order of
        :func:`ridge_first`).
    stop_on_lower : bool
        Raise :class:`LowerOptimum` at the first side (in that order, so the same side whatever the timing)
        that reaches a point below the optimum; the workers are stopped.
    **kwargs
        Passed to :func:`profile_side`.

    Returns
    -------
    list of ProfilePath
        One per index, in the order of ``indices``.

    Raises
    ------
    LowerOptimum
        With ``stop_on_lower``: a profile fit found a lower cost than ``theta_hat``'s.
    """
    indices = list(indices)
    tasks = [(i, side) for i in ridge_first(cov_hat, indices) for side in (1.0, -1.0)] if indices else []
    _POOL.update(problem=problem, theta=theta_hat, sigma=sigma, cov=cov_hat, kwargs=kwargs)
    out: dict[int, ProfilePath] = {}

    def collect(sides) -> list[ProfilePath]:
        done: list[ProfileSide] = []
        for (i, _), side in zip(tasks, sides):
            low = lowest_point(side.points) if stop_on_lower else None
            if low is not None:
                raise LowerOptimum(problem.names[i], low)
            done.append(side)
            if len(done) == 2:
                out[i] = join_sides(problem, theta_hat, cov_hat, i, done)
                done = []
                if progress is not None:
                    progress(out[i], len(out), len(indices))
        return [out[i] for i in indices]

    try:
        if processes <= 1 or len(indices) == 0:
            return collect(_side_task(t) for t in tasks)
        with mp_context().Pool(min(processes, len(tasks)), initializer=_init_profile_worker,
                               initargs=(dict(_POOL),)) as pool:
            return collect(pool.imap(_side_task, tasks))
    finally:
        _POOL.clear()


def profiles_through_lowest(problem: Problem, ls: LeastSquaresResult, indices, processes: int = 1, progress=None,
                            max_nfev: int = 200, on_refit=None,
                            **kwargs) -> tuple[list[ProfilePath], LeastSquaresResult]:
    """Profile paths through the least-squares optimum, refitted first wherever a path shows it was not the
    lowest point.

    The paths (:func:`profile_paths`) stop at the first side that reaches below ``ls``'s optimum
    (:class:`LowerOptimum`); the least squares are refitted from that point (:func:`.leastsq.refit_from_lower`)
    and the paths start again from the new optimum, at most :data:`MAX_LOWER_REFITS` times (the last paths are
    kept as they come, points below the optimum included).

    Parameters
    ----------
    problem : Problem
        The run's statistical problem.
    ls : LeastSquaresResult
        The least-squares optimum (theta, sigma [m] per flight, covariance).
    indices : iterable of int
        Parameters to profile.
    processes : int
        Worker processes of the profile fits.
    progress : callable, optional
        ``progress(path, done, total)`` after each profile (:func:`profile_paths`); counts start again after a refit.
    max_nfev : int
        Evaluation budget of each refinement round of a refit.
    on_refit : callable, optional
        Called as ``on_refit(found, ls)`` after each refit: the :class:`LowerOptimum` and the new result.
    **kwargs
        Passed to :func:`profile_side`.

    Returns
    -------
    paths : list of ProfilePath
        One per index, in the order of ``indices``, through ``ls``'s optimum as returned.
    ls : LeastSquaresResult
        ``ls`` itself, or its last refit (``lower_optima`` records each).
    """
    indices = list(indices)
    for attempt in range(MAX_LOWER_REFITS + 1):
        try:
            return profile_paths(problem, ls.theta, ls.sigma, ls.cov, indices, processes=processes, progress=progress,
                                 stop_on_lower=attempt < MAX_LOWER_REFITS, **kwargs), ls
        except LowerOptimum as found:
            ls = refit_from_lower(problem, ls, found.point.theta, max_nfev=max_nfev,
                                  found={"profile": found.name, "t": float(found.point.t),
                                         "deviance": float(found.point.deviance)})
            if on_refit is not None:
                on_refit(found, ls)
    raise AssertionError("unreachable: the last attempt does not stop on a lower point")
