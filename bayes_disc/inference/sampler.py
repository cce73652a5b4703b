"""emcee ensembles over coefficients, extra-term parameters, every flight's initial conditions and noise.

* Several independent ensembles (R-hat across ensembles), each with its own ``emcee.backends.HDFBackend``
  file, advanced in rounds of ``check_every`` steps (in parallel processes), so an interrupted run
  resumes from the files with no lost samples.
* Walkers start from the least-squares optimum spread by its Gauss–Newton covariance.
* Moves: Metropolis–Hastings moves built on a Gaussian reference N(μ, Σ) — independence jumps and
  preconditioned Crank–Nicolson steps; the acceptance includes the proposal density ratio, so each
  kernel leaves the posterior invariant — mixed with emcee's differential-evolution moves, which take
  over where the posterior is far from Gaussian. The reference starts as the Laplace approximation
  (least-squares optimum and covariance) and is re-fitted to the pooled ensembles' samples twice
  during warm-up (after ``adapt_steps`` and 2·``adapt_steps`` steps); it is fixed afterwards and the
  warm-up is discarded as burn-in.
* Stopping: R-hat across ensembles < ``rhat`` for every parameter, bulk ESS ≥ ``ess`` for every
  coefficient (ArviZ, rank-normalised; walkers as chains, so walkers that have not mixed lower it),
  and every chain ≥ ``n_tau`` · τ after burn-in (τ: emcee's integrated autocorrelation time,
  reported with N/τ; emcee's walker-averaged τ ignores differences between walkers, which the ESS
  catches, so the default n_tau is a floor of 10 rather than emcee's 50); or the ``max_steps`` cap.
"""
from __future__ import annotations

import json
import multiprocessing as mp
import time
from dataclasses import dataclass, field
from pathlib import Path

import emcee
import numpy as np

from .config import SamplerSettings
from .model import Problem

# A Student-t proposal is no good in ~60 dimensions: its radius spreads far more than the posterior's,
# so the importance weights vary by e^±10 and almost nothing is accepted. Gaussian (ν = ∞) it is.
T_DOF = np.inf
ADAPTATIONS = 2
PROPOSAL_INFLATION = 1.03  # proposal sd / posterior sd after adaptation (slightly wider: safe tails)


@dataclass(frozen=True)
class Proposal:
    """Gaussian reference N(μ, Σ), Σ = L Lᵀ (a Student-t with ν dof when ν is finite), used as a
    preconditioned Crank–Nicolson proposal x′ = μ + ρ (x − μ) + √(1 − ρ²) L z, z ~ N(0, I).

    ρ = 0 is the independence sampler; ρ > 0 makes a local move that is reversible with respect to
    the Gaussian, so its Metropolis–Hastings factor is the same density ratio N(x) / N(x′)
    (Cotter et al. 2013). Where the posterior deviates from the Gaussian, ρ > 0 keeps acceptance high
    while ρ = 0 makes the big jumps. (Gaussian only: with finite ν the factor holds for ρ = 0.)"""

    mean: np.ndarray
    chol: np.ndarray
    dof: float = T_DOF
    adapted: int = 0   # how many warm-up re-fits this proposal has had
    rho: float = 0.0

    def with_rho(self, rho: float) -> "Proposal":
        return Proposal(self.mean, self.chol, self.dof, self.adapted, rho)

    @classmethod
    def from_cov(cls, mean, cov, dof=T_DOF, adapted=0) -> "Proposal":
        """Proposal whose covariance is ``cov`` (t: scale matrix cov·(ν−2)/ν)."""
        cov = 0.5 * (cov + cov.T) * (1.0 if np.isinf(dof) else (dof - 2.0) / dof)
        return cls(mean=np.asarray(mean, float), chol=scaled_cholesky(cov), dof=dof, adapted=adapted)

    def refit(self, samples: np.ndarray) -> "Proposal":
        """The proposal re-fitted to samples (n, dim): their mean and inflated covariance."""
        cov = np.cov(samples.T) * PROPOSAL_INFLATION**2
        return Proposal.from_cov(samples.mean(axis=0), cov, self.dof, self.adapted + 1)

    def log_density(self, x: np.ndarray) -> np.ndarray:
        z = np.linalg.solve(self.chol, (x - self.mean).T).T
        if np.isinf(self.dof):
            return -0.5 * np.sum(z * z, axis=1)
        d = self.mean.size
        return -0.5 * (self.dof + d) * np.log1p(np.sum(z * z, axis=1) / self.dof)

    def draw(self, n: int, random) -> np.ndarray:
        d = self.mean.size
        z = random.randn(n, d)
        if np.isinf(self.dof):
            return self.mean + z @ self.chol.T
        g = random.chisquare(self.dof, size=n) / self.dof
        return self.mean + (z @ self.chol.T) / np.sqrt(g)[:, None]

    def __call__(self, coords, random):
        """emcee MHMove proposal: new points and ln q(x | x′) − ln q(x′ | x) = ln N(x) − ln N(x′)."""
        fresh = self.draw(coords.shape[0], random)
        if self.rho == 0.0:
            new = fresh
        else:
            new = self.mean + self.rho * (coords - self.mean) + np.sqrt(1 - self.rho**2) * (fresh - self.mean)
        return new, self.log_density(coords) - self.log_density(new)

    def save(self, path: Path) -> None:
        np.savez(path, mean=self.mean, chol=self.chol, dof=self.dof, adapted=self.adapted)

    @classmethod
    def load(cls, path: Path) -> "Proposal":
        z = np.load(path)
        return cls(mean=z["mean"], chol=z["chol"], dof=float(z["dof"]), adapted=int(z["adapted"]))


