"""``bayes-disc diagnose``: base fit, candidate ranking, refit with the accepted terms, diagnosis.json.

Writes into the run's output folder:

* ``diagnosis.json`` (docs/outputs.md): verdict, accepted effects ranked best first ({id, evidence (ΔBIC),
  estimate, where}, with ``status`` — ``explains`` or ``partially_explains`` — and ``share_explained``,
  the share of the base model's excess misfit the term removes with those before it), marker RMS per
  flight before/after [mm] (``rms_before_mm``, ``rms_after_mm``: the flights with markers); ``rms_before``/``rms_after``: every flight's RMS per recorded quantity
  ({flight: {markers|gyro|acc: {rms, unit}}}, as ``predict`` reports channels); plus every candidate's
  evidence, status and ``share_explained`` (:mod:`.missing_physics`), whiteness before/after, the shifted
  base coefficients, unexplained structure (each with the flight's height over its peak window,
  ``peak_height_m``), the noise floor the shares refer to (``noise_floor``: σ̂ per noise group from second
  differences), ``partial_explanation`` ({ids, share_explained, evidence} when the adopted terms only
  partly explain the data, else null), the candidates skipped (with the reason) and the diagnosis in words;
* ``wobble`` in ``diagnosis.json``: per inertial throw, the transverse gyro rates of the data and of the base
  fit split into nutation (κ × spin in the body), precession (fixed in space) and a part fixed in sensor
  axes, in sliding windows, compared in words (:mod:`.wobble`); null for a run without inertial throws;
* ``random_nutation`` in ``diagnosis.json``: whether the base fit's transverse gyro residuals are a randomly
  forced nutation (:mod:`.random_nutation`: its evidence, rate, decay and size per throw, and words); null for a
  run without inertial throws fitted with white gyro noise;
* ``learned_discrepancy`` in ``diagnosis.json``: when the base model leaves structure, a sparse correction
  in functions of height, α and spin learned without assuming a formula (:mod:`.discrepancy`): what it
  selected, whether it whitens the residuals, the flight variable and family it names, and its curve
  beside the fitted family's. It describes; it never changes the verdict or the effects;
* ``diagnosis_residuals.npz``: the residual series before and after (report figures): per flight k and
  series name ``{k}_before_{name}``, ``{k}_after_{name}``, ``{k}_se_{name}`` (noise standard error),
  ``{k}_times_{name}`` [s], and ``{k}_times`` (the flight's first observation model's times);
* ``diagnosis_refit/``: the resampled run with the accepted terms (unless ``sample=False``).

Correlated noise or missing physics? The marker noise of every ``auto`` flight is chosen at the base
model's least squares by :func:`bayes_disc.inference.fitting.noise_choice.choose_noise` — the call
``sample`` makes, so the two never disagree — but the candidate terms are first judged with white noise on
those flights: AR(1) noise with ρ → 1 would otherwise absorb the smooth misfit of missing physics. When that
diagnosis accepts no term and leaves structure in a flight with markers, and the evidence chose AR(1) (or
per-point) noise for some flight — ΔBIC_f = n_f ln(S̃_f,white / S̃_f,AR(1)) − ln n_f > 10 per flight, S̃ the
effective sums of squares of the whitened residuals — the candidates are judged again under the chosen
models (their evidence under them, whiteness of the AR(1) innovations), and ``diagnosis.json`` says so
under ``noise`` (``model``, ``rho`` per flight, ``evidence``, and ``choice``, the per-flight records):
"noise correlated, ρ = 0.85; no missing physics" when nothing is left, or the terms found under correlated
noise (:func:`correlated_noise`).

The ``diagnose`` job (:mod:`bayes_disc.jobs.diagnose`) runs :func:`analyse`, resamples with the accepted terms
(:func:`refit_config`), writes :func:`diagnosis_record` and rebuilds the report; this module knows nothing of
sampling runs or reports.
"""
from __future__ import annotations

