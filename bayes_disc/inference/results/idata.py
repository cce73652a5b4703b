"""ArviZ InferenceData of a run (``posterior.nc``): posterior, sample statistics, pointwise log-likelihood,
posterior predictive, prior and observed data.

Layout of ``posterior.nc`` (ArviZ InferenceData; :func:`build_inference_data`):

* ``posterior``: dims ``chain`` × ``draw``; every emcee walker is one chain (``chain`` has the non-index
  coordinates ``ensemble`` and ``walker``: chain ``c`` is walker ``walker[c]`` of the independent ensemble
  ``ensemble[c]``), ``draw`` is the kept step after burn-in. Coefficients and extra-term parameters are
  scalar variables (``CLa``, ``CY`` …); each flight's initial conditions (``x y z vx vy vz th1 th2 th3 wx wy
  wz``, units in their ``units`` attribute) and noise scale ``sigma`` [m] have a ``flight`` dimension.
  summary.json keeps the flat names of docs/outputs.md: ``x_<flight>`` is ``posterior["x"].sel(flight=<flight>)``,
  ``sigma_<flight>`` is ``posterior["sigma"].sel(flight=<flight>)`` (:func:`posterior_draws` reads either).
* ``sample_stats``: ``lp``, the log-posterior of θ (σ integrated out) of every sample.
* ``log_likelihood``: ``markers`` (chain, draw, point), pointwise log-likelihood of every observed marker
  point (the three coordinates of one marker at one sample time form one observation) for a thinned set of
  draws, ``log N(y | m(θ), σ_f² I₃)`` with the draw's own σ_f; ``point`` carries ``point_flight``,
  ``point_time`` and ``point_marker`` coordinates. ``az.loo(idata)`` / ``az.compare`` use it.
* ``posterior_predictive``: ``markers_<flight>`` (chain, draw, time, marker, axis) [m], simulated markers
  plus N(0, σ_f²) noise for a thinned set of draws, dims as ``observed_data``.
* ``prior``, ``observed_data`` (``markers_<flight>``, NaN where a marker was not seen).
"""
from __future__ import annotations

import arviz as az
import numpy as np
import xarray as xr

from ...observation.models import MarkerPositions
from ...observation.models.inertial import InertialMeasurements
from ..model.problem import Problem
from ..sampling.chains import Chains
from .draws import _walkers_as_chains, flight_entries, flight_variables, structured_samples


#: the inertial channels, in the order of the models' predictions (a throw may have a subset)
IMU_CHANNELS = ("gx", "gy", "gz", "ax", "ay", "az", "mx", "my", "mz", "baro")
#: the channel label of each inertial series name
IMU_LABEL = {"gyro_x": "gx", "gyro_y": "gy", "gyro_z": "gz", "acc_x": "ax", "acc_y": "ay", "acc_z": "az",
             "mag_x": "mx", "mag_y": "my", "mag_z": "mz", "baro": "baro"}
#: most (chain × draw) samples in the ``log_likelihood`` group (float32; ~4000 draws × ~1300 points: ~21 MB)
N_LOG_LIKELIHOOD_DRAWS = 4000
#: most (chain × draw) samples in the ``posterior_predictive`` group (float32; demo: ~16 MB)
N_PREDICTIVE_DRAWS = 1000
#: simulated in one batch when computing the pointwise log-likelihood
BATCH = 500


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


def _place_channels(x: np.ndarray, names, used: list) -> np.ndarray:
    """x (..., c) of series ``names`` spread over the run's channels ``used`` (labels), NaN where a throw has
    none (a throw without the magnetometer or barometer among throws with them)."""
    out = np.full(x.shape[:-1] + (len(used),), np.nan, dtype=x.dtype)
    for j, name in enumerate(names):
        out[..., used.index(IMU_LABEL[name])] = x[..., j]
    return out


def _used_channels(models) -> list:
    """The channel labels any of the inertial ``models`` predicts, in :data:`IMU_CHANNELS` order."""
    have = {IMU_LABEL[n] for c in models for n in c.series_names}
    return [ch for ch in IMU_CHANNELS if ch in have]


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
        ch += [IMU_LABEL[c.series_names[i]] for i in j]
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

    Long: one pass over the groups in the order they draw from ``rng`` (prior, predictive noise), which fixes
    the file's numbers.

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
    used = _used_channels(c for _, c in imu_flights)          # channels: NaN where a throw has fewer
    for k, c in imu_flights:
        key = f"imu_{c.flight}"
        observed[key] = _place_channels(c.measured, c.series_names, used)
        obs_coords[f"row_{c.flight}"] = c.row_offsets.astype(int)
        obs_dims[key] = [f"row_{c.flight}", "imu_channel"]
    if imu_flights:
        obs_coords["imu_channel"] = used
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
        per_channel = np.array(c.series_groups)                             # noise group of gx … (mz)
        s = sg_pp[..., g][..., per_channel][:, :, None, :]
        predictive[f"imu_{c.flight}"] = _place_channels(m + s * rng.standard_normal(m.shape), c.series_names,
                                                        used).astype(np.float32)
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
