"""emcee ensembles over coefficients, extra-term parameters, every flight's initial conditions and noise.

* Several independent ensembles (R-hat across ensembles), each with its own ``emcee.backends.HDFBackend``
  file, advanced in rounds of ``check_every`` steps (in parallel processes), so an interrupted run
  resumes from the files with no lost samples.
* Walkers start from a ridge-aware approximation of the posterior (:mod:`.proposals`), over-dispersed
  relative to the Laplace approximation where the posterior is, so that R-hat across ensembles can see
  a failure to mix.
* Moves: Metropolis–Hastings moves with exact acceptance ratios (each leaves the posterior invariant),
  mixed with emcee's differential-evolution moves:
  - independence jumps from :func:`.proposals.independence_proposal`: the Laplace approximation plus a
    ridge proposal along every profile-likelihood path (:mod:`.profile`) that departs from it. A weakly
    identified combination (the demo's CM0 and CMq with the flights' wobble initial conditions) makes
    a thin curved valley that a Gaussian cannot cover and that local moves cross only over thousands
    of steps; the ridge proposals follow the valley, so the jumps reach all of it;
  - preconditioned Crank–Nicolson steps on a Gaussian reference N(μ, Σ): first the moments of the
    independence proposal;
  - both are re-fitted to the pooled ensembles' samples twice during warm-up (after ``adapt_steps`` and
    2·``adapt_steps`` steps: the reference's mean and covariance, the independence proposal's weights);
    they are fixed afterwards and the warm-up is discarded as burn-in;
  - emcee's DE moves, mostly with γ scaled down (local steps accepted often), some at the default γ,
    and snooker moves.
* Stopping: R-hat across ensembles < ``rhat`` for every parameter, bulk ESS ≥ ``ess`` for every
  coefficient (ArviZ, rank-normalised; walkers as chains, so walkers that have not mixed lower it),
  and every chain ≥ ``n_tau`` · τ after burn-in (τ: emcee's integrated autocorrelation time,
  reported with N/τ; emcee's walker-averaged τ ignores differences between walkers, which the ESS
  catches, so the default n_tau is a floor of 10 rather than emcee's 50); or the ``max_steps`` cap.
"""
from __future__ import annotations

import json
import time
from dataclasses import dataclass, field
from pathlib import Path

import emcee
import numpy as np

from ..physics.parallel import mp_context
from .config import SamplerSettings
from .model import Problem
from .proposals import CompositeProposal, Proposal

#: re-fits of the pCN reference during warm-up
ADAPTATIONS = 2

#: Within the Metropolis–Hastings share: independence jumps and long pCN steps. Measured on the demo
#: posterior (a curved valley) after warm-up: independence jumps accepted 17 % of the time (the CMq
#: ridge part, weight 0.8, 19 %) and they cross the whole valley; pCN with ρ = 0.97 3 %, ρ ≤ 0.9 ≤ 1 %.
MH_MIX = ((None, 0.5), (0.97, 0.5))
#: Within the DE share: emcee's DE move with γ scaled down (accepted ~30 % on the demo posterior,
#: against ~4 % for the default γ = 2.38/√(2·dim)), the default DE move and the snooker move.
DE_SCALE = 0.35
DE_MIX = ((DE_SCALE, 0.7), (1.0, 0.15), ("snooker", 0.15))


def _moves(proposal: Proposal, independence: CompositeProposal, fraction: float, dim: int):
    moves = []
    if fraction > 0:
        for rho, share in MH_MIX:
            move = independence if rho is None else proposal.with_rho(rho)
            moves.append((emcee.moves.MHMove(move), fraction * share))
    if fraction < 1:
        g0 = 2.38 / np.sqrt(2 * dim)
        for kind, share in DE_MIX:
            move = emcee.moves.DESnookerMove() if kind == "snooker" else emcee.moves.DEMove(gamma0=kind * g0)
            moves.append((move, (1 - fraction) * share))
    return moves


def n_walkers(settings: SamplerSettings, dim: int) -> int:
    w = settings.walkers or 2 * dim + 2
    return max(w + (w % 2), 2 * dim + 2)


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


def _init_worker(problem, proposal, independence, fraction):
    _WORKER.update(problem=problem, proposal=proposal, independence=independence, fraction=fraction)