import json
import logging
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from ..inference.model.config import RunConfig
from ..inference.model.data import build_problem, load_run_flights
from ..inference.model.inertial import load_run_throws
from ..inference.fitting.leastsq import fit_least_squares
from ..inference.fitting.noise_choice import NoiseChoice, choose_noise, run_settings
from ..observation.registry import PHYSICS_TERM, unit
from ..physics import COEFFICIENT_NAMES
from ..physics.discrepancy import coefficient_curve
from .discrepancy import Z_KEEP, LearnedDiscrepancy, family_of, learn_discrepancy
from .missing_physics import (CANDIDATES, EVIDENCE_THRESHOLD, SHARE_PARTIAL, Diagnosis, ModelFit,
                              applicable_candidates, diagnose, model_fit, structured)
from .mismatch import describe_where, fingerprint
from .mismatch import onset_of_mismatch, onset_unavailable
from .residuals import noise_floor, peak_window
from .lines import residual_lines
from .wobble import wobble_records
from .random_nutation import random_nutation
from .diagnosis_words import rms_text, words

logger = logging.getLogger(__name__)
#: a base coefficient "moved" when the refit shifts it by more than this many base standard deviations
SHIFT_SD = 2.0


def unit_parameter_names(unit_id: str, marker_ids) -> tuple[str, ...]:
    """Extra parameter names of a physics term or data explanation."""
    return unit(unit_id).parameter_names(tuple(marker_ids))


def _title(term_id: str) -> str:
    return unit(term_id).title


def _whiteness(fit: ModelFit) -> dict:
    """{flight: {series: Ljung–Box p}}."""
    return {f: {s: d["ljung_box_p"] for s, d in per.items()} for f, per in fit.localisation.items()}


def _ls_estimates(fit: ModelFit, names) -> dict:
    sd = np.sqrt(np.diag(fit.ls.cov))
    idx = {n: i for i, n in enumerate(fit.problem.names)}
    out = {}
    for n in names:
        v, s = float(fit.ls.theta[idx[n]]), float(sd[idx[n]])
        out[n] = {"value": v, "sd": s, "q025": v - 1.96 * s, "q975": v + 1.96 * s, "source": "least squares (Laplace)"}
    return out


def _posterior_estimates(run_dir: Path, names) -> dict:
    import arviz as az
    post = az.from_netcdf(str(run_dir / "posterior.nc")).posterior
    out = {}
    for n in names:
        x = np.asarray(post[n]).reshape(-1)
        out[n] = {"value": float(np.mean(x)), "sd": float(np.std(x)), "q025": float(np.quantile(x, 0.025)),
                  "q975": float(np.quantile(x, 0.975)), "source": "posterior (emcee)"}
    return out


def _sampled_base(out: Path, base_ids) -> bool:
    """Whether ``out`` holds a ``sample`` run of the base model (its posterior then gives "before")."""
    try:
        summary = json.loads((out / "summary.json").read_text())
    except (OSError, ValueError):
        return False
    return (out / "posterior.nc").is_file() and list(summary.get("physics_terms", [])) == list(base_ids)


def coefficient_shifts(before: dict, after: dict) -> list[dict]:
    """Base coefficients whose estimate moved by more than SHIFT_SD of the base model's sd."""
    out = []
    for n in COEFFICIENT_NAMES:
        b, a = before[n], after[n]
        z = (a["value"] - b["value"]) / b["sd"] if b["sd"] > 0 else 0.0
        if abs(z) > SHIFT_SD:
            out.append({"name": n, "before": b["value"], "before_sd": b["sd"], "after": a["value"],
                        "after_sd": a["sd"], "shift_sd": float(z)})
    return sorted(out, key=lambda s: -abs(s["shift_sd"]))


#: points of a learned curve
CURVE_POINTS = 41


def _curve_grid(learned: LearnedDiscrepancy, variable: str) -> np.ndarray:
    """Grid over the flown range of ``variable`` (5th–95th percentile; height from the ground)."""
    lo, _, hi = learned.flown[variable]
    if variable == "height":
        lo = 0.0
    return np.linspace(lo, hi, CURVE_POINTS)


def _family_fit(diag: Diagnosis, family: str | None):
    """(term, fitted values) of the library family ``family`` from its candidate fit in the first round, or None."""
    if family is None or not diag.rounds:
        return None
    cand = next((c for c in diag.rounds[0] if c.id == family), None)
    if cand is None or unit(family).kind != PHYSICS_TERM:
        return None
    theta = dict(zip(cand.fit.problem.names, cand.fit.ls.theta))
    term = unit(family).obj
    return term, [float(theta[p.name]) for p in term.parameters]


