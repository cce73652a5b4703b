"""Coverage of the profile intervals: at one fixed truth (the noise alone redrawn) or over a campaign's replicates.

Each data set is fitted as ``bayes-disc sample`` fits it before sampling — least squares with the campaign's run
settings, then the profile path of every coefficient (``jobs.sample.posterior_approximation``, which writes
``profiles.json``) — and the truth's quantile u under each coefficient's normalised profile
(``inference.fitting.profile_interval.profile_cdf``) is recorded. u is uniform when the profile intervals cover
as they claim: printed and written are the coverage of the central 50 % and 90 % intervals (|u − ½| < ¼, < 0.45)
and mean and sd of z = Φ⁻¹(u) (sd 1 when calibrated; within 1 ± 0.15 asked at a fixed truth). The joint
statement beside them is the profile deviance of the whole coefficient vector at the truth, W = 2 [cost(c̃, x̂(c̃))
− cost(θ̂)] with every flight's initial conditions re-optimised (``inference.fitting.joint_region.profile_deviance``,
the test ``sample`` applies to the published coefficient sets; the likelihood-ratio statistic, χ²₁₀ when the
profile likelihood's joint regions are calibrated): printed and written are its mean (band 10 ± 2·√20/√K over K
data sets) and the share of data sets with W below χ²₁₀'s 90 % point (the coverage of the joint 90 % region).

``--replicate I --draws K``: replicate I of the campaign fixes the coefficients and every flight's launch (its
design); the marker noise is drawn K times with synth seeds 5000 … 5000 + K − 1, the noise draws of
benchmarks/bench_fixed_truth_posterior.py and benchmarks/bench_fixed_truth.py, so the files pair draw by draw.
``--replicates N``: the campaign's first N replicates as ``bayes-disc calibrate`` draws them (each its own truth
and design). ``--out FILE`` (a new file) keeps the figures and every data set's u; tools/make_validation.py
reads such files from runs/calibration/profile/.

    python benchmarks/bench_profile_coverage.py runs/calibration/four_flights_varied.yaml --replicate 1 --draws 150
                                                [--processes 2] [--out FILE]
    python benchmarks/bench_profile_coverage.py runs/calibration/four_flights_varied.yaml --replicates 100
"""
from __future__ import annotations

import argparse
import json
import logging
import sys
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import asdict, replace
from pathlib import Path

import numpy as np
from scipy.stats import chi2, norm

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bayes_disc.calibration.config import load_cal_config  # noqa: E402
from bayes_disc.calibration.replicate import replicate_data, replicate_run  # noqa: E402
from bayes_disc.inference.fitting.leastsq import fit_least_squares  # noqa: E402
from bayes_disc.inference.fitting.profile_interval import profile_cdf  # noqa: E402
from bayes_disc.inference.fitting.joint_region import profile_deviance  # noqa: E402
from bayes_disc.inference.model.config import config_from_mapping  # noqa: E402
from bayes_disc.inference.model.data import build_problem  # noqa: E402
from bayes_disc.jobs.sample import posterior_approximation  # noqa: E402
from bayes_disc.observation.synth import synthesize, write_synth  # noqa: E402
from bayes_disc.physics import Coefficients  # noqa: E402
from bench_fixed_truth_posterior import fixed_design  # noqa: E402  (the same design and sampler seed)

#: noise draws of a fixed design use synth seeds from here on (as the other fixed-truth benchmarks)
FIRST_SEED = 5000
#: the launch values of each flight written with a fixed design's figures
DESIGN = ("name", "speed", "launch_angle_deg", "alpha_deg", "roll_deg", "spin", "p", "q", "duration", "noise_mm")


def truth_quantiles(result, truth: dict, sampler_seed: int, cal) -> tuple[list[float], float]:
    """The truth's quantile u under each coefficient's normalised profile, and the profile deviance W of the whole
    coefficient vector at the truth, for one synthetic data set fitted with the campaign's run settings."""
    with tempfile.TemporaryDirectory(prefix="bd-profile-") as tmp:
        tmp = Path(tmp)
        write_synth(result, tmp / "markers.csv", tmp / "truth.json")
        cfg = config_from_mapping(replicate_run(cal, result, sampler_seed), tmp / "config.yaml")
        problem = build_problem(cfg)
        ls = fit_least_squares(problem, starts=cfg.least_squares.starts, max_nfev=cfg.least_squares.max_nfev,
                               seed=cfg.sampler.seed)
        _, ls = posterior_approximation(problem, ls, 1, tmp, max_nfev=cfg.least_squares.max_nfev)
        paths = json.loads((tmp / "profiles.json").read_text())
    u = [float(profile_cdf(paths[n], truth[n])[0]) for n in cal.names]
    return u, profile_deviance(problem, ls, {n: truth[n] for n in cal.names}).deviance


