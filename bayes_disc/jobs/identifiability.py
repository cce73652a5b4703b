"""``bayes-disc identifiability CONFIG.yaml``: least squares, Fisher information, verdicts, next throw.

Writes ``<output>/identifiability.json``:

    {"CL0": {"verdict", "reason"}, ..., (docs/outputs.md: one entry per coefficient)
     "coefficients": {name: {verdict, reason, sd, prior_sd, contraction, relative_sd, ...}},
     "envelope": {"flights": {flight: {alpha_deg, speed_m_s, spin_rad_s}}, "set": {...},
                  "alpha_histogram": {"edges_deg", "counts"}},
     "fisher": {"condition_number", "eigenvalues", "weak_directions": [{text, pair, correlation, ...}]},
     "profiles": {name: {value, deviance, shape}} (with --profiles),
     "posterior": {contraction, correlation, verdicts, agreement} (when `sample` has run),
     "data": {markers, inertial, inertial_only, text},
     "least_squares": {cost, rms_mm (marker flights), noise: {sigma name: {value, unit}}, lower_optima},
     "noise_choice": {flight: record} (the marker noise models `sample` uses, fitted here too),
     "design": {"weak", "recommendation", "best", "ranking": [...]} or {"skipped": reason}}

Runs with inertial logs: the entries besides the ten coefficients include the logger's shared mount
(``imu_offset_*``, ``imu_lpf_tau``, ``imu_tilt_*``) with verdicts of their own; the reasons say when there
are no positions (airspeed and α seen only through the dynamics); the next-throw design, which simulates
marker flights, is skipped with its reason when the run has no marker data.
"""
from __future__ import annotations

import json
import logging
import time
import warnings
from pathlib import Path

import numpy as np

from ..diagnostics.identifiability import (ALPHA_PAIRS, coefficient_information, data_description,
                                           describe_throw, design_skip_reason, flight_envelopes, marker_noise,
                                           rank_throws, verdicts_from_covariance, weak_directions)
from ..inference.model.config import RunConfig
from ..inference.model.data import build_problem
from ..inference.fitting.leastsq import fit_least_squares, noise_text
from ..inference.fitting.noise_choice import choose_noise, run_settings
from ..inference.fitting.residuals import jacobian_blocks
from ..inference.fitting.profile import profiles_through_lowest
from .outputs import Outcome
from .progress import RESULT

ALPHA_COEFFICIENTS = tuple(n for pair in ALPHA_PAIRS for n in pair)
logger = logging.getLogger(__name__)


def _posterior_block(out: Path, names) -> tuple[np.ndarray, np.ndarray] | None:
    """Mean and covariance of the coefficients in ``<out>/posterior.nc`` (None if `sample` has not run)."""
    path = out / "posterior.nc"
    if not path.is_file():
        return None
    import arviz as az
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        idata = az.from_netcdf(str(path))
    try:
        x = np.column_stack([idata.posterior[n].values.ravel() for n in names])
    except KeyError:
        return None
    return x.mean(axis=0), np.cov(x.T)


def _profiles(problem, ls, cfg: RunConfig, out: Path):
    """Profile paths of the coefficients through the optimum; a path that reaches below the optimum has the
    least squares refitted (``least_squares.json`` rewritten). Returns (paths by name, their record, ls)."""
    def refitted(found, new):
        logger.warning(f"{found}, which was not the lowest point: the least squares are refitted from there "
                       f"(cost {new.cost:.1f}), then the profiles start again")
        (out / "least_squares.json").write_text(json.dumps(new.to_dict(), indent=1))
    found, ls = profiles_through_lowest(problem, ls, range(problem.ic_start), processes=cfg.sampler.processes,
                                        max_nfev=cfg.least_squares.max_nfev, on_refit=refitted)
    paths = {p.name: p for p in found}
    record = {p.name: {"value": [q.value for q in p.points], "deviance": p.deviance.tolist(),
                       "shape": p.classify(), "halfwidth": p.halfwidth()} for p in found}
    return paths, record, ls


def envelope_record(problem, theta: np.ndarray) -> dict:
    """The flight envelope at ``theta``: α [°], speed [m/s] and spin [rad/s] ranges per flight and for the
    set, and a histogram of α in 2° bins."""
    env = flight_envelopes(problem, theta)
    all_alpha = np.concatenate([e.alpha_deg for e in env])
    span = (float(all_alpha.min()), float(all_alpha.max()))
    counts, edges = np.histogram(all_alpha, bins=np.arange(np.floor(span[0] / 2) * 2 - 2, span[1] + 4, 2.0))
    envelope = {"flights": {e.name: e.ranges() for e in env},
                "set": {"alpha_deg": list(span),
                        "speed_m_s": [min(e.speed.min() for e in env), max(e.speed.max() for e in env)],
                        "spin_rad_s": [min(e.spin.min() for e in env), max(e.spin.max() for e in env)]},
                "alpha_histogram": {"edges_deg": edges.tolist(), "counts": counts.tolist()}}
    envelope["set"] = {k: [float(a), float(b)] for k, (a, b) in envelope["set"].items()}
    return envelope


