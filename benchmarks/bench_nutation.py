"""What the randomly forced nutation (``gyro_noise: nutation``) costs per log-posterior evaluation.

The shipped real throws with the wobble run's model (``runs/flatball/wobble/config.yaml``), at its least-squares
optimum, with white transverse gyro noise and with the nutation (its parameters at λ = 3 /s, κ_N = 0.9, a = 5):
the wall time of ``log_prob`` for a batch of walkers (the optimum repeated), median over repeats, both measured
in the same run, and their ratio. The Kalman filter runs over the rows of each throw once per lane for the
whitening and once for the log-determinant; the simulation dominates both.

    python benchmarks/bench_nutation.py [--batch 64] [--repeats 7]
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bayes_disc.inference.model.config import load_config  # noqa: E402
from bayes_disc.inference.model.data import build_problem  # noqa: E402

NUTATION = {"nutation_decay": 3.0, "nutation_kappa": 0.9, "nutation_amplitude": 5.0}


def timed(problem, theta: np.ndarray, repeats: int) -> float:
    """Median wall time [s] of ``problem.log_prob(theta)`` over ``repeats`` calls (after one warm-up call)."""
    problem.log_prob(theta)
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        problem.log_prob(theta)
        times.append(time.perf_counter() - t0)
    return float(np.median(times))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--batch", type=int, default=64)
    ap.add_argument("--repeats", type=int, default=7)
    a = ap.parse_args(argv)
    cfg = load_config(ROOT / "runs/flatball/wobble/config.yaml")
    start = {n: v["value"] for n, v in json.loads(
        (ROOT / "runs/flatball/wobble/out/least_squares.json").read_text())["parameters"].items()}
    start.update(NUTATION)
    out = {}
    for name, c in (("white", cfg), ("nutation", replace(cfg, imu=tuple(replace(s, gyro_noise="nutation")
                                                                         for s in cfg.imu)))):
        problem = build_problem(c)
        theta = np.tile([start[n] for n in problem.names], (a.batch, 1))
        out[name] = timed(problem, theta, a.repeats)
        print(f"{name}: log_prob of {a.batch} lanes, median of {a.repeats}: {out[name] * 1e3:.1f} ms", flush=True)
    print(f"nutation / white: {out['nutation'] / out['white']:.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
