"""Learning what the model misses when no term of the library explains it.

The base model is extended by the learned discrepancy of :mod:`bayes_disc.physics.discrepancy` (46
columns: five directions × functions of height, α and spin), and a sparse set of columns is selected by
sequentially thresholded least squares on the model linearised at the base optimum (Brunton et al.'s
SINDy selection, with z-scores in place of a fixed threshold):

1. solve the linearised joint least squares for the base parameters and the active columns; each column's
   z-score is its estimate over its Gauss–Newton sd;
2. drop the columns with |z| < ``Z_KEEP`` — at most half of the active set per round, the weakest first
   (columns are correlated: dropping all weak ones at once can drop the one that mattered);
3. repeat until every active column has |z| ≥ ``Z_KEEP`` (at most ``MAX_ROUNDS`` rounds).

The selected columns are then fitted with the full non-linear model (the others held at zero), from the
linearised step and from the current point (the better kept: with one start only, the refit from a base
far from the corrected optimum stalls with the misfit still several times the noise); the model is linearised again where that refit ends and the selection repeated
over every column, until it no longer changes or no longer lowers Σ_g n_g ln S_g (at most
``OUTER_ROUNDS``): the base optimum can lie far from the corrected one. The learned correction is judged like a candidate: ΔBIC over the base with k = the number of selected
columns, whiteness of every flight's residuals after, and its share of the base model's excess misfit
(:func:`.missing_physics.excess_share`). Where it is concentrated — the share of its Wald
statistic (c_gᵀ Σ_gg⁻¹ c_g over the columns of a flight variable g: height, α, spin, constant) — names the
flight variable and so the family of the library the effect belongs to (height → ground effect, α →
non-linear aerodynamics, spin → side force, spin lift or roll coupling by direction) when one variable
holds at least ``CONCENTRATION_NAMED`` of it and the correction leaves white residuals or removes at least
``SHARE_PARTIAL`` of the excess misfit (a correction that removes little names nothing: the mismatch is not
a smooth function of these variables — a gust, say). The correction's curve against that variable, with its
band, is what the model was missing, in the user's terms.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..inference.fitting.covariance import covariance_from_jacobian
from ..inference.fitting.leastsq import refine_least_squares
from ..inference.fitting.residuals import whitened_jacobian, whitened_residuals
from ..physics.discrepancy import COLUMNS, DISCREPANCY, DIRECTIONS, FUNCTIONS, basis, column_name
from .missing_physics import (SHARE_PARTIAL, ModelFit, excess_share, extend_theta, model_fit, replicating_flights,
                              structured)
from .residuals import channel_runs

#: least |z| of a kept column
Z_KEEP = 3.0
#: most selection rounds
MAX_ROUNDS = 12
#: least share of the Wald statistic in one flight variable for it to be named
CONCENTRATION_NAMED = 0.6
#: linearise–select–refit rounds (the base optimum can be far from the corrected one: linearising once
#: there selects well but starts the refit in the wrong place)
OUTER_ROUNDS = 4
#: the family of the library a (variable, main direction) belongs to
FAMILY_VARIABLE = {("height", None): "ground_effect", ("alpha", None): "nonlinear_aero",
                   ("spin", "side"): "side_force", ("spin", "lift"): "spin_lift", ("spin", "roll"): "roll_spin_coupling"}
#: the flight variables, in the order of their functions
VARIABLES = ("height", "alpha", "spin", "constant")


def family_of(variable: str | None, direction: str | None) -> str | None:
    """The library family a correction concentrated in ``variable`` (mainly in ``direction``) belongs to."""
    if variable is None:
        return None
    return FAMILY_VARIABLE.get((variable, None), FAMILY_VARIABLE.get((variable, direction)))


def select_columns(J: np.ndarray, r: np.ndarray, keep: np.ndarray, candidates: np.ndarray, z_keep: float = Z_KEEP,
                   max_rounds: int = MAX_ROUNDS) -> tuple[np.ndarray, np.ndarray]:
    """Sequentially thresholded least squares on a linearised problem (module docstring).

    Parameters
    ----------
    J : (n, dim) array
        Whitened Jacobian at the linearisation point.
    r : (n,) array
        Whitened residuals there.
    keep : (dim,) bool array
        Parameters always in the fit (the base model's).
    candidates : (m,) int array
        Columns of J that may be selected.
    z_keep : float
    max_rounds : int

    Returns
    -------
    selected : (m',) int array
        The selected columns (subset of ``candidates``).
    z : (m',) array
        Their final z-scores.
    step : (dim,) array
        The linearised least-squares step of the final selection (zero for the columns left out).
    """
    active = np.array(candidates, int)
    z, step = np.zeros(0), np.zeros(J.shape[1])
    for _ in range(max_rounds):
        cols = np.r_[np.flatnonzero(keep), active]
        A = J[:, cols]
        cov = covariance_from_jacobian(A)
        delta = -cov @ (A.T @ r)
        step = np.zeros(J.shape[1])
        step[cols] = delta
        if active.size == 0:
            break
        z = delta[-active.size:] / np.sqrt(np.maximum(np.diag(cov)[-active.size:], 1e-300))
        weak = np.flatnonzero(np.abs(z) < z_keep)
        if weak.size == 0:
            break
        weak = weak[np.argsort(np.abs(z[weak]))][: max(1, active.size // 2)]
        mask = np.ones(active.size, bool)
        mask[weak] = False
        active, z = active[mask], z[mask]
    return active, z, step


@dataclass
class LearnedDiscrepancy:
    """The learned correction: its selected columns (names, values, sd, covariance), the fit, ΔBIC over the
    base, whiteness after, the share of its Wald statistic per flight variable and per direction, and the
    flown range of every variable (height [m], α [rad], μ)."""

    fit: ModelFit
    names: list
    values: np.ndarray
    sd: np.ndarray
    cov: np.ndarray
    delta_bic: float
    white: bool
    concentration: dict
    direction_share: dict
    flown: dict = field(default_factory=dict)
    share: float = float("nan")
    replicated: bool = False

    @property
    def explains(self) -> bool:
        """White residuals after, or at least ``SHARE_PARTIAL`` of the base model's excess misfit removed and
        that removal :attr:`replicated`: in two flights (:func:`.missing_physics.replicating_flights`), or in
        one when no other flight flew where the correction matters (:func:`unreached_elsewhere`)."""
        return self.white or (np.isfinite(self.share) and self.share >= SHARE_PARTIAL and self.replicated)

    @property
    def variable(self) -> str | None:
        """The flight variable that holds at least ``CONCENTRATION_NAMED`` of the correction (not the
        constant) when the correction :attr:`explains` the mismatch, or None."""
        v, share = max(self.concentration.items(), key=lambda t: t[1]) if self.concentration else (None, 0.0)
        named = v not in (None, "constant") and share >= CONCENTRATION_NAMED and self.explains
        return v if named else None

    @property
    def direction(self) -> str | None:
        """The direction that holds most of the correction."""
        return max(self.direction_share.items(), key=lambda t: t[1])[0] if self.direction_share else None

    @property
    def family(self) -> str | None:
        """The library family of :attr:`variable` and :attr:`direction` (:data:`FAMILY_VARIABLE`), or None."""
        return family_of(self.variable, self.direction)

    def curve(self, direction: str, variable: str, grid: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """ΔC in ``direction`` against ``variable`` on ``grid`` (height [m], α [rad] or μ), the other
        variables at the median flown values; returns (value, sd) each shaped like ``grid``."""
        state = {v: np.full(np.shape(grid), self.flown[v][1]) for v in ("height", "alpha", "spin")}
        state[variable] = np.asarray(grid, float)
        phi = basis(state["height"], state["alpha"], state["spin"])
        g = np.zeros((len(self.names),) + np.shape(grid))
        for i, n in enumerate(self.names):
            for j, f in enumerate(FUNCTIONS):
                if n == column_name(direction, f):
                    g[i] = phi[j]
        value = np.tensordot(self.values, g, axes=1)
        var = np.einsum("i...,ij,j...->...", g, self.cov, g)
        return value, np.sqrt(np.maximum(var, 0.0))


def _score(problem, theta: np.ndarray) -> float:
    """Σ_g n_g ln S_g at θ: the profile negative log-likelihood (×2, up to a constant) with every noise
    group's σ profiled out; lower is better."""
    return float(np.sum(problem.n_coords * np.log(problem.sum_squares(theta[None])[0])))


def _zeroed(x: np.ndarray, columns: np.ndarray, kept: np.ndarray) -> np.ndarray:
    """x with the correction's ``columns`` not in ``kept`` set to zero (the other start of a refit)."""
    out = x.copy()
    out[np.setdiff1d(columns, kept)] = 0.0
    return out


def _flown_values(fit: ModelFit) -> list[dict]:
    """Per flight, {variable: values along its fitted trajectory}: height z [m], α [rad], μ = r d / 2|v_a|."""
    p, out = fit.problem, []
    for k in range(p.n_flights):
        _, tr, _, _, air = channel_runs(p, fit.ls.theta, k)[0]
        out.append({"height": tr.states[0][:, 2], "alpha": air.alpha[0],
                    "spin": air.pqr[0, :, 2] * p.disc.diameter / (2 * np.maximum(air.speed[0], 1e-9))})
    return out


def flown_range(fit: ModelFit) -> dict:
    """{variable: (5th percentile, median, 95th percentile)} over every flight's fitted trajectory: height z
    [m], α [rad], advance ratio μ = r d / 2|v_a|."""
    per = _flown_values(fit)
    return {v: tuple(float(q) for q in np.nanpercentile(np.concatenate([f[v] for f in per]), [5, 50, 95]))
            for v in ("height", "alpha", "spin")}


#: a learned correction matters where it exceeds this many sd and this fraction of its largest value
MATTERS_SD, MATTERS_FRACTION = 3.0, 0.1


def unreached_elsewhere(learned: "LearnedDiscrepancy", per_flight: list[dict], removing: list[int]) -> bool:
    """Whether only the flights in ``removing`` flew where the correction matters (along its strongest
    variable, in its main direction: |ΔC| > ``MATTERS_SD`` sd and > ``MATTERS_FRACTION`` of its peak): then a
    gain confined to them is what physics of that state gives, not a sign of a disturbance (a ground effect
    that only the one low flight reaches)."""
    variable = max((v for v in learned.concentration if v != "constant"), key=lambda v: learned.concentration[v],
                   default=None)
    direction = learned.direction
    if variable is None or direction is None:
        return False
    values = np.concatenate([f[variable] for f in per_flight])
    grid = np.linspace(np.nanmin(values), np.nanmax(values), 200)
    value, sd = learned.curve(direction, variable, grid)
    matters = (np.abs(value) > MATTERS_SD * sd) & (np.abs(value) > MATTERS_FRACTION * np.max(np.abs(value)))
    for k, f in enumerate(per_flight):
        if k in removing:
            continue
        lo, hi = np.nanmin(f[variable]), np.nanmax(f[variable])
        if np.any(matters & (grid >= lo) & (grid <= hi)):
            return False
    return True


def _wald_shares(names: list, values: np.ndarray, cov: np.ndarray, key) -> dict:
    """{group: share of Σ Wald statistics} with columns grouped by ``key(direction, function)``."""
    groups = {}
    for i, n in enumerate(names):
        d, f = COLUMN_OF[n]
        groups.setdefault(key(d, f), []).append(i)
    stats = {}
    for g, idx in groups.items():
        c, S = values[idx], cov[np.ix_(idx, idx)]
        stats[g] = float(c @ np.linalg.pinv(S) @ c)
    total = sum(stats.values())
    return {g: s / total for g, s in stats.items()} if total > 0 else {}


#: parameter name → (direction, function)
COLUMN_OF = {column_name(d, f): (d, f) for d, f in COLUMNS}


def learn_discrepancy(base: ModelFit, build, max_nfev: int = 200, log=lambda msg: None) -> LearnedDiscrepancy | None:
    """Learn a sparse correction to the base model (module docstring).

    Parameters
    ----------
    base : ModelFit
        The base model's fit.
    build : callable
        ``build(ids)`` → the :class:`~bayes_disc.inference.model.problem.Problem` of a model.
    max_nfev : int
        Evaluations of the non-linear refit.
    log : callable
        Progress messages.

    Returns
    -------
    LearnedDiscrepancy or None
        None when no column is selected.
    """
    p = build(base.ids + (DISCREPANCY.id,))
    x = extend_theta(base.ls.theta, base.problem, p)
    sigma = base.ls.sigma
    idx = np.array([p.layout.index(column_name(d, f)) for d, f in COLUMNS])
    keep = np.ones(p.dim, bool)
    keep[idx] = False
    selected, ls, cost = np.zeros(0, int), None, np.inf
    for it in range(OUTER_ROUNDS):
        # linearise where the last refit ended (the base optimum at first) and select again from every column
        J, r = whitened_jacobian(x, p, sigma), whitened_residuals(x, p, sigma)
        chosen, _, step = select_columns(J, r, keep, idx)
        if chosen.size == 0:
            break
        if ls is not None and set(chosen) == set(selected):
            break
        free = keep.copy()
        free[chosen] = True
        start = x.copy()
        start[idx] = 0.0
        start[free] += step[free]
        log(f"  learned discrepancy, round {it + 1}: {chosen.size} columns "
            f"({', '.join(p.names[j] for j in chosen)}); refitting")
        trial = [refine_least_squares(p, x0, max_nfev=max_nfev, free=free) for x0 in (start, _zeroed(x, idx, chosen))]
        scores = [_score(p, t.theta) for t in trial]
        best, score = trial[int(np.argmin(scores))], min(scores)
        if ls is not None and score >= cost:
            break
        selected, ls, cost = chosen, best, score
        x, sigma = best.theta, best.sigma
    if ls is None:
        log("  learned discrepancy: no column of the correction is significant")
        return None
    names = [p.names[j] for j in selected]
    fit = model_fit(p, ls, base.ids + (DISCREPANCY.id,))
    n = base.problem.n_coords.astype(float)
    delta_bic = float(np.sum(n * np.log(base.ss / fit.ss)) - selected.size * np.log(n.sum()))
    values, cov = ls.theta[selected], ls.cov[np.ix_(selected, selected)]
    learned = LearnedDiscrepancy(
        fit=fit, names=names, values=values, sd=np.sqrt(np.diag(cov)), cov=cov, delta_bic=delta_bic,
        white=not any(structured(fit).values()),
        concentration=_wald_shares(names, values, cov, lambda d, f: FUNCTIONS[f][0]),
        direction_share=_wald_shares(names, values, cov, lambda d, f: d),
        flown=flown_range(base),
        share=excess_share(base.ss, fit.ss, base.noise_floor, base.problem.n_coords))
    bp = base.problem
    removing = replicating_flights(base.ss, fit.ss, base.noise_floor, bp.n_coords,
                                   [bp.flight_groups(k) for k in range(bp.n_flights)])
    learned.replicated = (len(removing) >= min(2, bp.n_flights)
                          or (len(removing) == 1 and unreached_elsewhere(learned, _flown_values(base), removing)))
    log(f"  learned discrepancy: ΔBIC {delta_bic:.1f}, residuals {'white' if learned.white else 'structured'}, "
        f"share of the excess misfit {learned.share:.2f}, "
        + ", ".join(f"{v} {s:.2f}" for v, s in sorted(learned.concentration.items(), key=lambda t: -t[1])))
    return learned


__all__ = ["LearnedDiscrepancy", "learn_discrepancy", "select_columns", "flown_range", "family_of", "DIRECTIONS"]
