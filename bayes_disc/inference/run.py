"""``bayes-disc sample``: least squares, then emcee; writes summary.json, posterior.nc and the LS result."""
from __future__ import annotations

import json
import time
from dataclasses import asdict
from pathlib import Path

import numpy as np

from .config import RunConfig
from .data import build_problem
from .leastsq import fit_least_squares
from .results import build_inference_data, build_summary, format_table
from .sampler import run_sampler


def _flight_info(problem) -> dict:
    return {f.name: {"file": f.source, "samples": int(f.times.size), "points": int(f.n_points),
                     "t_start": float(f.times[0]), "t_end": float(f.times[-1])} for f in problem.flights}


def run_sample(cfg: RunConfig, resume: bool = False, progress: bool = True, log=print, report: bool = True,
               reports_dir="reports") -> dict:
    """Least squares, emcee, summary.json, posterior.nc and (``report``) ``reports/<name>.html``."""
    t0 = time.perf_counter()
    out = Path(cfg.output)
    out.mkdir(parents=True, exist_ok=True)
    problem = build_problem(cfg)
    log(f"{cfg.name}: {problem.n_flights} flights, {int(problem.n_coords.sum() // 3)} marker points, "
        f"{problem.dim} parameters")
    ls_path = out / "least_squares.json"
    ls = fit_least_squares(problem, starts=cfg.least_squares.starts, max_nfev=cfg.least_squares.max_nfev,
                           seed=cfg.sampler.seed)
    ls_dict = ls.to_dict()
    ls_path.write_text(json.dumps(ls_dict, indent=1))
    np.save(out / "least_squares_cov.npy", ls.cov)
    np.save(out / "least_squares_theta.npy", ls.theta)
    log(f"least squares: cost {ls.cost:.1f}, condition number {ls.condition_number:.3g}, RMS "
        + ", ".join(f"{k} {v:.2f} mm" for k, v in ls_dict["rms_mm"].items()))
    chains = run_sampler(problem, ls.theta, ls.cov, cfg.sampler, out, resume=resume, progress=progress)
    info = {"name": cfg.name, "config": str(cfg.path), "flights": _flight_info(problem),
            "sampler_settings": asdict(cfg.sampler), "markers": cfg.markers}
    summary = build_summary(problem, chains, ls_dict, info)
    (out / "summary.json").write_text(json.dumps(summary, indent=1))
    idata = build_inference_data(problem, chains, np.random.default_rng(cfg.sampler.seed))
    idata.to_netcdf(str(out / "posterior.nc"))
    from ..report.content import software_versions
    run_info = {"wall_time_s": time.perf_counter() - t0, "sampling_wall_time_s": chains.wall_time_s,
                "history": chains.history, "versions": software_versions()}
    (out / "run_info.json").write_text(json.dumps(run_info, indent=1))
    log(format_table(summary))
    c = summary["convergence"]
    log(f"{c['reason']}: {c['total_steps']} steps × {c['walkers_per_ensemble']} walkers × {c['ensembles']} "
        f"ensembles, burn-in {c['burn_in_steps']}, τ max {c['tau_max_steps']:.1f}, N/τ {c['n_over_tau']:.0f}, "
        f"R-hat max {c['r_hat_max']:.4f}, min coefficient ESS {c['ess_bulk_min_coefficient']:.0f}; "
        f"{run_info['wall_time_s']:.0f} s")
    log(f"wrote {out / 'summary.json'}, {out / 'posterior.nc'}")
    if report:
        from ..report import build_report
        path = build_report(out, reports_dir=Path(reports_dir), seed=cfg.sampler.seed, log=log)
        log(f"wrote {path}")
    return summary
