"""Coverage of the posterior at one fixed truth: the noise alone redrawn, a short sampling run each time, with
the initial conditions' conditional reference prior and without it.

Replicate I of a calibration campaign fixes the coefficients and every flight's launch (its design); the
synthetic marker noise is drawn K times (synth seeds 5000 … 5000 + K − 1) and each data set is sampled with the
campaign's run settings under ``prior.initial_conditions`` ``reference`` and ``flat`` (same data, same sampler
seed). Printed after every draw, per prior: the mean over the draws of the truth's Mahalanobis distance² under
the posterior mean and covariance of the ten coefficients (χ²₁₀ if the intervals are right: expected 10, band
10 ± 2·√20/√K), and mean and sd over the draws of z_k = (θ̃_k − posterior mean_k)/posterior sd_k (sd(z) = 1
when calibrated, within 1 ± 0.15 asked), the truth's posterior quantile u_k (the share of draws below it:
uniform when the intervals cover as they claim, whatever the posterior's shape) as the coverage of the central
50 % and 90 % intervals and as the sd of Φ⁻¹(u_k), and how many runs stopped unconverged. With ``--out`` the figures,
every draw's distance², z and convergence, and how the reference prior's surrogate is fitted
(``reference_surrogate``: Huber threshold, refinement rounds and tolerance) are written as JSON (a new file:
an existing one is not replaced); tools/make_validation.py reads such files from runs/calibration/fixed_truth/.

Every draw is reproducible on its own (synth seed 5000 + k, the replicate's sampler seed), so ``--extend FILE``
takes the draws of an earlier file of the same replicate and priors and computes only the draws after them: the
result is the file ``--draws K`` would write (its ``command`` says so). ``--processes N`` runs N draws at a
time. ``--sampler KEY=VALUE …`` overrides the campaign's sampler settings (e.g. ``max_steps=3000 min_steps=1000``
for runs longer than the template's short ones, with the same noise draws); the file records them.

    python benchmarks/bench_fixed_truth_posterior.py runs/calibration/four_flights_varied.yaml [--replicate 0]
                                                     [--draws 20] [--priors reference flat] [--out FILE]
                                                     [--extend FILE] [--processes 1] [--sampler KEY=VALUE …]
"""
from __future__ import annotations

import argparse
import json
import logging
import sys
import tempfile
from concurrent.futures import ProcessPoolExecutor
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


#: every draw's values kept per prior
PER_DRAW = ("distance2", "z", "quantile", "converged")
#: the launch values of each flight written with the figures (the design)
DESIGN = ("name", "speed", "launch_angle_deg", "alpha_deg", "roll_deg", "spin", "p", "q", "duration", "noise_mm")


def coverage_figures(truth: np.ndarray, draws: np.ndarray) -> tuple[float, np.ndarray]:
    """Mahalanobis distance² of ``truth`` (n,) under the mean and covariance of ``draws`` (m, n), and z (n,)."""
    mean, cov = draws.mean(axis=0), np.cov(draws.T)
    d = truth - mean
    return float(d @ np.linalg.solve(cov, d)), d / np.sqrt(np.diag(cov))


def truth_quantiles(truth: np.ndarray, draws: np.ndarray) -> np.ndarray:
    """(n,) the truth's posterior quantile per coefficient: the share of ``draws`` (m, n) below it."""
    return np.mean(draws < truth, axis=0)


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


