"""Posterior summaries (SPEC §6 ``summary.json``), ArviZ InferenceData and the terminal table."""
from __future__ import annotations

import warnings

import arviz as az
import numpy as np

from ..physics import COEFFICIENT_NAMES, LITERATURE
from .diagnostics_mcmc import ess_bulk, rhat_across
from .model import Problem
from .priors import coefficient_prior
from .sampler import Chains


def public_samples(problem: Problem, theta: np.ndarray, sigma: np.ndarray) -> dict:
    """Samples θ (..., dim) and σ (..., n_flights) → {public name: values} (σ in m)."""
    out = {n: theta[..., i] for i, n in enumerate(problem.names)}
    out.update({n: sigma[..., k] for k, n in enumerate(problem.sigma_names)})
    return out


def summarize(problem: Problem, chains: Chains) -> dict:
    post = np.concatenate([chains.chain, chains.sigma], axis=-1)
    rh = rhat_across(post)
    ess = ess_bulk(post)
    flat = post.reshape(-1, post.shape[-1])
    params = {}
    samples = public_samples(problem, flat[:, : problem.dim], flat[:, problem.dim:])
    for i, (name, values) in enumerate(samples.items()):
        q05, q50, q95 = np.quantile(values, [0.05, 0.5, 0.95])
        q025, q975 = np.quantile(values, [0.025, 0.975])
        params[name] = {"mean": float(values.mean()), "sd": float(values.std(ddof=1)), "q05": float(q05),
                        "q50": float(q50), "q95": float(q95), "q025": float(q025), "q975": float(q975),
                        "r_hat": float(rh[i]), "ess_bulk": float(ess[i])}
    return params


def literature_table() -> dict:
    return {k: dict(s.values) for k, s in LITERATURE.items()}


def build_summary(problem: Problem, chains: Chains, ls_dict: dict, cfg_info: dict) -> dict:
    params = summarize(problem, chains)
    coef = list(COEFFICIENT_NAMES) + problem.ext_names
    tau = np.nanmax(chains.tau, axis=0)
    return {
        "parameters": params,
        "coefficients": coef,
        "literature": literature_table(),
        "prior": {"name": problem.prior_name, "description": coefficient_prior(problem.prior_name).description},
        "physics_terms": problem.model_ids,
        "convergence": {
            "converged": chains.converged, "reason": chains.reason, "ensembles": int(chains.chain.shape[0]),
            "walkers_per_ensemble": int(chains.chain.shape[2]), "total_steps": int(chains.total_steps),
            "burn_in_steps": int(chains.burn), "kept_steps": int(chains.chain.shape[1]),
            "tau_max_steps": float(np.nanmax(tau)),
            "tau_steps": {n: float(t) for n, t in zip(problem.names, tau)},
            "n_over_tau": float(chains.chain.shape[1] / np.nanmax(tau)),
            "r_hat_max": float(max(p["r_hat"] for p in params.values())),
            "ess_bulk_min_coefficient": float(min(params[c]["ess_bulk"] for c in coef)),
            "acceptance_mean": float(np.mean(chains.acceptance)),
        },
        "least_squares": ls_dict,
        **cfg_info,
    }


def build_inference_data(problem: Problem, chains: Chains, rng: np.random.Generator, n_prior: int = 4000):
    n_ens, n_steps, n_w, dim = chains.chain.shape
    per_walker = np.moveaxis(chains.chain, 2, 1).reshape(n_ens * n_w, n_steps, dim)
    sig = np.moveaxis(chains.sigma, 2, 1).reshape(n_ens * n_w, n_steps, -1)
    posterior = public_samples(problem, per_walker, sig)
    lp = np.moveaxis(chains.log_prob, 2, 1).reshape(n_ens * n_w, n_steps)
    # prior on σ_f is the improper 1/σ; the prior group shows it on [10 µm, 10 cm] (log-uniform)
    prior_sigma = np.exp(rng.uniform(np.log(1e-5), np.log(0.1), size=(1, n_prior, problem.n_flights)))
    prior = public_samples(problem, problem.sample_prior(n_prior, rng)[None], prior_sigma)
    observed, coords, dims = {}, {}, {}
    for f in problem.flights:
        key = f"markers_{f.name}"
        observed[key] = f.positions
        coords[f"time_{f.name}"] = f.times
        dims[key] = [f"time_{f.name}", "marker", "axis"]
    coords.update(marker=list(problem.flights[0].marker_ids), axis=["x", "y", "z"])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # short runs: "more chains than draws" is fine
        idata = az.from_dict(posterior=posterior, sample_stats={"lp": lp}, prior=prior, observed_data=observed,
                             coords=coords, dims=dims)
    idata.posterior.attrs["ensemble_of_chain"] = np.repeat(np.arange(n_ens), n_w).tolist()
    idata.posterior.attrs["note"] = ("chains are emcee walkers; walker w of ensemble e is chain e*n_walkers+w; "
                                     "R-hat in summary.json is computed across ensembles")
    return idata


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
        scale = 1e3 if n.startswith("sigma_") else 1.0
        label = n + (" [mm]" if scale != 1 else "")
        rows.append(f"{label:<16}{p['q50'] * scale:>11.4g}{p['q05'] * scale:>11.4g}{p['q95'] * scale:>11.4g}"
                    f"{p['r_hat']:>8.3f}{p['ess_bulk']:>8.0f}"
                    f"{'' if pc is None else format(pc, '.4g'):>10}{'' if hh is None else format(hh, '.4g'):>10}")
    return "\n".join(rows)
