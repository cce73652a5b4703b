"""Where do too-narrow intervals come from: the likelihood or the sampler? (issue 16, AR(1) coverage)

For the replicates of a finished calibration campaign (its ``replicates/replicate_*.json``), the same
synthetic data are made again (:func:`bayes_disc.calibration.replicate.replicate_data`: every replicate's
data come from its own random stream) and fitted by least squares with the campaign's run settings. For each
coefficient the standardised errors of the truth

    z_LS   = (θ̃ − θ̂_LS) / sd_LS        (Laplace: the Gauss–Newton covariance at the optimum)
    z_post = (θ̃ − mean_post) / sd_post  (the campaign's posterior record)

are collected over the replicates; sd(z) = 1 when the intervals have the right width, > 1 when too narrow
(also printed: the robust sd from the median absolute deviation, and how many |z_LS| exceed 3, which
separates intervals too narrow everywhere from a few fits caught in a wrong optimum).
If sd(z_LS) ≈ sd(z_post) > 1, the likelihood (the noise model's curvature) is too sharp; if sd(z_LS) ≈ 1 <
sd(z_post), the sampler or the posterior's shape is the cause.

    python benchmarks/bench_laplace_coverage.py runs/calibration/cal4_ar1.yaml [--replicates 30] [--fix-rho 0.85]
                                                [--json]
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bayes_disc.calibration.config import load_cal_config  # noqa: E402
from bayes_disc.calibration.replicate import replicate_problem  # noqa: E402
from bayes_disc.inference.fitting.leastsq import fit_least_squares, refine_least_squares  # noqa: E402


def laplace_z(cal, index: int, names, fix_rho: float | None = None) -> tuple[np.ndarray, float, list]:
    """(z_LS per name, seconds, fitted AR(1) coefficients ρ̂ of the flights, if any) of replicate ``index``."""
    problem, cfg, _, truth = replicate_problem(cal, index)
    t0 = time.perf_counter()
    ls = fit_least_squares(problem, starts=cfg.least_squares.starts, max_nfev=cfg.least_squares.max_nfev,
                           seed=cfg.sampler.seed)
    if fix_rho is not None:            # the AR(1) coefficients held at a value (the truth): refit the rest
        held = np.array([n.startswith("rho_") for n in problem.names])
        x0 = ls.theta.copy()
        x0[held] = fix_rho
        ls = refine_least_squares(problem, x0, max_nfev=cfg.least_squares.max_nfev, free=~held)
    dt = time.perf_counter() - t0
    idx = [problem.names.index(n) for n in names]
    sd = np.sqrt(np.diag(ls.cov))[idx]
    rho = [float(v) for n, v in zip(problem.names, ls.theta) if n.startswith("rho_")]   # AR(1) noise, if fitted
    return (np.array([truth[n] for n in names]) - ls.theta[idx]) / sd, dt, rho


def robust_sd(z: np.ndarray) -> float:
    """1.4826 · median |z − median z|: the sd of a normal sample, insensitive to a few wild values."""
    return float(1.4826 * np.median(np.abs(z - np.median(z))))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("campaign", type=Path)
    ap.add_argument("--replicates", type=int, default=30, help="first N finished replicates (default 30)")
    ap.add_argument("--fix-rho", type=float, default=None,
                    help="hold the flights' AR(1) coefficients at this value (the truth) in the least-squares fit")
    ap.add_argument("--json", action="store_true")
    a = ap.parse_args(argv)
    cal = load_cal_config(a.campaign)
    names = list(cal.names)
    files = sorted((cal.output / "replicates").glob("replicate_*.json"))[: a.replicates]
    z_ls, z_post, times, rhos = [], [], [], []
    for f in files:
        rec = json.loads(f.read_text())
        if rec.get("status") != "ok":
            continue
        z, dt, rho = laplace_z(cal, rec["index"], names, a.fix_rho)
        z_ls.append(z)
        rhos += rho
        times.append(dt)
        z_post.append([(rec["truth"][n] - rec["posterior"][n]["mean"]) / rec["posterior"][n]["sd"] for n in names])
        print(f"replicate {rec['index']}: least squares {dt:.1f} s", file=sys.stderr, flush=True)
    z_ls, z_post = np.array(z_ls), np.array(z_post)
    out = {"campaign": str(a.campaign), "replicates": len(z_ls), "median_ls_s": float(np.median(times)),
           "sd_z": {n: {"laplace": float(np.std(z_ls[:, j], ddof=1)), "posterior": float(np.std(z_post[:, j], ddof=1)),
                        "laplace_robust": robust_sd(z_ls[:, j]), "posterior_robust": robust_sd(z_post[:, j]),
                        "laplace_beyond_3": int(np.sum(np.abs(z_ls[:, j]) > 3))}
                    for j, n in enumerate(names)},
           "rho_hat": ({"median": float(np.median(rhos)), "mean": float(np.mean(rhos)), "q05": float(np.quantile(rhos, 0.05)),
                        "q95": float(np.quantile(rhos, 0.95)), "n": len(rhos)} if rhos else None)}
    if a.json:
        print(json.dumps(out, indent=1))
    else:
        print(f"{out['replicates']} replicates of {a.campaign}; least squares median {out['median_ls_s']:.1f} s")
        print(f"{'':6s} {'sd z_LS':>8s} {'sd z_post':>9s} {'robust LS':>9s} {'robust post':>11s} {'|z_LS|>3':>8s}"
              f"   (1 = right width; se of an sd ≈ {1 / np.sqrt(2 * max(len(z_ls) - 1, 1)):.2f})")
        for n, v in out["sd_z"].items():
            print(f"{n:6s} {v['laplace']:8.2f} {v['posterior']:9.2f} {v['laplace_robust']:9.2f} "
                  f"{v['posterior_robust']:11.2f} {v['laplace_beyond_3']:8d}")
        if out["rho_hat"]:
            r = out["rho_hat"]
            print(f"AR(1) ρ̂ over {r['n']} flights: median {r['median']:.3f}, mean {r['mean']:.3f}, "
                  f"5–95 % {r['q05']:.3f}–{r['q95']:.3f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