def learned_record(learned: LearnedDiscrepancy, diag: Diagnosis) -> dict:
    """The learned correction for ``diagnosis.json``: columns with values and sd, ΔBIC, whiteness, RMS after,
    its concentration per flight variable and direction, the variable and family it names (or null), and
    its curve along the strongest variable in the main direction — beside the curve of the library family
    fitted as a candidate, where there is one."""
    variable = learned.variable or max((v for v in learned.concentration if v != "constant"),
                                       key=lambda v: learned.concentration[v], default=None)
    direction = learned.direction
    rec = {"selected": len(learned.names),
           "columns": {n: {"value": float(v), "sd": float(s)} for n, v, s in zip(learned.names, learned.values,
                                                                                   learned.sd)},
           "evidence": learned.delta_bic, "white": learned.white, "share_explained": learned.share,
           "replicated": learned.replicated, "explains": learned.explains,
           "rms_after_mm": learned.fit.rms_mm,
           "rms_after": learned.fit.rms, "concentration": learned.concentration,
           "direction_share": learned.direction_share, "variable": learned.variable, "direction": direction,
           "family": learned.family, "flown": learned.flown,
           "structured_after": structured(learned.fit), "curve": None}
    if variable is not None and direction is not None:
        grid = _curve_grid(learned, variable)
        value, sd = learned.curve(direction, variable, grid)
        curve = {"variable": variable, "direction": direction, "grid": grid, "value": value, "sd": sd,
                 "state": {v: learned.flown[v][1] for v in learned.flown}, "family": None}
        fam = _family_fit(diag, family_of(variable, direction))
        if fam is not None:
            term, vals = fam
            curve["family"] = {"id": term.id, "parameters": dict(zip(term.parameter_names, vals)),
                               "value": coefficient_curve(term, vals, direction, variable, grid, curve["state"],
                                                          diag.base.problem.disc)}
        rec["curve"] = curve
    return rec


def _unexplained(diag: Diagnosis) -> list[dict]:
    """Flights whose residuals stay structured after the accepted terms: the series (most structured
    first), the window where the structure is strongest (and the flight's height there), and the Ljung–Box
    p-values. The onset search (when the model stops following the flight) locates a disturbance; it is
    not run on the rest of a partial explanation, which acts wherever its effect does."""
    out = []
    final = diag.final
    names = [f.name for f in final.problem.flights]
    rms, rms_mm = final.rms, final.rms_mm
    for flight, series in diag.unexplained.items():
        if not series:
            continue
        k = names.index(flight)
        loc = final.localisation[flight]
        series = sorted(series, key=lambda s: loc[s]["ljung_box_p"])
        why = (PARTIAL_ONSET_NOTE if diag.partial else onset_unavailable(final.problem, k))
        window = peak_window(final.residuals[k], final.ls.sigma)
        u = {"flight": flight, "series": series,
             "model_follows_until_s": onset_of_mismatch(final, k) if why is None else None,
             "peak_window_s": window, "peak_height_m": _window_height(final.residuals[k], window),
             "rms": rms[flight], "ljung_box_p": {s: loc[s]["ljung_box_p"] for s in series}}
        if flight in rms_mm:
            u["rms_mm"] = rms_mm[flight]
        if why is not None:
            u["onset_note"] = why
        out.append(u)
    return out


#: why no onset is searched in the structure a partial explanation leaves
PARTIAL_ONSET_NOTE = "not searched: the structure is the rest of a partially explained effect, not a disturbance"


def _window_height(fr, window) -> list | None:
    """[min, max] height [m] of the fitted flight over the time window [t0, t1] [s] (the ``height``
    covariate of its first residual series that has one); None if none."""
    for part in fr.parts:
        h = part.covariates.get("height")
        if h is None:
            continue
        sel = (part.times >= window[0]) & (part.times <= window[1]) & np.isfinite(h)
        if sel.any():
            return [float(np.min(h[sel])), float(np.max(h[sel]))]
    return None


