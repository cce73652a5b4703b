"""A randomly forced nutation concealed in synthetic logger throws: what white gyro noise makes of it, and what the
fit with ``gyro_noise: nutation`` recovers.

Synthesizes ``runs/concealed_nutation/synth.yaml`` (three throws, no extra physics; the transverse gyro carries a
randomly forced nutation) into ``runs/concealed_nutation/out/`` and fits ``runs/concealed_nutation/config.yaml``:

- ``white``: white gyro noise, the run's own least squares (its starts);
- ``white_terms``: white noise and the three wobble terms of the real throws' run (``inertia_ratio``,
  ``disc_asymmetry``, ``rate_damping``), refitted from ``white``;
- ``nutation``: ``gyro_noise: nutation``, no term, refitted from ``white``;
- ``nutation_terms``: the nutation and the three terms, refitted from ``nutation``.

Each refit as in ``tools/nutation_refit.py`` (:func:`nutation_refit.refit`, records by :func:`nutation_refit.record`). Writes
``runs/concealed_nutation/nutation_blind.json`` (``--output``): the truth (coefficients and the nutation) and
per variant the log-likelihood, the numbers of parameters and residuals, the parameters and per throw the misfit.

Usage (from the repository root; about 10 min on two cores)::

    python tools/nutation_blind.py [--overwrite]
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from bayes_disc.inference.fitting.leastsq import fit_least_squares
from bayes_disc.inference.model.config import load_config
from bayes_disc.inference.model.data import build_problem
from bayes_disc.observation.synth import synthesize, write_synth
from bayes_disc.observation.synth_config import load_synth_spec
from nutation_refit import NUTATION_START, record, refit

ROOT = Path(__file__).resolve().parents[1]
RUN = "runs/concealed_nutation"
#: the wobble terms of the real throws' run
TERMS = ["inertia_ratio", "disc_asymmetry", "rate_damping"]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--output", default=f"{RUN}/nutation_blind.json")
    ap.add_argument("--max-nfev", type=int, default=300)
    ap.add_argument("--overwrite", action="store_true", help="replace an existing output file")
    a = ap.parse_args(argv)
    out = ROOT / a.output
    if out.exists() and not a.overwrite:
        print(f"{a.output} exists; --overwrite replaces it", file=sys.stderr)
        return 2
    spec, markers, truth_path = load_synth_spec(ROOT / RUN / "synth.yaml")
    result = synthesize(spec)
    write_synth(result, markers, truth_path)
    truth = result.truth
    cfg = load_config(ROOT / RUN / "config.yaml")
    nut_cfg = replace(cfg, imu=tuple(replace(s, gyro_noise="nutation") for s in cfg.imu))
    rec = {"synth": f"{RUN}/synth.yaml", "config": f"{RUN}/config.yaml", "max_nfev": a.max_nfev,
           "truth": {"coefficients": truth["coefficients"], "nutation": truth["imu"]["logger"]["nutation"],
                     "gyro_noise_rad_s": truth["imu"]["logger"]["gyro_noise_rad_s"]},
           "variants": {}}
    t0 = time.perf_counter()
    problem = build_problem(cfg)
    ls = fit_least_squares(problem, starts=cfg.least_squares.starts, max_nfev=cfg.least_squares.max_nfev,
                           seed=cfg.sampler.seed)
    rec["variants"]["white"] = record(problem, ls.theta, time.perf_counter() - t0)
    start = dict(zip(problem.names, ls.theta))
    start.update(NUTATION_START)
    optimum = {}
    for name, c, terms, base in (("white_terms", cfg, TERMS, "white"), ("nutation", nut_cfg, [], "white"),
                                 ("nutation_terms", nut_cfg, TERMS, "nutation")):
        p = build_problem(c, terms_override=terms)
        at = {**start, **optimum.get(base, {})}
        x0 = np.array([at.get(n, 0.0) for n in p.names])          # a term's parameters start switched off
        r = refit(p, x0, a.max_nfev)
        optimum[name] = r.pop("optimum")
        rec["variants"][name] = r
        print(name, round(r["log_likelihood"], 1), flush=True)
    out.write_text(json.dumps(rec, indent=1))
    print(f"wrote {a.output}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
