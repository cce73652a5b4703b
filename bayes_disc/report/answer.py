"""The report's first screen: what was estimated, the coefficients, three one-line verdicts and the marker
noise model of every flight with the reason it was chosen (``noise_choice`` in ``summary.json``).

The verdicts answer "can I trust this?" in one line each:

* convergence, from ``summary.json`` (R-hat, smallest ESS, converged or step cap reached);
* identifiability, from ``identifiability.json`` (``bayes-disc identifiability``) when the run folder has it,
  else the command that computes it;
* model adequacy, from ``diagnosis.json`` (``bayes-disc diagnose``) when present, else the command, with the
  posterior predictive coverage the report computes anyway.

The verdict functions are pure (dicts in, :class:`Verdict` out) so they can be tested without a run.
"""
from __future__ import annotations

from dataclasses import dataclass

from ..inference.fitting.joint_region import p_text
from ..inference.results.summary import STALLED_ACCEPTANCE, stalled_moves
from .sections import Raw, Section, esc, fmt, fmt_count, fmt_estimate, fmt_percent, fmt_scaled, table

LIT_LABELS = {"potts_crowther": "Potts & Crowther 2000", "hummel2002": "Hummel & Hubbard 2002 (Table 2)"}
#: the posterior interval of the first screen
INTERVAL = ("q05", "q95")
INTERVAL_LABEL = "90 % interval"
PROFILE_LABEL = "profile 90 % interval"


@dataclass(frozen=True)
class Verdict:
    """One line of the first screen.

    topic : "Convergence", "Identifiability" or "Model adequacy"; status : "ok" (nothing to worry about),
    "attention" (read the section it links to) or "not run" (the check needs a command, given in ``command``);
    text : the line itself (plain text); link : the section id with the details, or "".
    """

    topic: str
    status: str
    text: str
    command: str = ""
    link: str = ""


STATUS_WORDS = {"ok": "ok", "attention": "check", "not run": "not run"}


def convergence_verdict(convergence: dict, settings: dict | None = None) -> Verdict:
    """The convergence line from ``summary.json``'s ``convergence`` block.

    Parameters
    ----------
    convergence : dict
        ``converged``, ``reason``, ``r_hat_max``, ``ess_bulk_min_coefficient``, ``total_steps``,
        ``kept_steps``, ``walkers_per_ensemble``, ``ensembles``.
    settings : dict, optional
        ``sampler_settings`` of summary.json (thresholds ``rhat``, ``ess`` and the cap ``max_steps``).

    Returns
    -------
    Verdict
        Status "ok" when the stopping rule was met, else "attention" (cap reached or stopped early).
    """
    s = settings or {}
    ok = bool(convergence.get("converged"))
    rh, ess = convergence.get("r_hat_max"), convergence.get("ess_bulk_min_coefficient")
    rh_txt = f"R-hat max {fmt(rh, 4)}" + (f" (threshold {fmt(s['rhat'])})" if "rhat" in s else "")
    ess_txt = f"smallest coefficient ESS {fmt_count(ess)}" + (f" (needed {fmt_count(s['ess'])})" if "ess" in s else "")
    total = convergence.get("total_steps")
    cap = s.get("max_steps")
    if ok:
        head = f"converged after {total} steps"
    elif cap is not None and total is not None and int(total) >= int(cap):
        head = f"NOT converged: step cap of {cap} reached"
    else:
        head = f"NOT converged ({convergence.get('reason', 'stopped early')})"
    stalled = stalled_moves(convergence.get("moves") or {})
    if not ok and stalled:
        head += (f" ({' and '.join(stalled)} accepted less than {STALLED_ACCEPTANCE:.0%} of the time: the posterior "
                 "is not the shape their proposals assume, and the walkers moved by local steps alone)")
    samples = ""
    if all(k in convergence for k in ("kept_steps", "walkers_per_ensemble", "ensembles")):
        n = convergence["kept_steps"] * convergence["walkers_per_ensemble"] * convergence["ensembles"]
        samples = (f"; {n} samples kept ({convergence['ensembles']} ensembles × "
                   f"{convergence['walkers_per_ensemble']} walkers × {convergence['kept_steps']} steps)")
    return Verdict("Convergence", "ok" if ok else "attention", f"{head}; {rh_txt}, {ess_txt}{samples}.",
                   link="convergence")