def noise_scales(fit: ModelFit) -> dict:
    """{sigma name: {"value", "unit"}}: the least-squares noise scale of every noise group of ``fit``."""
    out = {}
    names = fit.problem.sigma_names
    for fr in fit.residuals:
        for part, off in zip(fr.parts, fr.group_offsets):
            for g, (_, u) in enumerate(part.group_channels):
                out[names[off + g]] = {"value": float(fit.ls.sigma[off + g]), "unit": u}
    return out


def save_series(path: Path, diag: Diagnosis) -> None:
    """Residual series before/after per flight for the report's figures."""
    arrays = {}
    for k, (b, a) in enumerate(zip(diag.base.residuals, diag.final.residuals)):
        arrays[f"{k}_times"] = b.parts[0].times
        after = a.series
        for name, x in b.series.items():
            arrays[f"{k}_times_{name}"] = b.part(name).times
            arrays[f"{k}_before_{name}"] = x
            arrays[f"{k}_after_{name}"] = after[name]
            arrays[f"{k}_se_{name}"] = a.se(name, diag.final.ls.sigma)
    arrays["flights"] = np.array([f.name for f in diag.base.problem.flights])
    np.savez_compressed(path, **arrays)


def correlated_noise(cfg: RunConfig, diag: Diagnosis, build_for, candidates, choice: NoiseChoice,
                     processes: int = 1) -> tuple:
    """The diagnosis again under the marker noise models ``noise: auto`` chose, when they may explain the
    structure the white diagnosis leaves (module docstring).

    Parameters
    ----------
    cfg : RunConfig
        The run.
    diag : Diagnosis
        The diagnosis with white noise on the ``auto`` flights.
    build_for : callable
        ``build_for(cfg)`` → ``build(ids)``: the problem of the run configuration ``cfg`` with the extra
        term ids.
    candidates : list of str
        The candidate ids judged.
    choice : NoiseChoice
        The choice at the base model's least squares (:func:`~bayes_disc.inference.fitting.noise_choice.
        choose_noise`, the same call ``sample`` makes).
    processes : int
        Parallel candidate fits.

    Returns
    -------
    (Diagnosis, dict, RunConfig)
        The diagnosis, the ``noise`` record and the configuration it used. The chosen models are adopted
        (``adopted`` true, ``model`` ``ar1`` or ``per_point``, ``rho``, ``evidence``) when the white diagnosis
        accepts no term but leaves structure in a flight with markers, evidence chose AR(1) or per-point noise
        for some flight, and under them a term explains the structure or none is left. Otherwise the white
        diagnosis stays (``model`` ``white``, ``ar1_evidence``); when the chosen models were tried and leave
        the structure too, ``ar1_rho`` and ``ar1_explains`` false: a deterministic disturbance pushes ρ towards
        1 without whitening the residuals. ``choice`` always holds the per-flight records.
    """
    records = choice.records
    chosen = {f: r for f, r in records.items() if r["by"] == "evidence" and r["label"] != r["reference"]}
    ar1 = {f: r["rho"][r["label"]] for f, r in chosen.items() if r["label"] in r["rho"]}
    evidence = float(sum(r["delta_bic"][r["label"]] for r in chosen.values()))
    tried = [r["delta_bic"]["ar1"] for r in records.values() if (r.get("delta_bic") or {}).get("ar1") is not None]
    white = {"model": "white", "adopted": False, "choice": records}
    if tried:
        white["ar1_evidence"] = float(sum(tried))
    marker_flights = set(records)
    left = {f for f, series in diag.unexplained.items() if series}
    if diag.accepted or not (left & marker_flights) or not chosen:
        return diag, white, cfg
    logger.info("the white diagnosis leaves structure; judging the candidates again with the noise models chosen: "
                + "; ".join(records[f]["text"] for f in chosen))
    cfg_c = cfg.with_flight_noise(choice.settings())
    build = build_for(cfg_c)
    again = diagnose(model_fit(choice.problem, choice.ls, diag.base.ids), build, processes=processes,
                     max_nfev=cfg.least_squares.max_nfev, candidates=candidates, log=logger.info)
    if again.accepted or not any(again.unexplained.values()):
        return again, {"model": "ar1" if ar1 else "per_point", "adopted": True, "rho": ar1,
                       "evidence": evidence, "choice": records}, cfg_c
    # AR(1) only absorbs structure it cannot whiten (a gust, say, gives ρ → 1): not evidence of correlated noise
    logger.info("the chosen noise models leave the structure unexplained too; the diagnosis stays with white noise")
    return diag, {**white, "ar1_rho": ar1, "ar1_explains": False}, cfg


