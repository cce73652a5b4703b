"""emcee ensembles over coefficients, extra-term parameters, every flight's initial conditions and noise.

* Several independent ensembles (R-hat across ensembles), each with its own ``emcee.backends.HDFBackend``
  file (written once per round by :class:`.backend.RoundBackend`), advanced in rounds of ``check_every``
  steps (in parallel processes), so an interrupted run resumes from the files with no lost samples.
* Walkers start from a ridge-aware approximation of the posterior (:mod:`.proposals`), over-dispersed
  relative to the Laplace approximation where the posterior is, so that R-hat across ensembles can see
  a failure to mix.
* Moves: Metropolis–Hastings moves with exact acceptance ratios (each leaves the posterior invariant),
  mixed with emcee's differential-evolution moves:
  - block moves (:mod:`.moves`, a ``block_fraction`` share, used when the walkers are fewer than
    2·dim + 2: by default on runs whose 2·dim + 2 exceeds ``WALKERS_CAP``): sweeps over the flights that
    update every flight's own block given the shared parameters (one flight's simulation per proposal),
    drawing it afresh from a ridge proposal's conditional (:class:`.moves.RidgeFlightRefresh`) or by a
    random walk (:class:`.moves.FlightBlockMove`); without ridge proposals, random-walk sweeps and shared
    random-walk steps that carry every flight along its regression on the shared parameters. With them
    the ensembles need only 2·(s + p_max) + 2 walkers (s shared parameters, p_max the largest flight
    block) instead of 2·dim + 2, so a step's cost grows with the flights only through their simulations;
  - independence jumps from :func:`.proposals.independence_proposal`: the Laplace approximation plus a
    ridge proposal along every profile-likelihood path (:mod:`.profile`) that departs from it. A weakly
    identified combination (the demo's CM0 and CMq with the flights' wobble initial conditions) makes
    a thin curved valley that a Gaussian cannot cover and that local moves cross only over thousands
    of steps; the ridge proposals follow the valley, so the jumps reach all of it. The independence
    proposal's weights and the Gaussian reference (the random-walk sweeps' shape) are re-fitted to the
    pooled ensembles' samples twice during warm-up (after ``adapt_steps`` and 2·``adapt_steps`` steps),
    fixed afterwards, and the warm-up is discarded as burn-in;
  - ridge carries (:class:`.moves.RidgeCarry`, half of the Metropolis–Hastings share when there are
    ridge proposals): the coefficients drawn afresh along a ridge while every flight keeps its whitened
    place across the valley, so that their acceptance does not fall as flights are added (an independence
    jump redraws every flight too, and pays the proposal's misfit in all of their dimensions);
  - emcee's DE moves, mostly with γ scaled down (local steps accepted often), some at the default γ,
    and snooker moves.
  The Metropolis–Hastings moves (independence jumps and ridge carries) have the larger share
  (``independence_fraction``, default 0.8): their jumps do not depend on where the other walkers are.
  DE moves do, and in ~60 dimensions an ensemble that has contracted re-expands under them only over thousands of steps (an exact Gaussian with the
  AR(1) campaign's posterior covariance: DE alone held an ensemble started at 0.83 of the sd at 0.78
  for 2000 steps) — a contraction every ensemble shares, which R-hat, ESS and τ cannot see. With a 0.3
  share the posteriors stopped 5–19 % too narrow (tests/test_sample.py, the AR(1) importance-sampling
  test; the demo's lift and drag sds grew by up to 13 % at 0.8).
* Stopping: R-hat across ensembles < ``rhat`` for every parameter, bulk ESS ≥ ``ess`` for every
  coefficient (rank-normalised, computed as ArviZ does in :mod:`.diagnostics_mcmc`; walkers as chains,
  so walkers that have not mixed lower it), and every chain ≥ ``n_tau`` · τ after burn-in (τ: emcee's
  integrated autocorrelation time, reported with N/τ; emcee's walker-averaged τ ignores differences
  between walkers, which the ESS catches, so the default n_tau is a floor of 10 rather than emcee's 50);
  or the ``max_steps`` cap.
"""
from __future__ import annotations

import json
import logging
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

import emcee
import numpy as np
import scipy.fft

from ...physics.parallel import mp_context
from .backend import RoundBackend
from ..model.config import SamplerSettings
from . import mcmc_stats
from ..model.problem import Problem
from .moves import FlightBlockMove, IndependenceJump, RidgeCarry, RidgeFlightRefresh, SharedShift, block_factors
from .proposals import CompositeProposal, Proposal, RidgeProposal

logger = logging.getLogger(__name__)

#: re-fits of the Gaussian reference (and of the independence proposal's weights) during warm-up
ADAPTATIONS = 2