def identifiability_verdict(data: dict | None, coefficients, config_path) -> Verdict:
    """The identifiability line from ``identifiability.json``, or the command that writes it.

    Parameters
    ----------
    data : dict or None
        Content of ``identifiability.json`` (per coefficient ``verdict``: identified, weak or unidentified),
        None when the file is absent.
    coefficients : sequence of str
        The run's coefficients, in table order.
    config_path : str or Path
        The run's configuration (for the command).

    Returns
    -------
    Verdict
        "ok" when every coefficient is identified, "attention" otherwise, "not run" without data.
    """
    verdicts = coefficient_verdicts(data)
    if not verdicts:
        return Verdict("Identifiability", "not run", "not run; for a verdict per coefficient and the throw that "
                       "would pin down the weak ones:",
                       command=f"bayes-disc identifiability {config_path}")
    groups: dict[str, list[str]] = {}
    for n in coefficients:
        if n in verdicts:
            groups.setdefault(verdicts[n], []).append(n)
    n_id = len(groups.get("identified", []))
    parts = [f"{n_id} of {sum(len(v) for v in groups.values())} coefficients identified"]
    for word in ("weak", "unidentified"):
        if groups.get(word):
            parts.append(f"{word}: {', '.join(groups[word])}")
    bad = any(groups.get(w) for w in ("weak", "unidentified"))
    designed = bool((data.get("design") or {}).get("ranking")) if isinstance(data, dict) else False
    below = "reasons and the throw that would pin them down below" if designed else "reasons below"
    text = "; ".join(parts) + (f" ({below})." if bad else ".")
    return Verdict("Identifiability", "attention" if bad else "ok", text, link="identifiability")


def coefficient_verdicts(data: dict | None) -> dict:
    """{coefficient: verdict} of ``identifiability.json`` (full records, or the top-level
    ``{name: {verdict, reason}}`` entries alone); empty without data."""
    if not data:
        return {}
    coefs = data.get("coefficients") or {k: v for k, v in data.items() if isinstance(v, dict) and "verdict" in v}
    return {k: str(v["verdict"]) for k, v in coefs.items() if isinstance(v, dict) and "verdict" in v}


def adequacy_verdict(diagnosis: dict | None, config_path, coverage: float | None = None) -> Verdict:
    """The model-adequacy line from ``diagnosis.json``, or the command that writes it.

    Parameters
    ----------
    diagnosis : dict or None
        Content of ``diagnosis.json`` (``verdict`` "adequate" or "missing_physics", ``effects``,
        ``unexplained``, ``random_nutation``), None when absent.
    config_path : str or Path
        The run's configuration (for the command).
    coverage : float, optional
        Share of measured coordinates inside their 90 % posterior predictive interval (0…1), quoted when
        the diagnosis has not run.

    Returns
    -------
    Verdict
        "ok" for an adequate model, "attention" for missing physics, "not run" without a diagnosis.
    """
    if not diagnosis:
        cov = (f" (posterior predictive check: {100 * coverage:.0f} % of measured coordinates inside their 90 % "
               "interval)") if coverage is not None else ""
        return Verdict("Model adequacy", "not run", f"missing-physics search not run{cov}; to run it:",
                       command=f"bayes-disc diagnose {config_path}", link="flights")
    verdict = diagnosis.get("verdict")
    if verdict == "adequate":
        return Verdict("Model adequacy", "ok", "adequate: residuals of every flight are white and no candidate "
                       "term earns its place.", link="missing-physics")
    effects = [e for e in diagnosis.get("effects") or [] if isinstance(e, dict)]
    named = ", ".join(f"{e.get('id')} (ΔBIC {_evidence(e.get('evidence'))})" for e in effects)
    unexplained = diagnosis.get("unexplained") or []
    flights = sorted({u.get("flight") for u in unexplained if isinstance(u, dict)})
    partial = diagnosis.get("partial_explanation")
    parts = []
    if named:
        parts.append(f"missing physics found: {named}" + (
            f", explaining {fmt_percent(partial.get('share_explained'))} of the excess misfit; its form differs "
            "from the library's" if isinstance(partial, dict) else ""))
    if flights:
        parts.append(f"{'the rest sits' if isinstance(partial, dict) else 'unexplained structure left'} in "
                     f"{', '.join(map(str, flights))}")
    nutation = diagnosis.get("random_nutation")
    if isinstance(nutation, dict) and nutation.get("found"):
        parts.append(f"the transverse gyro misfit behaves as a randomly forced nutation (ΔBIC "
                     f"{_evidence(nutation.get('evidence'))}), from which candidates judged with white gyro noise gain "
                     "evidence: refit with gyro_noise: nutation to judge them without it")
    text = "; ".join(parts) or f"verdict {verdict}"
    refit = (diagnosis.get("settings") or {}).get("refit_run")
    tail = f" The coefficients above are those of the model without it; the refit is in {refit}." if (
        named and refit) else ""
    return Verdict("Model adequacy", "attention", text + "." + tail, link="missing-physics")


