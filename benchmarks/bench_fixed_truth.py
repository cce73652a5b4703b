"""Interval width at one fixed truth: the noise alone redrawn, least squares each time.

Replicate I of a calibration campaign fixes the coefficients and every flight's launch; the synthetic marker
noise is then drawn K times (synth seeds 5000 … 5000 + K − 1), optionally scaled by ``--scale``, and each data
set is fitted by least squares with the campaign's run settings (the AR(1) coefficients held at ``--fix-rho``
when given). Printed every five fits: mean and sd over the fits of z = (θ̃ − θ̂)/sd_Laplace per coefficient.

In the linear regime, with the noise model's whitening exact and the optimum found, sd(z) ≤ 1 (the prior can
only shrink it); equal z's at ``--scale 1`` and ``--scale 0.1`` (same seeds) show the regime is linear.

``--out FILE`` (a new file) keeps every fit's optimum and Laplace sd of the coefficients. The noise draws are
those of benchmarks/bench_fixed_truth_posterior.py (same seeds), so the two files pair draw by draw: the
validation page compares the posterior's z with the least-squares z of the same data
(tools/validation_fixed_truth.py).

    python benchmarks/bench_fixed_truth.py runs/calibration/four_flights_ar1.yaml [--replicate 0] [--fits 40]
                                           [--scale 1.0] [--fix-rho 0.85] [--out FILE]
"""
from __future__ import annotations

import argparse
import json
import sys
import tempfile
from dataclasses import replace
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bayes_disc.calibration.config import load_cal_config  # noqa: E402
from bayes_disc.calibration.replicate import (draw_truth, jittered_flights, replicate_data,  # noqa: E402
                                              replicate_rng, replicate_run)
from bayes_disc.inference.model.config import config_from_mapping  # noqa: E402
from bayes_disc.inference.model.data import build_problem  # noqa: E402
from bayes_disc.inference.fitting.leastsq import fit_least_squares, refine_least_squares  # noqa: E402
from bayes_disc.observation.synth import synthesize, write_synth  # noqa: E402
from bayes_disc.physics import Coefficients  # noqa: E402


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("campaign", type=Path)
    ap.add_argument("--replicate", type=int, default=0)
    ap.add_argument("--fits", type=int, default=40)
    ap.add_argument("--scale", type=float, default=1.0, help="factor on every flight's noise_mm")
    ap.add_argument("--fix-rho", type=float, default=None, help="hold the AR(1) coefficients at this value")
    ap.add_argument("--out", type=Path, help="write every fit's optimum and Laplace sd here (a new file)")
    a = ap.parse_args(argv)
    if a.out is not None and a.out.exists():
        raise SystemExit(f"{a.out} exists: give a new file (it is not replaced)")
    cal = load_cal_config(a.campaign)
    rng = replicate_rng(cal, a.replicate)          # the replicate's own stream: sampler seed, truth, launches
    sampler_seed = int(rng.integers(2 ** 20))
    truth = draw_truth(cal, rng)
    flights = tuple(replace(f, noise_mm=f.noise_mm * a.scale) for f in jittered_flights(cal, rng))
    names = list(cal.names)
    # the stream above is replicate_data's first draw; a replicate whose first truth failed to simulate was redrawn
    if replicate_data(cal, a.replicate)[1] != truth:
        raise SystemExit(f"replicate {a.replicate} was redrawn: its truth is not the stream's first draw")
    zs, optima, sds = [], [], []
    for k in range(a.fits):
        spec = replace(cal.template, name=f"fixed_{a.replicate}", flights=flights,
                       coefficients=Coefficients.from_mapping(truth), seed=5000 + k)
        result = synthesize(spec)
        with tempfile.TemporaryDirectory() as tmp:
            tmp = Path(tmp)
            write_synth(result, tmp / "markers.csv", tmp / "truth.json")
            cfg = config_from_mapping(replicate_run(cal, result, sampler_seed), tmp / "config.yaml")
            p = build_problem(cfg)
            ls = fit_least_squares(p, starts=cfg.least_squares.starts, max_nfev=cfg.least_squares.max_nfev, seed=1)
            if a.fix_rho is not None:
                held = np.array([n.startswith("rho_") for n in p.names])
                x0 = ls.theta.copy()
                x0[held] = a.fix_rho
                ls = refine_least_squares(p, x0, max_nfev=cfg.least_squares.max_nfev, free=~held)
        idx = [p.names.index(n) for n in names]
        optima.append(ls.theta[idx])
        sds.append(np.sqrt(np.diag(ls.cov))[idx])
        zs.append((np.array([truth[n] for n in names]) - optima[-1]) / sds[-1])
        z = np.array(zs)
        if (k + 1) % 5 == 0:
            print(json.dumps({"replicate": a.replicate, "scale": a.scale, "fits": k + 1,
                              "mean_z": dict(zip(names, z.mean(0).round(2).tolist())),
                              "sd_z": dict(zip(names, z.std(0, ddof=1).round(2).tolist()))}), flush=True)
    if a.out is not None:
        command = (f"python benchmarks/bench_fixed_truth.py {a.campaign.as_posix()} --replicate {a.replicate} "
                   f"--fits {a.fits}" + (f" --scale {a.scale}" if a.scale != 1.0 else "")
                   + (f" --fix-rho {a.fix_rho}" if a.fix_rho is not None else ""))
        head = json.dumps({"campaign": cal.name, "replicate": a.replicate, "fits": a.fits, "scale": a.scale,
                           "fix_rho": a.fix_rho, "truth": truth, "synth_seeds": [5000, 5000 + a.fits - 1],
                           "command": command}, indent=1)

        def rows(values):   # one draw per line, ten significant digits
            return ",\n  ".join(json.dumps([float(f"{v:.10g}") for v in row]) for row in values)
        a.out.write_text(head[:-2] + ',\n "per_draw": {\n "theta": [\n  ' + rows(optima) + '],\n "laplace_sd": [\n  '
                         + rows(sds) + "]}\n}\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