def one_noise_draw(campaign: Path, replicate: int, design: tuple, k: int) -> tuple[list[float], float]:
    """Noise draw k of the replicate's fixed design (its truth, flights and sampler seed,
    ``bench_fixed_truth_posterior.fixed_design``): u per coefficient and W."""
    logging.getLogger("bayes_disc").setLevel(logging.WARNING)
    cal = load_cal_config(campaign)
    truth, flights, sampler_seed = design
    spec = replace(cal.template, name=f"fixed_{replicate}", flights=flights,
                   coefficients=Coefficients.from_mapping(truth), seed=FIRST_SEED + k)
    return truth_quantiles(synthesize(spec), truth, sampler_seed, cal)


def one_replicate(campaign: Path, index: int) -> tuple[list[float], float]:
    """Replicate ``index`` of the campaign (its own truth and design): u per coefficient and W."""
    logging.getLogger("bayes_disc").setLevel(logging.WARNING)
    cal = load_cal_config(campaign)
    result, truth, _, sampler_seed = replicate_data(cal, index)
    return truth_quantiles(result, truth, sampler_seed, cal)


def figures(u: np.ndarray, w: np.ndarray, names: list) -> dict:
    """Coverage and z figures of the quantiles u (n, k), and the joint figures of the deviances W (n,)."""
    z = norm.ppf(np.clip(u, 1e-6, 1 - 1e-6))
    n, k = u.shape
    return {"n": int(n),
            "coverage_50": dict(zip(names, np.mean(np.abs(u - 0.5) < 0.25, axis=0).round(3).tolist())),
            "coverage_90": dict(zip(names, np.mean(np.abs(u - 0.5) < 0.45, axis=0).round(3).tolist())),
            "mean_z": dict(zip(names, z.mean(axis=0).round(3).tolist())),
            "sd_z": dict(zip(names, z.std(axis=0, ddof=1).round(3).tolist())),
            "mean_deviance": round(float(np.mean(w)), 2),
            "deviance_band": [round(k - 2 * np.sqrt(2 * k / n), 2), round(k + 2 * np.sqrt(2 * k / n), 2)],
            "joint_coverage_90": round(float(np.mean(w < chi2.ppf(0.9, k))), 3)}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("campaign", type=Path)
    which = ap.add_mutually_exclusive_group(required=True)
    which.add_argument("--replicate", type=int, help="the fixed design: this replicate's truth and launches")
    which.add_argument("--replicates", type=int, help="the campaign's first N replicates")
    ap.add_argument("--draws", type=int, default=50, help="noise draws of the fixed design")
    ap.add_argument("--processes", type=int, default=1, help="data sets fitted at a time")
    ap.add_argument("--out", type=Path, help="write the figures and every data set's u here (a new file)")
    a = ap.parse_args(argv)
    if a.out is not None and a.out.exists():
        raise SystemExit(f"{a.out} exists: give a new file (it is not replaced)")
    cal = load_cal_config(a.campaign)
    names = list(cal.names)
    fixed = a.replicate is not None
    n = a.draws if fixed else a.replicates
    t0 = time.perf_counter()
    us, ws = [], []
    if fixed:
        truth, flights, sampler_seed = fixed_design(cal, a.replicate)
    with ProcessPoolExecutor(max_workers=a.processes) as pool:
        jobs = (pool.map(one_noise_draw, [a.campaign] * n, [a.replicate] * n, [(truth, flights, sampler_seed)] * n,
                         range(n)) if fixed else pool.map(one_replicate, [a.campaign] * n, range(n)))
        for k, (u, w) in enumerate(jobs):
            us.append(u)
            ws.append(w)
            if (k + 1) % 10 == 0 or k + 1 == n:
                print(json.dumps({"data_sets": k + 1, "seconds": round(time.perf_counter() - t0),
                                  **figures(np.array(us), np.array(ws), names)}), flush=True)
    u, w = np.array(us), np.array(ws)
    if a.out is not None:
        design = {}
        if fixed:
            design = {"replicate": a.replicate, "draws": n, "truth": truth,
                      "flights": [{key: v for key, v in asdict(f).items() if key in DESIGN and v is not None}
                                  for f in flights],
                      "synth_seeds": [FIRST_SEED, FIRST_SEED + n - 1]}
        out = {"campaign": cal.name, **(design if fixed else {"replicates": n}),
               **figures(u, w, names), "quantile": np.round(u, 5).tolist(),
               "deviance": np.round(w, 3).tolist(),
               "command": (f"python benchmarks/bench_profile_coverage.py {a.campaign.as_posix()} "
                           + (f"--replicate {a.replicate} --draws {n}" if fixed else f"--replicates {n}"))}
        a.out.parent.mkdir(parents=True, exist_ok=True)
        a.out.write_text(json.dumps(out, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