# The Metropolis–Hastings share is all independence jumps. Preconditioned Crank–Nicolson steps (ρ = 0.97)
# on the Gaussian reference had half of it until stop 31; measured from stationary walkers of
# benchmarks/bench_scale.py's kept runs (benchmarks/bench_moves.py: acceptance and mean squared jump in posterior sds),
# they were accepted 0.7 % (4 flights), 0.3 % (12) and 0.0 % (24) of the time and moved the coefficients
# by 0.005 sd² per proposal, against 10 %, 10 % and 3 % and 1.7, 1.9 and 0.6 sd² for the independence
# jumps (the posterior's curved valley is not the Gaussian the pCN steps are reversible for). With their
# share given to the independence jumps, on the same steps of the same data (bench_scale.py): the
# coefficients' smallest bulk ESS 879 → 1141 (4 flights, steps 150–300) and 805 → 1006 (12 flights,
# 175–350), τ 14.3 → 12.8 and 18.6 → 15.8 steps.

#: Share of the Metropolis–Hastings moves given to ridge carries (:class:`.moves.RidgeCarry`) when the
#: independence proposal has ridge proposals; the rest are independence jumps. Measured at stop 38 from the
#: stationary walkers of seed 18's kept runs (benchmarks/bench_scale.py, one move alone for 20 steps):
#: ridge carries accepted 27 %, 36 %, 35 % at 4, 12, 24 flights with mean squared jumps of 0.41–0.71,
#: 0.44–0.88, 0.36–0.76 posterior variances per coefficient and step, independence jumps 13 %, 14 %, 6 %
#: with 0.20–0.31, 0.22–0.30, 0.09–0.18. Carries keep the flights' whitened places, which the independence
#: jumps redraw: at 4 flights (no flight-block sweeps) those jumps keep half of the share. (With this
#: share and the old block moves, random-walk sweeps and shared shifts, seed 18's 24-flight chain needed
#: 700 steps, τ 30 steps in the initial conditions; with the refresh sweeps below, 300.)
CARRY_SHARE = 0.5

#: Within the DE share: emcee's DE move with γ scaled down (accepted ~30 % on the demo posterior,
#: against ~4 % for the default γ = 2.38/√(2·dim)), the default DE move and the snooker move.
DE_SCALE = 0.35
DE_MIX = ((DE_SCALE, 0.7), (1.0, 0.15), ("snooker", 0.15))


#: Within the block share: Metropolis-within-Gibbs sweeps over the flights' own blocks, and shared shifts
#: that carry the flights along (:mod:`.moves`).
BLOCK_MIX = (("gibbs", 0.6), ("shift", 0.4))
#: The block share when the independence proposal has ridge proposals: sweeps that draw every flight afresh
#: from a ridge's conditional (:class:`.moves.RidgeFlightRefresh`) and the random-walk sweeps. The shared
#: shifts are left out: on seed 18's 24-flight walkers they were accepted 0.5 % of the time (their
#: regression is linear, the valley is not), while the refresh sweeps moved the flights' initial conditions
#: by 1.27 posterior variances per step (median; random-walk sweeps 0.056, independence jumps 0.11).
RIDGE_BLOCK_MIX = (("refresh", 0.7), ("gibbs", 0.3))


def uses_block_moves(block_fraction: float, walkers: int, dim: int) -> bool:
    """Whether the ensembles get block moves: when they are enabled (``block_fraction`` > 0) and the walkers
    are fewer than 2·dim + 2, too few for the DE moves to span every direction. With enough walkers the
    ensemble's own moves do better per step (demo, 4 flights, 118 walkers on a quiet machine: 1650 steps
    to the stopping rule with a 0.3 block share, 950 without, same data)."""
    return block_fraction > 0 and walkers < 2 * dim + 2


def _moves(problem: Problem, proposal: Proposal, independence: CompositeProposal, fraction: float,
           block_fraction: float = 0.0, walkers: int | None = None):
    """emcee's (move, weight) list: a ``block_fraction`` share of block moves (when :func:`uses_block_moves`;
    ``walkers`` None: whenever enabled), then of the rest a ``fraction`` share of Metropolis–Hastings moves
    (independence jumps) and DE moves. With fewer than 2·dim ``walkers`` (block moves on), the DE moves
    propose within the walkers' span only: still exact, so emcee's guard against them is lifted
    (``live_dangerously``)."""
    dangerous = walkers is not None and walkers < 2 * problem.dim
    if walkers is not None and not uses_block_moves(block_fraction, walkers, problem.dim):
        block_fraction = 0.0
    moves = []
    ridges = [j for j, q in enumerate(independence.parts) if isinstance(q, RidgeProposal)]
    ridge_parts = tuple(independence.parts[j] for j in ridges)
    ridge_weights = independence.log_weights[ridges]
    if block_fraction > 0:
        conditional, shared, regression = block_factors(problem, proposal.cov)
        for kind, share in (RIDGE_BLOCK_MIX if ridges else BLOCK_MIX):
            if kind == "gibbs":
                move = FlightBlockMove(problem, conditional)
            elif kind == "refresh":
                move = RidgeFlightRefresh(problem, ridge_parts, ridge_weights)
            else:
                move = emcee.moves.MHMove(SharedShift(shared, regression))
            moves.append((move, block_fraction * share))
    rest = 1.0 - block_fraction
    if fraction > 0:
        carry = CARRY_SHARE if ridges else 0.0
        moves.append((IndependenceJump(independence), rest * fraction * (1 - carry)))
        if carry:
            move = emcee.moves.MHMove(RidgeCarry(ridge_parts, ridge_weights, fresh=problem.ic_start - 1))
            moves.append((move, rest * fraction * carry))
    if fraction < 1:
        g0 = 2.38 / np.sqrt(2 * problem.dim)
        for kind, share in DE_MIX:
            move = (emcee.moves.DESnookerMove(live_dangerously=dangerous) if kind == "snooker"
                    else emcee.moves.DEMove(gamma0=kind * g0, live_dangerously=dangerous))
            moves.append((move, rest * (1 - fraction) * share))
    return moves


