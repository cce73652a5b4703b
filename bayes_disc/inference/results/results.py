"""Posterior summaries (SPEC §6 ``summary.json``), ArviZ InferenceData (``posterior.nc``) and the terminal table.

Layout of ``posterior.nc`` (ArviZ InferenceData; :func:`build_inference_data`):

* ``posterior``: dims ``chain`` × ``draw``; every emcee walker is one chain (``chain`` has the non-index
  coordinates ``ensemble`` and ``walker``: chain ``c`` is walker ``walker[c]`` of the independent ensemble
  ``ensemble[c]``), ``draw`` is the kept step after burn-in. Coefficients and extra-term parameters are
  scalar variables (``CLa``, ``CY`` …); each flight's initial conditions (``x y z vx vy vz th1 th2 th3 wx wy
  wz``, units in their ``units`` attribute) and noise scale ``sigma`` [m] have a ``flight`` dimension.
  summary.json keeps the flat names of SPEC §6: ``x_<flight>`` is ``posterior["x"].sel(flight=<flight>)``,
  ``sigma_<flight>`` is ``posterior["sigma"].sel(flight=<flight>)`` (:func:`posterior_draws` reads either).
* ``sample_stats``: ``lp``, the log-posterior of θ (σ integrated out) of every sample.
* ``log_likelihood``: ``markers`` (chain, draw, point), pointwise log-likelihood of every observed marker
  point (the three coordinates of one marker at one sample time form one observation) for a thinned set of
  draws, ``log N(y | m(θ), σ_f² I₃)`` with the draw's own σ_f; ``point`` carries ``point_flight``,
  ``point_time`` and ``point_marker`` coordinates. ``az.loo(idata)`` / ``az.compare`` use it.
* ``posterior_predictive``: ``markers_<flight>`` (chain, draw, time, marker, axis) [m], simulated markers
  plus N(0, σ_f²) noise for a thinned set of draws, dims as ``observed_data``.
* ``prior``, ``observed_data`` (``markers_<flight>``, NaN where a marker was not seen).

R-hat: ``summary.json``'s ``r_hat`` is the rank-normalised split R-hat with the independent *ensembles* as
chains (walkers of an ensemble pooled step by step: the sampler's stopping rule), i.e.
``az.rhat(ensemble_view(idata))``. ``az.summary(idata)`` treats every *walker* as a chain and reports that
walker-level R-hat, which summary.json records as ``r_hat_walkers``; ``ess_bulk``, ``ess_tail``,
``mcse_mean`` and ``mcse_sd`` in summary.json are ``az.summary(idata)``'s, computed for every parameter at once
by :func:`.mcmc_stats.summary_diagnostics` (ArviZ loops over the parameters through xarray).
"""
from __future__ import annotations

import contextlib
import warnings
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import arviz as az
import h5py
import numpy as np
import xarray as xr

from ...physics import COEFFICIENT_NAMES, LITERATURE
from ...physics.parallel import mp_context
from ...observation.models import MarkerPositions
from ...observation.models.inertial import InertialMeasurements
from ..sampling.mcmc_stats import rhat, summary_diagnostics
from ..model.layout import IC_NAMES
from ..model.problem import Problem
from ..model.priors import coefficient_prior
from ..sampling.chains import Chains

#: the inertial channels, in the order of the models' predictions
IMU_CHANNELS = ("gx", "gy", "gz", "ax", "ay", "az")
#: parameters summarised together (bounds the temporaries of the diagnostics: ~10 copies of the block's draws)
SUMMARY_BLOCK = 16

#: posterior.nc variables with a ``flight`` dimension for marker runs: the initial conditions and σ [m]
FLIGHT_VARIABLES = IC_NAMES + ("sigma",)
#: most (chain × draw) samples in the ``log_likelihood`` group (float32; ~4000 draws × ~1300 points: ~21 MB)
N_LOG_LIKELIHOOD_DRAWS = 4000
#: most (chain × draw) samples in the ``posterior_predictive`` group (float32; demo: ~16 MB)
N_PREDICTIVE_DRAWS = 1000
#: simulated in one batch when computing the pointwise log-likelihood
BATCH = 500


def prior_record(prior) -> dict:
    """summary.json's ``prior``: name, description and each coefficient's Gaussian (mean, sd).

    Parameters
    ----------
    prior : str or CoefficientPrior
        The run's prior (:func:`.priors.coefficient_prior`).

    Returns
    -------
    dict
        ``name``, ``description``, ``mean`` and ``sd`` ({coefficient: value}).
    """
    cp = coefficient_prior(prior)
    return {"name": cp.name, "description": cp.description, "mean": dict(cp.mean), "sd": dict(cp.sd)}


