"""The sampling job of ``bayes-disc sample``: least squares, then emcee.

Writes summary.json, posterior.nc, run_info.json, the least-squares result and ``noise_choice.json`` (each
marker flight's noise model and why: :mod:`bayes_disc.inference.fitting.noise_choice`) into the run's output
folder (and ``flagged.json``, the points judged outliers and frames judged label-swapped, and
``judgement_average.json``, the posterior averaged over that judgement, for ``robust`` marker noise:
:mod:`bayes_disc.inference.fitting.robust`).
:func:`sample` runs this job, then the run's HTML report (:func:`.outputs.build_run_report`).
Progress goes to the module's logger (INFO): a line when each stage starts and one when it ends, with
its duration (:func:`stage`); a line per least-squares start; a bar over the profile likelihoods and one
of the progress toward convergence while sampling (on a terminal; log lines otherwise). The results
table and the convergence line are INFO records marked ``result=True`` (the command line prints those
on stdout).

``resume=True`` continues from the chain files (:func:`bayes_disc.inference.sampling.sampler.run_sampler`) with
the saved least-squares result and proposals; it refuses a configuration that no longer describes the saved run
(:func:`check_same_run`).
"""
from __future__ import annotations

import json
import logging
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from ..inference.model.config import RunConfig
from ..inference.model.data import build_problem
from ..inference.model.describe import data_words, flight_info, noise_info, noise_words
from ..inference.model.inertial import load_run_throws
from ..inference.fitting.joint_region import literature_tests, literature_tests_through_lowest, p_text
from ..inference.fitting.leastsq import START_FLIGHTS, fit_least_squares, noise_text
from ..inference.fitting.profile import MAX_LOWER_REFITS, lowest_point, profiles_through_lowest
from ..inference.fitting.profile_interval import profile_interval
from ..inference.sampling.proposals import PROFILE_DEPARTURE, independence_proposal, path_departure
from ..inference.results.draws import prior_record
from ..inference.results.idata import build_inference_data
from ..inference.results.posterior_file import writing_posterior
from ..inference.results.summary import build_summary, format_table
from ..inference.fitting.robust import (FLAGGED, JUDGEMENT_AVERAGE, average_over_judgement, gross_error_advice,
                                robust_flights, robust_refit, suspected_gross_errors, with_saved_flags)
from ..inference.fitting.noise_choice import NOISE_CHOICE, choose_noise, run_settings, with_saved_choice
from ..inference.sampling.chains import saved_steps
from ..inference.sampling.mixing import n_walkers
from ..inference.sampling.sampler import run_sampler
from ..inference.results.versions import software_versions
from ..observation.config_io import ConfigError
from .ic_prior import check_initial_condition_prior, initial_condition_prior
from .outputs import Outcome, build_run_report
from .progress import RESULT, stage

logger = logging.getLogger(__name__)
#: what a run's chains were sampled for (written before sampling, checked on resume), in ``<output>/chains``
RUN_KEY = "run_key.json"
#: sampler settings that may change on resume (the stopping rule, the cap, parallelism)
RESUMABLE_SETTINGS = ("max_steps", "check_every", "min_steps", "n_tau", "rhat", "ess", "processes")
#: the published coefficient sets' joint tests (:func:`_literature_tests`)
LITERATURE_TESTS = "literature_tests.json"
#: least-squares files a resume reuses
LEAST_SQUARES_FILES = ("least_squares.json", "least_squares_theta.npy", "least_squares_cov.npy")


