"""How much an inertial logger tightens the coefficients over markers alone (mixed data study).

Three synthetic throws, each recorded by markers (120 Hz, 1.5 mm) and by an inertial logger in the disc
(gyro noise 0.005 axial / 0.05 transverse rad/s, accelerometer 0.05 m/s², row period 12.2 ms, no time
column), are written with ``bayes-disc synth`` and read back through run configurations (markers alone,
logger alone, both: a throw named like a marker flight is the same flight, its marker times start at
release). Each problem is fitted by least squares from the truth (``refine_least_squares``: noise scales
re-estimated from the residuals, then the Gauss–Newton covariance), and the Laplace sds of the ten
coefficients are compared. These are Laplace (Gauss–Newton) sds at the least-squares optimum, not posterior
widths from MCMC.

    python benchmarks/bench_mixed.py [--json] [--max-nfev 40]
"""
from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bayes_disc.inference.model.config import load_config  # noqa: E402
from bayes_disc.inference.model.data import build_problem  # noqa: E402
from bayes_disc.inference.fitting.leastsq import refine_least_squares  # noqa: E402
from bayes_disc.inference.model.truth import truth_theta  # noqa: E402
from bayes_disc.observation.synth_config import load_synth_spec
from bayes_disc.observation.synth import synthesize, write_synth  # noqa: E402
from bayes_disc.physics import COEFFICIENT_NAMES  # noqa: E402

RATE_COEFFICIENTS = ("CMq", "CRp", "CRr", "CNr")

SYNTH = """
name: mixed
seed: 11
sample_rate_hz: 120
coefficients: hummel2002
output: {markers: flights.csv, truth: truth.json}
imu:
  offset: [0.02, 0.0, -0.01]
  lpf_tau: 0.15
  period: 0.0122
  gyro_noise: [0.005, 0.05]
  acc_noise: [0.05, 0.05]
  output: logs
flights:
  - {name: a, speed: 13.0, launch_angle_deg: 5, alpha_deg: 8, spin: 55, roll_deg: 3, p: 2, q: -3, duration: 1.2,
     noise_mm: 1.5}
  - {name: b, speed: 11.0, launch_angle_deg: 10, alpha_deg: 20, spin: 50, roll_deg: -5, duration: 1.0,
     noise_mm: 1.5}
  - {name: c, speed: 15.0, launch_angle_deg: 2, alpha_deg: 3, spin: 60, roll_deg: 8, duration: 1.2, noise_mm: 1.5}
"""
MARKERS = """
flights: [{file: flights.csv}]
markers: {"0": [0.100, 0.000, -0.015], "1": [-0.0308, 0.0846, -0.015], "2": [-0.0707, -0.0778, -0.015]}
"""
IMU = """
imu:
  - {file: logs/a.csv, format: flatball-ins}
  - {file: logs/b.csv, format: flatball-ins}
  - {file: logs/c.csv, format: flatball-ins}
"""


def write_data(folder: Path) -> dict:
    """Synthesize the three throws into ``folder`` and write the three run configurations; returns the truth."""
    (folder / "synth.yaml").write_text(SYNTH)
    spec, markers_path, truth_path = load_synth_spec(folder / "synth.yaml")     # as `bayes-disc synth` does
    write_synth(synthesize(spec), markers_path, truth_path)
    for kind, body in (("markers", MARKERS), ("imu", IMU), ("both", MARKERS + IMU)):
        (folder / f"{kind}.yaml").write_text(f"name: mixed_{kind}\nprior: potts_crowther\noutput: out_{kind}\n" + body)
    return json.loads((folder / "truth.json").read_text())