def _replication_record(c, problem) -> dict | None:
    """{replicated, removing: [flight], acts_in: [flight] or None} of a candidate whose share was large enough
    for replication to be asked (:func:`.missing_physics.replication`), else None."""
    if c.replication is None:
        return None
    names = [f.name for f in problem.flights]
    acts = c.replication["reached"]
    return {"replicated": c.replication["replicated"], "removing": [names[k] for k in c.replication["removing"]],
            "acts_in": None if acts is None else [names[k] for k in acts]}


@dataclass
class Analysis:
    """The diagnosis of a run before any resampling: the base fit, the candidates judged, the noise model.

    Attributes
    ----------
    cfg : RunConfig
        The configuration the diagnosis was made with (with the chosen marker noise models when they were
        adopted: :func:`correlated_noise`).
    diag : Diagnosis
        Base fit, ranked candidates, accepted terms, final fit.
    noise : dict or None
        The ``noise`` record of :func:`correlated_noise` (None for a run without marker flights).
    skipped : dict
        Candidates not tried, with the reason.
    base_ids : tuple of str
        The configuration's own physics terms (the base model).
    problem : Problem
        The base model's statistical problem (the configuration's own noise model).
    build_for : callable
        ``build_for(cfg)`` → ``build(ids)``: the problem of ``cfg`` with the extra term ids.
    """

    cfg: RunConfig
    diag: Diagnosis
    noise: dict | None
    skipped: dict
    base_ids: tuple
    problem: object
    build_for: object


def analyse(cfg: RunConfig, processes: int = 2, candidates=None) -> Analysis:
    """Fit the base model, rank the candidate terms by ΔBIC and judge correlated noise (module docstring).

    Parameters
    ----------
    cfg : RunConfig
        The validated run configuration.
    processes : int
        Parallel candidate fits.
    candidates : sequence of str, optional
        The candidate ids to try (default: every one of ``CANDIDATES``); an unknown id is an error.

    Returns
    -------
    Analysis
    """
    wanted = list(CANDIDATES if candidates is None else candidates)
    unknown = [c for c in wanted if c not in CANDIDATES]
    if unknown:
        raise ValueError(f"unknown candidate(s) {unknown}; known: {list(CANDIDATES)}")
    flights = load_run_flights(cfg)
    throws = load_run_throws(cfg)          # read (and their repairs reported) once, not once per candidate
    base_ids = tuple(cfg.physics)

    def build_for(c: RunConfig):
        return lambda ids: build_problem(c, terms_override=list(ids), flights=flights, throws=throws)

    build = build_for(cfg)
    problem = build(base_ids)
    logger.info(f"{cfg.name}: {problem.n_flights} flights; base model"
                + (f" with {', '.join(base_ids)}" if base_ids else "") + "; fitting by least squares")
    ls = fit_least_squares(problem, starts=cfg.least_squares.starts, max_nfev=cfg.least_squares.max_nfev,
                           seed=cfg.sampler.seed)
    choice = choose_noise(problem, ls, run_settings(cfg, problem), max_nfev=cfg.least_squares.max_nfev)
    for line in choice.lines():
        logger.info(f"noise choice: {line}")
    base = model_fit(problem, ls, base_ids)
    logger.info("base RMS " + rms_text(base.rms))
    tried, skipped = applicable_candidates(problem, [c for c in wanted if c not in base_ids])
    for c, why in skipped.items():
        logger.info(f"not trying {c}: {why}")
    logger.info(f"ranking {len(tried)} candidates by ΔBIC (each a least-squares refit):")
    diag = diagnose(base, build, processes=processes, max_nfev=cfg.least_squares.max_nfev,
                    candidates=tried, log=logger.info)
    diag, noise, cfg = correlated_noise(cfg, diag, build_for, tried, choice, processes=processes)
    return Analysis(cfg, diag, noise if choice.records else None, skipped, base_ids, problem, build_for)