def run_key(cfg: RunConfig, problem) -> dict:
    """What a run's chains were sampled for: parameters, flights, markers, prior and the sampler settings
    that shape the chains (everything but :data:`RESUMABLE_SETTINGS`).

    Parameters
    ----------
    cfg : RunConfig
        The run configuration.
    problem : Problem
        Its statistical problem.

    Returns
    -------
    dict
        JSON-serialisable; two runs may share chain files only when their keys are equal.
    """
    flights = {name: {k: v for k, v in f.items() if k != "file"} for name, f in flight_info(problem).items()}
    settings = {k: v for k, v in asdict(cfg.sampler).items() if k not in RESUMABLE_SETTINGS}
    settings["walkers"] = n_walkers(cfg.sampler, problem)
    prior = cfg.prior if isinstance(cfg.prior, str) else prior_record(cfg.prior)
    key = {"parameters": list(problem.names), "flights": flights, "markers": cfg.markers, "prior": prior,
           "initial_conditions": cfg.ic_prior, "sampler": settings}
    noise = noise_info(problem)
    if any(d["model"] != "gaussian" or d["per_point"] for d in noise.values()):
        key["noise"] = noise                       # only when not the plain model: older runs still resume
    return json.loads(json.dumps(key))


def check_same_run(cfg: RunConfig, problem, out: Path) -> None:
    """Refuse to resume when the configuration no longer describes the run saved in ``out``.

    Parameters
    ----------
    cfg : RunConfig
        The configuration given with ``--resume``.
    problem : Problem
        Its statistical problem.
    out : Path
        The run folder (``chains/run_key.json``).

    Raises
    ------
    ConfigError
        Naming what differs (flights, parameters, markers, prior, sampler settings), or that the folder
        does not record what its chains were sampled for.
    """
    path = Path(out) / "chains" / RUN_KEY
    if not path.is_file():
        raise ConfigError(cfg.path, None, f"cannot resume: {path} is missing, so the chains in {path.parent} "
                                          "cannot be checked against this configuration (run without --resume)")
    saved, now = json.loads(path.read_text()), run_key(cfg, problem)
    differ = [k for k in now if saved.get(k) != now[k]]
    if not differ:
        return
    words = []
    for k in differ:
        a, b = saved.get(k), now[k]
        if k == "flights":
            words.append(f"flights (saved run: {', '.join(a or {})}; now: {', '.join(b)}"
                         + ("; same names, different data or time windows" if list(a or {}) == list(b) else "")
                         + ")")
        elif k == "parameters":
            extra, gone = sorted(set(b) - set(a or [])), sorted(set(a or []) - set(b))
            words.append("parameters (" + "; ".join(
                ([f"new: {', '.join(extra)}"] if extra else []) + ([f"gone: {', '.join(gone)}"] if gone else [])
                or ["order changed"]) + ")")
        elif k == "sampler":
            keys = sorted(x for x in set(a or {}) | set(b) if (a or {}).get(x) != b.get(x))
            words.append("sampler settings " + ", ".join(f"{x} {(a or {}).get(x)} → {b.get(x)}" for x in keys))
        else:
            words.append(f"{k} ({a} → {b})")
    raise ConfigError(cfg.path, None, f"cannot resume the run in {out}: the configuration changed since it was "
                                      f"sampled: {'; '.join(words)} (run without --resume to start again)")


def saved_least_squares(out: Path) -> dict | None:
    """The least-squares result saved in a run folder (``least_squares.json``), when it and the optimum and
    covariance files (``least_squares_theta.npy``, ``least_squares_cov.npy``) are all there.

    Parameters
    ----------
    out : Path
        The run folder.

    Returns
    -------
    dict or None
        The content of ``least_squares.json``; None when a file is missing.
    """
    out = Path(out)
    if not all((out / f).is_file() for f in LEAST_SQUARES_FILES):
        return None
    return json.loads((out / "least_squares.json").read_text())


def _least_squares(problem, cfg: RunConfig, out: Path):
    where = (f" on the {START_FLIGHTS} most informative flights" if problem.n_flights > START_FLIGHTS else "")
    with stage("least squares", f"{cfg.least_squares.starts} start(s){where}, ≤ {cfg.least_squares.max_nfev} "
                                "evaluations each") as st:
        def report(done, total, cost):
            if cost is None:
                joined = "joining the other flights to it and " if where else ""
                logger.info(f"least squares: {joined}refining the best start with per-flight noise scales "
                            f"({st.elapsed:.0f} s)")
            else:
                logger.info(f"least squares: start {done}/{total} cost {cost:.1f} ({st.elapsed:.0f} s)")
        ls = fit_least_squares(problem, starts=cfg.least_squares.starts, max_nfev=cfg.least_squares.max_nfev,
                               seed=cfg.sampler.seed, progress=report)
        ls_dict = _save_least_squares(ls, out)
        st.result = ((f"starts on {', '.join(ls.start_flights)}; " if ls.start_flights else "")
                     + f"cost {ls.cost:.1f}, condition number {ls.condition_number:.3g}, RMS "
                     + noise_text(ls_dict["noise"]))
    return ls, ls_dict