@contextlib.contextmanager
def _walkers_as_chains():
    """ArviZ warns when there are more chains than draws: with walkers as chains that is the intended layout
    of a short run. Only that warning is filtered."""
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message=r"More chains \(\d+\) than draws", category=UserWarning)
        yield


def flight_entries(problem: Problem) -> list[tuple[str, int, str, int]]:
    """Every per-flight quantity as (posterior.nc variable, flight index, "theta" | "sigma", index).

    Initial conditions and a flight's own observation-model parameters (θ entries ``<var>_<flight>``) and its
    noise scales (``<var>_<flight>`` among :attr:`Problem.sigma_names`) become variables with a ``flight``
    dimension (NaN for flights that do not have them, e.g. ``x`` of a flight seen only by an inertial logger).
    """
    out = []
    for k, f in enumerate(problem.flights):
        s = problem.layout.flight_slice(k)
        cut = len(f.name) + 1
        out += [(n[:-cut], k, "theta", s.start + j) for j, n in enumerate(problem.names[s])]
        out += [(problem.sigma_names[g][:-cut], k, "sigma", int(g)) for g in problem.flight_groups(k)]
    return out


def flight_variables(problem: Problem) -> list[str]:
    """posterior.nc variables with a ``flight`` dimension, in order of first appearance."""
    return list(dict.fromkeys(v for v, *_ in flight_entries(problem)))


def structured_samples(problem: Problem, theta: np.ndarray, sigma: np.ndarray) -> dict:
    """Samples in the posterior.nc layout.

    Parameters
    ----------
    problem : Problem
        The run's model.
    theta : ndarray, shape (..., problem.dim)
        Parameter vectors in model order.
    sigma : ndarray, shape (..., problem.n_groups)
        Noise scale of each noise group (unit of its data).

    Returns
    -------
    dict
        ``{name: (...,)}`` for coefficients and shared parameters, ``{var: (..., n_flights)}`` for the
        per-flight quantities of :func:`flight_entries` (NaN where a flight has no such quantity).
    """
    scalar = problem.names[: problem.ic_start]
    clash = set(scalar) & set(flight_variables(problem))
    if clash:
        raise ValueError(f"parameter name(s) {sorted(clash)} clash with posterior.nc's per-flight variables")
    out = {n: theta[..., i] for i, n in enumerate(scalar)}
    shape = theta.shape[:-1] + (problem.n_flights,)
    for var in flight_variables(problem):
        out[var] = np.full(shape, np.nan)
    for var, k, kind, i in flight_entries(problem):
        out[var][..., k] = theta[..., i] if kind == "theta" else sigma[..., i]
    return out


def _locate(posterior: xr.Dataset, name: str) -> tuple[str, str | None]:
    """(variable, flight or None) holding the summary.json parameter ``name`` in ``posterior``."""
    if name in posterior.data_vars and "flight" not in posterior[name].dims:
        return name, None
    if "flight" in posterior.coords:
        for f in (str(f) for f in posterior["flight"].values):
            var = name[: -len(f) - 1]
            if name.endswith("_" + f) and var in posterior.data_vars and "flight" in posterior[var].dims:
                return var, f
    raise KeyError(f"posterior has no parameter {name!r}")


def posterior_draws(posterior: xr.Dataset, name: str) -> np.ndarray:
    """Samples of one summary.json parameter from a posterior group.

    Parameters
    ----------
    posterior : xarray.Dataset
        ``idata.posterior`` of a posterior.nc (the layout with a ``flight`` dimension, or the older one with
        one variable per flight parameter).
    name : str
        summary.json name: a coefficient (``CLa``), ``sigma_<flight>`` or an initial condition ``x_<flight>``.

    Returns
    -------
    ndarray, shape (n_chain, n_draw)
        The samples (units of the parameter; σ in m).

    Raises
    ------
    KeyError
        If the posterior holds no such parameter.
    """
    var, flight = _locate(posterior, name)
    x = posterior[var] if flight is None else posterior[var].sel(flight=flight)
    return np.asarray(x.transpose("chain", "draw").values)


def has_parameter(posterior: xr.Dataset, name: str) -> bool:
    """Whether :func:`posterior_draws` finds ``name`` in ``posterior``."""
    try:
        _locate(posterior, name)
    except KeyError:
        return False
    return True


