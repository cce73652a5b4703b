"""The sampling job of ``bayes-disc sample``: least squares, then emcee.

Writes summary.json, posterior.nc, run_info.json and the least-squares result into the run's output folder.
The HTML report is not this module's business: :mod:`bayes_disc.pipeline` runs this job, then the report.
Progress goes to the module's logger (INFO); the results table and the convergence line are INFO records
marked ``result=True`` (the command line prints those on stdout).
"""
from __future__ import annotations

import json
import logging
import time
from dataclasses import asdict
from pathlib import Path
from types import MappingProxyType

import numpy as np

from .config import RunConfig
from .data import build_problem
from .leastsq import fit_least_squares
from .results import build_inference_data, build_summary, format_table
from .profile import profile_paths
from .proposals import PROFILE_DEPARTURE, independence_proposal, path_departure
from .sampler import run_sampler
from .versions import software_versions

logger = logging.getLogger(__name__)
#: ``extra`` of log records that are results (tables), not progress
RESULT = MappingProxyType({"result": True})


def _flight_info(problem) -> dict:
    return {f.name: {"file": f.source, "samples": int(f.times.size), "points": int(f.n_points),
                     "t_start": float(f.times[0]), "t_end": float(f.times[-1])} for f in problem.flights}


def posterior_approximation(problem, ls, processes: int, out: Path):
    """Profile paths of the coefficients through the least-squares optimum and the ridge-aware
    independence proposal built from them (:func:`.proposals.independence_proposal`).

    Parameters
    ----------
    problem : Problem
        The run's statistical problem.
    ls : LeastSquaresResult
        The least-squares optimum (theta, sigma [m] per flight, covariance).
    processes : int
        Parallel profile fits.
    out : Path
        Run folder; the paths are written to ``<out>/profiles.json``.

    Returns
    -------
    CompositeProposal
        The independence proposal for the sampler.
    """
    t0 = time.perf_counter()
    idx = range(problem.n_coef + problem.n_ext)
    paths = profile_paths(problem, ls.theta, ls.sigma, ls.cov, idx, processes=processes)
    proposal = independence_proposal(problem, ls.theta, ls.cov, paths)
    record = {}
    for path in paths:
        dep = path_departure(path, ls.theta, ls.cov)
        record[path.name] = {"value": [p.value for p in path.points], "t": path.t.tolist(),
                             "deviance": path.deviance.tolist(), "departure_from_laplace": dep,
                             "shape": path.classify()}
    (out / "profiles.json").write_text(json.dumps(record, indent=1))
    ridge = [n for n, r in record.items() if r["departure_from_laplace"] > PROFILE_DEPARTURE]
    logger.info(f"profile likelihood of {len(paths)} coefficients ({time.perf_counter() - t0:.0f} s): "
        + (f"non-Gaussian along {', '.join(ridge)}; " if ridge else "all close to Gaussian; ")
        + f"{len(proposal.parts) - 1} ridge proposal(s)")
    return proposal


def run_sample(cfg: RunConfig, resume: bool = False, progress: bool = True) -> dict:
    """Least squares, emcee, and the run files ``summary.json``, ``posterior.nc``, ``run_info.json``.

    Parameters
    ----------
    cfg : RunConfig
        The validated run configuration; files go to ``cfg.output``.
    resume : bool
        Continue an interrupted run from its chain files.
    progress : bool
        Show a progress bar while sampling.

    Returns
    -------
    dict
        The content of ``summary.json`` (SPEC §6): ``parameters`` ({name: {mean, sd, q05, q50, q95, r_hat,
        ess_bulk}}, coefficients dimensionless, ``sigma_<flight>`` in m, initial conditions in SI units),
        ``convergence`` and the run's description.
    """
    t0 = time.perf_counter()
    out = Path(cfg.output)
    out.mkdir(parents=True, exist_ok=True)
    problem = build_problem(cfg)
    logger.info(f"{cfg.name}: {problem.n_flights} flights, {int(problem.n_coords.sum() // 3)} marker points, "
        f"{problem.dim} parameters")
    ls_path = out / "least_squares.json"
    ls = fit_least_squares(problem, starts=cfg.least_squares.starts, max_nfev=cfg.least_squares.max_nfev,
                           seed=cfg.sampler.seed)
    ls_dict = ls.to_dict()
    ls_path.write_text(json.dumps(ls_dict, indent=1))
    np.save(out / "least_squares_cov.npy", ls.cov)
    np.save(out / "least_squares_theta.npy", ls.theta)
    logger.info(f"least squares: cost {ls.cost:.1f}, condition number {ls.condition_number:.3g}, RMS "
        + ", ".join(f"{k} {v:.2f} mm" for k, v in ls_dict["rms_mm"].items()))
    if resume and (out / "chains" / "independence.npz").is_file():
        proposal = None  # the sampler continues with the approximation saved beside its chains
    else:
        proposal = posterior_approximation(problem, ls, cfg.sampler.processes, out)
    chains = run_sampler(problem, proposal, cfg.sampler, out, resume=resume, progress=progress)
    info = {"name": cfg.name, "config": str(cfg.path), "flights": _flight_info(problem),
            "sampler_settings": asdict(cfg.sampler), "markers": cfg.markers}
    idata = build_inference_data(problem, chains, np.random.default_rng(cfg.sampler.seed))
    summary = build_summary(problem, chains, idata, ls_dict, info)
    (out / "summary.json").write_text(json.dumps(summary, indent=1))
    idata.to_netcdf(str(out / "posterior.nc"))
    run_info = {"wall_time_s": time.perf_counter() - t0, "sampling_wall_time_s": chains.wall_time_s,
                "history": chains.history, "versions": software_versions()}
    (out / "run_info.json").write_text(json.dumps(run_info, indent=1))
    logger.info(format_table(summary), extra=RESULT)
    c = summary["convergence"]
    logger.info(f"{c['reason']}: {c['total_steps']} steps × {c['walkers_per_ensemble']} walkers × {c['ensembles']} "
        f"ensembles, burn-in {c['burn_in_steps']}, τ max {c['tau_max_steps']:.1f}, N/τ {c['n_over_tau']:.0f}, "
        f"R-hat max {c['r_hat_max']:.4f}, min coefficient ESS {c['ess_bulk_min_coefficient']:.0f}; "
        f"{run_info['wall_time_s']:.0f} s", extra=RESULT)
    logger.info(f"wrote {out / 'summary.json'}, {out / 'posterior.nc'}")
    return summary