def _save_least_squares(ls, out: Path) -> dict:
    ls_dict = ls.to_dict()
    (out / "least_squares.json").write_text(json.dumps(ls_dict, indent=1))
    np.save(out / "least_squares_cov.npy", ls.cov)
    np.save(out / "least_squares_theta.npy", ls.theta)
    return ls_dict


def _noise_choice(problem, ls, ls_dict: dict, cfg: RunConfig, out: Path):
    """Each ``auto`` flight's marker noise model chosen by evidence
    (:func:`bayes_disc.inference.fitting.noise_choice.choose_noise`): written to ``noise_choice.json``, one
    log line per marker flight, the least-squares files rewritten when the choice refitted them. Returns
    (problem, least squares, its record) with the chosen models."""
    with stage("noise choice", "each auto flight's marker noise model by evidence (white, AR(1), per-point, "
                               "robust)") as st:
        def report(label, flights):
            logger.info(f"noise choice: refitting with {label} noise on {', '.join(flights)} ({st.elapsed:.0f} s)")
        choice = choose_noise(problem, ls, run_settings(cfg, problem), max_nfev=cfg.least_squares.max_nfev,
                              progress=report)
        choice.save(out)
        for line in choice.lines():
            logger.info(f"noise choice: {line}")
        if choice.ls is not ls:
            ls_dict = _save_least_squares(choice.ls, out)
        labels = [r["label"] for r in choice.records.values()]
        st.result = (", ".join(f"{labels.count(lab)} {lab}" for lab in dict.fromkeys(labels)) or "no marker flight") \
            + f" (listed in {out / NOISE_CHOICE})"
    return choice.problem, choice.ls, ls_dict


def flag_lines(flags: dict) -> list[str]:
    """Per flight its estimated mixture ("a: gross errors estimated at π = 0.12 % of points, ..."), then one
    line per flagged point or frame: "a t=0.2083 s marker 1: outlier (p = 0.998)"."""
    out = []
    for name, f in flags.items():
        m = f["mixture"]
        out.append(f"{name}: gross errors estimated at π = {100 * m['outlier_fraction']:.2f} % of points, spread "
                   f"w = {1e3 * m['outlier_width_m']:.1f} mm; swapped frames π_s = {100 * m['swap_fraction']:.2f} %")
        out += [f"{o['flight']} t={o['t']:.4f} s marker {o['marker']}: outlier (p = {o['probability']:.3f})"
                for o in f["outliers"]]
        out += [f"{w['flight']} t={w['t']:.4f} s markers {w['markers'][0]} and {w['markers'][1]}: labels swapped "
                f"(p = {w['probability']:.3f})" for w in f["swaps"]]
    return out


def _robust(problem, ls, ls_dict: dict, cfg: RunConfig, out: Path):
    """For ``robust`` marker noise: judge, clean and refit
    (:func:`bayes_disc.inference.fitting.robust.robust_refit`), write ``flagged.json`` and the refined
    least-squares files, log every flag. Flights with plain Gaussian noise whose data look as if they hold
    gross errors get a warning with the fix
    (:func:`bayes_disc.inference.fitting.robust.gross_error_advice`)."""
    advice = gross_error_advice(suspected_gross_errors(problem, ls.theta))
    if advice is not None:
        logger.warning(advice)
    if not robust_flights(problem):
        return problem, ls, ls_dict
    with stage("robust fit", "judging outliers and label swaps, refitting on the cleaned data") as st:
        def report(i, n_out, n_swap):
            logger.info(f"robust fit: round {i}: {n_out} outlier(s), {n_swap} swapped frame(s) ({st.elapsed:.0f} s)")
        problem, ls, flags = robust_refit(problem, ls, max_nfev=cfg.least_squares.max_nfev, progress=report)
        (out / FLAGGED).write_text(json.dumps(flags, indent=1))
        for line in flag_lines(flags):
            logger.info(f"flagged: {line}")
        ls_dict = _save_least_squares(ls, out)
        n_out = sum(len(f["outliers"]) for f in flags.values())
        n_swap = sum(len(f["swaps"]) for f in flags.values())
        st.result = f"{n_out} outlier(s) removed, {n_swap} swapped frame(s) restored (listed in {out / FLAGGED})"
    return problem, ls, ls_dict


