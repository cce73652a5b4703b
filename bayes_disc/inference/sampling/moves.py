"""The sampler's own Metropolis–Hastings moves: block moves that use the flights' structure, so that mixing
does not degrade as flights are added, and the independence jump that remembers its proposal densities.

θ = (θ_s, θ_1, …, θ_F): the shared parameters (coefficients, extension block) and every flight's own block
(initial conditions, its observation-model parameters). Given θ_s the flights are independent: the prior is
diagonal and every flight's likelihood reads only θ_s, θ_k and its own noise groups, so

    p(θ_k | θ_s, θ_−k, y) ∝ p(y_k | θ_s, θ_k) p(θ_k).

Three exact Metropolis–Hastings moves follow (each leaves the posterior invariant):

* :class:`FlightBlockMove` — Metropolis-within-Gibbs over the flights: for every flight k (all flights in
  one sweep: given θ_s the updates are independent, so updating them together equals updating them in
  turn) a Gaussian random-walk proposal θ_k′ = θ_k + (2.38/√p_k) L_k z, L_k Lₖᵀ the conditional covariance
  of θ_k given the rest under the reference Gaussian (the inverse of the precision's own block), accepted
  with probability min(1, p(y_k | θ_s, θ_k′) p(θ_k′) / p(y_k | θ_s, θ_k) p(θ_k)): one simulation of
  flight k per walker, the other flights untouched.
* :class:`RidgeFlightRefresh` — the same sweep with every flight's block drawn afresh from a ridge
  proposal's conditional given θ_s (an independence proposal per flight, whose Hastings factor reads that
  flight's block only), so a flight jumps across its posterior instead of stepping through it.
* :class:`SharedShift` — a random walk of the shared parameters that carries every flight along its
  regression on them: δ ~ N(0, (2.38²/s) Σ_ss), θ_s′ = θ_s + δ, θ_k′ = θ_k + Σ_ks Σ_ss⁻¹ δ (Σ the reference
  covariance). The proposal is a translation by M δ with M fixed and δ symmetric, so its Hastings factor
  is 1; it moves in the s-dimensional subspace where the coefficients' posterior correlations with the
  flights' initial conditions are followed, so its step size does not shrink with the number of flights.
  The regression is linear; along the curved CM0–CMq valley it is not, and on seed 18's 24-flight walkers
  (``benchmarks/bench_scale.py``) these steps were accepted 0.5 % of the time. Two variants go with the ridge
  proposals: the shared parameters alone with the flights held (the shared block's Gibbs step,
  :func:`shared_conditional`), and the observation models' shared parameters alone, carrying the flights
  along their regression given the coefficients (:func:`observation_shift`: a logger's position against
  every throw's accelerometer bias).

And :class:`IndependenceJump` — the independence Metropolis–Hastings jump x′ ~ q, accepted with probability
min(1, p(x′ | y) q(x) / p(x | y) q(x′)), that keeps ln q of every walker's position after the jump, so a
walker that has not moved since (rejected, or untouched by the moves in between) costs no new density
evaluation (with the ridge proposals' per-point algebra, ln q costs a fair share of a log-posterior
evaluation at many flights, even with block-sparse factors: :mod:`._ridge_kernels`).

And :class:`RidgeCarry` — the jump along a ridge proposal that draws the coefficients afresh and carries
every flight's whitened place across the valley, so that its acceptance does not fall as flights are
added (its docstring).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from emcee.moves.mh import MHMove
from emcee.moves.move import Move
from emcee.state import State

from ..model.problem import Problem
from ..fitting.covariance import scaled_cholesky


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
    precision = _precision(cov)
    conditional = []
    for k in range(problem.n_flights):
        sl = problem.layout.flight_slice(k)
        conditional.append(scaled_cholesky(np.linalg.inv(precision[sl, sl])))
    s = problem.ic_start
    Sss = cov[:s, :s]
    regression = np.linalg.solve(Sss, cov[:s, s:]).T
    return conditional, scaled_cholesky(Sss), regression


def _precision(cov: np.ndarray) -> np.ndarray:
    """Σ⁻¹ of a covariance whose scales span many decades (inverted in scale-free form, eigenvalues floored)."""
    cov = 0.5 * (cov + cov.T)
    d = np.sqrt(np.diag(cov))
    w, V = np.linalg.eigh(cov / np.outer(d, d))
    w = np.maximum(w, 1e-12 * w[-1])
    return (V / w) @ V.T / np.outer(d, d)


def shared_conditional(problem: Problem, cov: np.ndarray) -> np.ndarray:
    """Cholesky factor (s, s) of Cov(θ_s | every flight's block) = ((Σ⁻¹)_ss)⁻¹ under the Gaussian of
    covariance ``cov`` (dim, dim): the step shape of :class:`SharedShift` with the flights held."""
    s = problem.ic_start
    return scaled_cholesky(np.linalg.inv(_precision(cov)[:s, :s]))


def observation_shift(problem: Problem, cov: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The pieces of :class:`SharedShift` for the shared observation-model parameters (θ_o, the layout's
    ``observation_slice``: a logger's position, tilt and magnetometer) with the other shared parameters θ_c
    (coefficients, terms' parameters) held and the flights carried: under the Gaussian of covariance
    ``cov`` conditioned on θ_c, the Cholesky factor of Cov(θ_o | θ_c) and the flights' regression on θ_o.

    A logger's position in the disc and every throw's accelerometer bias trade off almost exactly
    (the centripetal acceleration ω² r at a slowly decaying spin reads like a bias), as do the
    magnetometer's field and hard iron with the throws' headings: narrow straight valleys across the
    shared and flight blocks that neither the flight sweeps nor a walk with the flights held can follow.

    Returns
    -------
    columns : (o,) int array
        Positions of θ_o in θ (empty: the run has none).
    chol : (o, o) array
    regression : (dim − s, o) array
    """
    s, obs = problem.ic_start, problem.layout.observation_slice
    columns = np.arange(obs.start, obs.stop)
    if columns.size == 0:
        return columns, np.zeros((0, 0)), np.zeros((problem.dim - s, 0))
    kept = np.r_[columns, s:problem.dim]
    given = np.linalg.inv(_precision(cov)[np.ix_(kept, kept)])     # Cov(θ_o, flights | the other shared)
    o = columns.size
    regression = np.linalg.solve(given[:o, :o], given[:o, o:]).T
    return columns, scaled_cholesky(given[:o, :o]), regression


def pick_ridges(log_weights: np.ndarray, n: int, random) -> np.ndarray:
    """A ridge for each of n walkers (n,), drawn with the (unnormalised) log weights: the choice the ridge
    moves make per walker, independent of where the walker is (so a mixture of exact moves stays exact)."""
    w = np.exp(log_weights - np.max(log_weights))
    return random.choice(len(log_weights), size=n, p=w / w.sum())


class _FlightSweep(Move):
    """A Metropolis-within-Gibbs sweep over every flight's own block θ_k, given the shared parameters θ_s
    (unchanged by the sweep): for every flight k a proposal θ_k′ from :meth:`block_proposal` with its log
    Hastings factor ln q(θ_k | θ_k′) − ln q(θ_k′ | θ_k), accepted with probability

        min(1, p(y_k | θ_s, θ_k′) p(θ_k′) q(θ_k | θ_k′) / p(y_k | θ_s, θ_k) p(θ_k) q(θ_k′ | θ_k)):

    one simulation of flight k per walker, the other flights untouched. Subclasses say how θ_k′ is
    proposed."""

    problem: Problem

    def prepare(self, coords: np.ndarray, random) -> None:
        """Called once per sweep with the walkers (nw, dim) before any flight is proposed."""

    def block_proposal(self, k: int, coords: np.ndarray, random) -> tuple[np.ndarray, np.ndarray]:
        """Flight k's proposed block (nw, p_k) for walkers coords (nw, dim), and the log Hastings factor (nw,)."""
        raise NotImplementedError

    def propose(self, model, state):
        p = self.problem
        coords = state.coords.copy()
        nw = coords.shape[0]
        blobs = np.asarray(state.blobs, float).reshape(nw, p.n_groups).copy()
        accepted = np.zeros(nw, bool)
        self.prepare(coords, model.random)
        for k in range(p.n_flights):
            sl, groups = p.layout.flight_slice(k), p.flight_groups(k)
            block, log_factor = self.block_proposal(k, coords, model.random)
            trial = coords.copy()
            trial[:, sl] = block
            ss = p.flight_sum_squares(trial, k)
            zn = (trial[:, sl] - p.prior_mean[sl]) / p.prior_sd[sl]
            zo = (coords[:, sl] - p.prior_mean[sl]) / p.prior_sd[sl]
            diff = (p.flight_log_likelihood(ss, k) - p.flight_log_likelihood(blobs[:, groups], k)
                    - 0.5 * np.sum(zn * zn - zo * zo, axis=1) + log_factor)
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


class FlightBlockMove(_FlightSweep):
    """Metropolis-within-Gibbs sweep over every flight's own block (module docstring): Gaussian random-walk
    proposals θ_k′ = θ_k + (2.38/√p_k) L_k z, Hastings factor 1.

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

    def block_proposal(self, k, coords, random):
        L = self.conditional[k]
        step = (self.scale * 2.38 / np.sqrt(L.shape[0])) * random.randn(coords.shape[0], L.shape[0]) @ L.T
        return coords[:, self.problem.layout.flight_slice(k)] + step, np.zeros(coords.shape[0])


class RidgeFlightRefresh(_FlightSweep):
    """A sweep over the flights that draws every flight's block afresh from a ridge proposal's conditional
    given the shared parameters (an independence proposal per flight, given θ_s):

        θ_k′ ~ N(m_k(v, θ_s), L_kk(v) L_kk(v)ᵀ)    (:meth:`.proposals.RidgeProposal.block_conditionals`),

    v = θ_i the ridge's coefficient. Its Hastings factor is ½|ξ|² − ½|L_kk⁻¹ (θ_k − m_k)|², ξ the draw's
    standard normal: the proposal depends on θ_s only, which the sweep does not change. Where the random
    walk of :class:`FlightBlockMove` moves a flight by a fraction of its conditional sd per step, this
    jumps across it, following the valley through the ridge's interpolated conditional mean. One ridge per
    walker, drawn with the ridges' weights.

    Parameters
    ----------
    problem : Problem
    ridges : tuple of RidgeProposal
    log_weights : (R,) array
    """

    def __init__(self, problem: Problem, ridges, log_weights):
        self.problem = problem
        self.ridges = tuple(ridges)
        self.log_weights = np.asarray(log_weights, float)
        self._conditionals: list | None = None

    def prepare(self, coords, random):
        p, nw = self.problem, coords.shape[0]
        pick = pick_ridges(self.log_weights, nw, random)
        blocks = [p.layout.flight_slice(k) for k in range(p.n_flights)]
        sizes = [b.stop - b.start for b in blocks]
        out = [(np.empty((nw, n)), np.empty((nw, n, n))) for n in sizes]
        for j in np.unique(pick):
            at = pick == j
            conditionals = self.ridges[j].block_conditionals(coords[at], p.ic_start - 1, blocks)
            for (mean, chol), (m, L) in zip(out, conditionals):
                mean[at], chol[at] = m, L
        self._conditionals = out

    def block_proposal(self, k, coords, random):
        mean, L = self._conditionals[k]
        xi = random.randn(*mean.shape)
        old = np.linalg.solve(L, (coords[:, self.problem.layout.flight_slice(k)] - mean)[..., None])[..., 0]
        log_factor = 0.5 * np.sum(xi * xi, axis=1) - 0.5 * np.sum(old * old, axis=1)
        return mean + np.einsum("npq,nq->np", L, xi), log_factor

@dataclass(frozen=True)
class SharedShift:
    """Proposal of the shared random walk that carries the flights along (module docstring), or, without a
    regression, that holds them; an emcee ``MHMove`` proposal function.

    Held, with the factor of the shared parameters' conditional covariance given the flights
    (:func:`shared_conditional`, of the Laplace approximation), it is the counterpart of the flight sweeps:
    the shared block's Metropolis-within-Gibbs step. On the real logger throws, where the coefficients'
    valley bends with the release speeds, the Laplace approximation's conditional is the local shape there
    (accepted 10–14 % at the default scale from the walkers of a run, while the same walk with the
    warm-up samples' conditional, or any move that redraws the shared parameters, was accepted < 1.5 %).

    On a subset of the shared parameters (``columns``) it moves those alone, the other shared parameters
    held: :func:`observation_shift`.

    Attributes
    ----------
    shared_chol : (m, m) array
        Cholesky factor of Σ_ss (carried), or of Cov(θ_s | flights) (held); m = s, or the subset's size.
    regression : (dim − s, m) array or None
        Σ_ks Σ_ss⁻¹ stacked over the flights; None: the flights are held.
    scale : float
        Multiplies 2.38/√m.
    columns : (m,) int array, optional
        The shared parameters moved (default: all s).
    """

    shared_chol: np.ndarray
    regression: np.ndarray | None
    scale: float = 1.0
    columns: np.ndarray | None = None

    def __call__(self, coords, random):
        m = self.shared_chol.shape[0]
        columns = np.arange(m) if self.columns is None else self.columns
        delta = (self.scale * 2.38 / np.sqrt(m)) * random.randn(coords.shape[0], m) @ self.shared_chol.T
        new = coords.copy()
        new[:, columns] += delta
        if self.regression is not None:
            s = new.shape[1] - self.regression.shape[0]
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


@dataclass(frozen=True)
class RidgeCarry:
    """Jumps along the ridge proposals' paths that carry every flight's place across the valley: an emcee
    ``MHMove`` proposal function.

    A ridge proposal (:class:`.proposals.RidgeProposal`) writes every point as (v, z): v = θ_i, the profiled
    coefficient, and z = L(v)⁻¹ (θ_−i − m(v)) the point's whitened place across the valley at v. θ_−i lists
    the other shared parameters first, then the flights, and L(v) is lower-triangular, so z = (z_s, z_f):
    z_s whitens the shared parameters given v, z_f every flight's block given v and them. The move draws v′
    from the ridge's 1-D density g and z_s′ ~ N(0, I) afresh and keeps the walker's z_f:

        v′ ~ g,    z_s′ ~ N(0, I_s),    θ′_−i = m(v′) + L(v′) (z_s′, z_f).

    In the coordinates (v, z) this proposal is reversible with respect to g(v) N(z; 0, I); the change of
    coordinates adds the Jacobian |L(v′)| / |L(v)|, so the move is exact with acceptance probability

        min(1, p(θ′ | y) q(θ) / p(θ | y) q(θ′)),

    q the ridge's density: the independence jump's ratio, in which the terms ½|z_f|² of q at θ and θ′
    are equal and cancel. That is the point. An independence jump draws every flight's z_f afresh and pays
    the misfit between the posterior's conditional and the ridge's in all of the flights' dimensions at
    every jump, so its acceptance falls as flights are added (seed 18 of ``benchmarks/bench_scale.py``, kept
    walkers: 13 %, 14 %, 6 % at 4, 12, 24 flights); a carried z_f pays only how that misfit changes
    between (v, z_s) and (v′, z_s′) (the same walkers: 27 %, 36 %, 35 %). The flights' z_f are moved by
    the other moves (flight-block sweeps, DE and independence jumps).

    One ridge per walker, drawn with the ridges' weights in the independence proposal (fixed during a
    round: a mixture of exact moves is exact).

    Attributes
    ----------
    ridges : tuple of RidgeProposal
    log_weights : (R,) array
        Log weights of the ridges (normalised here).
    fresh : int
        s, the number of leading whitened coordinates drawn afresh: the shared parameters other than θ_i
        (``Problem.ic_start − 1``); 0 carries all of z.
    """

    ridges: tuple
    log_weights: np.ndarray
    fresh: int = 0

    def __call__(self, coords, random):
        pick = pick_ridges(self.log_weights, coords.shape[0], random)
        new = coords.copy()
        factor = np.zeros(coords.shape[0])
        for j in np.unique(pick):
            at = pick == j
            ridge = self.ridges[j]
            n = int(at.sum())
            z, log_det = ridge.whiten(coords[at])
            v_new = ridge.draw_g(n, random)
            z_new = z.copy()
            z_new[:, :self.fresh] = random.randn(n, self.fresh)
            new[at], log_det_new = ridge.place(v_new, z_new)
            # ln q(θ) − ln q(θ′) of the ridge's density (its normalising constant cancels)
            factor[at] = ((ridge.log_g_density(coords[at, ridge.index]) - log_det - 0.5 * np.sum(z * z, axis=1))
                          - (ridge.log_g_density(v_new) - log_det_new - 0.5 * np.sum(z_new * z_new, axis=1)))
        return new, factor
