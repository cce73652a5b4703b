"""emcee ensembles over coefficients, extra-term parameters, every flight's initial conditions and noise.

* Several independent ensembles (R-hat across ensembles), each with its own ``emcee.backends.HDFBackend``
  file, advanced in rounds of ``check_every`` steps (in parallel processes), so an interrupted run
  resumes from the files with no lost samples.
* Walkers start from the least-squares optimum spread by its Gauss–Newton covariance.
* Moves: an *independence* Metropolis–Hastings move (multivariate Gaussian; the acceptance includes
  the proposal density ratio, so each kernel leaves the posterior invariant) mixed with emcee's
  differential-evolution moves, which take over where the posterior is far from Gaussian. The
  independence proposal starts as the Laplace approximation (least-squares optimum and covariance) and
  is re-fitted to the pooled ensembles' samples twice during warm-up (after ``adapt_steps`` and
  2·``adapt_steps`` steps); it is fixed afterwards and the warm-up is discarded as burn-in.
* Stopping: every chain ≥ n_tau · τ after burn-in (τ: emcee's integrated autocorrelation time), R-hat
  across ensembles < ``rhat`` for every parameter, bulk ESS ≥ ``ess`` for every coefficient; or the cap.
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
PROPOSAL_INFLATION = 1.1  # proposal sd / posterior sd after adaptation


@dataclass(frozen=True)
class Proposal:
    """Independence proposal N(μ, Σ) (or a Student-t with ν dof when ν is finite), Σ = L Lᵀ."""

    mean: np.ndarray
    chol: np.ndarray
    dof: float = T_DOF
    adapted: int = 0   # how many warm-up re-fits this proposal has had

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
        """emcee MHMove proposal: new points and ln q(x) − ln q(x′)."""
        new = self.draw(coords.shape[0], random)
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


def _moves(proposal: Proposal, fraction: float):
    moves = []
    if fraction > 0:
        moves.append((emcee.moves.MHMove(proposal), fraction))
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
    sampler = emcee.EnsembleSampler(nw, problem.dim, problem.log_prob, vectorize=True, backend=backend,
                                    moves=_moves(proposal, fraction))
    if start is not None:
        sampler.random_state = np.random.RandomState(seed).get_state()
        sampler.run_mcmc(start, n_steps, progress=False)
    else:
        sampler.run_mcmc(None, n_steps, progress=False)
    return backend.iteration


@dataclass
class Chains:
    """Post-burn-in samples: chain (n_ensembles, n_steps, n_walkers, dim), log_prob alike without dim."""

    chain: np.ndarray
    log_prob: np.ndarray
    acceptance: np.ndarray          # (n_ensembles, n_walkers)
    burn: int
    total_steps: int
    tau: np.ndarray                 # (n_ensembles, dim) steps
    converged: bool
    reason: str
    history: list = field(default_factory=list)
    wall_time_s: float = 0.0


def _read(paths):
    chains, lps, acc = [], [], []
    for p in paths:
        b = emcee.backends.HDFBackend(str(p), read_only=True)
        chains.append(b.get_chain())
        lps.append(b.get_log_prob())
        acc.append(b.accepted / max(b.iteration, 1))
    n = min(c.shape[0] for c in chains)
    return (np.stack([c[:n] for c in chains]), np.stack([lp[:n] for lp in lps]), np.stack(acc))


def _tau(chain: np.ndarray) -> np.ndarray:
    """Integrated autocorrelation time per parameter (steps), emcee's estimator on the walker mean."""
    return emcee.autocorr.integrated_time(chain, tol=0, quiet=True)


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
        done = min(emcee.backends.HDFBackend(str(p), read_only=True).iteration for p in paths)
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
                done = min(pool.map(_advance, tasks))
                starts = [None] * len(paths)
                bar.update(n)
    bar.close()
    chain, lp, acc = _read(paths)
    burn = verdict["burn"]
    reason = ("converged" if verdict["converged"] else
              f"cap of {settings.max_steps} steps reached before convergence")
    (out_dir / "chains" / "history.json").write_text(json.dumps(history, indent=1))
    return Chains(chain=chain[:, burn:], log_prob=lp[:, burn:], acceptance=acc, burn=burn,
                  total_steps=chain.shape[1], tau=verdict["tau"], converged=verdict["converged"], reason=reason,
                  history=history, wall_time_s=time.perf_counter() - t_start)