#: most default walkers per ensemble with block moves enabled: below it every run gets 2·dim + 2 walkers
#: and the ensemble's own moves (small runs: fewer walkers were not cheaper, the demo's 4 flights took twice
#: as long with 46 walkers and block moves as with 118 without); above it, the walkers stay at this many
#: (or the block minimum) and the block moves (:func:`uses_block_moves`) make up for them, so a step's cost
#: grows with the flights only through their simulations
WALKERS_CAP = 128


def n_walkers(settings: SamplerSettings, problem: Problem) -> int:
    """Walkers per ensemble: ``settings.walkers`` (made even), at least the minimum; by default (``walkers:
    0``) 2·dim + 2, or with block moves enabled max(minimum, :data:`WALKERS_CAP`) when 2·dim + 2 is more.

    The minimum is 2·dim + 2 when the ensemble's own moves (DE) must span the whole space; with block moves
    enabled (``block_fraction`` > 0: every flight's block and the shared block have full-rank moves of their
    own, used whenever the walkers are fewer than 2·dim + 2) it is 2·(s + p_max) + 2, s the shared parameters
    and p_max the largest flight block.

    Parameters
    ----------
    settings : SamplerSettings
    problem : Problem

    Returns
    -------
    int
    """
    if settings.block_fraction > 0:
        block = max(problem.layout.flight_slice(k).stop - problem.layout.flight_slice(k).start
                    for k in range(problem.n_flights))
        least = 2 * (problem.ic_start + block) + 2
        default = max(least, min(2 * problem.dim + 2, WALKERS_CAP))
    else:
        least = default = 2 * problem.dim + 2
    w = settings.walkers or default
    return max(w + (w % 2), least)


def initial_walkers(start: CompositeProposal, n: int, problem: Problem, rng: np.random.Generator) -> np.ndarray:
    """Draws from ``start`` with finite log-posterior (redrawn otherwise), linearly independent."""
    random = np.random.RandomState(rng.integers(2**32))
    out = np.empty((n, problem.dim))
    filled = 0
    for _ in range(50):
        cand = start.draw(n, random)
        ok = np.isfinite(problem.log_prob(cand))
        take = min(int(ok.sum()), n - filled)
        out[filled: filled + take] = cand[ok][:take]
        filled += take
        if filled == n:
            return out
    raise RuntimeError("could not place walkers with finite posterior around the least-squares optimum")


# ------------------------------------------------------------------------------------------------------
# workers: one ensemble advanced by n steps; the problem reaches them through the initializer
_WORKER: dict = {}


def _init_worker(problem, proposal, independence, fraction, block_fraction=0.0):
    _WORKER.update(problem=problem, proposal=proposal, independence=independence, fraction=fraction,
                   block_fraction=block_fraction)


class _InProcessPool:
    """The worker-pool interface run in this process, for ``processes: 1``: no child process, so that a
    run can itself be a task of a daemonic worker (a Dask worker, which may not start children)."""

    def __init__(self, initargs):
        self.initargs = initargs

    def __enter__(self):
        _init_worker(*self.initargs)
        return self

    def __exit__(self, *exc):
        _WORKER.clear()
        return False

    def map(self, fn, tasks):
        return [fn(t) for t in tasks]


def _pool(settings, initargs):
    """Worker pool advancing the ensembles: ``min(processes, ensembles)`` processes, or this process alone."""
    if settings.processes <= 1:
        return _InProcessPool(initargs)
    return mp_context().Pool(min(settings.processes, settings.ensembles), initializer=_init_worker,
                             initargs=initargs)


def _advance(task) -> int:
    path, n_steps, start, seed = task
    problem, proposal, independence = _WORKER["problem"], _WORKER["proposal"], _WORKER["independence"]
    backend = RoundBackend(str(path))
    nw = start.shape[0] if start is not None else backend.shape[0]
    sampler = emcee.EnsembleSampler(nw, problem.dim, problem.log_prob_blobs, vectorize=True, backend=backend,
                                    moves=_moves(problem, proposal, independence, _WORKER["fraction"],
                                                 _WORKER["block_fraction"], nw),
                                    blobs_dtype=float)
    # fewer walkers than parameters (block moves on): they cannot be linearly independent, which emcee's
    # start check demands; the block moves, not the ensemble's span, make the chain move in every direction
    skip = nw <= problem.dim
    try:
        if start is not None:
            sampler.random_state = np.random.RandomState(seed).get_state()
            sampler.run_mcmc(start, n_steps, progress=False, skip_initial_state_check=skip)
        else:
            sampler.run_mcmc(None, n_steps, progress=False, skip_initial_state_check=skip)
    finally:
        backend.flush()     # the steps done, also when interrupted
    return backend.iteration