def ensemble_view(posterior: xr.Dataset) -> xr.Dataset:
    """The posterior with the independent ensembles as chains (walkers pooled step by step).

    ``az.rhat(ensemble_view(idata.posterior))`` is summary.json's ``r_hat`` (the split halves are early and
    late steps). Needs the ``ensemble`` and ``walker`` coordinates of ``chain``.

    Parameters
    ----------
    posterior : xarray.Dataset
        ``idata.posterior`` with dims (chain, draw, ...), chain = walker.

    Returns
    -------
    xarray.Dataset
        Same variables with dims (chain, draw, ...): chain = ensemble, draw = step·n_walkers + walker.
    """
    if "ensemble" not in posterior.coords or "walker" not in posterior.coords:
        raise KeyError("posterior has no 'ensemble'/'walker' coordinates (posterior.nc from an older version)")
    ens = np.asarray(posterior["ensemble"].values, int)
    walker = np.asarray(posterior["walker"].values, int)
    n_ens, n_w = ens.max() + 1, walker.max() + 1
    if ens.size != n_ens * n_w or len(set(zip(ens, walker))) != ens.size:
        raise ValueError("chains do not form a full ensemble × walker grid")
    order = np.lexsort((walker, ens))
    n_draw = posterior.sizes["draw"]
    data = {}
    for v, da in posterior.data_vars.items():
        rest = [d for d in da.dims if d not in ("chain", "draw")]
        x = da.transpose("chain", "draw", *rest).values[order]
        x = x.reshape(n_ens, n_w, n_draw, *x.shape[2:]).swapaxes(1, 2).reshape(n_ens, n_draw * n_w, *x.shape[2:])
        data[v] = (("chain", "draw", *rest), x)
    coords = {d: posterior.coords[d] for d in posterior.dims if d not in ("chain", "draw") and d in posterior.coords}
    return xr.Dataset(data, coords={**coords, "chain": np.arange(n_ens), "draw": np.arange(n_draw * n_w)})


def summary_names(problem: Problem) -> list[str]:
    """summary.json parameter names in order: θ's (coefficients, extra terms, initial conditions), then σ."""
    return list(problem.names) + list(problem.sigma_names)


def _summary_block(post: xr.Dataset, by_ensemble: xr.Dataset, block: list[str]) -> dict:
    """:func:`summarize`'s records of the parameters ``block``."""
    x = np.stack([np.asarray(posterior_draws(post, n), float) for n in block])        # (p, walker, draw)
    diag = summary_diagnostics(x)
    rh = rhat(np.stack([np.asarray(posterior_draws(by_ensemble, n), float) for n in block]))
    params = {}
    for i, name in enumerate(block):
        values = x[i].reshape(-1)
        q025, q05, q50, q95, q975 = np.quantile(values, [0.025, 0.05, 0.5, 0.95, 0.975])
        params[name] = {"mean": float(values.mean()), "sd": float(values.std(ddof=1)), "q05": float(q05),
                        "q50": float(q50), "q95": float(q95), "q025": float(q025), "q975": float(q975),
                        "r_hat": float(rh[i]), "r_hat_walkers": float(diag["r_hat"][i]),
                        "ess_bulk": float(diag["ess_bulk"][i]), "ess_tail": float(diag["ess_tail"][i]),
                        "mcse_mean": float(diag["mcse_mean"][i]), "mcse_sd": float(diag["mcse_sd"][i])}
    return params


def summarize(idata, names, threads: int = 1) -> dict:
    """summary.json ``parameters`` records from posterior.nc's InferenceData.

    Parameters
    ----------
    idata : arviz.InferenceData
        Built by :func:`build_inference_data` (posterior with ``ensemble``/``walker`` chain coordinates).
    names : list of str
        summary.json parameter names (:func:`summary_names`).
    threads : int
        Blocks of :data:`SUMMARY_BLOCK` parameters computed at once (the sorts and FFTs release the GIL).

    Returns
    -------
    dict
        ``{name: {"mean", "sd", "q05", "q50", "q95", "q025", "q975", "r_hat", "r_hat_walkers", "ess_bulk",
        "ess_tail", "mcse_mean", "mcse_sd"}}`` in the parameter's unit (σ in m; ESS in samples). ``r_hat`` is
        across ensembles (``az.rhat(ensemble_view(idata.posterior))``); ``r_hat_walkers``, the ESS and the MCSE
        are ``az.summary(idata, kind="diagnostics")``'s (walkers as chains), computed for every parameter at
        once by :mod:`.mcmc_stats` (equal to ArviZ's; tests/test_diagnostics_mcmc.py, tests/test_results.py).
    """
    post = idata.posterior
    by_ensemble = ensemble_view(post)
    blocks = [list(names[j:j + SUMMARY_BLOCK]) for j in range(0, len(names), SUMMARY_BLOCK)]
    params = {}
    with warnings.catch_warnings():                        # (the filter is process-wide: set around the threads)
        warnings.simplefilter("ignore", RuntimeWarning)    # 0/0 of a constant parameter
        with ThreadPoolExecutor(max_workers=max(1, threads)) as pool:
            for part in pool.map(lambda b: _summary_block(post, by_ensemble, b), blocks):
                params.update(part)
    return params


def literature_table() -> dict:
    return {k: dict(s.values) for k, s in LITERATURE.items()}


