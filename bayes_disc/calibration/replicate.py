"""One replicate of a calibration campaign: draw a truth, synthesise the flights, fit, rank the truth.

A replicate is a pure function of the campaign and its index (:func:`run_replicate`), so that it can run
as a Dask task on any worker: it works in a temporary folder of the worker's machine and returns its
record (a JSON-ready dict); the campaign (:mod:`.campaign`) writes the record where the campaign lives.
The fit is the ordinary sampling job (:func:`bayes_disc.api.sample`: least squares, then emcee) with the
campaign's run configuration, in the worker's process (``sampler.processes`` 1).
"""
from __future__ import annotations

import logging
import socket
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from ..observation.synth import SynthResult, SynthSpec, synthesize, write_synth
from ..physics import Coefficients
from .config import CalConfig, replicate_rng
from .stats import LEVELS, covers, sbc_rank, thinned_draws

logger = logging.getLogger(__name__)
#: posterior quantiles kept in a replicate record
QUANTILES = {"q05": 0.05, "q25": 0.25, "q50": 0.5, "q75": 0.75, "q95": 0.95}


def draw_truth(cal: CalConfig, rng: np.random.Generator) -> dict:
    """One truth θ̃: every coefficient independently N(values_k, sd_k²) (config.TruthSpec).

    Parameters
    ----------
    cal : CalConfig
    rng : numpy.random.Generator

    Returns
    -------
    dict
        Coefficient name → value (dimensionless; rate coefficients per rad/s).
    """
    t = cal.truth
    return {n: float(t.values[n] + t.sd[n] * rng.standard_normal()) for n in cal.names}


def jittered_flights(cal: CalConfig, rng: np.random.Generator) -> tuple:
    """The template's flights with every ``launch_jitter`` value moved by U(−h, h) (unset values stay unset)."""
    out = []
    for f in cal.template.flights:
        changes = {}
        for k, h in cal.launch_jitter.items():
            v = getattr(f, k)
            shift = rng.uniform(-h, h)
            if v is not None:
                changes[k] = float(v + shift)
        out.append(replace(f, **changes))
    return tuple(out)


def replicate_data(cal: CalConfig, index: int) -> tuple[SynthResult, dict, int, int]:
    """The synthetic data of replicate ``index`` (same every time: its own random stream).

    Parameters
    ----------
    cal : CalConfig
    index : int

    Returns
    -------
    result : SynthResult
    truth : dict
        The coefficients drawn.
    redraws : int
        Truths drawn again because a flight failed to simulate.
    sampler_seed : int
        Seed of this replicate's sampler.

    Raises
    ------
    ValueError
        If ``max_redraws`` + 1 truths in a row fail to simulate.
    """
    rng = replicate_rng(cal, index)
    sampler_seed = int(rng.integers(2 ** 20))        # the sampler seeds its ensembles with seed·1000 + e < 2³²
    last = None
    for attempt in range(cal.truth.max_redraws + 1):
        truth = draw_truth(cal, rng)
        flights = jittered_flights(cal, rng)
        spec: SynthSpec = replace(cal.template, name=f"{cal.name}_{index:05d}", flights=flights,
                                  coefficients=Coefficients.from_mapping(truth), seed=int(rng.integers(2 ** 31)))
        try:
            return synthesize(spec), truth, attempt, sampler_seed
        except ValueError as e:                 # a flight of this truth cannot be simulated: draw again
            last = e
    raise ValueError(f"replicate {index}: {cal.truth.max_redraws + 1} truths in a row failed to simulate "
                     f"(last: {last})")


def rank_record(truth: dict, chains: np.ndarray, names: list[str], tau: float, n_draws: int,
                rng: np.random.Generator) -> dict:
    """Ranks, coverage and posterior quantiles of one replicate.

    Parameters
    ----------
    truth : dict
        θ̃ per name.
    chains : ndarray, shape (n_chains, n_steps, n_names)
        Post-burn-in posterior samples.
    names : list of str
        The quantities, in the order of the last axis.
    tau : float
        Autocorrelation time [steps] for thinning.
    n_draws : int
        L draws for the ranks.
    rng : numpy.random.Generator

    Returns
    -------
    dict
        ``ranks`` {name: r ∈ 0…L}, ``covered`` {"50", "90": {name: bool}} (central intervals of all the
        samples), ``posterior`` {name: {mean, sd, q05 … q95}}, ``draws`` L, ``thinning_steps``.
    """
    thin = thinned_draws(chains, tau, n_draws, rng)
    flat = chains.reshape(-1, len(names))
    rec = {"draws": n_draws, "thinning_steps": max(1, int(np.ceil(tau))) if np.isfinite(tau) else None,
           "ranks": {n: sbc_rank(truth[n], thin[:, j]) for j, n in enumerate(names)},
           "covered": {str(int(100 * lv)): {n: covers(truth[n], flat[:, j], lv) for j, n in enumerate(names)}
                       for lv in LEVELS},
           "posterior": {}}
    for j, n in enumerate(names):
        q = np.quantile(flat[:, j], list(QUANTILES.values()))
        rec["posterior"][n] = {"mean": float(flat[:, j].mean()), "sd": float(flat[:, j].std(ddof=1)),
                               **{k: float(v) for k, v in zip(QUANTILES, q)}}
    return rec


