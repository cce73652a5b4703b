"""Coverage of the posterior at one fixed truth: the noise alone redrawn, a short sampling run each time, with
the initial conditions' conditional reference prior and without it.

Replicate I of a calibration campaign fixes the coefficients and every flight's launch (its design); the
synthetic marker noise is drawn K times (synth seeds 5000 … 5000 + K − 1) and each data set is sampled with the
campaign's run settings under ``prior.initial_conditions`` ``reference`` and ``flat`` (same data, same sampler
seed). Printed after every draw, per prior: the mean over the draws of the truth's Mahalanobis distance² under
the posterior mean and covariance of the ten coefficients (χ²₁₀ if the intervals are right: expected 10, band
10 ± 2·√20/√K), and mean and sd over the draws of z_k = (θ̃_k − posterior mean_k)/posterior sd_k (sd(z) = 1
when calibrated).

    python benchmarks/bench_fixed_truth_posterior.py runs/calibration/four_flights_varied.yaml [--replicate 0]
                                                     [--draws 20] [--priors reference flat]
"""
from __future__ import annotations

import argparse
import json
import logging
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
from bayes_disc.inference.results.draws import posterior_draws  # noqa: E402
from bayes_disc.jobs.sample import run_sample  # noqa: E402
from bayes_disc.observation.synth import synthesize, write_synth  # noqa: E402
from bayes_disc.physics import Coefficients  # noqa: E402


def coverage_figures(truth: np.ndarray, draws: np.ndarray) -> tuple[float, np.ndarray]:
    """Mahalanobis distance² of ``truth`` (n,) under the mean and covariance of ``draws`` (m, n), and z (n,)."""
    mean, cov = draws.mean(axis=0), np.cov(draws.T)
    d = truth - mean
    return float(d @ np.linalg.solve(cov, d)), d / np.sqrt(np.diag(cov))


def sample_draws(run: dict, ic: str, folder: Path, names: list) -> np.ndarray:
    """(m, n) posterior draws of the coefficients ``names`` of one run under ``prior.initial_conditions`` = ic."""
    prior = run.get("prior", "potts_crowther")
    prior = {**prior, "initial_conditions": ic} if isinstance(prior, dict) else {"coefficients": prior,
                                                                                  "initial_conditions": ic}
    cfg = config_from_mapping({**run, "prior": prior, "output": f"run_{ic}"}, folder / "config.yaml")
    run_sample(cfg, progress=False)
    import arviz as az
    post = az.from_netcdf(str(folder / f"run_{ic}" / "posterior.nc")).posterior
    return np.stack([np.asarray(posterior_draws(post, n), float).reshape(-1) for n in names], axis=-1)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("campaign", type=Path)
    ap.add_argument("--replicate", type=int, default=0)
    ap.add_argument("--draws", type=int, default=20)
    ap.add_argument("--priors", nargs="+", default=["reference", "flat"], choices=["reference", "flat"])
    a = ap.parse_args(argv)
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
    for k in range(a.draws):
        spec = replace(cal.template, name=f"fixed_{a.replicate}", flights=flights,
                       coefficients=Coefficients.from_mapping(truth), seed=5000 + k)
        result = synthesize(spec)
        with tempfile.TemporaryDirectory(prefix="bd-fixed-") as tmp:
            tmp = Path(tmp)
            write_synth(result, tmp / "markers.csv", tmp / "truth.json")
            run = replicate_run(cal, result, sampler_seed)
            for ic in a.priors:
                dd, z = coverage_figures(t, sample_draws(run, ic, tmp, names))
                d2[ic].append(dd)
                zs[ic].append(z)
        n = k + 1
        band = 2.0 * np.sqrt(20.0 / n)
        print(json.dumps({"replicate": a.replicate, "draws": n, **{ic: {
            "mean_distance2": round(float(np.mean(d2[ic])), 2), "band": [round(10 - band, 2), round(10 + band, 2)],
            "mean_z": dict(zip(names, np.mean(zs[ic], axis=0).round(2).tolist())),
            "sd_z": dict(zip(names, (np.std(zs[ic], axis=0, ddof=1) if n > 1 else np.full(10, np.nan)).round(2)
                             .tolist()))} for ic in a.priors}}), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
