"""``bayes-disc predict``: held-out validation of a run's coefficients on flights it has not seen.

Every flight of the configuration is fitted twice by least squares:

* **fixed** — the coefficients, extra-term parameters and the observation models' shared parameters (e.g.
  the logger's position and filter constant) held at the posterior medians of ``RUN_DIR`` (or, for a folder
  without a posterior such as an ``identifiability`` run's, at its least-squares optimum); only the
  flight's own initial conditions and nuisance parameters (row period, biases, filter state) free;
* **free** — everything free (the flights of this configuration alone).

The fixed fit starts from the flight's own start, from its block of the free fit and from the release state
of every flight of the run (its fitted initial conditions, with the free fit's nuisance parameters), and keeps
the one with the lowest profile deviance (the wobble's phase makes these fits multimodal; a throw of the same
logger often flies only from a release the run's coefficients were fitted with). Where the flight cannot be
simulated with the fixed parameters from any start, it is reached by continuation from the free fit (the shared
parameters moved in steps from the free fit's values to the run's, the flight's block refitted at every step);
a flight the continuation does not bring to the run's parameters either is reported ``failed`` with the
simulator's reason.

The ratio of the two RMS per channel says how well the run's physics predicts a throw it did not see
(≈ 1: as well as a fit to the throw itself). Inertial throws flown upside down are reported as
``out_of_model`` and not fitted. Output ``prediction.json``:
``{"flights": {flight: {"status" (ok | failed | out_of_model), "reason",
"start" (own | free | run flight <name> | continuation), "channels": {channel: {"unit", "rms_fixed", "rms_free"}}}}}``,
channels ``markers`` [m], ``gyro`` [rad/s], ``acc`` [m/s²], ``mag`` [µT], ``baro`` [Pa].
"""
from __future__ import annotations

import json
import logging
import time
from pathlib import Path

import numpy as np
from scipy.optimize import least_squares

from ..observation.config_io import ConfigError
from ..observation.models import MarkerPositions
from ..inference.model.config import RunConfig
from ..inference.model.data import build_problem
from ..inference.model.inertial import load_run_throws
from ..inference.model.layout import InitialConditions
from ..inference.fitting.leastsq import fit_least_squares
from ..inference.fitting.residuals import FAILED_RESIDUAL

log = logging.getLogger(__name__)

#: channel name, unit and the noise-group names (without ``_<flight>``) it pools, per observation model
CHANNELS = {"markers": ("m", ("sigma",)), "gyro": ("rad/s", ("sigma_gyro_axial", "sigma_gyro_transverse")),
            "acc": ("m/s²", ("sigma_acc_axial", "sigma_acc_transverse")),
            "mag": ("µT", ("sigma_mag_axial", "sigma_mag_transverse")), "baro": ("Pa", ("sigma_baro",))}


def channel_rms(problem, theta: np.ndarray, k: int) -> dict:
    """{channel: RMS} of flight k's residuals at θ (dim,), channels of :data:`CHANNELS`."""
    r, ok = problem.residuals(theta[None], k)
    groups = problem.residual_groups(k)
    name = problem.flights[k].name
    out = {}
    for ch, (_, prefixes) in CHANNELS.items():
        ids = [problem.sigma_names.index(f"{p}_{name}") for p in prefixes if f"{p}_{name}" in problem.sigma_names]
        if ids:
            sel = np.isin(groups, ids)
            out[ch] = float(np.sqrt(np.mean(r[0, sel] ** 2))) if ok[0] else float("nan")
    return out


def _fit_own(problem, theta: np.ndarray, k: int, max_nfev: int) -> tuple[np.ndarray, float]:
    """θ with flight k's own block refitted from θ's values (shared entries held), the weights refined twice
    from the RMS; and the fit's profile deviance Σ_g n_g ln RMS_g² over flight k's noise groups g (+inf when
    the flight cannot be simulated there), which compares fits with different noise scales."""
    cols = np.arange(problem.layout.flight_slice(k).start, problem.layout.flight_slice(k).stop)
    x = theta.copy()
    sigma = problem.nominal_noise.copy()
    groups = problem.residual_groups(k)
    for _ in range(3):
        def resid(v):
            y = x.copy()
            y[cols] = v
            r, ok = problem.residuals(y[None], k)
            r = r[0] / sigma[groups]
            if not ok[0] or not np.all(np.isfinite(r)):
                r = np.full(r.shape, FAILED_RESIDUAL)
            return np.r_[r, (v - problem.prior_mean[cols]) / problem.prior_sd[cols]]
        res = least_squares(resid, x[cols], x_scale=problem.prior_sd[cols], max_nfev=max_nfev, xtol=1e-10,
                            ftol=1e-10)
        x[cols] = res.x
        r, ok = problem.residuals(x[None], k)
        if not (ok[0] and np.all(np.isfinite(r[0]))):
            return x, float("inf")
        for g in problem.flight_groups(k):
            sigma[g] = max(float(np.sqrt(np.mean(r[0, groups == g] ** 2))), 5e-3 * problem.nominal_noise[g])
    deviance = sum(np.sum(groups == g) * np.log(np.mean(r[0, groups == g] ** 2)) for g in problem.flight_groups(k))
    return x, float(deviance)