def _advance(task) -> int:
    path, n_steps, start, seed = task
    problem, proposal, independence = _WORKER["problem"], _WORKER["proposal"], _WORKER["independence"]
    backend = emcee.backends.HDFBackend(str(path))
    nw = start.shape[0] if start is not None else backend.shape[0]
    sampler = emcee.EnsembleSampler(nw, problem.dim, problem.log_prob_blobs, vectorize=True, backend=backend,
                                    moves=_moves(proposal, independence, _WORKER["fraction"], problem.dim),
                                    blobs_dtype=float)
    if start is not None:
        sampler.random_state = np.random.RandomState(seed).get_state()
        sampler.run_mcmc(start, n_steps, progress=False)
    else:
        sampler.run_mcmc(None, n_steps, progress=False)
    return backend.iteration


@dataclass
class Chains:
    """Post-burn-in samples: chain (n_ensembles, n_steps, n_walkers, dim), log_prob alike without dim,
    σ per flight (n_ensembles, n_steps, n_walkers, n_flights) drawn from its exact conditional."""

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


def _read(paths, blobs: bool = False):
    chains, lps, acc, ss = [], [], [], []
    for p in paths:
        b = emcee.backends.HDFBackend(str(p), read_only=True)
        chains.append(b.get_chain())
        lps.append(b.get_log_prob())
        acc.append(b.accepted / max(b.iteration, 1))
        if blobs:  # S_f per flight; emcee drops the last axis when there is one flight
            c = chains[-1]
            ss.append(np.asarray(b.get_blobs(), float).reshape(c.shape[0], c.shape[1], -1))
    n = min(c.shape[0] for c in chains)
    out = (np.stack([c[:n] for c in chains]), np.stack([lp[:n] for lp in lps]), np.stack(acc))
    if blobs:
        out = out + (np.stack([x[:n] for x in ss]),)
    return out


def _tau(chain: np.ndarray, c: float = 5.0) -> np.ndarray:
    """Integrated autocorrelation time per parameter (steps): emcee's estimator (walker-averaged
    autocorrelation function, Sokal's automatic window c), skipping walkers that did not move in the
    window (their autocorrelation is undefined; emcee would return NaN)."""
    n_steps, n_w, dim = chain.shape
    tau = np.empty(dim)
    for d in range(dim):
        f = np.zeros(n_steps)
        used = 0
        for k in range(n_w):
            x = chain[:, k, d]
            if np.ptp(x) > 0:
                f += emcee.autocorr.function_1d(x)
                used += 1
        if used == 0:
            tau[d] = np.inf
            continue
        taus = 2.0 * np.cumsum(f / used) - 1.0
        tau[d] = taus[emcee.autocorr.auto_window(taus, c)]
    return tau


