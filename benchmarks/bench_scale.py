"""Benchmark of campaign scale: how least squares, profile likelihoods and sampling grow with
the number of flights.

For each flight count (default 4, 8, 12, 24) a synthetic data set is made from the demo's four kinds of
throw (runs/demo/synth.yaml), repeated with jittered speed, angles and spin, and every stage a user waits
for is timed in this process:

* least squares (``fit_least_squares``: the block-arrow Levenberg–Marquardt, the configured starts) and,
  for comparison on the same data, one start of scipy's dense trust-region fit (the solver used before);
* the profile likelihoods of the coefficients and the independence proposal built from them; also their
  work, which does not depend on the machine's speed: the Jacobians and residual evaluations of the final
  paths' fits (``profiles.json``; a pass that a lower point ended is not counted), each one batched
  simulation per flight, so the stage's simulation work is linear in the flights where these counts stay
  level;
* sampling to the stopping rule (R-hat < 1.01, bulk ESS ≥ 400 for every coefficient, N/τ ≥ 10, at least
  ``min_steps``) or the cap; also reported, the time to the first convergence check that met R-hat < 1.01
  for every parameter and bulk ESS ≥ 400 for every coefficient (``rhat_ess_total_s``, from the check's
  ``elapsed_s``), and to the first that met the criterion for the coefficients alone, R-hat < 1.01
  and bulk ESS ≥ 400 for every coefficient (``coef_total_s``). The checks come every ``check_every`` (50)
  steps, so these times move in steps of that much sampling.

Prints one line per flight count and a table of ratios to the 4-flight figures; ``--json`` prints a JSON
object. Peak memory is the process's maximum resident set (children included).

    python benchmarks/bench_scale.py [--flights 4 8 12 24] [--max-steps 3000] [--sampler "walkers: 64"]
                                     [--no-dense] [--json] [--keep DIR]
"""
from __future__ import annotations

import argparse
import json
import resource
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bayes_disc.inference.model.config import load_config  # noqa: E402
from bayes_disc.inference.model.data import build_problem  # noqa: E402
from bayes_disc.inference.fitting.leastsq import fit_least_squares
from bayes_disc.inference.fitting.residuals import whitened_jacobian, whitened_residuals  # noqa: E402
from bayes_disc.jobs.sample import posterior_approximation  # noqa: E402
from bayes_disc.inference.sampling.mixing import n_walkers
from bayes_disc.inference.sampling.sampler import run_sampler  # noqa: E402
from bayes_disc.observation.synth_config import load_synth_spec
from bayes_disc.observation.synth import synthesize, write_synth  # noqa: E402

DEMO = ROOT / "runs" / "demo"


def flight_set(n: int, seed: int):
    """n launches: the demo's four kinds in turn, each repeat jittered (speed ±10 %, angles ±2°, spin ±10 %)."""
    spec, _, _ = load_synth_spec(DEMO / "synth.yaml")
    rng = np.random.default_rng(seed)
    out = []
    for i in range(n):
        base = spec.flights[i % len(spec.flights)]
        if i < len(spec.flights):
            out.append(base)
            continue
        jitter = dict(name=f"{base.name}_{i // len(spec.flights)}", speed=base.speed * (1 + 0.1 * rng.uniform(-1, 1)),
                      spin=base.spin * (1 + 0.1 * rng.uniform(-1, 1)),
                      launch_angle_deg=base.launch_angle_deg + 2 * rng.uniform(-1, 1))
        for key in ("alpha_deg", "pitch_deg"):
            if getattr(base, key, None) is not None:
                jitter[key] = getattr(base, key) + 2 * rng.uniform(-1, 1)
        out.append(replace(base, **jitter))
    return replace(spec, flights=tuple(out), seed=seed)


def write_case(folder: Path, n: int, seed: int, sampler: str) -> Path:
    spec = flight_set(n, seed)
    write_synth(synthesize(spec), folder / "flights.csv", folder / "truth.json")
    demo = (DEMO / "config.yaml").read_text()
    cfg = demo.replace("name: demo", f"name: scale{n}").replace("output: out", "output: out")
    cfg += f"sampler: {{{sampler}}}\n"
    path = folder / "config.yaml"
    path.write_text(cfg)
    return path