def figures(rec: dict, names: list, n_draws: int) -> dict:
    """Mean distance² with its Monte-Carlo band, mean and sd of z per coefficient, the coverage of the central
    50 % and 90 % intervals and the sd of Φ⁻¹(u) per coefficient, unconverged runs; ``rec`` holds every draw's
    ``distance2``, ``z``, ``quantile`` (u) and ``converged``, ``n_draws`` the posterior draws per run (u is
    clipped to [1/(2·n_draws), 1 − 1/(2·n_draws)] before Φ⁻¹)."""
    from scipy.stats import norm
    n = len(rec["distance2"])
    band = 2.0 * np.sqrt(20.0 / n)
    zs, u = np.asarray(rec["z"]), np.asarray(rec["quantile"])
    sd_z = np.std(zs, axis=0, ddof=1) if n > 1 else np.full(len(names), np.nan)
    eps = 0.5 / n_draws
    zq = norm.ppf(np.clip(u, eps, 1.0 - eps))
    sd_zq = np.std(zq, axis=0, ddof=1) if n > 1 else np.full(len(names), np.nan)
    return {"mean_distance2": round(float(np.mean(rec["distance2"])), 2),
            "band": [round(10 - band, 2), round(10 + band, 2)],
            "mean_z": dict(zip(names, np.mean(zs, axis=0).round(3).tolist())),
            "sd_z": dict(zip(names, np.round(sd_z, 3).tolist())),
            "coverage_50": dict(zip(names, np.mean(np.abs(u - 0.5) < 0.25, axis=0).round(3).tolist())),
            "coverage_90": dict(zip(names, np.mean(np.abs(u - 0.5) < 0.45, axis=0).round(3).tolist())),
            "sd_quantile_z": dict(zip(names, np.round(sd_zq, 3).tolist())),
            "not_converged": int(n - sum(rec["converged"]))}


def one_draw(campaign: Path, replicate: int, k: int, priors: list, sampler: dict) -> dict:
    """Noise draw ``k`` of the replicate's fixed design, sampled under each prior of the initial conditions with
    the campaign's sampler settings overridden by ``sampler``: {prior: (distance², z (n,), u (n,), converged,
    posterior draws)}."""
    logging.getLogger("bayes_disc").setLevel(logging.WARNING)
    cal = load_cal_config(campaign)
    truth, flights, sampler_seed = fixed_design(cal, replicate)
    names = list(cal.names)
    t = np.array([truth[n] for n in names])
    spec = replace(cal.template, name=f"fixed_{replicate}", flights=flights,
                   coefficients=Coefficients.from_mapping(truth), seed=5000 + k)
    result = synthesize(spec)
    out = {}
    with tempfile.TemporaryDirectory(prefix="bd-fixed-") as tmp:
        tmp = Path(tmp)
        write_synth(result, tmp / "markers.csv", tmp / "truth.json")
        run = replicate_run(cal, result, sampler_seed)
        run = {**run, "sampler": {**run["sampler"], **sampler}}
        for ic in priors:
            draws, converged = sample_draws(run, ic, tmp, names)
            dd, z = coverage_figures(t, draws)
            out[ic] = (dd, z, truth_quantiles(t, draws), bool(converged), int(draws.shape[0]))
    return out


def fixed_design(cal, replicate: int) -> tuple[dict, list, int]:
    """The replicate's truth, jittered launches and sampler seed (the campaign's own stream)."""
    rng = replicate_rng(cal, replicate)
    sampler_seed = int(rng.integers(2 ** 20))
    truth = draw_truth(cal, rng)
    flights = jittered_flights(cal, rng)
    if replicate_data(cal, replicate)[1] != truth:
        raise SystemExit(f"replicate {replicate} was redrawn: its truth is not the stream's first draw")
    return truth, flights, sampler_seed


def sampler_overrides(items: list) -> dict:
    """{key: number} of ``--sampler KEY=VALUE`` items (integers where the value is one)."""
    out = {}
    for item in items:
        key, sep, value = item.partition("=")
        try:
            number = float(value)
        except ValueError:
            number = None
        if not sep or not key or number is None:
            raise SystemExit(f"--sampler {item!r}: give KEY=NUMBER, e.g. max_steps=3000")
        out[key] = int(number) if number.is_integer() else number
    return out