def _fisher_record(problem, ls, names) -> tuple[dict, np.ndarray]:
    """Fisher information of the coefficients with the initial conditions as nuisance: the record (condition
    number, eigenvalues per prior variance, weak directions) and the information matrix."""
    nc = problem.ic_start
    J = jacobian_blocks(ls.theta, problem, ls.sigma)
    info = coefficient_information(problem, J)
    prior_sd = problem.prior_sd[:nc]
    Fs = info * np.outer(prior_sd, prior_sd)
    ev = np.linalg.eigvalsh(0.5 * (Fs + Fs.T))
    fisher = {"condition_number": float(ev[-1] / max(ev[0], 1e-300)), "eigenvalues": ev.tolist(),
              "scale": "information per prior variance (eigenvalue 1: data as informative as the prior)",
              "weak_directions": weak_directions(info, prior_sd, ls.cov[:nc, :nc], names)}
    return fisher, info


def _posterior_record(post, names, prior_sd, span, data_text, floors, coefs) -> dict:
    """The sampled posterior's contraction, correlation and verdicts, and whether they agree with the
    least-squares verdicts."""
    mean, pcov = post
    pv = verdicts_from_covariance(names, mean, pcov, prior_sd, span, data=data_text, size_floors=floors)
    sd = np.sqrt(np.diag(pcov))
    return {"contraction": {n: float(1 - sd[i] ** 2 / prior_sd[i] ** 2) for i, n in enumerate(names)},
            "correlation": {"names": names, "matrix": (pcov / np.outer(sd, sd)).round(4).tolist()},
            "verdicts": {n: {"verdict": v["verdict"], "reason": v["reason"]} for n, v in pv.items()},
            "agreement": {n: pv[n]["verdict"] == coefs[n]["verdict"] for n in names}}


def _design_record(problem, ls, names, coefs) -> dict | None:
    """The ranked next throws for the weak coefficients (the α coefficients when none is weak); None when
    no candidate throw was ranked."""
    weak = [i for i, n in enumerate(names) if coefs[n]["verdict"] != "identified"]
    block = weak or [i for i, n in enumerate(names) if n in ALPHA_COEFFICIENTS]
    sigma_m = marker_noise(problem, ls.sigma)
    ranking = rank_throws(problem, ls.theta, ls.cov[:problem.ic_start, :problem.ic_start], block, sigma_m)
    wn = [names[i] for i in block]
    if not ranking:
        return None
    best = ranking[0]
    return {"weak": wn, "block": "weak coefficients" if weak else "α coefficients (none is weak)",
            "noise_m": sigma_m, "recommendation": describe_throw(best, wn),
            "best": {**{k: getattr(best["launch"], k) for k in ("speed", "launch_angle_deg", "alpha_deg",
                                                                 "spin", "duration")},
                     "gain": best["gain"], "sd_before": dict(zip(wn, best["sd_before"].tolist())),
                     "sd_after": dict(zip(wn, best["sd_after"].tolist()))},
            "ranking": [{**{k: getattr(r["launch"], k) for k in ("speed", "launch_angle_deg", "alpha_deg", "spin")},
                         "gain": r["gain"]} for r in ranking[:10]]}


