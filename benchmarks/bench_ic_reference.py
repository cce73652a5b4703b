"""The demo's pitching-moment coefficients with and without the initial conditions' conditional reference prior.

Runs ``runs/demo/config.yaml`` (output in a temporary folder, one process) under ``prior.initial_conditions``
``reference`` and ``flat`` and prints, per prior, the posterior median and sd of CM0, CMa, CMq beside the
least-squares optimum and its sd, and the surrogate's held-out accuracy. Without the reference prior the
marginal of CMq sits away from the joint optimum (the initial conditions' volume changes along the
pitching-moment direction, once per flight); with it the marginal follows the profile likelihood.

    python benchmarks/bench_ic_reference.py [--config runs/demo/config.yaml]
"""
from __future__ import annotations

import argparse
import json
import logging
import sys
import tempfile
from dataclasses import replace
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bayes_disc.inference.model.config import load_config  # noqa: E402
from bayes_disc.jobs.sample import run_sample  # noqa: E402

NAMES = ("CM0", "CMa", "CMq")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--config", type=Path, default=ROOT / "runs/demo/config.yaml")
    a = ap.parse_args(argv)
    logging.getLogger("bayes_disc").setLevel(logging.WARNING)
    for ic in ("reference", "flat"):
        with tempfile.TemporaryDirectory(prefix="bd-ic-") as tmp:
            cfg = load_config(a.config, output_override=Path(tmp) / "out")
            cfg = replace(cfg, ic_prior=ic, sampler=replace(cfg.sampler, processes=1))
            s = run_sample(cfg, progress=False)
        ls = s["least_squares"]["parameters"]
        print(json.dumps({"initial_conditions": ic, **{n: {
            "median": round(s["parameters"][n]["q50"], 5), "sd": round(s["parameters"][n]["sd"], 5),
            "least_squares": round(ls[n]["value"], 5), "least_squares_sd": round(ls[n]["sd"], 5)} for n in NAMES},
            "surrogate_accuracy": s["initial_condition_prior"].get("surrogate_accuracy")}), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