def _evidence(x) -> str:
    """ΔBIC as a reader wants it: whole numbers from 100 on ("4540"), one decimal below."""
    try:
        xf = float(x)
    except (TypeError, ValueError):
        return "–"
    return fmt_count(xf) if abs(xf) >= 100 else fmt(round(xf, 1), 3)


def render_verdict(v: Verdict) -> str:
    """One verdict as an HTML line (class ``verdict-line`` and ``status-…``)."""
    cls = v.status.replace(" ", "-")
    more = f' <a href="#{esc(v.link)}">details</a>' if v.link else ""
    cmd = f" <code>{esc(v.command)}</code>" if v.command else ""
    return (f'<li class="verdict-line status-{cls}"><span class="badge">{esc(STATUS_WORDS[v.status])}</span>'
            f"<b>{esc(v.topic)}:</b> {esc(v.text)}{cmd}{more}</li>")


def compare(value, lo: float, hi: float, scale: float = 0.0) -> Raw:
    """A published or true value and, in neutral words, whether it lies in the interval [lo, hi].

    Parameters
    ----------
    value : float or None
        The value ('–' when None).
    lo, hi : float
        The posterior interval.
    scale : float
        Magnitude for :func:`~.sections.fmt_scaled` (round-off of zero prints as 0).

    Returns
    -------
    Raw
        ``value <span class=cmp>in</span>`` or ``… out``.
    """
    if value is None:
        return Raw("–")
    inside = lo <= value <= hi
    word, title = ("in", "inside the posterior 90 % interval") if inside else (
        "out", "outside the posterior 90 % interval")
    return Raw(f'{esc(fmt_scaled(value, scale))} <span class="cmp cmp-{word}" title="{title}">{word}</span>')


def estimated_text(ctx) -> str:
    """One sentence: what was estimated from what."""
    s = ctx.summary
    flights = s["flights"]
    n_points = sum(int(f.get("points", 0)) for f in flights.values())
    n_samples = sum(int(f.get("samples", 0)) for f in flights.values())
    n_inertial = sum(int(f.get("inertial_values", 0)) for f in flights.values())
    data = []
    if n_points:
        data.append(f"{n_samples} time samples, <b>{n_points} marker points</b>")
    if n_inertial:
        data.append(f"<b>{n_inertial} gyro and accelerometer values</b> of an inertial logger")
    coefs = ctx.coefficients
    extra = [c for c in coefs if c not in DEFAULT_TEN]
    what = f"the {len(coefs) - len(extra)} aerodynamic coefficients of the Hummel &amp; Hubbard (2002) model"
    if extra:
        what += " plus " + ", ".join(esc(e) for e in extra)
    n_f = len(flights)
    noise = "marker noise" if not n_inertial else ("sensor noise and logger parameters" if not n_points
                                                  else "marker and sensor noise and logger parameters")
    return (f"<p class=lead>Estimated: {what}, with each flight's initial state and {noise}, from "
            f"<b>{n_f} flight{'s' if n_f != 1 else ''}</b> ({esc(', '.join(flights))}): {'; '.join(data)}. "
            f"Prior: {esc(s['prior']['name'] if s['prior']['name'] != 'around' else s['prior']['description'])}.</p>")


DEFAULT_TEN = ("CL0", "CLa", "CD0", "CDa", "CM0", "CMa", "CMq", "CRr", "CRp", "CNr")


