"""Posterior summaries (``summary.json``, docs/outputs.md) and the terminal table.

R-hat: ``summary.json``'s ``r_hat`` is the rank-normalised split R-hat with the independent *ensembles* as
chains (walkers of an ensemble pooled step by step: the sampler's stopping rule), i.e.
``az.rhat(ensemble_view(idata))``. ``az.summary(idata)`` treats every *walker* as a chain and reports that
walker-level R-hat, which summary.json records as ``r_hat_walkers``; ``ess_bulk``, ``ess_tail``,
``mcse_mean`` and ``mcse_sd`` in summary.json are ``az.summary(idata)``'s, computed for every parameter at once
by :func:`.mcmc_stats.summary_diagnostics` (ArviZ loops over the parameters through xarray).
"""
from __future__ import annotations

import warnings
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import xarray as xr

from ...physics import COEFFICIENT_NAMES, LITERATURE
from ..sampling.mcmc_stats import rhat, summary_diagnostics
from ..model.problem import Problem
from ..sampling.chains import Chains
from .draws import ensemble_view, posterior_draws, prior_record


#: parameters summarised together (bounds the temporaries of the diagnostics: ~10 copies of the block's draws)
SUMMARY_BLOCK = 16


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
        once by :mod:`bayes_disc.inference.sampling.mcmc_stats` (equal to ArviZ's; tests/test_mcmc_stats.py, tests/test_results.py).
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


def move_records(counts: dict) -> dict:
    """summary.json's ``convergence.moves``: every move's share of the proposals, its proposals (one per walker)
    and the share of them accepted, after the warm-up; from {label: [share, proposed, accepted]}."""
    return {label: {"share": round(float(share), 4), "proposals": int(n),
                    "acceptance": float(a / n) if n else None}
            for label, (share, n, a) in counts.items()}


#: a move accepted less often than this after the warm-up has stalled: its proposals do not fit the posterior
STALLED_ACCEPTANCE = 0.01
#: ... counted when it has at least this share of the proposals
STALLED_SHARE = 0.05


def stalled_moves(moves: dict) -> list[str]:
    """The moves of ``convergence.moves`` (:func:`move_records`) with a share of at least
    :data:`STALLED_SHARE` accepted less than :data:`STALLED_ACCEPTANCE` of the time: their proposals (a
    Gaussian or ridge approximation of the posterior) do not fit it, and the walkers moved by the others."""
    return [label for label, m in moves.items() if m["share"] >= STALLED_SHARE and m["proposals"]
            and m["acceptance"] is not None and m["acceptance"] < STALLED_ACCEPTANCE]


def mean_draw_gap(problem: Problem, chains: Chains) -> float | None:
    """How far the log-posterior at the draws' mean lies below that of the median draw [nats]: about −dim/2
    for a Gaussian posterior (its mean is its mode), positive when the posterior is curved — a bent ridge
    whose mean lies off it, where a Gaussian approximation of the draws puts its centre. None when the
    model cannot be evaluated at the mean."""
    mean = chains.chain.reshape(-1, problem.dim).mean(axis=0)
    at_mean = float(problem.log_prob(mean[None])[0])
    return float(np.median(chains.log_prob) - at_mean) if np.isfinite(at_mean) else None


def build_summary(problem: Problem, chains: Chains, idata, ls_dict: dict, cfg_info: dict, threads: int = 1) -> dict:
    """summary.json (docs/outputs.md) of a run: parameter records (:func:`summarize`, in ``threads`` threads),
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
            "moves": move_records(chains.moves),
            "log_prob_gap_at_mean": mean_draw_gap(problem, chains), "dimension": int(problem.dim),
        },
        "least_squares": ls_dict,
        **cfg_info,
    }


def format_table(summary: dict) -> str:
    """Median, 90 % credible interval, the profile 90 % interval (runs that record it), R-hat and ESS beside the
    literature values."""
    lit = summary["literature"]
    profile = summary.get("profile_intervals") or {}
    rows = [f"{'parameter':<16}{'median':>11}{'q05':>11}{'q95':>11}"
            + (f"{'profile q05':>13}{'profile q95':>13}" if profile else "")
            + f"{'R-hat':>8}{'ESS':>8}{'P&C 2000':>10}{'H&H 2002':>10}"]
    names = summary["coefficients"] + [n for n in summary["parameters"] if n.startswith("sigma_")]
    for n in names:
        p = summary["parameters"][n]
        pc = lit["potts_crowther"].get(n)
        hh = lit["hummel2002"].get(n)
        inertial = n.startswith(("sigma_gyro_", "sigma_acc_"))
        scale = 1e3 if n.startswith("sigma_") and not inertial else 1.0
        label = n + (" [mm]" if scale != 1 else " [rad/s]" if n.startswith("sigma_gyro_") else
                     " [m/s²]" if inertial else "")
        pi = profile.get(n)
        rows.append(f"{label:<16}{p['q50'] * scale:>11.4g}{p['q05'] * scale:>11.4g}{p['q95'] * scale:>11.4g}"
                    + ((f"{pi['q05']:>13.4g}{pi['q95']:>13.4g}" if pi else " " * 26) if profile else "")
                    + f"{p['r_hat']:>8.3f}{p['ess_bulk']:>8.0f}"
                    f"{'' if pc is None else format(pc, '.4g'):>10}{'' if hh is None else format(hh, '.4g'):>10}")
    return "\n".join(rows)