def peak_mb() -> float:
    own = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    kids = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
    return max(own, kids) / 1024.0


def dense_fit_time(problem, x0, sigma, max_nfev: int) -> tuple[float, float, int]:
    """One start of scipy's dense trust-region reflective fit (for comparison with the block-arrow solver)."""
    from scipy.optimize import least_squares
    t0 = time.perf_counter()
    res = least_squares(whitened_residuals, x0, jac=whitened_jacobian, args=(problem, sigma), method="trf",
                        x_scale=problem.prior_sd, max_nfev=max_nfev, xtol=1e-10, ftol=1e-10)
    return time.perf_counter() - t0, float(res.cost), int(res.nfev)


def one_case(n: int, seed: int, sampler: str, dense: bool, tmp: Path) -> dict:
    folder = tmp / f"f{n}"
    folder.mkdir()
    cfg = load_config(write_case(folder, n, seed, sampler))
    problem = build_problem(cfg)
    problem.log_prob(problem.start_vector()[None])        # compiled kernel loaded (cached on disk)
    row = {"flights": n, "dim": problem.dim, "walkers": n_walkers(cfg.sampler, problem)}
    t0 = time.perf_counter()
    ls = fit_least_squares(problem, starts=cfg.least_squares.starts, max_nfev=cfg.least_squares.max_nfev)
    row["least_squares_s"] = time.perf_counter() - t0
    row["least_squares_cost"] = ls.cost
    if dense:
        from bayes_disc.inference.fitting.minimiser import minimise
        x0 = problem.start_vector()
        t0 = time.perf_counter()
        new = minimise(problem, x0, problem.nominal_noise, max_nfev=cfg.least_squares.max_nfev)
        row["one_start_arrow_s"], row["one_start_arrow_cost"] = time.perf_counter() - t0, new.cost
        row["one_start_dense_s"], row["one_start_dense_cost"], _ = dense_fit_time(problem, x0, problem.nominal_noise,
                                                                                cfg.least_squares.max_nfev)
    out = folder / "out"
    out.mkdir()
    t0 = time.perf_counter()
    proposal, ls = posterior_approximation(problem, ls, cfg.sampler.processes, out)
    row["profiles_s"] = time.perf_counter() - t0
    row["lower_optima"] = len(ls.lower_optima)
    paths = json.loads((out / "profiles.json").read_text())
    row["profile_points"] = sum(len(r["t"]) - 1 for r in paths.values())            # the optimum not counted
    row["profile_jacobians"] = sum(r["jacobians"] for r in paths.values())
    row["profile_evaluations"] = sum(r["evaluations"] for r in paths.values())
    t0 = time.perf_counter()
    chains = run_sampler(problem, proposal, cfg.sampler, out, progress=False)
    row["sampling_s"] = time.perf_counter() - t0
    last = [h for h in chains.history if "rhat_max" in h]
    row.update(steps=chains.total_steps, converged=chains.converged,
               rhat_max=last[-1]["rhat_max"] if last else np.nan, ess_min_coef=last[-1]["ess_min_coef"] if last else np.nan,
               n_over_tau=last[-1]["n_over_tau"] if last else np.nan,
               acceptance=float(np.mean(chains.acceptance)))
    # which parameters set τ (the N/τ rule): the final check's τ, largest over the ensembles
    tau = np.nanmax(chains.tau, axis=0)
    row.update(tau_max_coefficients=float(np.nanmax(tau[:problem.ic_start])),
               tau_max_initial_conditions=float(np.nanmax(tau[problem.ic_start:])))
    row["total_s"] = row["least_squares_s"] + row["profiles_s"] + row["sampling_s"]
    # the first check at which R-hat < 1.01 (of every parameter: rhat_ess; of the coefficients, the scale
    # criterion: coef) and every coefficient's bulk ESS ≥ 400, without the sampler's N/τ ≥ 10 and min_steps
    for prefix, rhat_key in (("rhat_ess", "rhat_max"), ("coef", "rhat_max_coef")):
        met = [h for h in last if h[rhat_key] < cfg.sampler.rhat and h["ess_min_coef"] >= cfg.sampler.ess]
        row[f"{prefix}_steps"] = met[0]["steps"] if met else None
        before = row["least_squares_s"] + row["profiles_s"]
        row[f"{prefix}_total_s"] = before + met[0]["elapsed_s"] if met else np.nan
    row["peak_rss_mb"] = peak_mb()
    return row


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--flights", type=int, nargs="+", default=[4, 8, 12, 24])
    ap.add_argument("--max-steps", type=int, default=3000)
    ap.add_argument("--seed", type=int, default=18)
    ap.add_argument("--sampler", default="", help="extra sampler keys, e.g. 'block_fraction: 0, walkers: 64'")
    ap.add_argument("--no-dense", action="store_true", help="skip the dense-solver comparison")
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--keep", type=Path, default=None,
                    help="keep every case's data, config and chains in this (new or empty) folder")
    args = ap.parse_args(argv)
    rows = []
    if args.keep is not None:
        args.keep.mkdir(parents=True, exist_ok=True)
        if any(args.keep.iterdir()):
            ap.error(f"--keep {args.keep}: folder not empty")
    with tempfile.TemporaryDirectory() as scratch:
        tmp = scratch if args.keep is None else args.keep
        for n in args.flights:
            sampler = ", ".join([f"max_steps: {args.max_steps}"] + ([args.sampler] if args.sampler else []))
            row = one_case(n, args.seed, sampler, not args.no_dense, Path(tmp))
            rows.append(row)
            if not args.json:
                dense = (f", one start arrow {row['one_start_arrow_s']:.1f} s vs dense {row['one_start_dense_s']:.1f} s"
                         if "one_start_dense_s" in row else "")
                refits = (f" (least squares refitted {row['lower_optima']}× from a lower point on a profile)"
                          if row["lower_optima"] else "")
                print(f"{n:3d} flights ({row['dim']} parameters, {row['walkers']} walkers): least squares "
                      f"{row['least_squares_s']:.1f} s{dense}; profiles {row['profiles_s']:.1f} s "
                      f"({row['profile_points']} points, {row['profile_jacobians']} Jacobians, "
                      f"{row['profile_evaluations']} evaluations){refits}; sampling "
                      f"{row['sampling_s']:.1f} s ({row['steps']} steps, converged {row['converged']}, R-hat "
                      f"{row['rhat_max']:.4f}, ESS {row['ess_min_coef']:.0f}, N/τ {row['n_over_tau']:.1f}, τ max coefficients "
                      f"{row['tau_max_coefficients']:.1f} / initial conditions {row['tau_max_initial_conditions']:.1f} steps, "
                      f"acceptance {row['acceptance']:.2f}); total {row['total_s']:.1f} s; "
                      f"R-hat and ESS alone met at step {row['rhat_ess_steps']}, {row['rhat_ess_total_s']:.1f} s in all; "
                      f"the coefficients' R-hat and ESS at step {row['coef_steps']}, {row['coef_total_s']:.1f} s; peak "
                      f"{row['peak_rss_mb']:.0f} MB", flush=True)
    base = rows[0]
    for r in rows:
        r["ratio_to_first"] = {k: r[k] / base[k] for k in ("least_squares_s", "profiles_s", "sampling_s", "total_s",
                                                           "rhat_ess_total_s", "coef_total_s")}
    if args.json:
        print(json.dumps(rows, indent=1))
    else:
        print(f"\nratios to {base['flights']} flights:")
        for r in rows:
            q = r["ratio_to_first"]
            print(f"{r['flights']:3d} flights: least squares ×{q['least_squares_s']:.2f}, profiles ×{q['profiles_s']:.2f} "
                  f"(Jacobians ×{r['profile_jacobians'] / base['profile_jacobians']:.2f}), "
                  f"sampling ×{q['sampling_s']:.2f}, total ×{q['total_s']:.2f}, "
                  f"to R-hat and ESS alone ×{q['rhat_ess_total_s']:.2f}, to the coefficients' ×{q['coef_total_s']:.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