def with_free_block(problem, theta: np.ndarray, free_theta: np.ndarray, k: int) -> np.ndarray:
    """θ (dim,) with flight k's block taken from the free fit's θ (dim,): the held-out fit's second start."""
    block = problem.layout.flight_slice(k)
    out = theta.copy()
    out[block] = free_theta[block]
    return out


#: the continuation's largest step in λ (:func:`fit_by_continuation`)
CONTINUATION_STEP = 0.125
#: the step in λ below which the continuation gives up
CONTINUATION_MIN_STEP = 1.0 / 128


def fit_by_continuation(problem, theta: np.ndarray, free_theta: np.ndarray, k: int, max_nfev: int):
    """Flight k's own block fitted with the shared entries of θ held, reached from the free fit.

    The shared entries move along θ_s(λ) = (1 − λ) θ_s,free + λ θ_s from λ = 0 (the free fit) to λ = 1 (the
    run's values); at every λ the block is refitted (:func:`_fit_own`) from the block of the last λ. A step
    whose fit cannot be simulated is halved; after a success the step doubles again, up to
    :data:`CONTINUATION_STEP`. This follows the block along with the shared parameters, where a fit started at
    λ = 1 from the free fit's block may not fly at all (an initial wobble the run's coefficients drive beyond
    the integrator's envelope).

    Parameters
    ----------
    problem : Problem
    theta : (dim,) array
        The run's shared entries (θ[:ic_start]); its blocks are not read.
    free_theta : (dim,) array
        The free fit: the path's start.
    k : int
        The flight.
    max_nfev : int
        Budget of every refit.

    Returns
    -------
    (dim,) array or None
        The fit at λ = 1; None when the step fell below :data:`CONTINUATION_MIN_STEP` first.
    float
        The last λ whose fit could be simulated.
    """
    s = problem.ic_start
    x, lam, step = free_theta.copy(), 0.0, CONTINUATION_STEP
    while lam < 1.0:
        trial = min(1.0, lam + step)
        y = x.copy()
        y[:s] = (1.0 - trial) * free_theta[:s] + trial * theta[:s]
        y, deviance = _fit_own(problem, y, k, max_nfev)
        log.debug("%s: continuation λ = %.4f, deviance %.6g", problem.flights[k].name, trial, deviance)
        if np.isfinite(deviance):
            x, lam, step = y, trial, min(2.0 * step, CONTINUATION_STEP)
        else:
            step /= 2.0
            if step < CONTINUATION_MIN_STEP:
                return None, lam
    return x, lam


def run_release_states(params: dict, kind: InitialConditions) -> dict:
    """The release states of a run's flights: {flight: (kind.size,) initial conditions} for every flight whose
    parameters ``params`` ({name: value}, as ``summary.json`` or ``least_squares.json`` hold them) include a
    full set of initial conditions of ``kind`` (named ``<ic>_<flight>``)."""
    first = kind.names[0] + "_"
    out = {}
    for key in params:
        if key.startswith(first):
            flight = key[len(first):]
            names = [f"{n}_{flight}" for n in kind.names]
            if all(n in params for n in names):
                out[flight] = np.array([float(params[n]) for n in names])
    return out


def fit_held_out(problem, theta: np.ndarray, free_theta: np.ndarray, k: int, max_nfev: int,
                 release_states: dict | None = None):
    """Flight k's own block fitted with the shared entries of θ held, from several starts: the problem's own
    start for the flight, the flight's block of the free fit and, for every run flight in ``release_states``,
    the free fit's block with that flight's initial conditions (the wobble phase makes the fit multimodal);
    where none can be simulated, by continuation from the free fit (:func:`fit_by_continuation`).

    Parameters
    ----------
    problem : Problem
    theta : (dim,) array
        The run's shared entries (θ[:ic_start]) and the problem's own start for the flight.
    free_theta : (dim,) array
        The free fit.
    k : int
        The flight.
    max_nfev : int
        Budget of every fit.
    release_states : dict, optional
        {run flight: (n_ic,) its initial conditions, of flight k's kind} (:func:`run_release_states`).

    Returns
    -------
    (dim,) array or None
        The best fit's θ; None when no start reaches a fit that can be simulated.
    str
        How it was reached: ``own``, ``free``, ``run flight <name>`` or ``continuation``; for None, how far the
        continuation got.
    """
    free_start = with_free_block(problem, theta, free_theta, k)
    starts = {"own": theta, "free": free_start}
    for flight, ic in (release_states or {}).items():
        start = free_start.copy()
        start[problem.layout.ic_slice(k)] = ic
        starts[f"run flight {flight}"] = start
    fits = {name: _fit_own(problem, start, k, max_nfev) for name, start in starts.items()}
    name = min(fits, key=lambda n: fits[n][1])
    x, deviance = fits[name]
    if np.isfinite(deviance):
        return x, name
    x, lam = fit_by_continuation(problem, theta, free_theta, k, max_nfev)
    return (x, "continuation") if x is not None else (None, f"the continuation got {100 * lam:.2g} % of the way")


