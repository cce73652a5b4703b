"""The real throws with their rows equally spaced and with the rows placed by the magnetometer, fitted alike.

Writes ``runs/flatball/wobble/row_times.json`` (``--output``), which docs/validation.md reads:

- ``refit``: for each row placement (``uniform``, ``magnetometer``) the same least squares from the same
  point, the wobble run's optimum (``runs/flatball/wobble/out/least_squares.json``): the throws' initial
  conditions alone (``IC_NFEV`` evaluations), then everything (``--max-nfev`` per round, three rounds of
  noise re-estimation). Per noise group its RMS and count, Σ n ln σ over all groups and over the groups
  other than the magnetometer's (which places the rows, so its own misfit is no independent check).
- ``run_starts``: the run's own least squares (its starts, ``least_squares`` settings of the config) with
  the rows placed by the magnetometer: where the start search ends.
- ``rows``: per throw, how far the magnetometer puts the rows from equally spaced ones (the observation
  model's ``row_time_summary``, from ``row_offsets_from_magnetometer``).

Usage (from the repository root; about 5 min on two cores)::

    python tools/row_times_refit.py [--overwrite]
"""
from __future__ import annotations

import argparse
import json
import math
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from bayes_disc.inference.fitting.leastsq import fit_least_squares, refine_least_squares
from bayes_disc.inference.model.config import load_config
from bayes_disc.inference.model.data import build_problem
from bayes_disc.observation.models.inertial import InertialMeasurements

ROOT = Path(__file__).resolve().parents[1]
#: evaluations of the initial-conditions-only fit that adapts the run's optimum to a row placement
IC_NFEV = 60


def noise_record(ls) -> dict:
    """{"noise": {group: {value, unit, n}}, "sum_n_ln_sigma", "sum_n_ln_sigma_without_mag"} of a fit."""
    noise = ls.noise()
    total = sum(v["n"] * math.log(v["value"]) for v in noise.values())
    other = sum(v["n"] * math.log(v["value"]) for k, v in noise.items() if not k.startswith("sigma_mag"))
    return {"noise": noise, "sum_n_ln_sigma": total, "sum_n_ln_sigma_without_mag": other}


def refit(problem, x0: np.ndarray, max_nfev: int) -> dict:
    """The initial conditions alone, then everything, from x0 (module docstring)."""
    t0 = time.perf_counter()
    ic = np.zeros(x0.size, bool)
    for k in range(problem.n_flights):
        ic[problem.ic_slice(k)] = True
    x = refine_least_squares(problem, x0, max_nfev=IC_NFEV, free=ic).theta
    ls = refine_least_squares(problem, x, max_nfev=max_nfev, rounds=3)
    coef = {n: float(v) for n, v in zip(problem.names[:problem.ic_start], ls.theta)}
    return {**noise_record(ls), "coefficients": coef, "nfev": ls.nfev, "wall_time_s": time.perf_counter() - t0}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--config", default="runs/flatball/wobble/config.yaml")
    ap.add_argument("--start", default="runs/flatball/wobble/out/least_squares.json")
    ap.add_argument("--output", default="runs/flatball/wobble/row_times.json")
    ap.add_argument("--max-nfev", type=int, default=300)
    ap.add_argument("--overwrite", action="store_true", help="replace an existing output file")
    a = ap.parse_args(argv)
    out = ROOT / a.output
    if out.exists() and not a.overwrite:
        print(f"{a.output} exists; --overwrite replaces it", file=sys.stderr)
        return 2
    cfg = load_config(ROOT / a.config)
    start = json.loads((ROOT / a.start).read_text())["parameters"]
    rec = {"config": a.config, "start": a.start, "max_nfev": a.max_nfev, "ic_nfev": IC_NFEV, "refit": {}}
    for placement in ("uniform", "magnetometer"):
        c = replace(cfg, imu=tuple(replace(s, row_times=placement) for s in cfg.imu))
        problem = build_problem(c)
        missing = [n for n in problem.names if n not in start]
        if missing:
            raise SystemExit(f"{a.start} lacks {missing[:3]}…: not an optimum of {a.config}")
        x0 = np.array([start[n]["value"] for n in problem.names])
        rec["refit"][placement] = refit(problem, x0, a.max_nfev)
        print(placement, round(rec["refit"][placement]["sum_n_ln_sigma_without_mag"], 1), flush=True)
        if placement == "magnetometer":
            rec["rows"] = {f.name: m.row_time_summary for f, ms in zip(problem.flights, problem.observations)
                           for m in ms if isinstance(m, InertialMeasurements)}
            t0 = time.perf_counter()
            ls = fit_least_squares(problem, starts=c.least_squares.starts, max_nfev=c.least_squares.max_nfev,
                                   seed=c.sampler.seed)
            rec["run_starts"] = {**noise_record(ls), "wall_time_s": time.perf_counter() - t0}
    out.write_text(json.dumps(rec, indent=1))
    print(f"wrote {a.output}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