def convergence(chain: np.ndarray, settings: SamplerSettings, coef_idx: np.ndarray, min_burn: int = 0):
    """Burn-in, τ, R-hat and ESS for chain (n_ens, n_steps, n_walkers, dim); returns a verdict dict.

    Burn-in: the warm-up (``min_burn``) and at least 5 τ after it."""
    from .diagnostics_mcmc import ess_bulk, rhat_across
    n_ens, n_steps = chain.shape[:2]
    tau0 = np.array([_tau(chain[e, min_burn:]) for e in range(n_ens)])
    burn = int(min(min_burn + np.ceil(5 * np.nanmax(tau0)), min_burn + (n_steps - min_burn) // 2))
    post = chain[:, burn:]
    tau = np.array([_tau(post[e]) for e in range(n_ens)])
    n_over_tau = (n_steps - burn) / np.nanmax(tau)
    rh = rhat_across(post)
    ess = ess_bulk(post)
    ok = (n_steps >= settings.min_steps and n_over_tau >= settings.n_tau and np.all(rh < settings.rhat)
          and np.all(ess[coef_idx] >= settings.ess))
    return {"burn": burn, "tau": tau, "n_over_tau": float(n_over_tau), "rhat_max": float(np.max(rh)),
            "ess_min_coef": float(np.min(ess[coef_idx])), "converged": bool(ok)}


def run_sampler(problem: Problem, independence: CompositeProposal | None, settings: SamplerSettings, out_dir: Path,
                resume: bool = False, progress: bool = True) -> Chains:
    """Run (or resume) the ensembles until converged or the cap; returns the post-burn-in chains.
    ``independence``: the ridge-aware posterior approximation (:func:`.proposals.independence_proposal`)
    that starts the walkers and proposes the independence jumps; on resume (None allowed) the one saved
    with the chains is used."""
    from tqdm import tqdm
    t_start = time.perf_counter()
    out_dir = Path(out_dir)
    chain_dir = out_dir / "chains"
    chain_dir.mkdir(parents=True, exist_ok=True)
    paths = [chain_dir / f"ensemble_{e}.h5" for e in range(settings.ensembles)]
    prop_path, ind_path = chain_dir / "proposal.npz", chain_dir / "independence.npz"
    nw = n_walkers(settings, problem.dim)
    existing = [p.exists() for p in paths]
    if resume and all(existing) and prop_path.exists() and ind_path.exists():
        proposal = Proposal.load(prop_path)
        independence = CompositeProposal.load(ind_path)
        done = int(min(emcee.backends.HDFBackend(str(p), read_only=True).iteration for p in paths))
        starts = [None] * len(paths)
    else:
        if any(existing) and not resume:
            for p in paths:
                p.unlink(missing_ok=True)
        if resume and any(existing):
            raise ValueError(f"{chain_dir}: incomplete chain files; cannot resume (remove the folder to restart)")
        if independence is None:
            raise ValueError(f"{chain_dir}: nothing to resume; a fresh run needs the posterior approximation")
        rng = np.random.default_rng(settings.seed)
        proposal = Proposal.from_cov(*independence.moments(np.random.RandomState(rng.integers(2**32))))
        proposal.save(prop_path)
        independence.save(ind_path)
        starts = [initial_walkers(independence, nw, problem, rng) for _ in paths]
        done = 0
    coef_idx = np.arange(problem.n_coef + problem.n_ext)
    adapt_at = [settings.adapt_steps * (i + 1) for i in range(ADAPTATIONS)]
    history = []
    ctx = mp_context()
    bar = tqdm(total=settings.max_steps, initial=done, desc="sampling", unit="step", disable=not progress,
               leave=False)
    verdict = {"converged": False, "burn": min(done, adapt_at[-1]), "tau": np.full((1, problem.dim), np.nan)}
    finished = False
    while not finished:
        with ctx.Pool(min(settings.processes, settings.ensembles), initializer=_init_worker,
                      initargs=(problem, proposal, independence, settings.independence_fraction)) as pool:
            while True:
                if done > 0 and proposal.adapted < ADAPTATIONS and done >= adapt_at[proposal.adapted]:
                    chain, _, _ = _read(paths)
                    lo = adapt_at[proposal.adapted - 1] if proposal.adapted else 0
                    warm = chain[:, (lo + done) // 2: done].reshape(-1, problem.dim)
                    proposal = proposal.refit(warm)
                    proposal.save(prop_path)
                    sub = warm[np.random.default_rng(settings.seed + done).choice(len(warm), min(len(warm), 4000),
                                                                                 replace=False)]
                    independence = independence.reweighted(sub)
                    independence.save(ind_path)
                    history.append({"steps": done, "adapted_proposal": proposal.adapted,
                                    "independence_weights": np.exp(independence.log_weights).round(4).tolist()})
                    break  # new pool with the new proposal
                if done >= adapt_at[-1] + settings.check_every:
                    chain, _, _ = _read(paths)
                    verdict = convergence(chain, settings, coef_idx, min_burn=adapt_at[-1])
                    history.append({"steps": done, **{k: v for k, v in verdict.items() if k != "tau"}})
                    (chain_dir / "history.json").write_text(json.dumps(history, indent=1))
                    bar.set_postfix(rhat=f"{verdict['rhat_max']:.3f}", ess=f"{verdict['ess_min_coef']:.0f}",
                                    n_tau=f"{verdict['n_over_tau']:.0f}")
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
                done = int(min(pool.map(_advance, tasks)))
                starts = [None] * len(paths)
                bar.update(n)
    bar.close()
    chain, lp, acc, ss = _read(paths, blobs=True)
    burn = verdict["burn"]
    sigma = problem.draw_sigma(ss[:, burn:].reshape(-1, problem.n_flights),
                               np.random.default_rng(settings.seed)).reshape(ss[:, burn:].shape)
    reason = ("converged" if verdict["converged"] else
              f"cap of {settings.max_steps} steps reached before convergence")
    (out_dir / "chains" / "history.json").write_text(json.dumps(history, indent=1))
    return Chains(chain=chain[:, burn:], log_prob=lp[:, burn:], sigma=sigma, acceptance=acc, burn=burn,
                  total_steps=chain.shape[1], tau=verdict["tau"], converged=verdict["converged"], reason=reason,
                  history=history, wall_time_s=time.perf_counter() - t_start)


