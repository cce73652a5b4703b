"""Whitened residuals and their Jacobian: per flight, as costs, as one vector, and as the block-arrow Jacobian
(:mod:`.arrow`) by finite differences whose steps shrink where the residuals are not linear over them.
"""
from __future__ import annotations

import numpy as np

from .arrow import ArrowJacobian
from ..model.problem import Problem


FAILED_RESIDUAL = 1e3  # whitened residual standing in for a failed simulation


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
        Central differences; a one-sided difference where the lane on the other side failed (a parameter
        at the edge of its domain: AR(1)'s ρ a step from 1); zero where both failed, or one did and the
        centre's simulation failed too.
    bend, slope : (c,) arrays
        |d⁺ − d⁻|² and |d⁺ + d⁻|²/4 summed over the rows, d± the one-sided differences; where a lane failed
        and the centre did not, bend is inf and slope zero (the step reaches where the simulation fails: a
        smaller one may not); zero where the centre failed.
    centre : (n_k,) array or None
        The residuals at x (None if that simulation failed).

    A lane fails when its simulation does or any of its residuals is not finite.
    """
    w = sigma[problem.residual_groups(k)]
    if cols.size == 0:
        return np.zeros((0, w.size)), np.zeros(0), np.zeros(0), centre
    lanes = np.repeat(x[None], 2 * cols.size + (centre is None), axis=0)
    lanes[np.arange(cols.size), cols] += h
    lanes[cols.size + np.arange(cols.size), cols] -= h
    r, ok = problem.noise_residuals(lanes, k)
    ok = ok & np.all(np.isfinite(r), axis=1)
    if centre is None:
        centre = r[-1] if ok[-1] else None
    plus, minus = r[: cols.size], r[cols.size: 2 * cols.size]
    up, down = ok[: cols.size], ok[cols.size: 2 * cols.size]
    good = up & down
    d = np.zeros((cols.size, w.size))
    d[good] = (plus - minus)[good] / (2 * h)[good, None] / w
    bend, slope = np.zeros(cols.size), np.zeros(cols.size)
    if centre is not None:
        dp, dm = (plus - centre) / w, (centre - minus) / w
        d[up & ~down] = dp[up & ~down] / h[up & ~down, None]
        d[down & ~up] = dm[down & ~up] / h[down & ~up, None]
        bend[good] = np.sum((dp - dm)[good] ** 2, axis=1)
        slope[good] = np.sum((0.5 * (dp + dm))[good] ** 2, axis=1)
        bend[~good] = np.inf
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
    secant across a bend. A column with a failed lane (a step that reaches coefficients or initial conditions
    the simulation cannot integrate, as next to an unstable wobble mode, or beyond a parameter's domain) is
    reduced the same way. Where no column bends the result is the plain central difference.

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
