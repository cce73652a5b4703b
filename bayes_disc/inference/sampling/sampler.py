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
    jump redraws every flight too, and pays the proposal's misfit in all of their dimensions); half of
    them keep the other shared parameters' whitened places too, and so follow a valley that bends in
    several shared directions at once (:data:`.mixing.CARRY_MIX`);
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
  coefficient (rank-normalised, computed as ArviZ does in :mod:`.mcmc_stats`; walkers as chains,
  so walkers that have not mixed lower it), and every chain ≥ ``n_tau`` · τ after burn-in (τ: emcee's
  integrated autocorrelation time, reported with N/τ; emcee's walker-averaged τ ignores differences
  between walkers, which the ESS catches, so the default n_tau is a floor of 10 rather than emcee's 50);
  or the ``max_steps`` cap.
"""
from __future__ import annotations

import json
import logging
import time
from pathlib import Path
from typing import NamedTuple

import emcee
import numpy as np

from ..model.config import SamplerSettings
from ..model.problem import Problem
from .proposals import CompositeProposal, Proposal
from .chains import Chains, StoredChains, _read, _read_history, chain_paths, saved_steps
from .stopping import ADAPTATIONS, convergence, convergence_fraction
from .mixing import add_counts, initial_walkers, n_walkers
from .pool import _advance, _pool
from .progress import Progress, _Bar

logger = logging.getLogger(__name__)


def _fresh_start(independence: CompositeProposal, settings: SamplerSettings, problem: Problem, nw: int):
    """The Gaussian reference and every ensemble's initial walkers, drawn in a fixed order from the seed (so
    a resume can redraw the start of an ensemble that never saved a step)."""
    rng = np.random.default_rng(settings.seed)
    proposal = Proposal.from_cov(*independence.moments(np.random.RandomState(rng.integers(2**32))))
    starts = [initial_walkers(independence, nw, problem, rng) for _ in range(settings.ensembles)]
    return proposal, starts


class _Files(NamedTuple):
    """A run's chain folder: the ensembles' chain files, the saved proposals and the history."""

    chain_dir: Path
    paths: list
    proposal: Path
    independence: Path
    history: Path


def _files(out_dir: Path, ensembles: int) -> _Files:
    chain_dir = Path(out_dir) / "chains"
    return _Files(chain_dir, chain_paths(out_dir, ensembles), chain_dir / "proposal.npz",
                  chain_dir / "independence.npz", chain_dir / "history.json")


def _start(problem: Problem, independence: CompositeProposal | None, settings: SamplerSettings, out_dir: Path,
           files: _Files, nw: int, resume: bool):
    """The proposals, every ensemble's start (None: continue its file), steps saved per ensemble, the step all
    have reached and the history: read back from the chain folder on a resume, drawn afresh otherwise."""
    steps = saved_steps(out_dir, settings.ensembles) if resume else None
    if steps is not None:
        proposal = Proposal.load(files.proposal)
        independence = CompositeProposal.load(files.independence)
        for p in files.paths:
            shape = emcee.backends.HDFBackend(str(p), read_only=True).shape
            if tuple(shape) != (nw, problem.dim):
                raise ValueError(f"{p}: chains of {shape[0]} walkers × {shape[1]} parameters, the configuration "
                                 f"has {nw} × {problem.dim}; cannot resume (remove the folder to restart)")
        history = _read_history(files.history)
        done = max(steps)
        # an ensemble that never saved a step restarts from its original walkers (same seed, same draws)
        starts = (_fresh_start(independence, settings, problem, nw)[1] if min(steps) == 0
                  else [None] * len(files.paths))
        starts = [s if k == 0 else None for s, k in zip(starts, steps)]
        history.append({"steps": done, "resumed": True, "ensemble_steps": steps})
        files.history.write_text(json.dumps(history, indent=1))
        return proposal, independence, starts, steps, done, history
    for p in files.paths:
        p.unlink(missing_ok=True)
    files.history.unlink(missing_ok=True)
    if independence is None:
        raise ValueError(f"{files.chain_dir}: nothing to resume; a fresh run needs the posterior approximation")
    proposal, starts = _fresh_start(independence, settings, problem, nw)
    proposal.save(files.proposal)
    independence.save(files.independence)
    return proposal, independence, starts, [0] * len(files.paths), 0, []


def _align(pool, files: _Files, starts: list, steps: list, done: int, settings: SamplerSettings) -> list:
    """Advance the ensembles saved with fewer than ``done`` steps (a resume) to ``done``; their steps."""
    tasks = [(p, done - k, s, settings.seed * 1000 + e)
             for e, (p, s, k) in enumerate(zip(files.paths, starts, steps)) if k < done]
    pool.map(_advance, tasks)
    steps = [int(emcee.backends.HDFBackend(str(p), read_only=True).iteration) for p in files.paths]
    if min(steps) != done or max(steps) != done:
        raise RuntimeError(f"{files.chain_dir}: could not align the ensembles at step {done}: {steps}")
    return steps


def _adapt(proposal: Proposal, independence: CompositeProposal, files: _Files, adapt_at: list, done: int,
           settings: SamplerSettings, dim: int):
    """A warm-up adaptation at step ``done``: the Gaussian reference re-fitted to the second half of the steps
    since the last one, the independence proposal re-weighted to (at most 4000 of) them; both saved."""
    lo = adapt_at[proposal.adapted - 1] if proposal.adapted else 0
    first = (lo + done) // 2
    warm = _read(files.paths, start=first)[0][:, : done - first].reshape(-1, dim)
    proposal = proposal.refit(warm)
    proposal.save(files.proposal)
    sub = warm[np.random.default_rng(settings.seed + done).choice(len(warm), min(len(warm), 4000), replace=False)]
    independence = independence.reweighted(sub)
    independence.save(files.independence)
    return proposal, independence


def _counts_since_adaptation(history: list) -> dict:
    """The moves' counts ({label: [share, proposed, accepted]}) of the last convergence check after the last
    warm-up adaptation in a run's history (empty when there is none): where a resumed run's counts go on."""
    counts = {}
    for entry in history:
        if "adapted_proposal" in entry:
            counts = {}
        elif "moves" in entry:
            counts = entry["moves"]
    return counts


def _finish(problem: Problem, settings: SamplerSettings, files: _Files, verdict: dict, checked, adapt_at: list,
            history: list, t_start: float, counts: dict) -> Chains:
    """The post-burn-in chains of the ensembles (of equal length) with σ drawn from its conditional."""
    lengths = {int(emcee.backends.HDFBackend(str(p), read_only=True).iteration) for p in files.paths}
    if len(lengths) != 1:
        raise RuntimeError(f"{files.chain_dir}: ensembles of unequal length {sorted(lengths)} after sampling")
    total = lengths.pop()
    # no convergence check (the cap came during the warm-up): the warm-up is burn-in, at most half the chain
    burn = verdict["burn"] if checked is not None else min(adapt_at[-1], total // 2)
    chain, lp, acc, ss = _read(files.paths, blobs=True, start=burn)
    sigma = problem.draw_sigma(ss.reshape(-1, problem.n_groups), np.random.default_rng(settings.seed),
                               chain.reshape(-1, problem.dim)).reshape(ss.shape)
    reason = ("converged" if verdict["converged"] else
              f"cap of {settings.max_steps} steps reached before convergence")
    files.history.write_text(json.dumps(history, indent=1))
    return Chains(chain=chain, log_prob=lp, sigma=sigma, acceptance=acc, burn=burn,
                  total_steps=total, tau=verdict["tau"], converged=verdict["converged"], reason=reason,
                  history=history, wall_time_s=time.perf_counter() - t_start, ss=ss, moves=counts)


def run_sampler(problem: Problem, independence: CompositeProposal | None, settings: SamplerSettings, out_dir: Path,
                resume: bool = False, progress: bool = True) -> Chains:
    """Run (or resume) the ensembles until converged or the cap; returns the post-burn-in chains.

    Long: the rounds of sampling, warm-up adaptations and convergence checks are one loop whose state its
    branches share (the pool is rebuilt after each adaptation).

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
    files = _files(out_dir, settings.ensembles)
    files.chain_dir.mkdir(parents=True, exist_ok=True)
    paths = files.paths
    nw = n_walkers(settings, problem)
    proposal, independence, starts, steps, done, history = _start(problem, independence, settings, out_dir, files,
                                                                  nw, resume)

    def record(entry):
        history.append(entry)
        files.history.write_text(json.dumps(history, indent=1))

    coef_idx = np.arange(problem.n_coef + problem.n_ext)
    adapt_at = [settings.adapt_steps * (i + 1) for i in range(ADAPTATIONS)]
    bar = _Bar(settings, progress)
    verdict = {"converged": False, "tau": np.full((1, problem.dim), np.nan)}
    checked, fraction = None, 0.0
    counts = _counts_since_adaptation(history)     # the moves' proposals and acceptances since the warm-up
    bar.show(Progress(done, settings.max_steps, 0.0, None), checked=False)
    finished = False
    try:
        while not finished:
            with _pool(settings, (problem, proposal, independence, settings.independence_fraction,
                                  settings.block_fraction)) as pool:
                if min(steps) < done:   # resumed with unequal ensembles: bring the shorter ones level first
                    steps = _align(pool, files, starts, steps, done, settings)
                    starts = [None] * len(paths)
                    record({"steps": done, "aligned": True, "ensemble_steps": steps})
                while True:
                    if done > 0 and proposal.adapted < ADAPTATIONS and done >= adapt_at[proposal.adapted]:
                        proposal, independence = _adapt(proposal, independence, files, adapt_at, done, settings,
                                                        problem.dim)
                        counts = {}
                        record({"steps": done, "adapted_proposal": proposal.adapted,
                                "independence_weights": np.exp(independence.log_weights).round(4).tolist()})
                        logger.debug(f"warm-up adaptation {proposal.adapted} of {ADAPTATIONS} at step {done}")
                        break  # new pool with the new proposal
                    if done >= adapt_at[-1] + settings.check_every and checked != done:
                        verdict = convergence(StoredChains(paths, start=adapt_at[-1]), settings, coef_idx,
                                              first_step=adapt_at[-1])
                        checked, fraction = done, convergence_fraction(verdict, settings, done)
                        record({"steps": done, "elapsed_s": round(time.perf_counter() - t_start, 3),
                                **{k: v for k, v in verdict.items() if k != "tau"}, "moves": counts})
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
                    advanced = pool.map(_advance, tasks)
                    steps = [int(k) for k, _ in advanced]
                    for _, c in advanced:
                        counts = add_counts(counts, c)
                    done = min(steps)
                    starts = [None] * len(paths)
                    bar.show(Progress(done, settings.max_steps, fraction, verdict if checked is not None else None),
                             checked=False)
    finally:
        bar.close()
    return _finish(problem, settings, files, verdict, checked, adapt_at, history, t_start, counts)
