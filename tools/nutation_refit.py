"""The real throws with white transverse gyro noise and with a randomly forced nutation, fitted alike.

Writes ``runs/flatball/wobble/nutation.json`` (``--output``), which docs/validation.md reads. Each variant is
refitted from the same point, the wobble run's optimum (``runs/flatball/wobble/out/least_squares.json``;
the nutation's parameters start at λ = 3 /s, κ_N = 0.9, a = 5): the nutation's parameters alone
(``NUTATION_NFEV`` evaluations, when it has them), the throws' initial conditions alone (``IC_NFEV``), then
everything (``--max-nfev`` per round, three rounds of noise re-estimation):

- ``white``: the run's configuration (the wobble terms, white gyro noise);
- ``nutation``: the same with ``gyro_noise: nutation``;
- ``nutation_without_terms``: ``gyro_noise: nutation`` and no extra physics term.

Per variant: the log-likelihood with every noise scale integrated out, the numbers of parameters and of
residuals, the fitted
coefficients, the terms' and the nutation's parameters, and per throw and noise group the RMS of the residuals
(``rms``); for the transverse gyro also, with the nutation, the white part σ of its noise, the RMS of the
Kalman filter's innovations (the misfit of a one-row-ahead prediction) and the nutation's RMS a σ.

Usage (from the repository root; about 10 min on two cores)::

    python tools/nutation_refit.py [--overwrite]
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from bayes_disc.inference.fitting.leastsq import refine_least_squares
from bayes_disc.inference.model.config import load_config
from bayes_disc.inference.model.data import build_problem
from bayes_disc.observation.models.inertial import InertialMeasurements

ROOT = Path(__file__).resolve().parents[1]
#: evaluations of the fits of the nutation's parameters alone and of the initial conditions alone
NUTATION_NFEV, IC_NFEV = 60, 60
#: where the nutation's parameters start
NUTATION_START = {"nutation_decay": 3.0, "nutation_kappa": 0.9, "nutation_amplitude": 5.0}


def throw_record(problem, theta: np.ndarray, k: int) -> dict:
    """RMS per noise group of throw k at θ; for the transverse gyro with the nutation also its white σ, the
    filter's innovation RMS and the nutation's RMS."""
    (model, pred), = [(c, p) for c, p in problem.channel_predictions(theta[None], k)[0]
                      if isinstance(c, InertialMeasurements)]
    extra = problem._extra(theta[None], k, 0)
    res = model.residuals(pred)[0]
    out = {g: float(np.sqrt(np.mean(res[model.group_index == i] ** 2))) for i, g in enumerate(model.group_names)}
    rec = {"rms": out}
    if model.gyro_noise == "nutation":
        ex, ey, ld = model._nutation(res[None], extra)
        e = np.c_[ex[0], ey[0]]
        sigma = float(np.sqrt(np.mean(e ** 2)))
        rec.update(white_sigma=sigma, innovation_rms=float(np.sqrt(np.mean((e * np.exp(-ld[0])[:, None]) ** 2))),
                   nutation_rms=float(model.split(extra)["nutation"][0, 2] * sigma))
    return rec


def refit(problem, x0: np.ndarray, max_nfev: int) -> dict:
    """The nutation's parameters, the initial conditions, then everything, from x0 (module docstring); the
    record holds the whole parameter vector as ``optimum`` ({name: value}) too."""
    t0 = time.perf_counter()
    nut = np.array([n in NUTATION_START for n in problem.names])
    x = refine_least_squares(problem, x0, max_nfev=NUTATION_NFEV, free=nut).theta if nut.any() else x0
    ic = np.zeros(x.size, bool)
    for k in range(problem.n_flights):
        ic[problem.ic_slice(k)] = True
    x = refine_least_squares(problem, x, max_nfev=IC_NFEV, free=ic).theta
    x = refine_least_squares(problem, x, max_nfev=max_nfev, rounds=3).theta
    return {**record(problem, x, time.perf_counter() - t0), "optimum": dict(zip(problem.names, map(float, x)))}


def record(problem, x: np.ndarray, wall: float) -> dict:
    """A fit's record at the optimum x: log-likelihood, numbers of parameters and residuals, the parameters
    shared by the throws (coefficients, terms, logger, nutation), per throw :func:`throw_record`, wall time [s]."""
    n_obs = sum(problem.noise_residuals(x[None], k)[0].shape[1] for k in range(problem.n_flights))
    return {"log_likelihood": float(problem.log_likelihood(x[None])[0]), "n_parameters": int(x.size),
            "n_observations": int(n_obs),
            "parameters": {n: float(v) for n, v in zip(problem.names[:problem.ic_start], x)},
            "throws": {f.name: throw_record(problem, x, k) for k, f in enumerate(problem.flights)},
            "wall_time_s": wall}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--config", default="runs/flatball/wobble/config.yaml")
    ap.add_argument("--start", default="runs/flatball/wobble/out/least_squares.json")
    ap.add_argument("--output", default="runs/flatball/wobble/nutation.json")
    ap.add_argument("--max-nfev", type=int, default=300)
    ap.add_argument("--overwrite", action="store_true", help="replace an existing output file")
    a = ap.parse_args(argv)
    out = ROOT / a.output
    if out.exists() and not a.overwrite:
        print(f"{a.output} exists; --overwrite replaces it", file=sys.stderr)
        return 2
    cfg = load_config(ROOT / a.config)
    start = {n: v["value"] for n, v in json.loads((ROOT / a.start).read_text())["parameters"].items()}
    start.update(NUTATION_START)
    rec = {"config": a.config, "start": a.start, "max_nfev": a.max_nfev, "nutation_start": NUTATION_START,
           "variants": {}}
    variants = {"white": (cfg, None), "nutation": (replace(cfg, imu=tuple(replace(s, gyro_noise="nutation")
                                                                          for s in cfg.imu)), None)}
    variants["nutation_without_terms"] = (variants["nutation"][0], [])
    for name, (c, terms) in variants.items():
        problem = build_problem(c, terms_override=terms)
        missing = [n for n in problem.names if n not in start]
        if missing:
            raise SystemExit(f"{a.start} lacks {missing[:3]}…: not an optimum of {a.config}")
        rec["variants"][name] = refit(problem, np.array([start[n] for n in problem.names]), a.max_nfev)
        rec["variants"][name].pop("optimum")
        print(name, round(rec["variants"][name]["log_likelihood"], 1), flush=True)
    out.write_text(json.dumps(rec, indent=1))
    print(f"wrote {a.output}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