def simulation_failure(problem, theta: np.ndarray, k: int) -> str:
    """Why flight k cannot be simulated at θ (dim,): the simulator's reason (``Trajectories.failure_reasons``),
    or "" when it can."""
    tr = problem.simulate(theta[None], k, want_states=False)
    return "" if tr.ok[0] else tr.failure_reasons()[0]


def run_predict(cfg: RunConfig, run_dir, output=None) -> dict:
    """Held-out validation (module docstring); writes ``<output>/prediction.json``.

    Parameters
    ----------
    cfg : RunConfig
        The configuration of the held-out flights.
    run_dir : str or Path
        Output folder of a ``bayes-disc sample`` run (its ``summary.json`` is read).
    output : str or Path, optional
        Where to write (default: the configuration's output folder).

    Returns
    -------
    dict
        The content of prediction.json.
    """
    t0 = time.perf_counter()
    run_dir = Path(run_dir)
    summary_path = run_dir / "summary.json"
    if summary_path.is_file():
        params = {n: v["q50"] for n, v in json.loads(summary_path.read_text())["parameters"].items()}
        source = f"posterior medians of {run_dir}"
    elif (run_dir / "least_squares.json").is_file():       # identifiability (or an interrupted sample) run
        summary_path = run_dir / "least_squares.json"
        params = {n: v["value"] for n, v in json.loads(summary_path.read_text())["parameters"].items()}
        source = f"least-squares optimum of {run_dir} (no posterior there)"
    else:
        raise ConfigError(summary_path, None, "not found: --from must be the output folder of a sample (or "
                          "identifiability) run")
    throws = load_run_throws(cfg) if cfg.imu else []
    problem = build_problem(cfg, throws=throws)
    theta = problem.start_vector()
    for i, name in enumerate(problem.names[: problem.ic_start]):
        if name not in params:
            raise ConfigError(summary_path, None, f"the run has no parameter {name!r} (its model differs from "
                              "this configuration's: physics terms and observation models must match)")
        theta[i] = params[name]
    log.info("predict: %d flight(s), coefficients and shared parameters: %s", problem.n_flights, source)
    free = fit_least_squares(problem, starts=cfg.least_squares.starts, max_nfev=cfg.least_squares.max_nfev,
                             seed=cfg.sampler.seed)
    flights = {}
    for k, f in enumerate(problem.flights):
        fixed, how = fit_held_out(problem, theta, free.theta, k, cfg.least_squares.max_nfev,
                                  run_release_states(params, problem.layout.flight_ic[k]))
        if fixed is None:
            at_free = with_free_block(problem, theta, free.theta, k)
            flights[f.name] = {"status": "failed", "channels": {},
                               "reason": "with the run's coefficients and shared parameters the throw could not "
                                         "be simulated from any start (the problem's, the free fit's and the run's "
                                         "release states) nor "
                                         f"reached from the free fit by continuation ({how} to the run's "
                                         "parameters): "
                                         + simulation_failure(problem, at_free, k)}
            log.warning("%s: %s", f.name, flights[f.name]["reason"])
            continue
        rf, rr = channel_rms(problem, fixed, k), channel_rms(problem, free.theta, k)
        flights[f.name] = {"status": "ok", "reason": "", "start": how,
                           "channels": {c: {"unit": CHANNELS[c][0], "rms_fixed": rf[c], "rms_free": rr[c]}
                                        for c in rf}}
        log.info("%s: %s (fixed fit started from: %s)", f.name,
                 ", ".join(f"{c} RMS fixed/free {rf[c]:.4g}/{rr[c]:.4g} {CHANNELS[c][0]} (×{rf[c] / rr[c]:.2f})"
                           for c in rf), how)
    for t in throws:
        if t.status != "ok":
            flights[t.name] = {"status": t.status, "reason": t.reason, "channels": {}}
            log.info("%s: %s — %s", t.name, t.status, t.reason)
    result = {"flights": flights, "from": str(run_dir), "source": source, "config": str(cfg.path),
              "fixed_parameters": {n: params[n] for n in problem.names[: problem.ic_start]},
              "marker_flights": [f.name for k, f in enumerate(problem.flights)
                                 if any(isinstance(c, MarkerPositions) for c in problem.channels[k])],
              "wall_time_s": time.perf_counter() - t0}
    out = Path(output) if output is not None else Path(cfg.output)
    out.mkdir(parents=True, exist_ok=True)
    (out / "prediction.json").write_text(json.dumps(result, indent=1))
    log.info("wrote %s", out / "prediction.json")
    return result