def _average_over_judgement(raw, problem, chains, cfg: RunConfig, out: Path) -> None:
    """The posterior averaged over the judgement of outliers and swaps
    (:func:`bayes_disc.inference.fitting.robust.average_over_judgement`):
    written to ``judgement_average.json`` and logged."""
    names = problem.names[: problem.n_coef + problem.n_ext]
    with stage("averaging over the judgement", "reweighting draws to the inlier/outlier/swap mixture likelihood") as st:
        avg = average_over_judgement(raw, problem, chains.chain.reshape(-1, problem.dim),
                                     chains.ss.reshape(-1, problem.n_groups), names,
                                     np.random.default_rng(cfg.sampler.seed), json.loads((out / FLAGGED).read_text()))
        (out / JUDGEMENT_AVERAGE).write_text(json.dumps(avg.to_dict(), indent=1))
        for line in avg.lines():
            logger.info(line)
        st.result = (f"Pareto k̂ {avg.pareto_k:.2f}, " + ("the averaged posterior is in " if avg.reliable else
                     "weights not trusted; see ") + str(out / JUDGEMENT_AVERAGE))


def posterior_approximation(problem, ls, processes: int, out: Path, progress: bool = False, max_nfev: int = 200,
                            with_prior=None):
    """Profile paths of the coefficients through the least-squares optimum and the ridge-aware
    independence proposal built from them (:func:`bayes_disc.inference.sampling.proposals.independence_proposal`).

    A profile that reaches a lower cost than the optimum shows the optimum was not the lowest point (a local
    optimum, or a fit stopped short of it): the least squares are refitted from that point and the profiles
    start again (:func:`bayes_disc.inference.fitting.profile.profiles_through_lowest`); the least-squares files are
    rewritten and a warning names the profile.

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
    progress : bool
        A bar over the coefficients (on a terminal); otherwise a log line per finished profile.
    max_nfev : int
        Evaluation budget of each least-squares refinement round after a lower point.
    with_prior : callable, optional
        ``with_prior(problem, ls) -> problem``: the problem whose posterior the proposal is built for, from the
        optimum the profiles went through (the initial conditions' reference prior,
        :func:`.ic_prior.initial_condition_prior`); default: ``problem`` as given.

    Returns
    -------
    proposal : CompositeProposal
        The independence proposal for the sampler.
    ls : LeastSquaresResult
        The optimum the profiles went through: ``ls`` itself, or its refit from a lower point.
    """
    from tqdm import tqdm
    idx = range(problem.n_coef + problem.n_ext)
    with stage("profile likelihoods", f"{len(idx)} coefficients in {processes} process(es)") as st:
        bar = tqdm(total=len(idx), desc="profiles", unit="coefficient", leave=False,
                   disable=None if progress else True)

        def report(path, done, total):
            bar.set_postfix_str(path.name, refresh=False)
            bar.update(1)
            if bar.disable:
                logger.info(f"profile likelihood {done}/{total}: {path.name}, {len(path.points)} points, "
                            f"{path.classify()} ({st.elapsed:.0f} s)")

        def refitted(found, new):
            bar.reset()
            logger.warning(f"{found}, which was not the lowest point: the least squares are refitted from there "
                           f"(cost {new.cost:.1f}; the earlier optimum's with the new noise scales "
                           f"{new.lower_optima[-1]['earlier_cost']:.1f}), then the profiles start again")
            _save_least_squares(new, out)
        try:
            paths, ls = profiles_through_lowest(problem, ls, idx, processes=processes, progress=report,
                                                max_nfev=max_nfev, on_refit=refitted)
        finally:
            bar.close()
        below = [p.name for p in paths if lowest_point(p.points) is not None]
        if below:
            logger.warning(f"the profiles of {', '.join(below)} still reach below the least-squares optimum after "
                           f"{MAX_LOWER_REFITS} refits from lower points: the posterior has several modes close in "
                           "cost (the profiles and the proposal built on them include those points)")
        target = problem if with_prior is None else with_prior(problem, ls)
        proposal = independence_proposal(target, ls.theta, ls.cov, paths)
        record = {}
        for path in paths:
            dep = path_departure(path, ls.theta, ls.cov)
            record[path.name] = {"value": [p.value for p in path.points], "t": path.t.tolist(),
                                 "deviance": path.deviance.tolist(), "departure_from_laplace": dep,
                                 "shape": path.classify(), "jacobians": path.njev, "evaluations": path.nfev}
        (out / "profiles.json").write_text(json.dumps(record, indent=1))
        ridge = [n for n, r in record.items() if r["departure_from_laplace"] > PROFILE_DEPARTURE]
        refits = (f"least squares refitted {len(ls.lower_optima)} time(s) from a lower point on a profile; "
                  if ls.lower_optima else "")
        st.result = (refits + (f"non-Gaussian along {', '.join(ridge)}; " if ridge else "all close to Gaussian; ")
                     + f"{len(proposal.parts) - 1} ridge proposal(s)")
    return proposal, ls


