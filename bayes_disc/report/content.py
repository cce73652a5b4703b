"""The standard section builders (see :mod:`.sections`). Each takes a ReportContext, returns a Section."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ..inference.model.layout import IC_NAMES as IC_ORDER
from ..inference.fitting.leastsq import noise_text
from ..inference.results.versions import software_versions
from ..observation.models.inertial import SERIES as INERTIAL_SERIES, SERIES_UNITS as INERTIAL_UNITS
from ..observation.models.magnetometer import MAG_SERIES
from ..observation.models.markers import ROTATIONS
from ..physics import TERMS, Disc
from ..physics.discrepancy import coefficient_curve
from ..physics.nature import NATURE
from . import figures as F
from .answer import LIT_LABELS, compare
from .sections import Raw, Section, esc, fmt, fmt_count, fmt_estimate, fmt_percent, ordinal, table

#: at most this many steps per trace line and draws per chain in the rank plots (evenly thinned)
MAX_TRACE_STEPS = 1000
MAX_RANK_DRAWS = 250
FORCE_COEFS = ("CL0", "CLa", "CD0", "CDa", "CM0", "CMa")
IC_LABELS = {"x": "x [m]", "y": "y [m]", "z": "z [m]", "vx": "vx [m/s]", "vy": "vy [m/s]", "vz": "vz [m/s]",
             "th1": "ϑ1 [rad]", "th2": "ϑ2 [rad]", "th3": "ϑ3 [rad]", "wx": "ωx [rad/s]", "wy": "ωy [rad/s]",
             "wz": "ωz [rad/s]"}


# ---------------------------------------------------------------------------------------------- helpers
def _figure(ctx, fig, name: str, caption: str):
    rf = F.save_figure(fig, ctx.figure_dir, name, caption)
    ctx.figures_written.append(rf)
    return rf


def _range(x, digits=1, scale=1.0) -> str:
    x = np.asarray(x, float) * scale
    if not np.isfinite(x).any():
        return "–"
    return f"{np.nanmin(x):.{digits}f} … {np.nanmax(x):.{digits}f}"


def _prior_table(prior: dict) -> dict:
    """{coefficient: (mean, sd)} of the run's Gaussian prior from summary.json's ``prior`` record (its
    ``mean``/``sd``, or for runs written before they were recorded, the named set); empty if unknown."""
    if "mean" in prior and "sd" in prior:
        return {k: (prior["mean"][k], prior["sd"][k]) for k in prior["mean"]}
    from ..inference.model.priors import coefficient_prior
    try:
        cp = coefficient_prior(prior["name"])
    except KeyError:
        return {}
    return {k: (cp.mean[k], cp.sd[k]) for k in cp.mean}


# ---------------------------------------------------------------------------------------------- sections
def _sampler_rows(settings: dict, conv: dict) -> list[tuple]:
    """The sampler settings as (name, value) rows, with the walkers actually used (a configured 0 means
    "automatic": the smallest even number ≥ 2·dim)."""
    rows = []
    for k, v in sorted(settings.items()):
        if k == "walkers" and "walkers_per_ensemble" in conv:
            used = conv["walkers_per_ensemble"]
            v = f"{used} per ensemble" + (" (automatic: smallest even number ≥ 2 × parameters)" if not v else "")
        rows.append((k, v))
    return rows


def flights_table(ctx) -> str:
    """Data, time span and covered conditions (α, speed, spin of the highest-posterior draw) per flight."""
    rows = []
    for k, (name, f) in enumerate(ctx.summary["flights"].items()):
        kk = ctx.kinematics[k]
        data = []
        if "points" in f:
            data.append(f"{f['points']} marker points ({f['samples']} samples)")
        if "inertial_values" in f:
            data.append(f"{f['inertial_values']} inertial values ({f['inertial_rows']} rows)")
        rows.append((name, Path(str(f.get("file", ""))).name, "; ".join(data),
                     f"{fmt(float(kk['times'][0]))} … {fmt(float(kk['times'][-1]))}",
                     _range(kk["alpha_ref"], 1, 180 / np.pi), _range(kk["speed"], 1), _range(kk["spin"], 0)))
    return table(["flight", "file", "data", "t [s] (simulated)", "α [deg]", "air speed [m/s]",
                  "spin ω·b3 [rad/s]"], rows, "num")


def appendix_section(ctx) -> Section:
    """Run, sampler, least-squares start and software: how the result was produced."""
    s = ctx.summary
    conv = s["convergence"]
    info = ctx.run.run_info
    files = sorted({str(f.get("file", "")) for f in s["flights"].values()})
    n_kept = conv["kept_steps"] * conv["walkers_per_ensemble"] * conv["ensembles"]
    general = table(["item", "value"], [
        ("run", s["name"]), ("run folder", str(ctx.run.run_dir)), ("configuration", str(ctx.run.config_path)),
        ("data files", ", ".join(files)),
        ("flights", len(s["flights"])),
        ("posterior samples kept", f"{conv['kept_steps']} steps × {conv['walkers_per_ensemble']} walkers × "
                                   f"{conv['ensembles']} ensembles = {n_kept}"),
        ("burn-in", f"{conv['burn_in_steps']} of {conv['total_steps']} steps"),
        ("prior", f"{s['prior']['name']}: {s['prior']['description']}"),
        ("physics terms beyond the ten-coefficient model", ", ".join(s.get("physics_terms") or []) or "none"),
        ("truth file", "yes (synthetic data; truths overlaid)" if ctx.truth_coefficients else "no"),
        ("wall time of the run", f"{info['wall_time_s']:.0f} s" if "wall_time_s" in info else "–"),
        ("of which sampling", f"{info['sampling_wall_time_s']:.0f} s" if "sampling_wall_time_s" in info else "–"),
    ], "kv")
    settings = s.get("sampler_settings") or {}
    sampler = table(["sampler setting", "value"], _sampler_rows(settings, conv), "kv")
    ls = s.get("least_squares") or {}
    ls_rows = [("cost", fmt(ls.get("cost"))), ("condition number", fmt(ls.get("condition_number"), 3)),
               ("residual RMS per noise group", _noise_rms(ls)), *_lower_optimum_rows(ls)]
    recorded = info.get("versions")
    if isinstance(recorded, dict) and recorded:
        software = ("<h3>Software (recorded by the run)</h3>"
                    + table(["package", "version"], list(recorded.items()), "kv"))
    else:
        software = ("<h3>Software (building this report)</h3><p class=note>The run folder records no versions; "
                    "these are the versions that built the report.</p>"
                    + table(["package", "version"], list(software_versions().items()), "kv"))
    html = ("<h3>Run</h3>" + general + '<div class="cols"><div><h3>Sampler</h3>' + sampler
            + "</div><div><h3>Least-squares start</h3>" + table(["item", "value"], ls_rows, "kv")
            + software + "</div></div>")
    return Section("appendix", "Appendix: run and software",
                   "How the result was produced: files, prior, sampler settings, the least-squares start and "
                   "the software versions.", html)



def _lower_optimum_rows(ls: dict) -> list[tuple[str, str]]:
    """One appendix row per least-squares refit from a point a profile found below the optimum
    (``lower_optima`` of ``least_squares.json``; none for runs written before that key)."""
    return [(f"refit {k + 1} from a lower point",
             f"the profile of {low['profile']} went below the earlier optimum (deviance {low['deviance']:.2f} at "
             f"t = {low['t']:+.2f}); that optimum's cost with the new noise scales: {low['earlier_cost']:.1f}, "
             f"the new one's {ls['cost']:.1f}")
            for k, low in enumerate(ls.get("lower_optima") or [])]


def _noise_rms(ls: dict) -> str:
    """The least-squares residual RMS of every noise group, with its unit (markers in mm); runs written
    before the ``noise`` key only have ``rms_mm`` (marker flights)."""
    noise = ls["noise"] if "noise" in ls else {
        f"sigma_{k}": {"value": 1e-3 * v, "unit": "m"} for k, v in (ls.get("rms_mm") or {}).items()}
    return noise_text(noise)


def _ic_scales(truth_ic: np.ndarray) -> np.ndarray:
    """(12,) magnitude of each initial-condition component's vector (position, velocity, attitude, rate):
    the scale against which a truth is round-off of zero."""
    return np.repeat([np.linalg.norm(truth_ic[i: i + 3]) for i in range(0, 12, 3)], 3)


def coefficient_table(ctx) -> Section:
    s = ctx.summary
    p = s["parameters"]
    lit = s["literature"]
    truth = ctx.truth_coefficients
    prior = _prior_table(s["prior"])
    heads = (["coefficient", "prior mean ± sd", "median", "90 % interval", "95 % interval"]
             + [LIT_LABELS.get(k, k) for k in lit])
    if truth:
        heads.append("truth")
    heads += ["R-hat", "bulk ESS", "tail ESS"]
    rows = []
    for n in s["coefficients"]:
        q = p[n]
        pm = prior.get(n)
        scale = max(abs(q["q05"]), abs(q["q95"]), abs(q["q50"]))
        med, i90 = fmt_estimate(q["q50"], q["q05"], q["q95"])
        row = [n, "–" if pm is None else f"{fmt(pm[0])} ± {fmt(pm[1])}", med, i90,
               fmt_estimate(q["q50"], q["q025"], q["q975"])[1]]
        row += [compare(lit[k].get(n), q["q05"], q["q95"], scale) for k in lit]
        if truth:
            row.append(compare(truth.get(n), q["q05"], q["q95"], scale))
        row += [fmt(q["r_hat"]), fmt_count(q["ess_bulk"]), fmt_count(q.get("ess_tail"))]
        rows.append(row)
    coef_html = table(heads, rows, "num")
    # per-flight quantities: noise scales, initial conditions, the flight's own observation-model parameters
    from ..inference.results.draws import flight_entries
    flights = ctx.flight_names
    problem = ctx.problem
    where = {}
    for var, k, kind, i in flight_entries(problem):
        unit = problem.layout.units[i] if kind == "theta" else problem.noise_units[i]
        where.setdefault((var, unit), {})[k] = kind
    truths = {f: ctx.truth_initial(k) if k in ctx.marker_flights else None for k, f in enumerate(flights)}
    scales = {f: (None if t is None else _ic_scales(t)) for f, t in truths.items()}
    frows = []
    for (var, unit), per in sorted(where.items(), key=lambda kv: (kv[0][0] not in ("sigma",) and
                                                                  not kv[0][0].startswith("sigma"))):
        mm = unit == "m" and var == "sigma"
        label = ("σ [mm]" if mm else IC_LABELS.get(var, f"{var} [{unit}]"))
        row = [label]
        for k, f in enumerate(flights):
            if k not in per:
                row.append("–")
                continue
            q = p[f"{var}_{f}"]
            sc = 1e3 if mm else 1.0
            cell = f"{fmt(q['q50'] * sc, 3 if mm else 4)} ({fmt(q['q05'] * sc, 3 if mm else 4)} … " \
                   f"{fmt(q['q95'] * sc, 3 if mm else 4)})"
            if var == "sigma" and ctx.truth_sigma(f) is not None:
                cell += f"<br><span class=truth>truth {ctx.truth_sigma(f) * 1e3:.3g}</span>"
            elif truths[f] is not None and var in IC_ORDER:
                j = IC_ORDER.index(var)
                cell += (f"<br><span class=truth>truth "
                         f"{compare(float(truths[f][j]), q['q05'], q['q95'], scales[f][j]).html}</span>")
            row.append(Raw(cell))
        frows.append(row)
    flight_html = table(["parameter"] + flights, frows, "num")
    html = (coef_html + "<p class=note><i>in</i> / <i>out</i>: the published (or true) value lies inside / outside "
            "the posterior 90 % interval (with a truth, about one value in ten is <i>out</i> by chance). Rate "
            "coefficients (CMq, CRr, CRp, CNr) are per rad/s, as in Hummel &amp; Hubbard (2002); Potts "
            "&amp; Crowther give no rate terms. The model, its coefficients and the published sets: docs/conventions.md in the repository.</p>"
            "<h3>Noise scale and initial conditions per flight</h3>" + flight_html
            + "<p class=note>Median (5 % … 95 %). Initial state at the flight's first sample: position, "
              "velocity, attitude as a rotation vector ϑ relative to the data-derived start attitude, and "
              "body-frame angular velocity. A truth that is zero up to round-off is shown as 0.</p>")
    return Section("coefficients", "Coefficients in detail",
                   "Prior, posterior median, 90 % and 95 % intervals, published values, R-hat and effective "
                   "sample sizes of every coefficient; then each flight's noise scale and initial state.", html)


def corner_section(ctx) -> Section:
    x = ctx.coefficient_samples
    rng = np.random.default_rng(ctx.seed + 1)
    if x.shape[0] > ctx.n_corner_samples:
        x = x[np.sort(rng.choice(x.shape[0], ctx.n_corner_samples, replace=False))]
    names = ctx.coefficients
    truth = ctx.truth_coefficients
    truths = [truth.get(n) for n in names] if truth else None
    fig = F.corner_figure(x, names, truths)
    lv = " and ".join(f"{int(round(100 * v))} %" for v in F.CORNER_LEVELS)
    cap = (f"Joint posterior of the ten coefficients ({x.shape[0]} samples). Contours enclose {lv} of the "
           "posterior mass; dashed lines in the histograms are the 5 %, 50 % and 95 % quantiles"
           + ("; red lines are the true values" if truths else "")
           + "; small coefficients are shown multiplied by the power of ten in their label.")
    rf = _figure(ctx, fig, "corner", cap)
    return Section("corner", "Posterior of the ten coefficients",
                   f"Diagonal: each coefficient's marginal; off-diagonal: pairs, contours at {lv} probability; "
                   "elongated, tilted contours mean the data trade one coefficient against another.",
                   f"<p class=note>{esc(cap)}</p>", [rf])


def _trace_bands(ctx, names):
    """Walker 5/50/95 % quantiles per step for each ensemble from the chain files (incl. burn-in)."""
    import h5py
    idx = [ctx.problem.names.index(n) for n in names]
    chain_dir = ctx.run.run_dir / "chains"
    files = sorted(chain_dir.glob("ensemble_*.h5"), key=lambda p: int(p.stem.split("_")[-1]))
    bands = []
    for path in files:
        with h5py.File(path, "r") as f:
            g = f["mcmc"]
            n = int(g.attrs["iteration"])
            c = g["chain"][:n, :, min(idx): max(idx) + 1][:, :, np.array(idx) - min(idx)]
        thin = int(np.ceil(n / MAX_TRACE_STEPS))
        bands.append(np.moveaxis(np.quantile(c[::thin], [0.05, 0.5, 0.95], axis=1), 0, -1))
    return bands, thin


def convergence_section(ctx) -> Section:
    s = ctx.summary
    conv = s["convergence"]
    p = s["parameters"]
    names = ctx.coefficients
    figs = []
    try:
        bands, thin = _trace_bands(ctx, names)
        burn = int(conv["burn_in_steps"])
        src = "chain files (all steps" + (f", every {ordinal(thin)} shown" if thin > 1 else "") + ")"
    except (OSError, KeyError, ValueError):
        bands, thin = [], 1
    if not bands:  # chain files absent: kept steps from posterior.nc
        post = ctx.coefficient_chains
        ens = ctx.ensemble_of_chain
        bands = [np.moveaxis(np.quantile(post[ens == e], [0.05, 0.5, 0.95], axis=0), 0, -1)
                 for e in np.unique(ens)]
        burn = 0
        src = "posterior.nc (kept steps only)"
    figs.append(_figure(ctx, F.trace_figure(bands, names, burn, step=thin), "trace",
                        f"Traces per ensemble from the {src}: coloured line = an ensemble's walker median, grey band "
                        "= the walkers' 5–95 % range (lowest and highest over the ensembles)."))
    post = ctx.coefficient_chains
    thin = int(np.ceil(post.shape[1] / MAX_RANK_DRAWS))
    figs.append(_figure(ctx, F.rank_figure(post[:, ::thin], ctx.ensemble_of_chain, names), "ranks",
                        "Rank plots of the kept samples" + (f" (every {ordinal(thin)} step)" if thin > 1 else "")
                        + ": histogram of each ensemble's ranks among all samples; flat at 1 (dotted) when the "
                        "ensembles sample the same distribution."))
    tau = conv.get("tau_steps") or {}
    kept = conv["kept_steps"]
    settings = s.get("sampler_settings") or {}

    def row(n):
        t = tau.get(n)
        ratio = kept / t if t and np.isfinite(t) and t > 0 else None
        r = p[n]["r_hat"]
        bad = (r is None or not np.isfinite(r) or r >= settings.get("rhat", 1.01))
        return [n, Raw(f'<span class="{"disagree" if bad else "agree"}">{esc(fmt(r))}</span>'),
                fmt_count(p[n]["ess_bulk"]), fmt(t, 3), fmt(ratio, 3)]
    main_names = names + [n for n in p if n.startswith("sigma_")]
    ic_names = [n for n in p if n not in main_names]
    heads = ["parameter", "R-hat (across ensembles)", "bulk ESS", "τ [steps]", "kept steps / τ"]
    crit = (f"Stopping rule: kept steps ≥ {fmt(settings.get('n_tau'))} τ, R-hat &lt; {fmt(settings.get('rhat'))} "
            f"for every parameter, bulk ESS ≥ {fmt(settings.get('ess'))} for every coefficient; cap "
            f"{settings.get('max_steps', '–')} steps.")
    state = "Converged" if conv["converged"] else "<b>Not converged</b>"
    why = "" if str(conv["reason"]).strip().lower() == "converged" else f": {esc(conv['reason'])}"
    html = (f"<p>{state}{why}. {crit}</p>"
            + table(heads, [row(n) for n in main_names], "num")
            + f"<details><summary>Initial conditions ({len(ic_names)} parameters)</summary>"
            + table(heads, [row(n) for n in ic_names], "num") + "</details>")
    return Section("convergence", "Convergence",
                   "Ensembles should overlap in the traces after burn-in and give flat rank histograms; R-hat "
                   "near 1 (red if above the run's threshold), large ESS and many autocorrelation times τ.",
                   html, figs)


def residual_section(ctx) -> Section | None:
    if not ctx.marker_flights:
        return None
    sims = ctx.flight_sims
    fig = _figure(ctx, F.residual_figure(sims), "residuals",
                  "Measured − predicted marker coordinates for the highest-posterior draw, per flight (columns), "
                  "axis (rows) and marker (colours); grey: ±2σ of the flight's posterior noise scale; cf. Hummel "
                  "& Hubbard (2002) Fig. 2.")
    rows = []
    p = ctx.summary["parameters"]
    for s in sims:
        r = s.residuals * 1e3
        per_axis = [float(np.sqrt(np.nanmean(r[..., a] ** 2))) for a in range(3)]
        rows.append([s.name, f"{s.rms * 1e3:.2f}"] + [f"{v:.2f}" for v in per_axis]
                    + [f"{p[f'sigma_{s.name}']['q50'] * 1e3:.2f}"])   # marker flights only
    html = table(["flight", "RMS [mm]", "x", "y", "z", "posterior σ median [mm]"], rows, "num")
    return Section("residuals", "Residuals",
                   "Residuals should look like white noise around zero with an RMS close to the fitted σ; "
                   "slow trends or oscillations point at missing physics or a bad start.", html, [fig])


def flight_section(ctx) -> Section | None:
    if not ctx.marker_flights:
        return None
    sims = ctx.flight_sims
    kin = [ctx.kinematics[k] for k in ctx.marker_flights]
    f_alpha = _figure(ctx, F.alpha_figure(sims, [k["alpha_ref"] for k in kin], [k["alpha_draws"] for k in kin]),
                      "angle_of_attack", "Angle of attack against time per flight: highest-posterior draw and the "
                      "90 % band of posterior draws (cf. Hummel & Hubbard 2002 Fig. 3); lower row: the band "
                      "minus the draw, magnified (a tight band is thinner than the line above).")
    f_traj = _figure(ctx, F.trajectory_figure(sims), "trajectories",
                     "Measured markers (dots) and the predicted marker paths of the highest-posterior draw "
                     "(lines): top view (y against x) and side view (z against x).")
    bands = ctx.predictive
    f_pp = _figure(ctx, F.predictive_figure(sims, bands), "posterior_predictive",
                   f"Posterior predictive check ({len(ctx.band_indices)} posterior draws, each with its own "
                   "noise σ): grey band = 90 % interval of replicated minus predicted coordinates (averaged over "
                   "markers); dots = measured minus predicted.")
    rows = [[s.name, f"{100 * b[2]:.1f} %", len(ctx.band_indices)] for s, b in zip(sims, bands)]
    html = ("<p class=note>Data per flight, and the conditions it covers (α, speed and spin of the "
            "highest-posterior draw's trajectory).</p>" + flights_table(ctx)
            + "<p class=note>A well-calibrated fit has about 90 % of the measured coordinates inside their "
            "90 % posterior predictive interval.</p>"
            + table(["flight", "coordinates inside 90 % predictive interval", "posterior draws"], rows, "num"))
    return Section("flights", "Flights: angle of attack, trajectories and posterior predictive check",
                   "Which angles of attack each flight covered (wide ranges pin down the α-slopes), how the "
                   "predicted paths match the measured markers, and whether the data sit inside the predictive band.",
                   html, [f_alpha, f_traj, f_pp])


def force_curve_section(ctx) -> Section:
    from ..physics.windtunnel import load_wind_tunnel
    tunnel = load_wind_tunnel()
    kin = ctx.kinematics
    a_all = np.concatenate([k["alpha_ref"] for k in kin])
    lo, hi = float(np.degrees(np.nanmin(a_all))), float(np.degrees(np.nanmax(a_all)))
    samples = ctx.coefficient_samples[:, [ctx.coefficients.index(n) for n in FORCE_COEFS]]
    rng = np.random.default_rng(ctx.seed + 3)
    if samples.shape[0] > 4000:
        samples = samples[rng.choice(samples.shape[0], 4000, replace=False)]
    coef = {n: samples[:, i] for i, n in enumerate(FORCE_COEFS)}
    lit = {LIT_LABELS.get(k, k): v for k, v in ctx.summary["literature"].items()}
    fig = _figure(ctx, F.force_curve_figure(coef, (lo, hi), tunnel, lit, ctx.truth_coefficients), "force_curves",
                  f"Implied CL(α) = CL0 + CLa·α, CD(α) = CD0 + CDa·α², CM(α) = CM0 + CMa·α: posterior median and "
                  f"90 % band over the flown range α = {lo:.1f}…{hi:.1f}° (shaded; dotted: extrapolation of the "
                  "median), published linearisations, and the wind-tunnel measurements (squares); lower row: "
                  "the 90 % band minus the median, magnified.")
    html = (f"<p class=note>Wind-tunnel data: {esc(tunnel.citation)}</p>")
    return Section("force-curves", "Implied force and moment curves",
                   "The flights constrain the curves only over the flown α range (shaded); compare the band with "
                   "the wind-tunnel squares there, not in the extrapolation.", html, [fig])


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
                 **{s: (f"magnetometer {s[-1]} [µT]", 1.0) for s in MAG_SERIES}}


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
