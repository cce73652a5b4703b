"""Benchmark of `bayes-disc sample` on a run configuration (default: the shipped demo, runs/demo/config.yaml).

Prints: wall time to a converged posterior (least squares + sampling), log-probability evaluation time
per walker (median over repeats, one ensemble's batch), ESS per second per coefficient, and the
convergence figures (R-hat across ensembles, min bulk ESS, τ, N/τ). ``--json`` prints a JSON object;
``--output DIR`` keeps the run folder there (a fresh folder; default: a temporary one, deleted), ``--progress``
logs the sampler's convergence checks to stderr.

    python benchmarks/bench_sample.py [--config runs/demo/config.yaml] [--json] [--output DIR] [--progress]
"""
from __future__ import annotations

import argparse
import json
import logging
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bayes_disc.inference.model.config import load_config  # noqa: E402
from bayes_disc.inference.model.data import build_problem  # noqa: E402
from bayes_disc.jobs.sample import run_sample  # noqa: E402
from bayes_disc.inference.sampling.mixing import n_walkers  # noqa: E402


def logprob_time(cfg, repeats: int = 15) -> tuple[float, int]:
    problem = build_problem(cfg)
    nw = n_walkers(cfg.sampler, problem)
    rng = np.random.default_rng(0)
    theta = problem.prior_mean + 1e-3 * problem.prior_sd * rng.standard_normal((nw, problem.dim))
    problem.log_prob(theta)  # compile
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        problem.log_prob(theta)
        times.append(time.perf_counter() - t0)
    return float(np.median(times)) / nw, nw


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--config", default=str(ROOT / "runs/demo/config.yaml"))
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--output", help="keep the run folder here (must not exist yet)")
    ap.add_argument("--progress", action="store_true", help="log the convergence checks to stderr")
    args = ap.parse_args(argv)
    if args.output and Path(args.output).exists():
        ap.error(f"--output {args.output} exists; the benchmark writes a fresh run folder")
    with tempfile.TemporaryDirectory() as tmp:
        out_dir = Path(args.output) if args.output else Path(tmp) / "out"
        cfg = load_config(args.config, output_override=out_dir)
        per_walker, nw = logprob_time(cfg)
        if args.progress:
            logging.basicConfig(level=logging.INFO, format="%(message)s", stream=sys.stderr)
        t0 = time.perf_counter()
        summary = run_sample(cfg, progress=args.progress)
        wall = time.perf_counter() - t0
        info = json.loads((out_dir / "run_info.json").read_text())
    conv = summary["convergence"]
    coefs = summary["coefficients"]
    ess_per_s = {c: summary["parameters"][c]["ess_bulk"] / wall for c in coefs}
    out = {
        "config": args.config, "wall_time_s": wall, "sampling_wall_time_s": info["sampling_wall_time_s"],
        "converged": conv["converged"], "r_hat_max": conv["r_hat_max"],
        "ess_bulk_min_coefficient": conv["ess_bulk_min_coefficient"], "tau_max_steps": conv["tau_max_steps"],
        "n_over_tau": conv["n_over_tau"], "total_steps": conv["total_steps"], "walkers": nw,
        "ensembles": conv["ensembles"], "acceptance_mean": conv["acceptance_mean"],
        "log_prob_us_per_walker": per_walker * 1e6, "ess_per_second": ess_per_s,
    }
    if args.json:
        print(json.dumps(out, indent=1))
        return 0
    print(f"{cfg.name} posterior: {'converged' if out['converged'] else 'NOT converged'} in {wall:.0f} s wall "
          f"({out['sampling_wall_time_s']:.0f} s sampling), {out['total_steps']} steps × {nw} walkers × "
          f"{out['ensembles']} ensembles, acceptance {out['acceptance_mean']:.2f}")
    print(f"R-hat max {out['r_hat_max']:.4f}; min coefficient bulk ESS {out['ess_bulk_min_coefficient']:.0f}; "
          f"τ max {out['tau_max_steps']:.1f} steps; N/τ {out['n_over_tau']:.0f}")
    print(f"log-probability: {out['log_prob_us_per_walker']:.0f} µs per walker (median of 15 batched calls, "
          f"all {len(summary['flights'])} flights)")
    print(f"{'coefficient':<12}{'ESS/s':>10}")
    for c, v in ess_per_s.items():
        print(f"{c:<12}{v:>10.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