def _resume_message(name: str, steps: list) -> str:
    n = max(steps)
    text = (f"resuming {name} from step {n} of each ensemble (ensembles at {', '.join(map(str, steps))} steps")
    return text + (f"; the shorter ones are first advanced to {n})" if min(steps) < n else ")")


def _read_problem(cfg: RunConfig, out: Path, resume: bool):
    """The "reading flights and checks" stage: the inertial throws, the statistical problem as read (``raw``)
    and as fitted (with a saved judgement of outliers and swaps applied on resume)."""
    with stage("reading flights and checks") as st:
        throws = load_run_throws(cfg) if cfg.imu else []
        problem = raw = build_problem(cfg, throws=throws)
        saved = resume and (out / "chains" / RUN_KEY).is_file()
        if saved and (out / NOISE_CHOICE).is_file():
            problem = raw = with_saved_choice(problem, out)
            logger.info(f"resume: the saved choice of marker noise models ({out / NOISE_CHOICE}) is applied")
        if saved and robust_flights(problem) and (out / FLAGGED).is_file():
            problem = with_saved_flags(problem, out)
            logger.info(f"resume: the saved judgement of outliers and label swaps ({out / FLAGGED}) is applied")
        st.result = f"{cfg.name}: {data_words(problem)}, {problem.dim} parameters"
        if noise_info(problem):
            logger.info(f"marker noise: {noise_words(noise_info(problem))}")
        for t in throws:
            if t.status != "ok":
                logger.info(f"{t.name}: {t.status}: {t.reason}")
    return throws, raw, problem


@dataclass
class Prepared:
    """What sampling starts from (:func:`_prepare_sampling`)."""

    raw: object            # Problem as read, with its noise models (None on resume)
    problem: object        # Problem sampled: robust flights cleaned, with the initial conditions' prior
    ls_dict: dict          # least-squares record
    proposal: object       # proposal (None on resume: the sampler reads the one saved with its chains)
    steps: list | None     # saved steps on resume, else None
    ic: dict               # summary.json's ``initial_condition_prior``
    ls: object = None      # LeastSquaresResult the initial conditions' prior was built at (None on resume)


