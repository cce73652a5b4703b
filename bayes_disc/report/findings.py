"""Section builders on what the data determine and what the model misses: identifiability, the missing-physics
diagnosis (with the learned correction) and the points judged outliers or swapped (see :mod:`.sections`)."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ..observation.models.inertial import SERIES as INERTIAL_SERIES, SERIES_UNITS as INERTIAL_UNITS
from ..observation.models.magnetometer import MAG_SERIES
from ..observation.models.markers import ROTATIONS
from ..physics import TERMS, Disc
from ..physics.discrepancy import coefficient_curve
from ..physics.nature import NATURE
from . import figures as F
from .content import _figure, _prior_table, _range
from .sections import Section, esc, fmt, fmt_percent, table


def identifiability_section(ctx) -> Section:
    """Verdicts, flight envelope, weak directions and the next throw from ``identifiability.json``
    (``bayes-disc identifiability``), and from the posterior: contraction and correlation."""
    data = ctx.run.extras.get("identifiability") or {}
    guide = ("Whether the data determine each coefficient (identified, weak, unidentified) and why; which "
             "combinations they tie together; which throw would determine the rest.")
    parts, figs = [], []
    prior = _prior_table(ctx.summary["prior"])
    # the full records, or the top-level {name: {verdict, reason}} entries alone
    coefs = data.get("coefficients") or {k: v for k, v in data.items() if isinstance(v, dict) and "verdict" in v}
    post = ctx.summary["parameters"]
    rows = []
    for name in ctx.coefficients:
        v = coefs.get(name, {})
        p = post.get(name, {})
        ratio = (p["sd"] / prior[name][1]) if name in prior and "sd" in p else None
        rows.append([name] + ([v.get("verdict", "–")] if coefs else []) + [fmt_percent(ratio)]
                    + ([v.get("reason", "–")] if coefs else []))
    heads = ["coefficient", "posterior sd / prior sd"]
    if coefs:
        heads = ["coefficient", "verdict", "posterior sd / prior sd", "reason"]
    else:
        guide = ("How far the data narrowed each coefficient beyond its prior, and which coefficients they tie "
                 "together. Verdicts, the flight envelope and the next throw come from `bayes-disc "
                 "identifiability` (not run for this run).")
    parts.append("<p class=note>Posterior sd / prior sd: the share of the prior's width the data left; 100 % "
                 "means the data taught nothing, 1 % that they narrowed the coefficient a hundredfold.</p>")
    parts.append(table(heads, rows, "num"))
    env = data.get("envelope")
    if env:
        parts.append("<h3>Flight envelope</h3>" + table(
            ["flight", "α [deg]", "speed [m/s]", "spin r [rad/s]"],
            [[f, _range(r["alpha_deg"]), _range(r["speed_m_s"]), _range(r["spin_rad_s"], 0)]
             for f, r in {**env["flights"], "all flights": env["set"]}.items()]))
        h = env.get("alpha_histogram")
        if h:
            figs.append(_figure(ctx, F.alpha_histogram_figure(h["edges_deg"], h["counts"], env["flights"]),
                                "alpha_histogram", "Angle of attack over all samples of the fitted flights, and "
                                "each flight's α range: the α-dependent coefficients need this spread."))
    fisher = data.get("fisher")
    if fisher:
        parts.append(f"<h3>Fisher information</h3><p>Condition number {fmt(fisher['condition_number'], 3)} (scale-free: "
                     "each coefficient in units of its prior sd; initial conditions marginalised). Least-determined "
                     "directions:</p><ul>" + "".join(f"<li>{esc(w['text'])}</li>" for w in fisher["weak_directions"])
                     + "</ul>")
    prof = data.get("profiles")
    if prof:
        parts.append("<h3>Profile likelihood</h3>" + table(
            ["coefficient", "shape", "half-width (deviance 1)", "points"],
            [[n, v["shape"], fmt(v.get("halfwidth"), 3), len(v["value"])] for n, v in prof.items()]))
    design = data.get("design")
    if design and "skipped" in design:
        parts.append(f"<h3>Next throw</h3><p>{esc(design['skipped'])}.</p>")
    elif design:
        parts.append(f"<h3>Next throw</h3><p>{esc(design['recommendation'])}</p>" + table(
            ["rank", "speed [m/s]", "launch angle [deg]", "α at release [deg]", "spin [rad/s]", "ln volume gain"],
            [[i + 1, fmt(r["speed"]), fmt(r["launch_angle_deg"]), fmt(r["alpha_deg"]), fmt(r["spin"]), fmt(r["gain"], 3)]
             for i, r in enumerate(design["ranking"][:5])]))
    samples = ctx.coefficient_samples
    corr = np.corrcoef(samples.T)
    figs.append(_figure(ctx, F.correlation_figure(corr, ctx.coefficients), "posterior_correlation",
                        "Posterior correlation of the coefficients: |values| near 1 mark combinations the data "
                        "determine only together."))
    return Section("identifiability", "Identifiability", guide, "".join(parts), figs)


#: the residual series the diagnosis figure draws: {name: (axis label, factor from the series' unit to the
#: label's)}; markers in m and rad, an inertial logger's in rad/s and m/s²
SERIES_LABELS = {"along": ("along-track [mm]", 1e3), "lateral": ("lateral [mm]", 1e3),
                 "normal": ("vertical [mm]", 1e3), "d1": ("d1 [mm]", 1e3), "d2": ("d2 [mm]", 1e3),
                 "d3": ("d3 [mm]", 1e3), "roll": ("roll [mrad]", 1e3), "pitch": ("pitch [mrad]", 1e3),
                 "spin_phase": ("spin phase [mrad]", 1e3),
                 **{s: (f"{'gyro' if s.startswith('gyro') else 'accelerometer'} {s[-1]} [{u}]", 1.0)
                    for s, u in zip(INERTIAL_SERIES, INERTIAL_UNITS)},
                 **{s: (f"magnetometer {s[-1]} [µT]", 1.0) for s in MAG_SERIES}, "baro": ("barometer [Pa]", 1.0)}


def _estimate_text(est: dict) -> str:
    return "; ".join(f"{n} = {v['value']:.4g} (95% {v['q025']:.4g} … {v['q975']:.4g})" for n, v in est.items())


def _fixed(x, spec: str = ".1f") -> str:
    return "–" if x is None or not np.isfinite(x) else format(x, spec)


def _min_p(per: dict) -> str:
    p = [v for v in per.values() if v is not None]
    return f"{min(p):.1e}" if p else "–"


def diagnosis_series(series: dict, data: dict) -> list[str]:
    """The residual series the diagnosis figure draws (at most three): the most structured series of the
    base fit that is not an attitude angle, the most structured attitude angle, then the accepted terms'
    effect series; only series with a label (:data:`SERIES_LABELS`) recorded for every flight.

    Parameters
    ----------
    series : dict
        The arrays of ``diagnosis_residuals.npz`` (``flights``, ``<c>_se_<name>``, …).
    data : dict
        ``diagnosis.json``.

    Returns
    -------
    list of str
    """
    n = len(series["flights"])

    def drawable(name) -> bool:
        return name in SERIES_LABELS and all(f"{c}_se_{name}" in series for c in range(n))
    ratio = {}
    for per in (data.get("localisation_before") or {}).values():
        for name, d in per.items():
            ratio.setdefault(name, []).append(d.get("noise_ratio") or 0.0)
    by_structure = [m for m in sorted(ratio, key=lambda m: -float(np.median(ratio[m]))) if drawable(m)]
    names = [next((m for m in by_structure if m not in ROTATIONS), None),
             next((m for m in by_structure if m in ROTATIONS), None)]
    names += [(e.get("fingerprint") or {}).get("effect_series") for e in data.get("effects") or []]
    return list(dict.fromkeys(m for m in names if m is not None and drawable(m)))[:3]


def _diagnosis_figure(ctx, data: dict):
    path = Path(ctx.run.run_dir) / "diagnosis_residuals.npz"
    if not path.is_file():
        return None
    with np.load(path) as z:
        series = {k: z[k] for k in z.files}
    flights = [str(f) for f in series["flights"]]
    names = diagnosis_series(series, data)
    if not names:
        return None
    fig = F.diagnosis_figure(series, flights, names, SERIES_LABELS)
    return _figure(ctx, fig, "diagnosis_residuals",
                   "Residual series before (grey) and after (blue) the diagnosis' refit, per flight: the most "
                   "structured translation and attitude series of the base fit and the direction in which the "
                   "accepted term moves the markers; band: ±2 noise standard errors.")


def missing_physics_section(ctx) -> Section | None:
    data = ctx.run.extras.get("diagnosis")
    guide = ("Whether the residuals call for physics the model lacks (side force, wind, ground effect …): every "
             "candidate of the library is fitted and must earn its place by ΔBIC; it explains the data when it "
             "leaves white residuals, and partially explains them when it removes at least half of the excess "
             "misfit (the misfit beyond the noise floor, estimated from second differences of the residuals) "
             "but leaves structure: its form then differs from the library's.")
    if not data:
        return None     # not run: the first screen's model-adequacy line gives the command
    effects = [e for e in data.get("effects") or [] if isinstance(e, dict)]
    before, after = data.get("rms_before_mm") or {}, data.get("rms_after_mm") or {}
    wb, wa = data.get("whiteness_before") or {}, data.get("whiteness_after") or {}
    words = "".join(f"<p>{esc(line)}</p>" for line in str(data.get("words", "")).splitlines())
    parts = [f"<p>Verdict: <b>{esc(data.get('verdict', '–'))}</b></p>", words]
    if effects:
        parts.append(table(["effect", "status", "share of excess misfit", "ΔBIC", "estimate", "where"],
                           [[e.get("id"), e.get("status", "–"), fmt_percent(e.get("share_explained")),
                             _fixed(e.get("evidence")), _estimate_text(e.get("estimate") or {}), e.get("where")]
                            for e in effects]))
    parts.append("<h3>Fit before and after</h3>" + table(
        ["flight", "RMS before [mm]", "RMS after [mm]", "min Ljung–Box p before", "min Ljung–Box p after"],
        [[f, fmt(before.get(f)), fmt(after.get(f)), _min_p(wb.get(f, {})), _min_p(wa.get(f, {}))] for f in before]))
    moved = data.get("shifted_coefficients") or []
    if moved:
        parts.append("<h3>Base coefficients the missing term had biased</h3>" + table(
            ["coefficient", "before", "after", "shift [before sd]"],
            [[s["name"], f"{s['before']:.4g} ± {s['before_sd']:.2g}", f"{s['after']:.4g} ± {s['after_sd']:.2g}",
              _fixed(s["shift_sd"], "+.1f")] for s in moved]))
    unexplained = data.get("unexplained") or []
    if unexplained:
        title = ("Structure the partial explanation leaves" if data.get("partial_explanation") else "Unexplained")
        parts.append(f"<h3>{title}</h3>" + table(
            ["flight", "structured series", "largest at [s]", "height there [m]", "model follows until [s]",
             "RMS [mm]"],
            [[u["flight"], ", ".join(u["series"]), "–".join(f"{x:.2f}" for x in u["peak_window_s"]),
              "–".join(f"{x:.2f}" for x in u["peak_height_m"]) if u.get("peak_height_m") else "–",
              fmt(u.get("model_follows_until_s")), fmt(u.get("rms_mm"))] for u in unexplained]))
    lines = data.get("lines") or {}
    if lines:
        parts.append("<h3>Oscillations left in the residuals</h3><p>The strongest sinusoid of each residual series "
                     "of the base fit, where it holds at least 30 % of the series (white residuals: about 4 %); its "
                     "frequency also as a multiple of the mean spin rate.</p>" + table(
                         ["flight", "series", "amplitude", "frequency [Hz]", "× spin", "cycles", "share"],
                         [[f, n, f"{x['amplitude']:.3g} {x['unit']}", f"{x['frequency_hz']:.3f}",
                           _fixed(x.get("per_spin"), ".3f"), f"{x['cycles']:.1f}", fmt_percent(x["share"])]
                          for f, per in lines.items() for n, x in per.items()]))
    cands = data.get("candidates") or []
    if cands:
        parts.append("<h3>Every candidate</h3>" + table(
            ["round", "candidate", "extra parameters", "ΔBIC", "share of excess misfit", "status"],
            [[c.get("round"), c.get("id"), c.get("extra_parameters"), _fixed(c.get("evidence")),
              fmt_percent(c.get("share_explained")), c.get("status")] for c in cands]))
    figs = [_diagnosis_figure(ctx, data)]
    learned = data.get("learned_discrepancy")
    if learned and learned.get("selected"):
        parts.append(_learned_table(learned))
        figs.append(_learned_figure(ctx, learned))
    return Section("missing-physics", "Missing physics", guide, "".join(parts), [f for f in figs if f])


def _learned_table(ld: dict) -> str:
    conc = ", ".join(f"{v} {100 * s:.0f} %" for v, s in sorted(ld["concentration"].items(), key=lambda t: -t[1]))
    rows = [[n, f"{c['value']:.4g} ± {c['sd']:.2g}"] for n, c in ld["columns"].items()]
    return ("<h3>Learned correction</h3>"
            f"<p>{ld['selected']} functions selected (ΔBIC {_fixed(ld.get('evidence'), ',.0f')}; residuals after: "
            f"{'white' if ld.get('white') else 'structured'}); evidence by flight variable: {esc(conc)}; named "
            f"family: {esc(ld.get('family') or 'none')}.</p>" + table(["column (dc_direction_function)", "value ± sd"], rows))


def generating_curve(truth: dict | None, curve: dict) -> tuple[np.ndarray, str] | None:
    """For synthetic data: the change of the curve's coefficient that the concealed terms and forms of nature
    of ``truth.json`` make along the curve's variable (summed), and their names; None without a truth file
    or when they change nothing there."""
    if not truth:
        return None
    disc = Disc(**truth["disc"]) if truth.get("disc") else Disc()
    total, names = np.zeros(len(curve["grid"])), []
    for block, registry in (("physics", TERMS), ("nature", NATURE)):
        for tid, params in (truth.get(block) or {}).items():
            term = registry.get(tid)
            if term is None or term.loads is None:
                continue
            vals = [params.get(q.name, q.off_value) for q in term.parameters]
            c = coefficient_curve(term, vals, curve["direction"], curve["variable"], curve["grid"], curve["state"], disc)
            if np.any(c != 0):
                total, names = total + c, names + [tid]
    return (total, "generating: " + " + ".join(n.replace("_", " ") for n in names)) if names else None


def _learned_figure(ctx, ld: dict):
    curve = ld.get("curve")
    if not curve:
        return None
    gen = generating_curve(ctx.run.truth, curve)
    fig = F.learned_curve_figure(curve, *(gen or (None, "")))
    return _figure(ctx, fig, "learned_curve",
                   f"The learned correction of the {curve['direction']} coefficient against {curve['variable']} "
                   "(blue, ±2 sd; the other flight variables at their median flown values)"
                   + (f", the fitted {curve['family']['id'].replace('_', ' ')} family (dashed)" if curve.get("family") else "")
                   + (", and the curve that generated these synthetic data (black)" if gen else "") + ".")


#: most flagged points and frames listed per table (all are in flagged.json)
MAX_FLAG_ROWS = 40


def flagged_section(ctx) -> Section | None:
    """Points judged gross outliers and frames judged label-swapped by the ``robust`` noise model
    (``flagged.json``: {flight: {"outliers": [...], "swaps": [...]}}), and the posterior averaged over that
    judgement beside the one given it (``judgement_average.json``); None for runs without robust flights."""
    data = ctx.run.extras.get("flagged")
    if not data:
        return None
    outliers = [r for f in data.values() for r in f.get("outliers", [])]
    swaps = [r for f in data.values() for r in f.get("swaps", [])]
    guide = ("Recorded points the robust noise model judged gross errors (removed before sampling) and frames "
             "whose marker labels it judged exchanged (restored), each with its probability at the "
             "least-squares optimum, and the mixture's π, w and π_s estimated for each flight (EM, priors centred "
             "on 1 %, 5 cm and 1 %). The sampled posterior is conditional on this judgement; the last table "
             "gives the posterior averaged over every judgement (the inlier/outlier/swap mixture as the "
             "likelihood of the data as recorded), by importance sampling of the sampled draws.")
    def shape(f):
        m = data[f].get("mixture")                     # absent in runs from before π, w, π_s were estimated
        return (["–"] * 3 if m is None else
                [f"{100 * m['outlier_fraction']:.2f} %", f"{1e3 * m['outlier_width_m']:.1f}", f"{100 * m['swap_fraction']:.2f} %"])
    counts = table(["flight", "outlying points", "swapped frames", "share of gross errors π", "their spread w [mm]",
                    "share of swapped frames π_s"],
                   [[f, sum(r["flight"] == f for r in outliers), sum(r["flight"] == f for r in swaps), *shape(f)]
                    for f in sorted(data)], "num")
    parts = [counts]
    if outliers:
        more = f" (first {MAX_FLAG_ROWS} of {len(outliers)}; all in flagged.json)" if len(outliers) > MAX_FLAG_ROWS else ""
        parts.append(f"<h3>Outlying points{more}</h3>" + table(
            ["flight", "t [s]", "marker", "probability"],
            [[r["flight"], f"{r['t']:.4f}", r["marker"], f"{r['probability']:.3f}"] for r in outliers[:MAX_FLAG_ROWS]]))
    if swaps:
        more = f" (first {MAX_FLAG_ROWS} of {len(swaps)}; all in flagged.json)" if len(swaps) > MAX_FLAG_ROWS else ""
        parts.append(f"<h3>Label-swapped frames{more}</h3>" + table(
            ["flight", "t [s]", "markers exchanged", "probability"],
            [[r["flight"], f"{r['t']:.4f}", " ↔ ".join(map(str, r["markers"])), f"{r['probability']:.3f}"]
             for r in swaps[:MAX_FLAG_ROWS]]))
    avg = ctx.run.extras.get("judgement_average")
    if avg:
        head = (f"<h3>Averaged over the judgement</h3><p>{avg['draws']} posterior draws reweighted; Pareto "
                f"k̂ of the weights {avg['pareto_k']:.2f}, effective sample size {avg['ess']:.0f}.")
        if not avg["reliable"]:
            parts.append(head + f" With k̂ above {avg['pareto_k_max']} the weights cannot be trusted: the "
                         "judgement matters more than these draws can tell, and only the posterior given it is "
                         "reported.</p>")
        else:
            rows = []
            for name, c in avg["conditional"].items():
                a = avg["averaged"][name]
                rows.append([name, f"{c['q50']:.4g}", f"{a['q50']:.4g}", f"{c['q05']:.4g} … {c['q95']:.4g}",
                             f"{a['q05']:.4g} … {a['q95']:.4g}", f"{a['sd'] / c['sd']:.3f}"])
            parts.append(head + "</p>" + table(["parameter", "median given the judgement", "median averaged",
                                                 "90 % given the judgement", "90 % averaged", "sd ratio"], rows, "num"))
    return Section("flagged", "Data judged bad", guide, "".join(parts))
