"""Sampler moves that use the flights' block structure, so that mixing does not degrade as flights are added.

θ = (θ_s, θ_1, …, θ_F): the shared parameters (coefficients, extension block) and every flight's own block
(initial conditions, its observation-model parameters). Given θ_s the flights are independent: the prior is
diagonal and every flight's likelihood reads only θ_s, θ_k and its own noise groups, so

    p(θ_k | θ_s, θ_−k, y) ∝ p(y_k | θ_s, θ_k) p(θ_k).

Two exact Metropolis–Hastings moves follow (each leaves the posterior invariant):

* :class:`FlightBlockMove` — Metropolis-within-Gibbs over the flights: for every flight k (all flights in
  one sweep: given θ_s the updates are independent, so updating them together equals updating them in
  turn) a Gaussian random-walk proposal θ_k′ = θ_k + (2.38/√p_k) L_k z, L_k Lₖᵀ the conditional covariance
  of θ_k given the rest under the reference Gaussian (the inverse of the precision's own block), accepted
  with probability min(1, p(y_k | θ_s, θ_k′) p(θ_k′) / p(y_k | θ_s, θ_k) p(θ_k)): one simulation of
  flight k per walker, the other flights untouched.
* :class:`SharedShift` — a random walk of the shared parameters that carries every flight along its
  regression on them: δ ~ N(0, (2.38²/s) Σ_ss), θ_s′ = θ_s + δ, θ_k′ = θ_k + Σ_ks Σ_ss⁻¹ δ (Σ the reference
  covariance). The proposal is a translation by M δ with M fixed and δ symmetric, so its Hastings factor
  is 1; it moves in the s-dimensional subspace where the coefficients' posterior correlations with the
  flights' initial conditions are followed, so its step size does not shrink with the number of flights.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from emcee.moves.move import Move
from emcee.state import State

from .model import Problem
from .proposals import scaled_cholesky


def block_factors(problem: Problem, cov: np.ndarray) -> tuple[list[np.ndarray], np.ndarray, np.ndarray]:
    """The reference Gaussian's pieces the block moves need.

    Parameters
    ----------
    problem : Problem
    cov : (dim, dim) array
        Reference covariance (the Laplace approximation, or the warm-up samples' covariance).

    Returns
    -------
    conditional : list of (p_k, p_k) arrays
        Per flight, the Cholesky factor of Cov(θ_k | everything else) = ((Σ⁻¹)_kk)⁻¹.
    shared : (s, s) array
        Cholesky factor of the shared block's marginal covariance Σ_ss.
    regression : (dim − s, s) array
        Σ_(flights),s Σ_ss⁻¹: how every flight's block follows the shared parameters.
    """
    cov = 0.5 * (cov + cov.T)
    d = np.sqrt(np.diag(cov))
    corr = cov / np.outer(d, d)
    w, V = np.linalg.eigh(corr)
    w = np.maximum(w, 1e-12 * w[-1])
    precision = (V / w) @ V.T / np.outer(d, d)
    conditional = []
    for k in range(problem.n_flights):
        sl = problem.layout.flight_slice(k)
        conditional.append(scaled_cholesky(np.linalg.inv(precision[sl, sl])))
    s = problem.ic_start
    Sss = cov[:s, :s]
    regression = np.linalg.solve(Sss, cov[:s, s:]).T
    return conditional, scaled_cholesky(Sss), regression


class FlightBlockMove(Move):
    """Metropolis-within-Gibbs sweep over every flight's own block (module docstring).

    Parameters
    ----------
    problem : Problem
        The posterior (its per-flight likelihood :meth:`Problem.flight_log_likelihood`).
    conditional : list of (p_k, p_k) arrays
        Per flight, the Cholesky factor of the proposal's shape (:func:`block_factors`).
    scale : float
        Multiplies 2.38/√p_k (the optimal random-walk scale for a Gaussian target).
    """

    def __init__(self, problem: Problem, conditional, scale: float = 1.0):
        self.problem = problem
        self.conditional = conditional
        self.scale = scale

    def propose(self, model, state):
        p = self.problem
        coords = state.coords.copy()
        nw = coords.shape[0]
        blobs = np.asarray(state.blobs, float).reshape(nw, p.n_groups).copy()
        accepted = np.zeros(nw, bool)
        for k, L in enumerate(self.conditional):
            sl, groups = p.layout.flight_slice(k), p.flight_groups(k)
            step = (self.scale * 2.38 / np.sqrt(L.shape[0])) * model.random.randn(nw, L.shape[0]) @ L.T
            trial = coords.copy()
            trial[:, sl] += step
            ss = p.flight_sum_squares(trial, k)
            zn = (trial[:, sl] - p.prior_mean[sl]) / p.prior_sd[sl]
            zo = (coords[:, sl] - p.prior_mean[sl]) / p.prior_sd[sl]
            diff = (p.flight_log_likelihood(ss, k) - p.flight_log_likelihood(blobs[:, groups], k)
                    - 0.5 * np.sum(zn * zn - zo * zo, axis=1))
            diff = np.where(np.isfinite(diff), diff, -np.inf)
            take = np.log(model.random.rand(nw)) < diff
            coords[take, sl] = trial[take, sl]
            blobs[np.ix_(take, groups)] = ss[take]
            accepted |= take
        # the log-posterior from its parts (no simulation): exactly what a full evaluation would give
        log_prob = p.log_prior(coords) + p.log_likelihood_from_ss(blobs)
        log_prob = np.where(np.isfinite(log_prob), log_prob, -np.inf)
        shaped = blobs.reshape(np.shape(state.blobs))
        return State(coords, log_prob=log_prob, blobs=shaped, random_state=state.random_state), accepted


@dataclass(frozen=True)
class SharedShift:
    """Proposal of the shared random walk that carries the flights along (module docstring); an emcee
    ``MHMove`` proposal function.

    Attributes
    ----------
    shared_chol : (s, s) array
        Cholesky factor of Σ_ss.
    regression : (dim − s, s) array
        Σ_ks Σ_ss⁻¹ stacked over the flights.
    scale : float
        Multiplies 2.38/√s.
    """

    shared_chol: np.ndarray
    regression: np.ndarray
    scale: float = 1.0

    def __call__(self, coords, random):
        s = self.shared_chol.shape[0]
        delta = (self.scale * 2.38 / np.sqrt(s)) * random.randn(coords.shape[0], s) @ self.shared_chol.T
        new = coords.copy()
        new[:, :s] += delta
        new[:, s:] += delta @ self.regression.T
        return new, np.zeros(coords.shape[0])