@dataclass
class Chains:
    """Post-burn-in samples: chain (n_ensembles, n_steps, n_walkers, dim), log_prob alike without dim,
    σ per noise group (n_ensembles, n_steps, n_walkers, n_groups) drawn from its exact conditional, and the
    effective sums of squares S̃_g it was drawn from (alike; the sampler's blobs; None when not kept)."""

    chain: np.ndarray
    log_prob: np.ndarray
    sigma: np.ndarray
    acceptance: np.ndarray          # (n_ensembles, n_walkers)
    burn: int
    total_steps: int
    tau: np.ndarray                 # (n_ensembles, dim) steps
    converged: bool
    reason: str
    history: list = field(default_factory=list)
    wall_time_s: float = 0.0
    ss: np.ndarray | None = None


class StoredChains:
    """The ensembles' stored steps from ``start`` on, read a block of parameters at a time, so that a
    convergence check holds one block of the chain in memory, not the whole chain (at 24 flights the
    chain after the warm-up was 1.0 GB at step 950 and grew with every step).

    Parameters
    ----------
    paths : list of Path
        The ensembles' chain files (:func:`chain_paths`).
    start : int
        First step read.

    Attributes
    ----------
    shape : tuple
        (n_ensembles, n_steps, n_walkers, dim): n_steps the shortest ensemble's steps after ``start``.
    """

    def __init__(self, paths, start: int = 0):
        self.backends = [emcee.backends.HDFBackend(str(p), read_only=True) for p in paths]
        n = min(b.iteration for b in self.backends) - start
        if n <= 0:
            raise ValueError(f"{Path(paths[0]).parent}: no stored step after step {start}")
        self.start = start
        self.shape = (len(paths), n, *self.backends[0].shape)
        self._lock = threading.Lock()      # one HDF5 read at a time (the check's threads share the files)

    def block(self, skip: int, cols: slice) -> np.ndarray:
        """Steps ``skip`` … of the parameters ``cols``: (n_ensembles, n_steps − skip, n_walkers, len(cols))."""
        first, n = self.start + skip, self.shape[1] - skip
        with self._lock:
            out = np.empty((self.shape[0], n, self.shape[2], len(range(self.shape[3])[cols])))
            for e, b in enumerate(self.backends):
                with b.open() as f:
                    out[e] = f[b.name]["chain"][first: first + n, :, cols]
        return out


class _InMemoryChains:
    """An in-memory chain (n_ensembles, n_steps, n_walkers, dim) behind :class:`StoredChains`' interface."""

    def __init__(self, chain: np.ndarray):
        self.chain = chain
        self.shape = chain.shape

    def block(self, skip: int, cols: slice) -> np.ndarray:
        return self.chain[:, skip:, :, cols]


def _read(paths, blobs: bool = False, start: int = 0):
    """The ensembles' stored steps from ``start`` on: chain (n_ens, n, walkers, dim), log-probabilities
    (n_ens, n, walkers), acceptance fractions (n_ens, walkers) and, with ``blobs``, S_g (n_ens, n, walkers,
    n_groups); n the shortest ensemble's steps after ``start``. Read into one preallocated array per
    quantity, only the steps asked for (memory: the part of the chain in use, not the whole run)."""
    stored = StoredChains(paths, start)
    backends = stored.backends
    _, n, walkers, dim = stored.shape
    chain = np.empty(stored.shape)
    lp = np.empty((len(paths), n, walkers))
    acc = np.stack([b.accepted / max(b.iteration, 1) for b in backends])
    ss = None
    for e, b in enumerate(backends):
        with b.open() as f:
            g = f[b.name]
            chain[e] = g["chain"][start: start + n]
            lp[e] = g["log_prob"][start: start + n]
            if blobs:  # S_g per noise group; emcee drops the last axis when there is one
                x = np.asarray(g["blobs"][start: start + n], float).reshape(n, walkers, -1)
                if ss is None:
                    ss = np.empty((len(paths), n, walkers, x.shape[-1]))
                ss[e] = x
    return (chain, lp, acc, ss) if blobs else (chain, lp, acc)


#: most float64 values of one batch of FFTs in :func:`_tau` (bounds its memory: 2²⁴ values, 128 MB complex)
TAU_BATCH_VALUES = 1 << 24