def run_identifiability(cfg: RunConfig, profiles: bool = False, design: bool = True) -> dict:
    """The ``identifiability`` command: least squares, Fisher information, verdicts and the next throw.

    Parameters
    ----------
    cfg : RunConfig
        The validated run configuration; ``identifiability.json`` goes to ``cfg.output``.
    profiles : bool
        Also profile the likelihood of every coefficient (slower).
    design : bool
        Rank candidate throws by how much they would shrink the weak coefficients' uncertainty.

    Returns
    -------
    dict
        The content of ``identifiability.json`` (module docstring): per coefficient ``verdict`` and
        ``reason``, plus ``coefficients``, ``envelope`` (α in degrees, speed in m/s, spin in rad/s),
        ``fisher``, ``least_squares`` (RMS in mm) and optionally ``profiles``, ``posterior``, ``design``.
    """
    t0 = time.perf_counter()
    out = Path(cfg.output)
    out.mkdir(parents=True, exist_ok=True)
    problem = build_problem(cfg)
    nc = problem.ic_start
    names = problem.names[:nc]
    ls = fit_least_squares(problem, starts=cfg.least_squares.starts, max_nfev=cfg.least_squares.max_nfev,
                           seed=cfg.sampler.seed)
    choice = choose_noise(problem, ls, run_settings(cfg, problem), max_nfev=cfg.least_squares.max_nfev)
    problem, ls = choice.problem, choice.ls          # the marker noise `sample` would use: the information under it
    for line in choice.lines():
        logger.info(f"noise choice: {line}")
    (out / "least_squares.json").write_text(json.dumps(ls.to_dict(), indent=1))   # the optimum (predict --from)
    logger.info(f"{cfg.name}: least squares cost {ls.cost:.1f}, residual RMS {noise_text(ls.noise())}")
    # profiles first: a path that reaches below the optimum has the least squares refitted (and everything
    # below is then computed at the lower optimum)
    paths, prof = None, None
    if profiles:
        paths, prof, ls = _profiles(problem, ls, cfg, out)
    noise, marker_rms = ls.noise(), ls.marker_rms_mm()
    data = data_description(problem)
    envelope = envelope_record(problem, ls.theta)
    span = tuple(envelope["set"]["alpha_deg"])
    fisher, _ = _fisher_record(problem, ls, names)
    prior_sd = problem.prior_sd[:nc]
    floors = {q.name: q.prior_sd for q in problem.layout.observation_parameters}   # a logger's mount: may be 0
    coefs = verdicts_from_covariance(names, ls.theta[:nc], ls.cov[:nc, :nc], prior_sd, span, paths, data["text"],
                                     floors)
    result = {n: {"verdict": v["verdict"], "reason": v["reason"]} for n, v in coefs.items()}
    result.update({"coefficients": coefs, "envelope": envelope, "fisher": fisher, "data": data,
                   "noise_choice": choice.records,
                   "least_squares": {"cost": ls.cost, "rms_mm": marker_rms, "noise": noise,
                                     "lower_optima": ls.lower_optima}})
    if prof is not None:
        result["profiles"] = prof
    post = _posterior_block(out, names)
    if post is not None:
        result["posterior"] = _posterior_record(post, names, prior_sd, span, data["text"], floors, coefs)
    skip = design_skip_reason(problem) if design else None
    if skip is not None:
        result["design"] = {"skipped": skip}
        logger.info(f"next-throw design {skip}")
    elif design:
        record = _design_record(problem, ls, names, coefs)
        if record is not None:
            result["design"] = record
    result["wall_time_s"] = time.perf_counter() - t0
    (out / "identifiability.json").write_text(json.dumps(result, indent=1))
    logger.info(format_verdicts(result), extra=RESULT)
    logger.info(f"wrote {out / 'identifiability.json'} ({result['wall_time_s']:.0f} s)")
    return result


def identifiability(cfg: RunConfig, *, profiles: bool = False, design: bool = True) -> Outcome:
    """``bayes-disc identifiability``: which coefficients the flights determine (no report of its own: the
    report of a sampled run in the same folder includes it).

    Parameters
    ----------
    cfg : RunConfig
        The validated run configuration.
    profiles : bool
        Also profile the likelihood of every coefficient.
    design : bool
        Rank candidate throws.

    Returns
    -------
    Outcome
        ``result``: the identifiability.json content; ``report``: None.
    """
    logger.debug(f"identifiability: configuration {cfg.path}, output {cfg.output}")
    return Outcome(run_identifiability(cfg, profiles=profiles, design=design), None)


def format_verdicts(result: dict) -> str:
    """The verdicts as text: α range, condition number, one line per coefficient, weak directions, next throw.

    Parameters
    ----------
    result : dict
        The content of ``identifiability.json``.

    Returns
    -------
    str
        Several lines, no trailing newline.
    """
    lines = [f"α over all flights {result['envelope']['set']['alpha_deg'][0]:.1f}–"
             f"{result['envelope']['set']['alpha_deg'][1]:.1f}°; Fisher condition number "
             f"{result['fisher']['condition_number']:.3g}"]
    for n, v in result["coefficients"].items():
        lines.append(f"  {n:<5} {v['verdict']:<12} {v['reason']}")
    for w in result["fisher"]["weak_directions"][:2]:
        lines.append(f"  weak direction: {w['text']}")
    if "design" in result:
        d = result["design"]
        lines.append(f"next throw: {d['recommendation']}" if "recommendation" in d else f"next throw: {d['skipped']}")
    return "\n".join(lines)