def _prepare_sampling(cfg: RunConfig, problem, out: Path, resume: bool, progress: bool) -> Prepared:
    """Before sampling: on resume, the saved chains' step counts and least squares (the proposals are saved
    with the chains); otherwise least squares, the choice of noise models, the robust fit, the profiles and
    their proposal."""
    if resume and (out / "chains" / RUN_KEY).is_file():
        check_same_run(cfg, problem, out)       # before counting chain files: the ensembles may differ
    steps = saved_steps(out, cfg.sampler.ensembles) if resume else None
    if resume and steps is None:
        logger.warning(f"--resume: no chain files in {out / 'chains'}; starting a fresh run")
    if steps is not None:
        check_same_run(cfg, problem, out)
        logger.info(_resume_message(cfg.name, steps))
        ls_dict = saved_least_squares(out)
        if ls_dict is None:
            logger.warning(f"resume: the least-squares files ({', '.join(LEAST_SQUARES_FILES)}) are not all in "
                           f"{out}; recomputing least squares")
            _, ls_dict = _least_squares(problem, cfg, out)
        else:
            logger.info(f"resume: reusing the saved least-squares optimum (cost {ls_dict['cost']:.1f}) and the "
                        "proposals saved with the chains")
        problem, ic = initial_condition_prior(problem, None, cfg, out, resume=True)
        return Prepared(None, problem, ls_dict, None, steps, ic)   # the sampler continues with the saved proposals
    ls, ls_dict = _least_squares(problem, cfg, out)
    problem, ls, ls_dict = _noise_choice(problem, ls, ls_dict, cfg, out)
    raw = problem
    problem, ls, ls_dict = _robust(problem, ls, ls_dict, cfg, out)
    chosen = {}

    def with_prior(p, optimum):
        chosen["problem"], chosen["ic"] = initial_condition_prior(p, optimum, cfg, out, resume=False)
        chosen["ls"] = optimum
        return chosen["problem"]
    # the joint tests first: a published set that fits better than the optimum moves it before the profiles
    ls = _literature_tests(problem, ls, out, cfg.least_squares.max_nfev)
    proposal, profiled = posterior_approximation(problem, ls, cfg.sampler.processes, out, progress=progress,
                                                 max_nfev=cfg.least_squares.max_nfev, with_prior=with_prior)
    if profiled is not ls:          # the profiles refitted it: the tests are against the new optimum
        ls = _literature_tests(problem, profiled, out, cfg.least_squares.max_nfev, refit=False)
    problem, ic = chosen["problem"], chosen["ic"]
    (out / "chains").mkdir(exist_ok=True)
    (out / "chains" / RUN_KEY).write_text(json.dumps(run_key(cfg, problem), indent=1))
    return Prepared(raw, problem, ls.to_dict(), proposal, None, ic, chosen["ls"])


def _literature_tests(problem, ls, out: Path, max_nfev: int, refit: bool = True):
    """Each published coefficient set against the data's joint profile region
    (:func:`bayes_disc.inference.fitting.joint_region.literature_tests`): logged and written to
    ``<out>/literature_tests.json`` (summary.json ``literature_tests``). With ``refit``, a set whose values held
    together fit better than the optimum has the least squares refitted from its conditional optimum (warned, the
    least-squares files rewritten) and the sets tested again. When a set's fit fails, the warning names it and no
    set's test is written; a set still below the optimum gets a warning instead of a verdict line. Returns the
    optimum the tests are against."""
    latest = [ls]                   # the last refit, kept should a later test's fit fail

    def refitted(key, test, new):
        latest.append(new)
        logger.warning(f"holding the {key} values reached a lower cost than the least-squares optimum (W = "
                       f"{test.deviance:.4g}), which was not the lowest point: the least squares are refitted from "
                       f"there (cost {new.cost:.1f}; the earlier optimum's with the new noise scales "
                       f"{new.lower_optima[-1]['earlier_cost']:.1f})")
        _save_least_squares(new, out)
    with stage("joint tests", "the published coefficient sets against the joint profile region"):
        try:
            if refit:
                tests, ls = literature_tests_through_lowest(problem, ls, max_nfev, on_refit=refitted)
            else:
                tests = literature_tests(problem, ls)
        except RuntimeError as e:
            logger.warning(f"no joint test of the published coefficient sets: {e}")
            (out / LITERATURE_TESTS).unlink(missing_ok=True)
            return latest[-1]
        for key, t in tests.items():
            if t.below_optimum:
                logger.warning(f"holding the {key} values reached a lower cost than the least-squares optimum (W = "
                               f"{t.deviance:.4g}): the optimum is not the lowest point, and these values fit the "
                               "data better than it; the intervals are those of the optimum found")
                continue
            where = "inside" if t.inside else "outside"
            logger.info(f"{key} ({t.dof} coefficients): profile deviance W = {t.deviance:.4g}, {where} the "
                        f"joint 90 % region ({p_text(t.p_value)})"
                        + ("" if t.converged else "; its fit stopped at its budget, so W is an upper bound"))
        (out / LITERATURE_TESTS).write_text(json.dumps({k: t.to_dict() for k, t in tests.items()}, indent=1))
    return ls