def build_summary(problem: Problem, chains: Chains, idata, ls_dict: dict, cfg_info: dict, threads: int = 1) -> dict:
    """summary.json (SPEC §6) of a run: parameter records (:func:`summarize`, in ``threads`` threads),
    convergence, literature."""
    params = summarize(idata, summary_names(problem), threads)
    coef = list(COEFFICIENT_NAMES) + problem.ext_names
    tau = np.nanmax(chains.tau, axis=0)
    return {
        "parameters": params,
        "coefficients": coef,
        "literature": literature_table(),
        "prior": prior_record(problem.prior_name),
        "physics_terms": problem.model_ids,
        "convergence": {
            "converged": chains.converged, "reason": chains.reason, "ensembles": int(chains.chain.shape[0]),
            "walkers_per_ensemble": int(chains.chain.shape[2]), "total_steps": int(chains.total_steps),
            "burn_in_steps": int(chains.burn), "kept_steps": int(chains.chain.shape[1]),
            "tau_max_steps": float(np.nanmax(tau)),
            "tau_steps": {n: float(t) for n, t in zip(problem.names, tau)},
            "n_over_tau": float(chains.chain.shape[1] / np.nanmax(tau)),
            "r_hat_max": float(max(p["r_hat"] for p in params.values())),
            "r_hat_definition": "rank-normalised split R-hat across the independent ensembles (walkers pooled); "
                                "r_hat_walkers: the same statistic with every walker as a chain (az.summary)",
            "ess_bulk_min_coefficient": float(min(params[c]["ess_bulk"] for c in coef)),
            "acceptance_mean": float(np.mean(chains.acceptance)),
        },
        "least_squares": ls_dict,
        **cfg_info,
    }


