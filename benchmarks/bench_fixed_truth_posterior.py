"""Coverage of the posterior at one fixed truth: the noise alone redrawn, a short sampling run each time, with
the initial conditions' conditional reference prior and without it.

Replicate I of a calibration campaign fixes the coefficients and every flight's launch (its design); the
synthetic marker noise is drawn K times (synth seeds 5000 … 5000 + K − 1) and each data set is sampled with the
campaign's run settings under ``prior.initial_conditions`` ``reference`` and ``flat`` (same data, same sampler
seed). Printed after every draw, per prior: the mean over the draws of the truth's Mahalanobis distance² under
the posterior mean and covariance of the ten coefficients (χ²₁₀ if the intervals are right: expected 10, band
10 ± 2·√20/√K), and mean and sd over the draws of z_k = (θ̃_k − posterior mean_k)/posterior sd_k (sd(z) = 1
when calibrated, within 1 ± 0.15 asked), and how many runs stopped unconverged. With ``--out`` the figures,
every draw's distance², z and convergence, and how the reference prior's surrogate is fitted
(``reference_surrogate``: Huber threshold, refinement rounds and tolerance) are written as JSON (a new file:
an existing one is not replaced); tools/make_validation.py reads such files from runs/calibration/fixed_truth/.

    python benchmarks/bench_fixed_truth_posterior.py runs/calibration/four_flights_varied.yaml [--replicate 0]
                                                     [--draws 20] [--priors reference flat] [--out FILE]
"""
from __future__ import annotations

import argparse
import json
import logging
import sys
import tempfile
from dataclasses import asdict, replace
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bayes_disc.calibration.config import load_cal_config  # noqa: E402
from bayes_disc.calibration.replicate import (draw_truth, jittered_flights, replicate_data,  # noqa: E402
                                              replicate_rng, replicate_run)
from bayes_disc.inference.fitting import reference  # noqa: E402
from bayes_disc.inference.model.config import config_from_mapping  # noqa: E402
from bayes_disc.inference.results.draws import posterior_draws  # noqa: E402
from bayes_disc.jobs.sample import run_sample  # noqa: E402
from bayes_disc.observation.synth import synthesize, write_synth  # noqa: E402
from bayes_disc.physics import Coefficients  # noqa: E402


#: the launch values of each flight written with the figures (the design)
DESIGN = ("name", "speed", "launch_angle_deg", "alpha_deg", "roll_deg", "spin", "p", "q", "duration", "noise_mm")


def coverage_figures(truth: np.ndarray, draws: np.ndarray) -> tuple[float, np.ndarray]:
    """Mahalanobis distance² of ``truth`` (n,) under the mean and covariance of ``draws`` (m, n), and z (n,)."""
    mean, cov = draws.mean(axis=0), np.cov(draws.T)
    d = truth - mean
    return float(d @ np.linalg.solve(cov, d)), d / np.sqrt(np.diag(cov))


def sample_draws(run: dict, ic: str, folder: Path, names: list) -> tuple[np.ndarray, bool]:
    """(m, n) posterior draws of the coefficients ``names`` of one run under ``prior.initial_conditions`` = ic,
    and whether the sampler met its convergence rule."""
    prior = run.get("prior", "potts_crowther")
    prior = {**prior, "initial_conditions": ic} if isinstance(prior, dict) else {"coefficients": prior,
                                                                                  "initial_conditions": ic}
    cfg = config_from_mapping({**run, "prior": prior, "output": f"run_{ic}"}, folder / "config.yaml")
    run_sample(cfg, progress=False)
    import arviz as az
    post = az.from_netcdf(str(folder / f"run_{ic}" / "posterior.nc")).posterior
    converged = json.loads((folder / f"run_{ic}" / "summary.json").read_text())["convergence"]["converged"]
    return np.stack([np.asarray(posterior_draws(post, n), float).reshape(-1) for n in names], axis=-1), converged


def figures(d2: list, zs: list, converged: list, names: list) -> dict:
    """Mean distance² with its Monte-Carlo band, mean and sd of z per coefficient, unconverged runs."""
    n = len(d2)
    band = 2.0 * np.sqrt(20.0 / n)
    sd_z = np.std(zs, axis=0, ddof=1) if n > 1 else np.full(len(names), np.nan)
    return {"mean_distance2": round(float(np.mean(d2)), 2), "band": [round(10 - band, 2), round(10 + band, 2)],
            "mean_z": dict(zip(names, np.mean(zs, axis=0).round(3).tolist())),
            "sd_z": dict(zip(names, np.round(sd_z, 3).tolist())), "not_converged": int(n - sum(converged))}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("campaign", type=Path)
    ap.add_argument("--replicate", type=int, default=0)
    ap.add_argument("--draws", type=int, default=20)
    ap.add_argument("--priors", nargs="+", default=["reference", "flat"], choices=["reference", "flat"])
    ap.add_argument("--out", type=Path, help="write the figures and every draw's values here (a new file)")
    a = ap.parse_args(argv)
    if a.out is not None and a.out.exists():
        raise SystemExit(f"{a.out} exists: give a new file (it is not replaced)")
    logging.getLogger("bayes_disc").setLevel(logging.WARNING)
    cal = load_cal_config(a.campaign)
    rng = replicate_rng(cal, a.replicate)
    sampler_seed = int(rng.integers(2 ** 20))
    truth = draw_truth(cal, rng)
    flights = jittered_flights(cal, rng)
    if replicate_data(cal, a.replicate)[1] != truth:
        raise SystemExit(f"replicate {a.replicate} was redrawn: its truth is not the stream's first draw")
    names = list(cal.names)
    t = np.array([truth[n] for n in names])
    d2 = {ic: [] for ic in a.priors}
    zs = {ic: [] for ic in a.priors}
    conv = {ic: [] for ic in a.priors}
    for k in range(a.draws):
        spec = replace(cal.template, name=f"fixed_{a.replicate}", flights=flights,
                       coefficients=Coefficients.from_mapping(truth), seed=5000 + k)
        result = synthesize(spec)
        with tempfile.TemporaryDirectory(prefix="bd-fixed-") as tmp:
            tmp = Path(tmp)
            write_synth(result, tmp / "markers.csv", tmp / "truth.json")
            run = replicate_run(cal, result, sampler_seed)
            for ic in a.priors:
                draws, converged = sample_draws(run, ic, tmp, names)
                dd, z = coverage_figures(t, draws)
                d2[ic].append(dd)
                zs[ic].append(z)
                conv[ic].append(bool(converged))
        out = {"campaign": cal.name, "replicate": a.replicate, "draws": k + 1,
               **{ic: figures(d2[ic], zs[ic], conv[ic], names) for ic in a.priors}}
        print(json.dumps(out), flush=True)
    if a.out is not None:
        out["truth"] = truth
        out["flights"] = [{key: v for key, v in asdict(f).items() if key in DESIGN and v is not None}
                          for f in flights]
        out["per_draw"] = {ic: {"distance2": np.round(d2[ic], 4).tolist(), "z": np.round(zs[ic], 4).tolist(),
                                "converged": conv[ic]} for ic in a.priors}
        out["reference_surrogate"] = {"huber": reference.HUBER, "refine_rounds": reference.REFINE_ROUNDS,
                                      "refine_tolerance": reference.REFINE_TOLERANCE}
        out["command"] = (f"python benchmarks/bench_fixed_truth_posterior.py {a.campaign.as_posix()} --replicate "
                          f"{a.replicate} --draws {a.draws} --priors {' '.join(a.priors)}")
        a.out.parent.mkdir(parents=True, exist_ok=True)
        a.out.write_text(json.dumps(out, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