def scaled_cholesky(cov: np.ndarray) -> np.ndarray:
    """Cholesky factor of a covariance whose scales span many decades (CNr ~ 1e−7 beside positions ~ 1e−3):
    factor the correlation matrix (eigenvalues floored at 1e−10) and scale back."""
    d = np.sqrt(np.maximum(np.diag(cov), 1e-300))
    corr = cov / np.outer(d, d)
    w, V = np.linalg.eigh(0.5 * (corr + corr.T))
    w = np.maximum(w, 1e-10 * w.max())
    return d[:, None] * np.linalg.cholesky((V * w) @ V.T)


#: share of the Gaussian-reference moves by ρ (independence jumps and pCN steps of two lengths)
PCN_MIX = ((0.0, 0.4), (0.7, 0.35), (0.9, 0.25))


def _moves(proposal: Proposal, fraction: float):
    moves = []
    if fraction > 0:
        moves += [(emcee.moves.MHMove(proposal.with_rho(rho)), fraction * share) for rho, share in PCN_MIX]
    if fraction < 1:
        moves += [(emcee.moves.DEMove(), 0.8 * (1 - fraction)), (emcee.moves.DESnookerMove(), 0.2 * (1 - fraction))]
    return moves


def n_walkers(settings: SamplerSettings, dim: int) -> int:
    w = settings.walkers or 2 * dim + 2
    return max(w + (w % 2), 2 * dim + 2)


def initial_walkers(mean, cov, n: int, problem: Problem, rng: np.random.Generator) -> np.ndarray:
    """Draws from N(mean, cov) with finite log-posterior (redrawn otherwise), linearly independent."""
    L = scaled_cholesky(cov)
    out = np.empty((n, mean.size))
    filled = 0
    for _ in range(50):
        cand = mean + rng.standard_normal((n, mean.size)) @ L.T
        ok = np.isfinite(problem.log_prob(cand))
        take = min(int(ok.sum()), n - filled)
        out[filled: filled + take] = cand[ok][:take]
        filled += take
        if filled == n:
            return out
    raise RuntimeError("could not place walkers with finite posterior around the least-squares optimum")


# ------------------------------------------------------------------------------------------------------
# workers: one ensemble advanced by n steps; the problem is inherited by fork (no pickling of kernels)
_WORKER: dict = {}


def _init_worker(problem, proposal, fraction):
    _WORKER.update(problem=problem, proposal=proposal, fraction=fraction)


def _advance(task) -> int:
    path, n_steps, start, seed = task
    problem, proposal, fraction = _WORKER["problem"], _WORKER["proposal"], _WORKER["fraction"]
    backend = emcee.backends.HDFBackend(str(path))
    nw = start.shape[0] if start is not None else backend.shape[0]
    sampler = emcee.EnsembleSampler(nw, problem.dim, problem.log_prob_blobs, vectorize=True, backend=backend,
                                    moves=_moves(proposal, fraction), blobs_dtype=float)
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


def run_sampler(problem: Problem, theta0: np.ndarray, cov0: np.ndarray, settings: SamplerSettings,
                out_dir: Path, resume: bool = False, progress: bool = True) -> Chains:
    """Run (or resume) the ensembles until converged or the cap; returns the post-burn-in chains."""
    from tqdm import tqdm
    t_start = time.perf_counter()
    out_dir = Path(out_dir)
    chain_dir = out_dir / "chains"
    chain_dir.mkdir(parents=True, exist_ok=True)
    paths = [chain_dir / f"ensemble_{e}.h5" for e in range(settings.ensembles)]
    prop_path = chain_dir / "proposal.npz"
    nw = n_walkers(settings, problem.dim)
    existing = [p.exists() for p in paths]
    if resume and all(existing) and prop_path.exists():
        proposal = Proposal.load(prop_path)
        done = int(min(emcee.backends.HDFBackend(str(p), read_only=True).iteration for p in paths))
        starts = [None] * len(paths)
    else:
        if any(existing) and not resume:
            for p in paths:
                p.unlink(missing_ok=True)
        if resume and any(existing):
            raise ValueError(f"{chain_dir}: incomplete chain files; cannot resume (remove the folder to restart)")
        proposal = Proposal.from_cov(theta0, cov0)
        proposal.save(prop_path)
        rng = np.random.default_rng(settings.seed)
        starts = [initial_walkers(theta0, cov0, nw, problem, rng) for _ in paths]
        done = 0
    coef_idx = np.arange(problem.n_coef + problem.n_ext)
    adapt_at = [settings.adapt_steps * (i + 1) for i in range(ADAPTATIONS)]
    history = []
    ctx = mp.get_context("fork")
    bar = tqdm(total=settings.max_steps, initial=done, desc="sampling", unit="step", disable=not progress,
               leave=False)
    verdict = {"converged": False, "burn": min(done, adapt_at[-1]), "tau": np.full((1, problem.dim), np.nan)}
    finished = False
    while not finished:
        with ctx.Pool(min(settings.processes, settings.ensembles), initializer=_init_worker,
                      initargs=(problem, proposal, settings.independence_fraction)) as pool:
            while True:
                if done > 0 and proposal.adapted < ADAPTATIONS and done >= adapt_at[proposal.adapted]:
                    chain, _, _ = _read(paths)
                    lo = adapt_at[proposal.adapted - 1] if proposal.adapted else 0
                    warm = chain[:, (lo + done) // 2: done].reshape(-1, problem.dim)
                    proposal = proposal.refit(warm)
                    proposal.save(prop_path)
                    history.append({"steps": done, "adapted_proposal": proposal.adapted})
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