def _tau(chain: np.ndarray, c: float = 5.0, workers: int = 1) -> np.ndarray:
    """Integrated autocorrelation time per parameter (steps): emcee's estimator (walker-averaged
    autocorrelation function, Sokal's automatic window c), skipping walkers that did not move in the
    window (their autocorrelation is undefined; emcee would return NaN).

    The autocorrelation functions are ``emcee.autocorr.function_1d``'s (the centred series' FFT, zero-padded
    so that the circular correlation is the linear one, normalised at lag 0), computed for every walker and
    parameter of a batch at once (at most :data:`TAU_BATCH_VALUES` transform values) with the shortest fast
    padding ≥ 2·n_steps − 1 instead of emcee's 2·next power of two: the same numbers to rounding
    (tests/test_sampler_tau.py), several times faster (``benchmarks/bench_convergence.py``).

    Parameters
    ----------
    chain : (n_steps, n_walkers, dim) array
        One ensemble's steps.
    c : float
        Sokal's window constant.
    workers : int
        Threads of the FFTs (the convergence check runs while the sampling processes wait).

    Returns
    -------
    (dim,) array
        τ [steps]; inf for a parameter no walker moved in.
    """
    n_steps, n_w, dim = chain.shape
    n_fft = scipy.fft.next_fast_len(2 * n_steps - 1, real=True)
    per = max(1, TAU_BATCH_VALUES // (n_fft * n_w))            # parameters per batch
    tau = np.empty(dim)
    for lo in range(0, dim, per):
        x = np.moveaxis(chain[:, :, lo: lo + per], 0, -1)      # (n_w, p, n_steps): time contiguous
        moved = np.ptp(x, axis=-1) > 0                         # (n_w, p)
        x = x - x.mean(axis=-1, keepdims=True)
        norm = np.sqrt(np.einsum("wpt,wpt->wp", x, x))         # √(lag-0 autocovariance · n_steps)
        x /= np.where(moved, norm, 1.0)[..., None]             # unit lag 0: each walker's ACF is normalised
        x[~moved] = 0.0                                        # a walker that stayed put has none
        f = scipy.fft.rfft(x, n=n_fft, axis=-1, workers=workers)
        power = np.einsum("wpk->pk", f.real ** 2 + f.imag ** 2)  # Σ over walkers: the transform is linear
        acf = scipy.fft.irfft(power, n=n_fft, axis=-1, workers=workers)[:, :n_steps]
        used = moved.sum(axis=0)                               # (p,)
        taus = 2.0 * np.cumsum(acf / np.maximum(used, 1)[:, None], axis=-1) - 1.0
        for j in range(x.shape[1]):
            tau[lo + j] = np.inf if used[j] == 0 else taus[j, emcee.autocorr.auto_window(taus[j], c)]
    return tau


#: most parameters per block in the convergence statistics
CHECK_BLOCK = 32
#: most draws (ensembles × steps × walkers × parameters) per block: bounds the rank and FFT work arrays
#: (≈ 10 arrays of this many values per block in flight; 2²² values: 32 MB each)
CHECK_VALUES = 1 << 22


def convergence(chain, settings: SamplerSettings, coef_idx: np.ndarray, first_step: int = 0):
    """Burn-in, τ, R-hat and ESS; returns a verdict dict.

    Parameters
    ----------
    chain : (n_ens, n, n_walkers, dim) array or StoredChains
        The ensembles' steps from ``first_step`` on (the warm-up before it is burn-in); stored chains are
        read a block of parameters at a time (:class:`StoredChains`).
    settings : SamplerSettings
    coef_idx : (k,) int array
        Parameters whose bulk ESS must reach ``settings.ess``.
    first_step : int
        Step number of ``chain[:, 0]``.

    Returns
    -------
    dict
        ``burn`` (absolute step: the warm-up and at least 5 τ after it, at most half of what follows it),
        ``tau`` (n_ens, dim), ``n_over_tau``, ``rhat_max`` (every parameter; the rule's), ``rhat_max_coef``
        (the coefficients'), ``ess_min_coef``, ``converged``. Every statistic
        is computed per parameter, in blocks of at most :data:`CHECK_BLOCK` parameters and
        :data:`CHECK_VALUES` draws (``settings.processes`` blocks at once, in threads: the sampling
        processes wait during a check), so memory stays bounded as the chains grow: two passes over the
        blocks, τ on the whole window (for the burn-in), then τ, R-hat and ESS after it.
    """
    source = chain if hasattr(chain, "block") else _InMemoryChains(np.asarray(chain))
    n_ens, n, n_w, dim = source.shape
    workers = max(1, settings.processes)
    per = max(1, min(CHECK_BLOCK, CHECK_VALUES // (n_ens * n * n_w)))
    blocks = [slice(j, min(j + per, dim)) for j in range(0, dim, per)]
    coef = np.zeros(dim, bool)
    coef[np.asarray(coef_idx)] = True

    with ThreadPoolExecutor(max_workers=workers) as threads:     # the sorts and FFTs release the GIL
        def tau_of(x):
            return np.array([_tau(x[e]) for e in range(n_ens)])             # (n_ens, block)

        tau0 = np.concatenate(list(threads.map(lambda b: tau_of(source.block(0, b)), blocks)), axis=1)
        skip = int(min(np.ceil(5 * np.nanmax(tau0)), n // 2))

        def after_burn(b):
            x = source.block(skip, b)
            wanted = np.flatnonzero(coef[b])                        # the rule asks ESS of the coefficients alone
            return (tau_of(x), mcmc_stats.rhat(x, layout="ensembles"),
                    mcmc_stats.ess(x[..., wanted], layout="walkers") if wanted.size else np.zeros(0))

        parts = list(threads.map(after_burn, blocks))
    tau = np.concatenate([p[0] for p in parts], axis=1)
    rh = np.concatenate([p[1] for p in parts])
    ess = np.concatenate([p[2] for p in parts])
    n_over_tau = (n - skip) / np.nanmax(tau)
    ok = (first_step + n >= settings.min_steps and n_over_tau >= settings.n_tau and np.all(rh < settings.rhat)
          and np.all(ess >= settings.ess))
    return {"burn": first_step + skip, "tau": tau, "n_over_tau": float(n_over_tau), "rhat_max": float(np.max(rh)),
            "rhat_max_coef": float(np.max(rh[coef])), "ess_min_coef": float(np.min(ess)),
            "converged": bool(ok)}


@dataclass(frozen=True)
class Progress:
    """Where the ensembles stand toward the stopping rule, as shown on the progress bar.

    Attributes
    ----------
    steps : int
        Steps done by every ensemble.
    cap : int
        The ``max_steps`` cap (shown, never used as a measure of progress).
    fraction : float
        Progress toward convergence in [0, 1] (:func:`convergence_fraction`); 0 during warm-up.
    verdict : dict or None
        The last convergence check (:func:`convergence`), None before the first.
    """

    steps: int
    cap: int
    fraction: float
    verdict: dict | None

    def describe(self, settings: SamplerSettings) -> str:
        """One line: step counter with the cap, and each criterion's figure beside its target."""
        head = f"step {self.steps} (cap {self.cap})"
        if self.verdict is None:
            return f"{head}, warm-up until step {warm_up_steps(settings)}"
        v = self.verdict
        return (f"{head}, R-hat {v['rhat_max']:.3f} (< {settings.rhat:g}), ESS {v['ess_min_coef']:.0f} "
                f"(≥ {settings.ess:g}), N/τ {v['n_over_tau']:.1f} (≥ {settings.n_tau:g})")


def warm_up_steps(settings: SamplerSettings) -> int:
    """Steps before the first convergence check: the warm-up adaptations and one round of ``check_every``.

    Parameters
    ----------
    settings : SamplerSettings
        The sampler settings.

    Returns
    -------
    int
        Steps of every ensemble.
    """
    return settings.adapt_steps * ADAPTATIONS + settings.check_every


def convergence_fraction(verdict: dict, settings: SamplerSettings, steps: int) -> float:
    """How far the ensembles are toward the stopping rule: the worst of its criteria, each as a fraction.

    R-hat: (rhat − 1) / (R-hat_max − 1) (1 when R-hat max reaches the target); ESS: min coefficient bulk
    ESS / ``ess``; N/τ: (N/τ) / ``n_tau``; steps: ``steps`` / ``min_steps``. The rule is met exactly when
    every fraction reaches 1 (R-hat strictly below its target), so the result is 1 only then.

    Parameters
    ----------
    verdict : dict
        A convergence check (:func:`convergence`): ``rhat_max``, ``ess_min_coef``, ``n_over_tau``,
        ``converged``.
    settings : SamplerSettings
        Targets ``rhat``, ``ess``, ``n_tau``, ``min_steps``.
    steps : int
        Steps done by every ensemble.

    Returns
    -------
    float
        In [0, 1]; 1 if and only if ``verdict["converged"]``.
    """
    if verdict["converged"]:
        return 1.0
    excess = verdict["rhat_max"] - 1.0
    parts = [(settings.rhat - 1.0) / excess if excess > 0 else (1.0 if excess <= 0 else np.nan),
             verdict["ess_min_coef"] / settings.ess,
             verdict["n_over_tau"] / settings.n_tau,
             steps / max(settings.min_steps, 1)]
    finite = [p if np.isfinite(p) else 0.0 for p in parts]
    # not converged: at least one criterion is unmet, so stay below 1 even when rounding says otherwise
    return float(min(min(finite), 0.999))


def chain_paths(out_dir: Path, ensembles: int) -> list[Path]:
    """The emcee chain files ``<out_dir>/chains/ensemble_<k>.h5`` of a run.

    Parameters
    ----------
    out_dir : Path
        The run's output folder.
    ensembles : int
        Number of ensembles.

    Returns
    -------
    list of Path
    """
    return [Path(out_dir) / "chains" / f"ensemble_{e}.h5" for e in range(ensembles)]


def saved_steps(out_dir: Path, ensembles: int) -> list[int] | None:
    """Steps saved in each ensemble's chain file, when the run folder holds everything a resume needs.

    Parameters
    ----------
    out_dir : Path
        The run's output folder.
    ensembles : int
        Number of ensembles of the configuration.

    Returns
    -------
    list of int or None
        Steps per ensemble; None when no chain file exists.

    Raises
    ------
    ValueError
        Some but not all chain files, or the proposals saved beside them, are missing.
    """
    chain_dir = Path(out_dir) / "chains"
    paths = chain_paths(out_dir, ensembles)
    present = [p.exists() for p in paths]
    if not any(present):
        return None
    missing = [p.name for p, ok in zip(paths, present) if not ok]
    missing += [n for n in ("proposal.npz", "independence.npz") if not (chain_dir / n).exists()]
    if missing:
        raise ValueError(f"{chain_dir}: incomplete chain files (no {', '.join(missing)}); cannot resume "
                         "(remove the folder to restart)")
    return [int(emcee.backends.HDFBackend(str(p), read_only=True).iteration) for p in paths]


def _fresh_start(independence: CompositeProposal, settings: SamplerSettings, problem: Problem, nw: int):
    """The Gaussian reference and every ensemble's initial walkers, drawn in a fixed order from the seed (so
    a resume can redraw the start of an ensemble that never saved a step)."""
    rng = np.random.default_rng(settings.seed)
    proposal = Proposal.from_cov(*independence.moments(np.random.RandomState(rng.integers(2**32))))
    starts = [initial_walkers(independence, nw, problem, rng) for _ in range(settings.ensembles)]
    return proposal, starts


def _read_history(path: Path) -> list:
    return json.loads(path.read_text()) if path.is_file() else []


class _Bar:
    """The convergence bar (tqdm; none when ``progress`` is False or stderr is not a terminal), and the
    same figures as log lines when there is no bar."""

    FORMAT = "{desc}: {percentage:3.0f}% of the way to convergence |{bar}|{postfix} [{elapsed}]"

    def __init__(self, settings: SamplerSettings, progress: bool):
        from tqdm import tqdm
        self.settings = settings
        self.bar = tqdm(total=100, desc="sampling", bar_format=self.FORMAT, leave=False,
                        disable=None if progress else True)

    @property
    def shown(self) -> bool:
        return not self.bar.disable

    def show(self, state: Progress, checked: bool) -> None:
        line = state.describe(self.settings)
        if self.shown:
            self.bar.n = int(round(100 * state.fraction))
            self.bar.set_postfix_str(line, refresh=False)
            self.bar.refresh()
        if checked:
            logger.log(logging.DEBUG if self.shown else logging.INFO,
                       f"convergence check: {line}; {100 * state.fraction:.0f}% of the way")

    def close(self) -> None:
        self.bar.close()


def run_sampler(problem: Problem, independence: CompositeProposal | None, settings: SamplerSettings, out_dir: Path,
                resume: bool = False, progress: bool = True) -> Chains:
    """Run (or resume) the ensembles until converged or the cap; returns the post-burn-in chains.

    Parameters
    ----------
    problem : Problem
        The run's statistical problem.
    independence : CompositeProposal or None
        The ridge-aware posterior approximation (:func:`.proposals.independence_proposal`) that starts
        the walkers and proposes the independence jumps; on resume (None allowed) the one saved with the
        chains is used.
    settings : SamplerSettings
        Ensembles, walkers, stopping rule, cap, seed, processes.
    out_dir : Path
        The run's output folder; chain files, proposals and ``history.json`` go to ``<out_dir>/chains``.
    resume : bool
        Continue from the saved chain files: ensembles saved with fewer steps than the longest are first
        advanced to its length, so that all ensembles have the same number of steps; the history saved
        in ``chains/history.json`` is kept and extended.
    progress : bool
        Show a bar of the progress toward convergence (on a terminal only); otherwise the convergence
        checks are logged (INFO).

    Returns
    -------
    Chains
        Post-burn-in samples of every ensemble (all of equal length) and the run's history.
    """
    t_start = time.perf_counter()
    out_dir = Path(out_dir)
    chain_dir = out_dir / "chains"
    chain_dir.mkdir(parents=True, exist_ok=True)
    paths = chain_paths(out_dir, settings.ensembles)
    prop_path, ind_path, hist_path = chain_dir / "proposal.npz", chain_dir / "independence.npz", chain_dir / "history.json"
    nw = n_walkers(settings, problem)
    steps = saved_steps(out_dir, settings.ensembles) if resume else None
    history: list = []
    if steps is not None:
        proposal = Proposal.load(prop_path)
        independence = CompositeProposal.load(ind_path)
        for p in paths:
            shape = emcee.backends.HDFBackend(str(p), read_only=True).shape
            if tuple(shape) != (nw, problem.dim):
                raise ValueError(f"{p}: chains of {shape[0]} walkers × {shape[1]} parameters, the configuration "
                                 f"has {nw} × {problem.dim}; cannot resume (remove the folder to restart)")
        history = _read_history(hist_path)
        done = max(steps)
        # an ensemble that never saved a step restarts from its original walkers (same seed, same draws)
        starts = _fresh_start(independence, settings, problem, nw)[1] if min(steps) == 0 else [None] * len(paths)
        starts = [s if k == 0 else None for s, k in zip(starts, steps)]
        history.append({"steps": done, "resumed": True, "ensemble_steps": steps})
        hist_path.write_text(json.dumps(history, indent=1))
    else:
        for p in paths:
            p.unlink(missing_ok=True)
        hist_path.unlink(missing_ok=True)
        if independence is None:
            raise ValueError(f"{chain_dir}: nothing to resume; a fresh run needs the posterior approximation")
        proposal, starts = _fresh_start(independence, settings, problem, nw)
        proposal.save(prop_path)
        independence.save(ind_path)
        steps = [0] * len(paths)
        done = 0

    def record(entry):
        history.append(entry)
        hist_path.write_text(json.dumps(history, indent=1))

    coef_idx = np.arange(problem.n_coef + problem.n_ext)
    adapt_at = [settings.adapt_steps * (i + 1) for i in range(ADAPTATIONS)]
    bar = _Bar(settings, progress)
    verdict = {"converged": False, "tau": np.full((1, problem.dim), np.nan)}
    checked, fraction = None, 0.0
    bar.show(Progress(done, settings.max_steps, 0.0, None), checked=False)
    finished = False
    try:
        while not finished:
            with _pool(settings, (problem, proposal, independence, settings.independence_fraction,
                                  settings.block_fraction)) as pool:
                if min(steps) < done:   # resumed with unequal ensembles: bring the shorter ones level first
                    tasks = [(p, done - k, s, settings.seed * 1000 + e)
                             for e, (p, s, k) in enumerate(zip(paths, starts, steps)) if k < done]
                    pool.map(_advance, tasks)
                    starts = [None] * len(paths)
                    steps = [int(emcee.backends.HDFBackend(str(p), read_only=True).iteration) for p in paths]
                    if min(steps) != done or max(steps) != done:
                        raise RuntimeError(f"{chain_dir}: could not align the ensembles at step {done}: {steps}")
                    record({"steps": done, "aligned": True, "ensemble_steps": steps})
                while True:
                    if done > 0 and proposal.adapted < ADAPTATIONS and done >= adapt_at[proposal.adapted]:
                        lo = adapt_at[proposal.adapted - 1] if proposal.adapted else 0
                        first = (lo + done) // 2
                        warm = _read(paths, start=first)[0][:, : done - first].reshape(-1, problem.dim)
                        proposal = proposal.refit(warm)
                        proposal.save(prop_path)
                        sub = warm[np.random.default_rng(settings.seed + done).choice(len(warm), min(len(warm), 4000),
                                                                                     replace=False)]
                        independence = independence.reweighted(sub)
                        independence.save(ind_path)
                        record({"steps": done, "adapted_proposal": proposal.adapted,
                                "independence_weights": np.exp(independence.log_weights).round(4).tolist()})
                        logger.debug(f"warm-up adaptation {proposal.adapted} of {ADAPTATIONS} at step {done}")
                        break  # new pool with the new proposal
                    if done >= adapt_at[-1] + settings.check_every and checked != done:
                        verdict = convergence(StoredChains(paths, start=adapt_at[-1]), settings, coef_idx,
                                              first_step=adapt_at[-1])
                        checked, fraction = done, convergence_fraction(verdict, settings, done)
                        record({"steps": done, "elapsed_s": round(time.perf_counter() - t_start, 3),
                                **{k: v for k, v in verdict.items() if k != "tau"}})
                        bar.show(Progress(done, settings.max_steps, fraction, verdict), checked=True)
                        if verdict["converged"]:
                            finished = True
                            break
                    if done >= settings.max_steps:
                        finished = True
                        break
                    n = min(settings.check_every, settings.max_steps - done)
                    if proposal.adapted < ADAPTATIONS:
                        n = min(n, adapt_at[proposal.adapted] - done)
                    tasks = [(p, n, s, settings.seed * 1000 + e) for e, (p, s) in enumerate(zip(paths, starts))]
                    steps = [int(k) for k in pool.map(_advance, tasks)]
                    done = min(steps)
                    starts = [None] * len(paths)
                    bar.show(Progress(done, settings.max_steps, fraction, verdict if checked is not None else None),
                             checked=False)
    finally:
        bar.close()
    lengths = {int(emcee.backends.HDFBackend(str(p), read_only=True).iteration) for p in paths}
    if len(lengths) != 1:
        raise RuntimeError(f"{chain_dir}: ensembles of unequal length {sorted(lengths)} after sampling")
    total = lengths.pop()
    # no convergence check (the cap came during the warm-up): the warm-up is burn-in, at most half the chain
    burn = verdict["burn"] if checked is not None else min(adapt_at[-1], total // 2)
    chain, lp, acc, ss = _read(paths, blobs=True, start=burn)
    sigma = problem.draw_sigma(ss.reshape(-1, problem.n_groups), np.random.default_rng(settings.seed),
                               chain.reshape(-1, problem.dim)).reshape(ss.shape)
    reason = ("converged" if verdict["converged"] else
              f"cap of {settings.max_steps} steps reached before convergence")
    hist_path.write_text(json.dumps(history, indent=1))
    return Chains(chain=chain, log_prob=lp, sigma=sigma, acceptance=acc, burn=burn,
                  total_steps=total, tau=verdict["tau"], converged=verdict["converged"], reason=reason,
                  history=history, wall_time_s=time.perf_counter() - t_start, ss=ss)