def _write_outputs(cfg: RunConfig, problem, chains, ls_dict: dict, throws, steps, out: Path, t0: float, ic: dict):
    """The "outputs" stage: summary.json, posterior.nc and run_info.json (its history of sampling sessions
    extended on resume). Returns (summary, run_info)."""
    with stage("outputs", "summary.json, posterior.nc, run_info.json"):
        info = {"name": cfg.name, "config": str(cfg.path), "flights": flight_info(problem),
                "sampler_settings": asdict(cfg.sampler), "markers": cfg.markers, "noise": noise_info(problem),
                "initial_condition_prior": ic}
        if (out / NOISE_CHOICE).is_file():
            info["noise_choice"] = json.loads((out / NOISE_CHOICE).read_text())
        if (out / LITERATURE_TESTS).is_file():
            info["literature_tests"] = json.loads((out / LITERATURE_TESTS).read_text())
        if (out / "profiles.json").is_file():
            info["profile_intervals"] = profile_intervals(json.loads((out / "profiles.json").read_text()))
        if (out / FLAGGED).is_file() and robust_flights(problem):
            flags = json.loads((out / FLAGGED).read_text())
            info["flagged"] = {"file": FLAGGED, "outliers": sum(len(f["outliers"]) for f in flags.values()),
                               "swaps": sum(len(f["swaps"]) for f in flags.values())}
        if throws:
            info["inertial_throws"] = {t.name: t.to_dict() for t in throws}
        idata = build_inference_data(problem, chains, np.random.default_rng(cfg.sampler.seed))
        with writing_posterior(idata, out / "posterior.nc", background=cfg.sampler.processes > 1):
            summary = build_summary(problem, chains, idata, ls_dict, info, threads=cfg.sampler.processes)
            (out / "summary.json").write_text(json.dumps(summary, indent=1))
        previous = out / "run_info.json"
        resumed = steps is not None and previous.is_file()
        sessions = json.loads(previous.read_text()).get("sessions", []) if resumed else []
        session = {"resumed_from_steps": steps, "total_steps": chains.total_steps,
                   "wall_time_s": time.perf_counter() - t0}
        run_info = {"wall_time_s": session["wall_time_s"], "sampling_wall_time_s": chains.wall_time_s,
                    "history": chains.history, "sessions": sessions + [session], "versions": software_versions()}
        previous.write_text(json.dumps(run_info, indent=1))
    return summary, run_info


def profile_intervals(profiles: dict) -> dict:
    """summary.json's ``profile_intervals``: each profiled parameter's profile interval
    (:func:`bayes_disc.inference.fitting.profile_interval.profile_interval`).

    Parameters
    ----------
    profiles : dict
        The content of ``profiles.json`` ({name: {value, t, deviance, …}}).

    Returns
    -------
    dict
        {name: {q05, q25, q50, q75, q95}} in the parameter's unit; a path without the optimum and another point
        gives none (a warning names it).
    """
    out = {}
    for name, path in profiles.items():
        try:
            out[name] = profile_interval(path)
        except ValueError as e:
            logger.warning(f"no profile interval for {name}: {e}")
    return out