def answer_table(ctx) -> str:
    """The coefficient table of the first screen: median, 90 % credible interval, the profile interval (runs
    that record it), literature, truth, verdict."""
    s = ctx.summary
    p = s["parameters"]
    lit = s["literature"]
    truth = ctx.truth_coefficients
    verdicts = coefficient_verdicts(ctx.run.extras.get("identifiability"))
    profile = s.get("profile_intervals") or {}
    heads = ["coefficient", "median", INTERVAL_LABEL] + ([PROFILE_LABEL] if profile else [])
    heads += [LIT_LABELS.get(k, k) for k in lit]
    if truth:
        heads.append("truth (synthetic data)")
    if verdicts:
        heads.append("identifiability")
    rows = []
    for n in ctx.coefficients:
        q = p[n]
        lo, hi = q[INTERVAL[0]], q[INTERVAL[1]]
        scale = max(abs(lo), abs(hi), abs(q["q50"]))
        row = [n, *fmt_estimate(q["q50"], lo, hi)]
        if profile:
            pi = profile.get(n)
            row.append(fmt_estimate(pi["q50"], pi["q05"], pi["q95"])[1] if pi else "–")
        row += [compare(lit[k].get(n), lo, hi, scale) for k in lit]
        if truth:
            row.append(compare(truth.get(n), lo, hi, scale))
        if verdicts:
            row.append(verdicts.get(n, "–"))
        rows.append(row)
    return table(heads, rows, "num answer")


def noise_choice_rows(choice: dict) -> list[list[str]]:
    """One row per marker flight of ``summary.json``'s ``noise_choice``: flight, its marker noise, and why.

    Parameters
    ----------
    choice : dict
        {flight: record} (:class:`bayes_disc.inference.fitting.noise_choice.NoiseChoice`).

    Returns
    -------
    list of [flight, model, reason]
    """
    rows = []
    for flight, r in choice.items():
        label = r.get("label", "")
        model = NOISE_WORDS.get(label, label)
        rho = (r.get("rho") or {}).get(label)
        if rho is not None:
            model += f", ρ̂ = {rho:.2f} per frame"
        by = r.get("by")
        if by == "configuration":
            why = "as configured"
        elif by == "gross errors":
            why = (f"{r.get('outliers', 0)} point(s) judged gross errors and {r.get('swaps', 0)} frame(s) "
                   "label-swapped at the white fit; removed before sampling")
        else:
            ref, delta = r.get("reference"), r.get("delta_bic") or {}
            others = {k: v for k, v in delta.items() if k != ref and v is not None}
            if label == ref:
                best = max(others, key=others.get, default=None)
                why = ("no candidate reaches ΔBIC > " + _evidence(r.get("threshold_delta_bic"))
                       + (f" (best: {NOISE_WORDS.get(best, best)}, {others[best]:+.1f})" if best else ""))
            else:
                why = f"ΔBIC {delta[label]:+.0f} over {NOISE_WORDS.get(ref, ref)} noise"
        rows.append([flight, model, why])
    return rows


#: noise labels (``noise_choice``) in words
NOISE_WORDS = {"white": "white", "per_point": "white, per-point errors", "ar1": "AR(1)",
               "ar1_per_point": "AR(1), per-point errors", "robust": "robust (gross errors removed)"}


def noise_choice_html(summary: dict) -> str:
    """The marker noise of every flight and why, for the first screen ("" for a run without the record)."""
    choice = summary.get("noise_choice") or {}
    if not choice:
        return ""
    auto = any(r.get("by") != "configuration" for r in choice.values())
    how = "<code>noise: auto</code> chooses by evidence at the least squares; " if auto else ""
    return (f"<p class=note>Marker noise per flight ({how}<code>noise_choice</code> in summary.json):</p>"
            + table(["flight", "marker noise", "why"], noise_choice_rows(choice), "noise-choice"))


def profile_note(summary: dict) -> str:
    """Which interval to quote, below the coefficient table ("" for a run without profile intervals)."""
    if not summary.get("profile_intervals"):
        return ""
    return ("<p class=note><b>Which interval to quote.</b> The 90 % interval is the posterior's (credible); the "
            "profile 90 % interval comes from the coefficient's profile likelihood alone, every other parameter "
            "re-optimised (<code>profile_intervals</code> in summary.json). At fixed truths of varied four-flight "
            "designs the profile intervals come closer to their nominal coverage than the credible ones, whose "
            "CRr and CRp intervals are about a fifth too narrow there (docs/validation.md, Profile intervals). "
            "For a statement about one coefficient of this disc (\"the true value lies in …, 90 % of the "
            "time\"), quote the profile interval; use the posterior for joint questions (correlations, "
            "predictions, functions of several coefficients). Both assume the model is adequate.</p>")