# ---------------------------------------------------------------------------------------------- netCDF
def _thinned_steps(n_chain: int, n_steps: int, n_max: int) -> np.ndarray:
    """Evenly spaced kept-step indices so that n_chain × len ≤ n_max (at least one step)."""
    k = max(1, min(n_steps, n_max // max(n_chain, 1)))
    return np.unique(np.linspace(0, n_steps - 1, k).round().astype(int))


def _marker_flights(problem: Problem) -> list[tuple[int, object]]:
    """(flight index, marker model) of every flight with marker positions."""
    return [(k, c) for k, ch in enumerate(problem.channels) for c in ch if isinstance(c, MarkerPositions)]


def _inertial_flights(problem: Problem) -> list[tuple[int, object]]:
    """(flight index, inertial model) of every flight with an inertial logger."""
    return [(k, c) for k, ch in enumerate(problem.channels) for c in ch if isinstance(c, InertialMeasurements)]


def observation_points(problem: Problem) -> dict:
    """Coordinates of the observed marker points, flight by flight in time-major order.

    Returns
    -------
    dict
        ``point_flight`` (P,) str, ``point_time`` (P,) [s], ``point_marker`` (P,) str: the P observed
        (time, marker) pairs, the order of :func:`pointwise_log_likelihood`'s marker points.
    """
    fl, t, m = [], [np.zeros(0)], []
    for k, c in _marker_flights(problem):
        f = c.data
        ti, mi = np.nonzero(f.observed)
        fl += [f.name] * ti.size
        t.append(f.times[ti])
        m += [str(f.marker_ids[j]) for j in mi]
    return {"point_flight": np.array(fl, dtype=str), "point_time": np.concatenate(t),
            "point_marker": np.array(m, dtype=str)}


def inertial_points(problem: Problem) -> dict:
    """Coordinates of the observed inertial values (every finite gyro and accelerometer entry).

    Returns
    -------
    dict
        ``imu_point_flight`` (Q,) str, ``imu_point_row`` (Q,) int (logger row since release),
        ``imu_point_channel`` (Q,) str (gx … az): the order of the inertial log-likelihood's last axis.
    """
    fl, rows, ch = [], [np.zeros(0, int)], []
    for k, c in _inertial_flights(problem):
        r, j = np.nonzero(c._seen)
        fl += [c.flight] * r.size
        rows.append(c.row_offsets[r].astype(int))
        ch += [IMU_CHANNELS[i] for i in j]
    return {"imu_point_flight": np.array(fl, dtype=str), "imu_point_row": np.concatenate(rows),
            "imu_point_channel": np.array(ch, dtype=str)}


def pointwise_log_likelihood(problem: Problem, theta: np.ndarray, sigma: np.ndarray, inertial: bool = False):
    """Pointwise conditional log-likelihoods (σ given) and the noise-free predictions.

    Parameters
    ----------
    problem : Problem
        The run's model.
    theta : ndarray, shape (B, problem.dim)
        Posterior draws.
    sigma : ndarray, shape (B, problem.n_groups)
        Each draw's noise scales (drawn jointly with θ).
    inertial : bool
        Also return the inertial part.

    Returns
    -------
    log_lik : ndarray, shape (B, P)
        Log-density [log m⁻³] of each observed marker point (three coordinates; points as in
        :func:`observation_points`); summed over the points of flight f it is the conditional
        log-likelihood −(3 n_f/2) log(2πσ_f²) − S_f/(2σ_f²) (+ log |W_f| for a shaped or correlated noise
        unit: each point's density given the flight's earlier points, from its whitened residual e and
        W's diagonal, :mod:`bayes_disc.observation.models.noise`).
    markers : list of ndarray, shape (B, n_times_f, n_markers, 3)
        Simulated markers [m] of every marker flight (at every sample time, also where unobserved).
    imu_log_lik : ndarray, shape (B, Q)
        (``inertial`` only) log N(y | ŷ(θ), σ_g²) of every observed inertial value (:func:`inertial_points`).
    imu : list of ndarray, shape (B, n_rows_f, 6)
        (``inertial`` only) predicted gyro [rad/s] and accelerometer [m/s²] of every inertial flight.

    Raises
    ------
    RuntimeError
        If a posterior draw's simulation fails (it had a finite posterior density when it was sampled).
    """
    theta = np.atleast_2d(theta)
    out, sims, imu_out, imu_sims = [], [], [], []
    wanted = {k for k, _ in _marker_flights(problem)} | ({k for k, _ in _inertial_flights(problem)} if inertial else set())
    for k in sorted(wanted):
        preds = [problem.channel_predictions(theta[i: i + BATCH], k)[0] for i in range(0, theta.shape[0], BATCH)]
        cols = problem.channel_columns(k)
        for j, (c, g) in enumerate(zip(problem.channels[k], problem.channel_groups(k))):
            pred = np.concatenate([p[j][1] for p in preds])
            extra = theta[:, cols[j]] if cols[j].size else None
            r = c.whiten(c.residuals(pred), extra)
            if not np.all(np.isfinite(r)):
                raise RuntimeError(f"flight {problem.flights[k].name}: a posterior draw no longer simulates")
            s2 = sigma[:, g][:, c.group_index] ** 2                          # (B, n_res)
            ll = -0.5 * np.log(2 * np.pi * s2) - 0.5 * r * r / s2
            log_diag = c.log_diagonal(extra)
            if log_diag is not None:
                ll = ll + log_diag
            if isinstance(c, MarkerPositions):
                out.append(ll.reshape(ll.shape[0], -1, 3).sum(axis=2))
                sims.append(pred)
            elif inertial:
                imu_out.append(ll)
                imu_sims.append(pred)
    marker_ll = np.concatenate(out, axis=1) if out else np.zeros((theta.shape[0], 0))
    if not inertial:
        return marker_ll, sims
    return marker_ll, sims, (np.concatenate(imu_out, axis=1) if imu_out else np.zeros((theta.shape[0], 0))), imu_sims


def build_inference_data(problem: Problem, chains: Chains, rng: np.random.Generator, n_prior: int = 4000,
                         n_log_likelihood: int = N_LOG_LIKELIHOOD_DRAWS, n_predictive: int = N_PREDICTIVE_DRAWS):
    """posterior.nc of a run (layout in this module's docstring).

    Parameters
    ----------
    problem : Problem
        The run's model.
    chains : Chains
        Kept samples, (n_ensembles, n_steps, n_walkers, ·).
    rng : numpy.random.Generator
        For the prior draws and the predictive noise.
    n_prior : int
        Prior draws.
    n_log_likelihood, n_predictive : int
        Most chain × draw samples in the ``log_likelihood`` and ``posterior_predictive`` groups (every
        walker, evenly spaced kept steps; re-simulated).

    Returns
    -------
    arviz.InferenceData
    """
    n_ens, n_steps, n_w, dim = chains.chain.shape
    n_chain = n_ens * n_w
    per_walker = np.moveaxis(chains.chain, 2, 1).reshape(n_chain, n_steps, dim)
    sig = np.moveaxis(chains.sigma, 2, 1).reshape(n_chain, n_steps, -1)
    lp = np.moveaxis(chains.log_prob, 2, 1).reshape(n_chain, n_steps)
    flights = [f.name for f in problem.flights]
    fvars = flight_variables(problem)
    flight_dims = {n: ["flight"] for n in fvars}
    # the improper 1/σ prior is shown on [nominal/200, 50·nominal] (log-uniform; markers: 10 µm … 10 cm)
    lo, hi = np.log(problem.nominal_noise / 200), np.log(problem.nominal_noise * 50)
    prior_sigma = np.exp(lo + (hi - lo) * rng.uniform(size=(1, n_prior, problem.n_groups)))
    prior = structured_samples(problem, problem.sample_prior(n_prior, rng)[None], prior_sigma)
    marker_flights, imu_flights = _marker_flights(problem), _inertial_flights(problem)
    observed, obs_coords, obs_dims = {}, {}, {}
    for k, c in marker_flights:
        f = c.data
        key = f"markers_{f.name}"
        observed[key] = f.positions
        obs_coords[f"time_{f.name}"] = f.times
        obs_dims[key] = [f"time_{f.name}", "marker", "axis"]
    if marker_flights:
        obs_coords.update(marker=[str(m) for m in problem.marker_ids], axis=["x", "y", "z"])
    for k, c in imu_flights:
        key = f"imu_{c.flight}"
        observed[key] = np.concatenate([c.log.gyro, c.log.acc], axis=1)
        obs_coords[f"row_{c.flight}"] = c.row_offsets.astype(int)
        obs_dims[key] = [f"row_{c.flight}", "imu_channel"]
    if imu_flights:
        obs_coords["imu_channel"] = list(IMU_CHANNELS)
    # thinned draws: pointwise log-likelihood and posterior predictive from one simulation
    ll_steps = _thinned_steps(n_chain, n_steps, n_log_likelihood)
    pp_steps = ll_steps[_thinned_steps(n_chain, ll_steps.size, n_predictive)]
    th = per_walker[:, ll_steps].reshape(-1, dim)
    sg = sig[:, ll_steps].reshape(-1, problem.n_groups)
    log_lik, sims, imu_ll, imu_sims = pointwise_log_likelihood(problem, th, sg, inertial=True)
    keep = np.isin(ll_steps, pp_steps)
    sg_pp = sig[:, pp_steps]                                                  # (n_chain, n_pp, n_groups)
    predictive = {}
    for (k, c), m in zip(marker_flights, sims):
        m = m.reshape(n_chain, ll_steps.size, *m.shape[1:])[:, keep]
        j = problem.channels[k].index(c)
        g = problem.channel_groups(k)[j].start
        if c.noise.white:
            s = sg_pp[..., g][..., None, None, None]
            noise = s * rng.standard_normal(m.shape)
        else:                                   # shaped or correlated noise: the unit draws it
            cols = problem.channel_columns(k)[j]
            extra = per_walker[:, pp_steps][..., cols].reshape(-1, cols.size) if cols.size else None
            noise = c.sample_noise(sg_pp[..., g].reshape(-1), extra, rng).reshape(m.shape)
        predictive[f"markers_{c.flight}"] = (m + noise).astype(np.float32)
    for (k, c), m in zip(imu_flights, imu_sims):
        m = m.reshape(n_chain, ll_steps.size, *m.shape[1:])[:, keep]
        g = problem.channel_groups(k)[problem.channels[k].index(c)]
        per_channel = np.array([1, 1, 0, 3, 3, 2])                           # noise group of gx … az
        s = sg_pp[..., g][..., per_channel][:, :, None, :]
        predictive[f"imu_{c.flight}"] = (m + s * rng.standard_normal(m.shape)).astype(np.float32)
    ll_vars, ll_coords = {}, {"chain": np.arange(n_chain), "draw": ll_steps}
    if marker_flights:
        ll_vars["markers"] = (("chain", "draw", "point"), log_lik.reshape(n_chain, ll_steps.size, -1).astype(np.float32))
        ll_coords.update(point=np.arange(log_lik.shape[1]), **{c: ("point", v) for c, v in observation_points(problem).items()})
    if imu_flights:
        ll_vars["imu"] = (("chain", "draw", "imu_point"), imu_ll.reshape(n_chain, ll_steps.size, -1).astype(np.float32))
        ll_coords.update(imu_point=np.arange(imu_ll.shape[1]),
                         **{c: ("imu_point", v) for c, v in inertial_points(problem).items()})
    with _walkers_as_chains():
        idata = az.from_dict(
            posterior=structured_samples(problem, per_walker, sig), sample_stats={"lp": lp},
            prior=prior, observed_data=observed,
            coords={**obs_coords, "flight": flights},
            dims={**flight_dims, **obs_dims})
        idata.add_groups(
            log_likelihood=xr.Dataset(ll_vars, coords=ll_coords),
            posterior_predictive=xr.Dataset(
                {k: (("chain", "draw", *obs_dims[k]), v) for k, v in predictive.items()},
                coords={"chain": np.arange(n_chain), "draw": pp_steps, **obs_coords}))
    ens_coords = {"ensemble": ("chain", np.repeat(np.arange(n_ens), n_w)),
                  "walker": ("chain", np.tile(np.arange(n_w), n_ens))}
    for group in ("posterior", "sample_stats", "log_likelihood", "posterior_predictive"):
        idata[group] = idata[group].assign_coords(ens_coords)
    units = {}
    for var, k, kind, i in flight_entries(problem):
        units.setdefault(var, problem.layout.units[i] if kind == "theta" else problem.noise_units[i])
    for n, unit in units.items():
        idata.posterior[n].attrs["units"] = unit
        idata.prior[n].attrs["units"] = unit
    idata.posterior.attrs["chain_layout"] = (f"every emcee walker is a chain: chain c is walker walker[c] of the "
                                             f"independent ensemble ensemble[c] ({n_ens} ensembles × {n_w} walkers)")
    idata.posterior.attrs["r_hat"] = (
        "summary.json r_hat: rank-normalised split R-hat across ensembles (walkers pooled step by step), "
        "= az.rhat(bayes_disc.inference.results.ensemble_view(idata.posterior)); az.summary(idata) treats "
        "each walker as a chain and gives summary.json's r_hat_walkers")
    idata.log_likelihood.attrs["observation"] = (
        "markers: one observed marker point (its x, y, z at one time): log N(y | m(theta), sigma_f^2 I3) with the "
        "draw's own sigma_f (with per-point errors or AR(1) noise: the point's density given the flight's earlier "
        "points, log N(e | 0, sigma_f^2 I3) + log|diag W|, e the whitened residual); imu: one gyro or accelerometer value, log N(y | yhat(theta), sigma_g^2); every "
        "walker, evenly spaced kept steps (draw = kept step index)")
    idata.posterior_predictive.attrs["content"] = ("simulated observations + Gaussian noise with the draw's noise "
                                                   "scales (and the flight's noise model: per-point shapes, AR(1)), every walker, evenly spaced kept steps (draw = kept step "
                                                   "index)")
    return idata


#: HDF5 filters of posterior.nc's numeric variables: zlib at level 1 after byte shuffling. The demo's
#: 500-step run: 35 MB written in 3.4 s, against 37 MB in 8.0 s by ``InferenceData.to_netcdf`` (zlib level 4,
#: no shuffle, and the groups ArviZ lists twice written twice); medians of 3 on a shared 2-core machine.
NETCDF_FILTERS = {"zlib": True, "complevel": 1, "shuffle": True}


def write_posterior(idata: az.InferenceData, path) -> None:
    """Write ``idata`` as ``posterior.nc``: ``az.InferenceData.to_netcdf``'s layout (root attributes, then
    one netCDF group per InferenceData group, engine h5netcdf), with :data:`NETCDF_FILTERS` on every numeric
    variable; ``az.from_netcdf`` reads it as any ArviZ file.

    Parameters
    ----------
    idata : arviz.InferenceData
        The run's InferenceData (:func:`build_inference_data`).
    path : str or Path
        File to (over)write.
    """
    mode = "w"
    if idata.attrs:
        xr.Dataset(attrs=idata.attrs).to_netcdf(str(path), mode=mode, engine="h5netcdf", group="/")
        mode = "a"
    for group in dict.fromkeys(idata.groups()):     # ArviZ lists a group twice once it has been extended
        data = getattr(idata, group)
        encoding = {name: dict(NETCDF_FILTERS) for name, v in data.variables.items() if v.dtype.kind in "biufc"}
        data.to_netcdf(str(path), mode=mode, group=group, engine="h5netcdf", encoding=encoding)
        mode = "a"


@contextlib.contextmanager
def writing_posterior(idata: az.InferenceData, path, background: bool):
    """Write ``posterior.nc`` (:func:`write_posterior`) while the body of the ``with`` runs: in a child process
    when ``background`` (compressing the file takes seconds that the summary can use on another core), else
    here before the body. Leaving the block waits for the file.

    Parameters
    ----------
    idata : arviz.InferenceData
    path : str or Path
    background : bool
        Write in a child process (:func:`~bayes_disc.physics.parallel.mp_context`); False where no child
        may be started (``processes: 1``, e.g. a run inside a Dask worker).

    Raises
    ------
    RuntimeError
        If the child process failed (its traceback is on stderr); an error of the body takes precedence.
    """
    if not background:
        write_posterior(idata, path)
        yield
        return
    child = mp_context().Process(target=write_posterior, args=(idata, str(path)), name="posterior.nc writer")
    child.start()
    try:
        yield
    finally:
        child.join()
    if child.exitcode != 0:
        raise RuntimeError(f"{path}: writing the posterior failed in its child process (exit code {child.exitcode})")


def load_posterior(path, groups: tuple[str, ...] | None = None) -> az.InferenceData:
    """Read a posterior.nc into memory (the file is closed afterwards, so a later run can rewrite it).

    Parameters
    ----------
    path : str or Path
        A posterior.nc written by ``bayes-disc sample``.
    groups : tuple of str, optional
        Read only these groups (those the file has; the report needs ``posterior`` and ``sample_stats``, a
        third of the demo's file); default every group, as ``az.from_netcdf``.

    Returns
    -------
    arviz.InferenceData
    """
    if groups is None:
        with az.rc_context({"data.load": "eager"}):
            return az.from_netcdf(str(path))
    with h5py.File(str(path), "r") as f:
        present = [g for g in groups if g in f]
    data = {}
    for g in present:
        with xr.open_dataset(str(path), group=g, engine="h5netcdf") as ds:
            data[g] = ds.load()
    return az.InferenceData(**data)


def run_label(run_dir) -> str:
    """A run's label in comparisons: its folder's name, or its parent folder's name for a folder called ``out``.

    Parameters
    ----------
    run_dir : str or Path

    Returns
    -------
    str
    """
    run_dir = Path(run_dir)
    return run_dir.parent.name if run_dir.name == "out" else run_dir.name


def compare_runs(run_dirs):
    """PSIS-LOO comparison of sampled runs of the same observations (``az.compare``).

    Parameters
    ----------
    run_dirs : sequence of str or Path, or dict {label: path}
        Output folders of ``bayes-disc sample`` (each with a posterior.nc that has a ``log_likelihood``
        group); labels default to the folder's run name (its parent folder's name for ``out``).

    Returns
    -------
    pandas.DataFrame
        ``az.compare``'s table, best model first: ``elpd_loo`` (log density, sum over observed marker
        points), ``p_loo``, ``elpd_diff``, ``weight``, ``se``, ``dse``, ``warning``; and ``pareto_k_high``,
        the number of points whose Pareto k̂ exceeds ArviZ's threshold min(1 − 1/log10 S, 0.7) for S draws
        (their PSIS-LOO values are unreliable).

    Notes
    -----
    With AR(1) noise a point's log-likelihood is its density given the flight's earlier points (see
    :func:`pointwise_log_likelihood`), so its "leave-one-out" value leaves out that conditional term; the
    sum over a flight is still the joint log-likelihood, and runs of the same points stay comparable.

    Raises
    ------
    ValueError
        If fewer than two runs are given, a posterior.nc lacks the ``log_likelihood`` group, or the runs'
        observed marker points differ (their LOO values would not be comparable).
    """
    items = dict(run_dirs) if isinstance(run_dirs, dict) else {run_label(d): d for d in run_dirs}
    if len(items) < 2:
        raise ValueError("compare_runs needs at least two runs (distinct labels)")
    data, ref = {}, None
    for label, d in items.items():
        path = Path(d) / "posterior.nc"
        idata = load_posterior(path)
        if "log_likelihood" not in idata.groups():
            raise ValueError(f"{path}: no log_likelihood group (written before pointwise log-likelihoods; re-run "
                             "`bayes-disc sample`)")
        ll = idata.log_likelihood
        key = tuple(np.asarray(ll[c].values).tobytes() for c in ("point_flight", "point_time", "point_marker"))
        if ref is not None and key != ref[1]:
            raise ValueError(f"{path}: observed marker points differ from {ref[0]}'s: LOO is not comparable")
        ref = ref or (path, key)
        data[label] = idata
    with warnings.catch_warnings():
        # ArviZ warns of high Pareto k̂ per run (counted in the table instead) and pandas of ArviZ's own
        # use of a deprecated keyword
        warnings.filterwarnings("ignore", message="Estimated shape parameter of Pareto")
        warnings.filterwarnings("ignore", message="The inplace keyword")
        loos = {label: az.loo(idata, pointwise=True) for label, idata in data.items()}   # once per run
        table = az.compare(loos)
    table["pareto_k_high"] = [int(np.sum(np.asarray(loos[label].pareto_k) > loos[label].good_k))
                              for label in table.index]
    return table


def format_table(summary: dict) -> str:
    """Median, 90 % interval, R-hat and ESS beside the literature values."""
    lit = summary["literature"]
    rows = [f"{'parameter':<16}{'median':>11}{'q05':>11}{'q95':>11}{'R-hat':>8}{'ESS':>8}"
            f"{'P&C 2000':>10}{'H&H 2002':>10}"]
    names = summary["coefficients"] + [n for n in summary["parameters"] if n.startswith("sigma_")]
    for n in names:
        p = summary["parameters"][n]
        pc = lit["potts_crowther"].get(n)
        hh = lit["hummel2002"].get(n)
        inertial = n.startswith(("sigma_gyro_", "sigma_acc_"))
        scale = 1e3 if n.startswith("sigma_") and not inertial else 1.0
        label = n + (" [mm]" if scale != 1 else " [rad/s]" if n.startswith("sigma_gyro_") else
                     " [m/s²]" if inertial else "")
        rows.append(f"{label:<16}{p['q50'] * scale:>11.4g}{p['q05'] * scale:>11.4g}{p['q95'] * scale:>11.4g}"
                    f"{p['r_hat']:>8.3f}{p['ess_bulk']:>8.0f}"
                    f"{'' if pc is None else format(pc, '.4g'):>10}{'' if hh is None else format(hh, '.4g'):>10}")
    return "\n".join(rows)