def fit(folder: Path, kind: str, truth: dict, max_nfev: int) -> dict:
    """Least squares of one data kind from the truth; the coefficients' values and Laplace sds."""
    t0 = time.perf_counter()
    cfg = load_config(folder / f"{kind}.yaml")
    problem = build_problem(cfg)
    ls = refine_least_squares(problem, truth_theta(problem, truth), max_nfev=max_nfev)
    sd = np.sqrt(np.diag(ls.cov))
    out = {"value": dict(zip(COEFFICIENT_NAMES, ls.theta[: problem.n_coef].tolist())),
           "sd": dict(zip(COEFFICIENT_NAMES, sd[: problem.n_coef].tolist())),
           "prior_sd": dict(zip(COEFFICIENT_NAMES, problem.prior_sd[: problem.n_coef].tolist())),
           "noise": dict(zip(problem.sigma_names, ls.sigma.tolist())), "flights": [f.name for f in problem.flights],
           "dim": problem.dim, "seconds": time.perf_counter() - t0}
    for n in ("imu_offset_x", "imu_offset_y", "imu_offset_z", "imu_lpf_tau",
              *(f"imu_period_{f.name}" for f in problem.flights)):
        if n in problem.names:
            i = problem.names.index(n)
            out.setdefault("logger", {})[n] = {"value": float(ls.theta[i]), "sd": float(sd[i])}
    return out


def mixed_study(folder: Path, max_nfev: int = 40) -> dict:
    """The study in ``folder``: {"truth", "logger_truth", "fits": {markers, imu, both}, "ratios": {name: sd_both /
    sd_markers}, "sd_kind"}; each fit: coefficient values and sds, prior sds, noise scales, the logger's
    mount and row periods (value, sd), dimension, seconds."""
    truth = write_data(folder)
    fits = {kind: fit(folder, kind, truth, max_nfev) for kind in ("markers", "imu", "both")}
    ratios = {n: fits["both"]["sd"][n] / fits["markers"]["sd"][n] for n in COEFFICIENT_NAMES}
    lg = truth["imu"]["logger"]
    logger_truth = {"imu_offset_x": lg["offset_m"][0], "imu_offset_y": lg["offset_m"][1],
                    "imu_offset_z": lg["offset_m"][2], "imu_lpf_tau": lg["lpf_tau_s"],
                    **{f"imu_period_{n}": t["period_s"] for n, t in truth["imu"]["throws"].items()}}
    return {"truth": truth["coefficients"], "logger_truth": logger_truth, "fits": fits, "ratios": ratios,
            "sd_kind": "Laplace (Gauss-Newton) sd at the least-squares optimum, prior included"}


def table(result: dict) -> str:
    f = result["fits"]
    lines = [f"{'coef':<5} {'truth':>10} {'prior sd':>10} {'markers sd':>11} {'IMU sd':>11} {'both sd':>11} "
             f"{'both/mark':>9} {'both/IMU':>9}"]
    for n in COEFFICIENT_NAMES:
        star = " *" if n in RATE_COEFFICIENTS else ""
        lines.append(f"{n:<5} {result['truth'][n]:>10.4g} {f['markers']['prior_sd'][n]:>10.3g} "
                     f"{f['markers']['sd'][n]:>11.3g} {f['imu']['sd'][n]:>11.3g} {f['both']['sd'][n]:>11.3g} "
                     f"{result['ratios'][n]:>9.3f} {f['both']['sd'][n] / f['imu']['sd'][n]:>9.3f}{star}")
    lines.append("(* rate coefficients; sds: " + result["sd_kind"] + ")")
    for kind in ("markers", "imu", "both"):
        lines.append(f"{kind}: {f[kind]['dim']} parameters, fit {f[kind]['seconds']:.0f} s")
    for kind in ("imu", "both"):
        lines.append(f"logger ({kind}): " + ", ".join(
            f"{n} {v['value']:.5g} ± {v['sd']:.2g} (truth {result['logger_truth'][n]:.5g})"
            for n, v in f[kind]["logger"].items()))
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--json", action="store_true", help="print the result as JSON")
    ap.add_argument("--max-nfev", type=int, default=40, help="evaluations per least-squares round")
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as d:
        result = mixed_study(Path(d), args.max_nfev)
    print(json.dumps(result, indent=1) if args.json else table(result))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