def earlier_draws(path: Path, campaign: str, replicate: int, priors: list, names: list, sampler: dict) -> dict:
    """{prior: ({distance2, z, quantile, converged: lists}, posterior draws per run)} of an earlier file of the
    same replicate and priors."""
    old = json.loads(path.read_text())
    if old["campaign"] != campaign or old["replicate"] != replicate or sorted(old["per_draw"]) != sorted(priors):
        raise SystemExit(f"{path} holds replicate {old['replicate']} of {old['campaign']} under "
                         f"{sorted(old['per_draw'])}: not this replicate and priors")
    if list(old["truth"]) != names:
        raise SystemExit(f"{path} holds other coefficients than the campaign's")
    if old.get("sampler", {}) != sampler:
        raise SystemExit(f"{path} was sampled with sampler settings {old.get('sampler', {})}, not {sampler}")
    if any("quantile" not in d for d in old["per_draw"].values()):
        raise SystemExit(f"{path} holds no truth quantiles (an older file): compute every draw afresh")
    return {ic: ({key: list(d[key]) for key in PER_DRAW}, old["posterior_draws"][ic])
            for ic, d in old["per_draw"].items()}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("campaign", type=Path)
    ap.add_argument("--replicate", type=int, default=0)
    ap.add_argument("--draws", type=int, default=20)
    ap.add_argument("--priors", nargs="+", default=["reference", "flat"], choices=["reference", "flat"])
    ap.add_argument("--out", type=Path, help="write the figures and every draw's values here (a new file)")
    ap.add_argument("--extend", type=Path, help="an earlier --out file of this replicate and these priors: its "
                                                "draws are taken, only the later ones computed")
    ap.add_argument("--processes", type=int, default=1, help="draws computed at a time")
    ap.add_argument("--sampler", nargs="*", default=[], metavar="KEY=VALUE",
                    help="override the campaign's sampler settings, e.g. max_steps=3000 min_steps=1000")
    a = ap.parse_args(argv)
    sampler = sampler_overrides(a.sampler)
    if a.out is not None and a.out.exists():
        raise SystemExit(f"{a.out} exists: give a new file (it is not replaced)")
    logging.getLogger("bayes_disc").setLevel(logging.WARNING)
    cal = load_cal_config(a.campaign)
    truth, flights, _ = fixed_design(cal, a.replicate)
    names = list(cal.names)
    rec = {ic: {key: [] for key in PER_DRAW} for ic in a.priors}
    n_draws = dict.fromkeys(a.priors, 0)
    if a.extend is not None:
        for ic, (old, m) in earlier_draws(a.extend, cal.name, a.replicate, a.priors, names, sampler).items():
            rec[ic], n_draws[ic] = {key: v[:a.draws] for key, v in old.items()}, m
    first = len(rec[a.priors[0]]["distance2"])
    with ProcessPoolExecutor(max_workers=a.processes) as pool:
        ks = range(first, a.draws)
        results = pool.map(one_draw, [a.campaign] * len(ks), [a.replicate] * len(ks), ks, [a.priors] * len(ks),
                           [sampler] * len(ks))
        for k, result in zip(ks, results):
            for ic, (dd, z, u, c, m) in result.items():
                for key, v in zip(PER_DRAW, (dd, z, u, c)):
                    rec[ic][key].append(v)
                n_draws[ic] = m
            print(json.dumps({"draws": k + 1, **{ic: figures(rec[ic], names, n_draws[ic]) for ic in a.priors}}),
                  flush=True)
    if not all(n_draws.values()):
        raise SystemExit("no draw computed: the posterior draws per run (for the quantiles' clipping) are unknown")
    out = {"campaign": cal.name, "replicate": a.replicate, "draws": len(rec[a.priors[0]]["distance2"]),
           **{ic: figures(rec[ic], names, n_draws[ic]) for ic in a.priors}}
    if a.out is not None:
        out["truth"] = truth
        out["flights"] = [{key: v for key, v in asdict(f).items() if key in DESIGN and v is not None}
                          for f in flights]
        out["per_draw"] = {ic: {"distance2": np.round(rec[ic]["distance2"], 4).tolist(),
                                "z": np.round(rec[ic]["z"], 4).tolist(),
                                "quantile": np.round(rec[ic]["quantile"], 5).tolist(),
                                "converged": rec[ic]["converged"]} for ic in a.priors}
        out["posterior_draws"] = n_draws
        out["reference_surrogate"] = {"huber": reference.HUBER, "refine_rounds": reference.REFINE_ROUNDS,
                                      "refine_tolerance": reference.REFINE_TOLERANCE}
        out["command"] = (f"python benchmarks/bench_fixed_truth_posterior.py {a.campaign.as_posix()} --replicate "
                          f"{a.replicate} --draws {out['draws']} --priors {' '.join(a.priors)}")
        if sampler:
            out["sampler"] = sampler
            out["command"] += " --sampler " + " ".join(f"{k}={v}" for k, v in sampler.items())
        a.out.parent.mkdir(parents=True, exist_ok=True)
        a.out.write_text(json.dumps(out, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
