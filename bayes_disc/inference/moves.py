"""The sampler's own Metropolis–Hastings moves: block moves that use the flights' structure, so that mixing
does not degrade as flights are added, and the independence jump that remembers its proposal densities.

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

And :class:`IndependenceJump` — the independence Metropolis–Hastings jump x′ ~ q, accepted with probability
min(1, p(x′ | y) q(x) / p(x | y) q(x′)), that keeps ln q of every walker's position after the jump, so a
walker that has not moved since (rejected, or untouched by the moves in between) costs no new density
evaluation: with the ridge proposals' per-point algebra, ln q costs about as much as the log-posterior at
24 flights (298 parameters: 0.097 s against 0.16 s for 128 walkers).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from emcee.moves.mh import MHMove
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


class IndependenceJump(MHMove):
    """Independence Metropolis–Hastings jumps from ``proposal`` with ln q of unmoved walkers remembered
    (module docstring). The same proposals, random numbers and acceptance ratios as ``MHMove(proposal)``
    (a proposal whose ``__call__`` draws and returns ln q(x) − ln q(x′)).

    Parameters
    ----------
    proposal : object
        ``draw(n, random)`` → (n, dim) points and ``log_density(x)`` → (n,) ln q (up to a constant), e.g.
        :class:`.proposals.CompositeProposal`.
    """

    def __init__(self, proposal):
        super().__init__(self._jump)
        self.proposal = proposal
        self._memo: tuple[np.ndarray, np.ndarray] | None = None   # walkers after the last jump, their ln q
        self._log_q: tuple[np.ndarray, np.ndarray] | None = None   # this jump's (ln q(x), ln q(x′))

    def _known(self, coords: np.ndarray) -> np.ndarray:
        """ln q (nw,) of the walkers: remembered where a walker is where the last jump left it."""
        out = np.empty(coords.shape[0])
        known = np.zeros(coords.shape[0], bool)
        if self._memo is not None and self._memo[0].shape == coords.shape:
            known = np.all(coords == self._memo[0], axis=1)
            out[known] = self._memo[1][known]
        if not known.all():
            out[~known] = self.proposal.log_density(coords[~known])
        return out

    def _jump(self, coords, random):
        new = self.proposal.draw(coords.shape[0], random)
        self._log_q = (self._known(coords), self.proposal.log_density(new))
        return new, self._log_q[0] - self._log_q[1]

    def propose(self, model, state):
        state, accepted = super().propose(model, state)
        self._memo = (state.coords.copy(), np.where(accepted, self._log_q[1], self._log_q[0]))
        return state, accepted