def estimates_before(analysis: Analysis, out: Path) -> dict:
    """The ten coefficients before the accepted terms: the posterior of a ``sample`` run of the base model in
    ``out`` when there is one, else the base model's least-squares (Laplace) estimates."""
    if _sampled_base(out, analysis.base_ids):
        return _posterior_estimates(out, COEFFICIENT_NAMES)      # the `sample` run of the same model
    return _ls_estimates(analysis.diag.base, COEFFICIENT_NAMES)


def _after_names(analysis: Analysis) -> tuple:
    return COEFFICIENT_NAMES + tuple(analysis.diag.final.problem.ext_names)


def estimates_after(analysis: Analysis, refit_dir: Path | None = None) -> dict:
    """The coefficients and the accepted terms' parameters after: from the resampled run in ``refit_dir``,
    or the final model's least-squares (Laplace) estimates."""
    if refit_dir is not None:
        return _posterior_estimates(refit_dir, _after_names(analysis))
    return _ls_estimates(analysis.diag.final, _after_names(analysis))


def refit_config(analysis: Analysis, output: Path) -> RunConfig:
    """The run configuration with the accepted terms at their least-squares values, written to ``output``
    and named ``<name>_refit``: what the diagnosis resamples."""
    cfg, final = analysis.cfg, analysis.diag.final
    physics = dict(cfg.physics)
    theta = dict(zip(final.problem.names, final.ls.theta))
    for c in analysis.diag.accepted:
        physics[c.id] = {n: float(theta[n]) for n in unit_parameter_names(c.id, analysis.problem.marker_ids)}
    return replace(cfg, name=f"{cfg.name}_refit", output=output, physics=physics)


def _effects(analysis: Analysis, after_est: dict) -> list[dict]:
    """The accepted effects ranked best first: {id, evidence, estimate, where, title, status, ...}."""
    diag, problem = analysis.diag, analysis.problem
    base = diag.base
    effects = []
    base_names = set(base.problem.ext_names)
    for rank, c in enumerate(diag.accepted):
        new = [n for n in c.fit.problem.ext_names if n not in base_names]
        base_names |= set(new)
        fp = fingerprint(base if rank == 0 else diag.accepted[rank - 1].fit, c.fit, new)
        effects.append({"id": c.id, "evidence": c.delta_bic, "estimate": {n: after_est[n] for n in new},
                        "where": describe_where(fp, problem.n_flights), "title": _title(c.id),
                        "status": "partially_explains" if diag.partial else c.status,
                        "share_explained": c.share, "fingerprint": fp})
    effects.sort(key=lambda e: -e["evidence"])
    return effects


def _noise_records(base: ModelFit, final: ModelFit) -> dict:
    """Marker σ before/after [mm], every noise group's σ before/after, and the noise floor."""
    sig_b, sig_a = noise_scales(base), noise_scales(final)
    marker_sigma = {f"sigma_{f}": f for f in base.rms_mm}
    floor = noise_floor(base.residuals, base.problem.n_groups)
    return {"noise_sigma_mm": {"before": {f: sig_b[s]["value"] * 1e3 for s, f in marker_sigma.items()},
                               "after": {f: sig_a[s]["value"] * 1e3 for s, f in marker_sigma.items()}},
            "noise_sigma": {"before": sig_b, "after": sig_a},
            "noise_floor": {n: {"value": float(v), "unit": sig_b[n]["unit"]}
                            for n, v in zip(base.problem.sigma_names, floor)}}


