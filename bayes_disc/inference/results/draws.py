"""Posterior draws in InferenceData form: every parameter as a variable (a ``flight`` dimension for each flight's
initial conditions and noise scale), read back by summary.json's flat names (``x_<flight>``, ``sigma_<flight>``),
the walkers as chains and the ensembles' view for R-hat across ensembles.
"""
from __future__ import annotations

import contextlib
import warnings

import numpy as np
import xarray as xr

from ..model.layout import IC_NAMES
from ..model.problem import Problem
from ..model.priors import coefficient_prior


#: posterior.nc variables with a ``flight`` dimension for marker runs: the initial conditions and σ [m]
FLIGHT_VARIABLES = IC_NAMES + ("sigma",)


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
