"""Cost of one convergence check of the sampler (τ, R-hat across ensembles, bulk ESS): the batched
statistics of ``bayes_disc.inference`` against the reference they replace — emcee's ``function_1d`` walker by
walker and ArviZ's ``rhat(method="rank")`` / ``ess(method="bulk")`` — on the same chains, alternating, so that
the ratio holds on a busy machine. The sampling processes wait during a check, so its time is wall time
of every run. Prints the median seconds of each, their ratio and the largest difference between the two
verdicts.

    python benchmarks/bench_convergence.py [--run RUN_DIR] [--steps 200] [--walkers 118] [--dim 58]
                                           [--repeats 5] [--json]

``--run``: the chains of a ``bayes-disc sample`` output folder (its steps after the warm-up, as the sampler's
last check saw them); default: synthetic AR(1) chains of the demo's shape (4 ensembles × ``--steps`` ×
``--walkers`` 118 × ``--dim`` 58 parameters, τ ≈ 10 steps; 12 flights: 128 walkers × 154 parameters).
"""
from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
import warnings
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bayes_disc.inference.model.config import SamplerSettings  # noqa: E402
from bayes_disc.inference.sampling.stopping import ADAPTATIONS, CHECK_BLOCK, convergence
from bayes_disc.inference.sampling.chains import _read, chain_paths  # noqa: E402


def reference_tau(chain: np.ndarray, c: float = 5.0) -> np.ndarray:
    """The sampler's τ before the batched version: emcee's function_1d walker by walker."""
    import emcee
    n_steps, n_w, dim = chain.shape
    tau = np.empty(dim)
    for d in range(dim):
        f, used = np.zeros(n_steps), 0
        for k in range(n_w):
            if np.ptp(chain[:, k, d]) > 0:
                f += emcee.autocorr.function_1d(chain[:, k, d])
                used += 1
        if used == 0:
            tau[d] = np.inf
            continue
        taus = 2.0 * np.cumsum(f / used) - 1.0
        tau[d] = taus[emcee.autocorr.auto_window(taus, c)]
    return tau


def reference_check(chain: np.ndarray, settings: SamplerSettings, coef_idx: np.ndarray) -> dict:
    """The sampler's check before the batched statistics (same rule, ArviZ and emcee)."""
    import arviz as az

    def ds(x):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)
            return az.convert_to_dataset({"p": x})
    n_ens, n = chain.shape[:2]
    tau0 = np.array([reference_tau(chain[e]) for e in range(n_ens)])
    skip = int(min(np.ceil(5 * np.nanmax(tau0)), n // 2))
    post = chain[:, skip:]
    tau = np.array([reference_tau(post[e]) for e in range(n_ens)])
    m = post.shape[1]
    rh, ess = [], []
    for j in range(0, chain.shape[-1], CHECK_BLOCK):
        b = post[..., j: j + CHECK_BLOCK]
        rh.append(np.asarray(az.rhat(ds(b.reshape(n_ens, m * b.shape[2], -1)), method="rank")["p"].values))
        ess.append(np.asarray(az.ess(ds(np.moveaxis(b, 2, 1).reshape(-1, m, b.shape[-1])), method="bulk")["p"].values))
    rh, ess = np.concatenate(rh), np.concatenate(ess)
    return {"n_over_tau": float((n - skip) / np.nanmax(tau)), "rhat_max": float(np.max(rh)),
            "ess_min_coef": float(np.min(ess[coef_idx]))}


def synthetic(steps: int, walkers: int, dim: int, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    rho = 0.82                                                  # τ = (1 + ρ)/(1 − ρ) ≈ 10 steps
    x = np.empty((4, steps, walkers, dim))
    x[:, 0] = rng.standard_normal((4, walkers, dim))
    for t in range(1, steps):
        x[:, t] = rho * x[:, t - 1] + np.sqrt(1 - rho ** 2) * rng.standard_normal((4, walkers, dim))
    return x


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--run", type=Path, help="a sample output folder (its chains/)")
    ap.add_argument("--steps", type=int, default=200, help="synthetic chains: steps after the warm-up")
    ap.add_argument("--walkers", type=int, default=118, help="synthetic chains: walkers per ensemble")
    ap.add_argument("--dim", type=int, default=58, help="synthetic chains: parameters")
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--json", action="store_true")
    a = ap.parse_args(argv)
    settings = SamplerSettings()
    if a.run is not None:
        saved = json.loads((a.run / "summary.json").read_text())["sampler_settings"]
        settings = SamplerSettings(**{k: v for k, v in saved.items() if k in SamplerSettings.__dataclass_fields__})
        first = settings.adapt_steps * ADAPTATIONS
        chain = _read(chain_paths(a.run, settings.ensembles), start=first)[0]
        source = f"{a.run} (steps {first}–{first + chain.shape[1]})"
    else:
        chain = synthetic(a.steps, a.walkers, a.dim)
        source = f"synthetic AR(1) chains {chain.shape}"
    coef_idx = np.arange(10)
    new_t, ref_t = [], []
    for _ in range(a.repeats):
        t0 = time.perf_counter()
        new = convergence(chain, settings, coef_idx)
        new_t.append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        ref = reference_check(chain, settings, coef_idx)
        ref_t.append(time.perf_counter() - t0)
    diff = {k: abs(new[k] - ref[k]) / abs(ref[k]) for k in ref}
    out = {"chains": source, "shape": list(chain.shape), "repeats": a.repeats,
           "batched_s": statistics.median(new_t), "reference_s": statistics.median(ref_t),
           "ratio": statistics.median(ref_t) / statistics.median(new_t), "max_relative_difference": diff,
           "verdict": {k: new[k] for k in ref}}
    if a.json:
        print(json.dumps(out, indent=1))
        return 0
    print(f"convergence check on {source}, shape {tuple(chain.shape)}, median of {a.repeats}:")
    print(f"  batched (bayes_disc)        {out['batched_s']:.2f} s")
    print(f"  reference (emcee + ArviZ)   {out['reference_s']:.2f} s   ratio {out['ratio']:.1f}")
    print("  verdict " + ", ".join(f"{k} {v:.4g} (relative difference {diff[k]:.1e})" for k, v in out["verdict"].items()))
    return 0


if __name__ == "__main__":
    sys.exit(main())