def diagnosis_record(analysis: Analysis, before_est: dict, after_est: dict, refit_dir: Path | None,
                     learn: bool = True) -> dict:
    """The content of ``diagnosis.json`` (module docstring), the diagnosis in words included.

    Parameters
    ----------
    analysis : Analysis
        The diagnosis (:func:`analyse`).
    before_est, after_est : dict
        The estimates before and after the accepted terms (:func:`estimates_before`, :func:`estimates_after`).
    refit_dir : Path or None
        The resampled run with the accepted terms, or None when nothing was resampled.
    learn : bool
        When the base model leaves structure, learn a correction (:mod:`.discrepancy`) and report it under
        ``learned_discrepancy``.

    Returns
    -------
    dict
        ``verdict``, ``effects`` ranked best first, RMS per flight before and after [mm] (``rms_before_mm``,
        ``rms_after_mm``) and the details listed in the module docstring (``words``: the diagnosis in words).
    """
    diag, cfg, problem = analysis.diag, analysis.cfg, analysis.problem
    base, final = diag.base, diag.final         # the base model's best optimum (it may have been refitted)
    result = {"verdict": diag.verdict, "effects": _effects(analysis, after_est), "rms_before_mm": base.rms_mm,
              "rms_after_mm": final.rms_mm, "rms_before": base.rms, "rms_after": final.rms,
              "skipped_candidates": analysis.skipped}
    result["unexplained"] = _unexplained(diag)
    result["partial_explanation"] = ({"ids": [c.id for c in diag.accepted], "share_explained": diag.share,
                                      "evidence": float(sum(c.delta_bic for c in diag.accepted)),
                                      "share_threshold": SHARE_PARTIAL} if diag.partial else None)
    result["shifted_coefficients"] = coefficient_shifts(before_est, after_est) if diag.accepted else []
    result["candidates"] = [{"id": c.id, "evidence": c.delta_bic, "status": c.status, "share_explained": c.share,
                             "evidence_from_white_flights": c.clean_evidence, "per_flight_gain": c.per_flight_gain,
                             "extra_parameters": c.extra_parameters, "replication": _replication_record(c, problem),
                             "round": r + 1, "rms_mm": c.fit.rms_mm, "rms": c.fit.rms,
                             "structured_after": c.structured_after}
                            for r, ranked in enumerate(diag.rounds) for c in ranked]
    result["whiteness_before"] = _whiteness(base)
    result["whiteness_after"] = _whiteness(final)
    result["localisation_before"] = base.localisation
    result.update(_noise_records(base, final))
    result["coefficients_before"] = before_est
    result["coefficients_after"] = after_est
    result["model"] = {"base": list(analysis.base_ids), "final": list(final.ids)}
    if analysis.noise is not None:
        result["noise"] = analysis.noise
    result["settings"] = {"evidence_threshold_delta_bic": EVIDENCE_THRESHOLD, "share_partial": SHARE_PARTIAL,
                          "resampled": refit_dir is not None,
                          "refit_run": str(refit_dir) if refit_dir is not None else None}
    result["learned_discrepancy"] = None
    if learn and any(structured(base).values()):
        logger.info("the base model leaves structure: learning a correction in height, α and spin")
        learned = learn_discrepancy(base, analysis.build_for(cfg), max_nfev=cfg.least_squares.max_nfev,
                                    log=logger.info)
        result["learned_discrepancy"] = learned_record(learned, diag) if learned is not None else {
            "selected": 0, "reason": f"no column of the correction reaches |z| ≥ {Z_KEEP:.0f}"}
    result["wobble"] = wobble_records(base.problem, base.ls.theta) or None
    result["random_nutation"] = random_nutation(base.problem, base.ls.theta)
    result["lines"] = residual_lines(base.residuals) or None
    result["words"] = words(result)
    return result


def write_diagnosis(out: Path, result: dict, diag: Diagnosis) -> None:
    """``<out>/diagnosis.json`` (NaN and ±inf as null) and ``<out>/diagnosis_residuals.npz``."""
    (out / "diagnosis.json").write_text(json.dumps(_finite(result), indent=1, allow_nan=False))
    save_series(out / "diagnosis_residuals.npz", diag)


def _finite(x):
    """JSON-safe copy: numpy scalars and arrays to Python, NaN and ±inf to null."""
    if isinstance(x, dict):
        return {str(k): _finite(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_finite(v) for v in x]
    if isinstance(x, np.ndarray):
        return _finite(x.tolist())
    if isinstance(x, (np.integer,)):
        return int(x)
    if isinstance(x, (float, np.floating)):
        return float(x) if np.isfinite(x) else None
    if isinstance(x, np.bool_):
        return bool(x)
    return x