def literature_test_note(summary: dict) -> str:
    """Each published set tested as a whole against the data's joint profile region (``literature_tests`` in
    summary.json; "" for a run without them)."""
    tests = summary.get("literature_tests") or {}
    if not tests:
        return ""
    items = []
    for key, t in tests.items():
        if t.get("below_optimum"):
            items.append(f"<b>{esc(LIT_LABELS.get(key, key))}</b>, its {t['dof']} values together: a lower cost "
                         f"than the least-squares optimum (W = {fmt(t['deviance'])}), so the optimum this run "
                         "reports is not the lowest point and these values fit the data better")
            continue
        where = "inside" if t["inside_90"] else "outside"
        p = esc(p_text(t["p_value"]))
        bound = "" if t["converged"] else " (an upper bound: its fit stopped at its budget)"
        items.append(f"<b>{esc(LIT_LABELS.get(key, key))}</b>, its {t['dof']} values together: "
                     f"W = {fmt(t['deviance'])}{bound}, {where} the data's joint 90 % region ({p})")
    return ("<p class=note><b>Published sets as a whole.</b> " + "; ".join(items) + ". W is the profile "
            "deviance of the set's values held together, every other parameter re-optimised: χ² with as many "
            "degrees of freedom as values when the set is this disc's truth "
            "(<code>literature_tests</code> in summary.json).</p>")


def qualified_by_adequacy(ident: Verdict, diagnosis: dict | None) -> Verdict:
    """The identifiability line, qualified when ``diagnose`` left structure no term explains: the verdicts
    then describe the curvature of a model the data reject, so "identified" is not a finding.

    Parameters
    ----------
    ident : Verdict
        :func:`identifiability_verdict`'s line.
    diagnosis : dict or None
        Content of ``diagnosis.json``.

    Returns
    -------
    Verdict
        ``ident``, or the same line with the caveat and status "attention".
    """
    if not diagnosis or not diagnosis.get("unexplained") or ident.status == "not run":
        return ident
    text = (ident.text + " These verdicts are local to a model that leaves unexplained structure in the "
            "data (Model adequacy): an identified coefficient of a misfitting model is not a finding.")
    return Verdict(ident.topic, "attention", text, ident.command, ident.link)

def answer_section(ctx) -> Section:
    """The first screen: what was estimated, the three verdicts, the coefficient table, each flight's marker
    noise (below the table, which stays on screen without scrolling)."""
    conv = convergence_verdict(ctx.summary["convergence"], ctx.summary.get("sampler_settings"))
    ident = identifiability_verdict(ctx.run.extras.get("identifiability"), ctx.coefficients, ctx.run.config_path)
    diag = ctx.run.extras.get("diagnosis")
    coverage = None if diag or not ctx.marker_flights else ctx.predictive_coverage   # markers' predictive check
    adequacy = adequacy_verdict(diag, ctx.run.config_path, coverage)
    ident = qualified_by_adequacy(ident, diag)
    verdicts = '<ul class="verdicts">' + "".join(render_verdict(v) for v in (conv, ident, adequacy)) + "</ul>"
    lit_note = ("<p class=note><i>in</i> / <i>out</i>: the published (or true) value lies inside / outside the "
                "posterior 90 % interval. Published values come from other discs and other methods, so "
                "<i>out</i> is a finding, not an error. Rate coefficients (CMq, CRr, CRp, CNr) are per rad/s; "
                "Potts &amp; Crowther give none. Details, 95 % intervals, R-hat and ESS per coefficient: "
                '<a href="#coefficients">Coefficients</a>.</p>')
    html = (estimated_text(ctx) + verdicts + answer_table(ctx) + lit_note + literature_test_note(ctx.summary)
            + profile_note(ctx.summary) + noise_choice_html(ctx.summary))
    return Section("answer", "Result", "", html)   # no reading guide: the first screen explains itself