def run_sample(cfg: RunConfig, resume: bool = False, progress: bool = True) -> dict:
    """Least squares, emcee, and the run files ``summary.json``, ``posterior.nc``, ``run_info.json``.

    Parameters
    ----------
    cfg : RunConfig
        The validated run configuration; files go to ``cfg.output``.
    resume : bool
        Continue an interrupted run from its chain files: the saved least-squares result and proposals
        are reused (least squares is recomputed, with a warning, only when its files are missing), every
        ensemble is brought to the same number of steps, and the sampler's history is extended. A
        folder without chain files starts afresh (with a warning).
    progress : bool
        Show progress bars (on a terminal only; log lines otherwise).

    Returns
    -------
    dict
        The content of ``summary.json`` (docs/outputs.md): ``parameters`` ({name: {mean, sd, q05, q50, q95, r_hat,
        ess_bulk}}, coefficients dimensionless, ``sigma_<flight>`` in m, initial conditions in SI units),
        ``convergence`` and the run's description.

    Raises
    ------
    ConfigError
        On resume, when the configuration no longer describes the saved run.
    """
    t0 = time.perf_counter()
    out = Path(cfg.output)
    out.mkdir(parents=True, exist_ok=True)
    throws, raw, problem = _read_problem(cfg, out, resume)
    prep = _prepare_sampling(cfg, problem, out, resume, progress)
    problem, steps = prep.problem, prep.steps
    raw = raw if prep.raw is None else prep.raw
    s = cfg.sampler
    with stage("sampling", f"{s.ensembles} ensembles × {n_walkers(s, problem)} walkers until R-hat < {s.rhat:g}, "
                           f"ESS ≥ {s.ess:g}, N/τ ≥ {s.n_tau:g} (cap {s.max_steps} steps)") as st:
        chains = run_sampler(problem, prep.proposal, cfg.sampler, out, resume=steps is not None, progress=progress)
        st.result = f"{chains.reason} at step {chains.total_steps}"
    if robust_flights(raw):
        _average_over_judgement(raw, problem, chains, cfg, out)
    check_initial_condition_prior(problem, prep.ls, chains, cfg, prep.ic)
    summary, run_info = _write_outputs(cfg, problem, chains, prep.ls_dict, throws, steps, out, t0, prep.ic)
    logger.info(format_table(summary), extra=RESULT)
    c = summary["convergence"]
    logger.info(f"{c['reason']}: {c['total_steps']} steps × {c['walkers_per_ensemble']} walkers × {c['ensembles']} "
                f"ensembles, burn-in {c['burn_in_steps']}, τ max {c['tau_max_steps']:.1f}, "
                f"N/τ {c['n_over_tau']:.0f}, R-hat max {c['r_hat_max']:.4f}, "
                f"min coefficient ESS {c['ess_bulk_min_coefficient']:.0f}; "
                f"{run_info['wall_time_s']:.0f} s", extra=RESULT)
    logger.info(f"wrote {out / 'summary.json'}, {out / 'posterior.nc'}")
    return summary


def sample(cfg: RunConfig, *, resume: bool = False, progress: bool = True, report: bool = True) -> Outcome:
    """``bayes-disc sample``: sample the posterior (:func:`run_sample`), then build the run's HTML report
    ``<output>/reports/<name>.html``.

    Parameters
    ----------
    cfg : RunConfig
        The validated run configuration.
    resume : bool
        Continue an interrupted run from its chain files.
    progress : bool
        Show progress bars (least-squares starts and stages are logged in any case).
    report : bool
        Build the HTML report after sampling.

    Returns
    -------
    Outcome
        ``result``: the summary.json content; ``report``: the HTML file (None without ``report``).
    """
    logger.debug(f"sample: configuration {cfg.path}, output {cfg.output}")
    summary = run_sample(cfg, resume=resume, progress=progress)
    path = build_run_report(cfg.output, cfg.sampler.seed, cfg.sampler.processes) if report else None
    return Outcome(summary, path)