def replicate_run(cal: CalConfig, result: SynthResult, sampler_seed: int) -> dict:
    """The run configuration (a mapping for :func:`bayes_disc.api.sample`) of one replicate: the campaign's
    run settings on the replicate's data written as ``markers.csv`` and ``truth.json`` beside it, results in
    ``run/``, the replicate's own sampler seed."""
    return {**cal.run, "name": result.truth["name"], "flights": [{"file": "markers.csv"}],
            "markers": dict(cal.template.markers), "truth": "truth.json", "output": "run",
            "sampler": {**cal.run.get("sampler", {}), "seed": sampler_seed}}


def replicate_problem(cal: CalConfig, index: int):
    """The statistical problem replicate ``index``'s fit builds (:func:`bayes_disc.inference.model.data.build_problem`
    on :func:`replicate_run`'s configuration), for checks that do not sample (benchmarks/bench_linear_sbc.py).
    The marker flights as the fit reads them, before any robust cleaning and
    without inertial logs; the configuration's file paths point into a temporary folder that is gone (use
    its settings only).

    Returns
    -------
    problem : Problem
    config : RunConfig
        The replicate's run configuration (least-squares and sampler settings).
    result : SynthResult
        Its synthetic data and their truth JSON.
    truth : dict
        The coefficients drawn, {name: value}.
    """
    from ..inference.model.config import config_from_mapping
    from ..inference.model.data import build_problem
    result, truth, _, sampler_seed = replicate_data(cal, index)
    with tempfile.TemporaryDirectory(prefix=f"bd-cal-{index:05d}-") as tmp:
        tmp = Path(tmp)
        write_synth(result, tmp / "markers.csv", tmp / "truth.json")
        cfg = config_from_mapping(replicate_run(cal, result, sampler_seed), tmp / "config.yaml")
        return build_problem(cfg), cfg, result, truth


#: sampler settings a replicate records (its run's, defaults included): the defaults may change between the
#: sessions of one resumed campaign
SAMPLER_RECORD = ("ensembles", "walkers", "independence_fraction", "block_fraction", "adapt_steps", "min_steps",
                  "check_every", "n_tau", "rhat", "ess", "max_steps")


def run_replicate(cal: CalConfig, index: int) -> dict:
    """Replicate ``index``: truth → synthetic flights → least squares + sampler → ranks and coverage.

    Parameters
    ----------
    cal : CalConfig
        The campaign.
    index : int
        Replicate number (0-based).

    Returns
    -------
    dict
        The replicate record (JSON-ready): ``index``, ``status`` "ok", ``truth`` {name: value}, the
        :func:`rank_record` keys, ``convergence`` (the run's), ``sampler`` (:data:`SAMPLER_RECORD`),
        ``noise`` ({flight: the marker noise model the run used, its ``noise_choice`` label}), ``redraws``,
        ``synth_seed``,
        ``sampler_seed``, ``host``, ``wall_time_s``; the defects injected (per flight, when any).
    """
    from ..api import sample
    from ..inference.results.draws import posterior_draws
    t0 = time.perf_counter()
    result, truth, redraws, sampler_seed = replicate_data(cal, index)
    with tempfile.TemporaryDirectory(prefix=f"bd-cal-{index:05d}-") as tmp:
        tmp = Path(tmp)
        write_synth(result, tmp / "markers.csv", tmp / "truth.json")
        res = sample(replicate_run(cal, result, sampler_seed), base_dir=tmp, progress=False)
        post = res.idata.posterior
        chains = np.stack([posterior_draws(post, n) for n in cal.names], axis=-1)
        conv = res.convergence
        sampler = res.raw["sampler_settings"]
        noise = {flight: r["label"] for flight, r in res.raw.get("noise_choice", {}).items()}
    rec = {"index": index, "status": "ok", "truth": truth,
           **rank_record(truth, chains, cal.names, float(conv["tau_max_steps"]), cal.draws,
                         np.random.default_rng([cal.seed, index, 1])),
           "convergence": {k: conv.get(k) for k in ("converged", "reason", "total_steps", "burn_in_steps",
                                                    "tau_max_steps", "r_hat_max", "ess_bulk_min_coefficient")},
           "sampler": {k: sampler[k] for k in SAMPLER_RECORD}, "noise": noise,
           "redraws": redraws, "synth_seed": int(result.truth["seed"]), "sampler_seed": sampler_seed,
           "host": socket.gethostname(), "wall_time_s": time.perf_counter() - t0}
    defects = {f: v["defects"] for f, v in result.truth["flights"].items() if "defects" in v}
    if defects:
        rec["defects"] = {f: {"outliers": len(d["outliers"]["points"]), "swapped_frames": len(d["swaps"]["frames"])}
                          for f, d in defects.items()}
    return rec


def replicate_task(cal: CalConfig, index: int) -> dict:
    """:func:`run_replicate` as a Dask task: a failure becomes a record (``status`` "failed", ``error``)
    instead of an exception, so that one bad replicate neither stops the campaign nor is retried forever."""
    t0 = time.perf_counter()
    try:
        return run_replicate(cal, index)
    except Exception as e:                          # recorded and reported, not swallowed
        logger.exception(f"replicate {index} failed")
        return {"index": index, "status": "failed", "error": f"{type(e).__name__}: {e}",
                "host": socket.gethostname(), "wall_time_s": time.perf_counter() - t0}
