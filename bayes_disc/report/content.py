"""The standard section builders of a sampled run: coefficients, posterior, convergence, residuals, flights, force
curves and the appendix (see :mod:`.sections`; identifiability and missing physics: :mod:`.findings`). Each takes a
ReportContext and returns a Section."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ..inference.model.layout import IC_NAMES as IC_ORDER
from ..inference.fitting.leastsq import noise_text
from ..inference.results.summary import STALLED_ACCEPTANCE, stalled_moves
from ..inference.results.versions import software_versions
from . import figures as F
from .answer import LIT_LABELS, compare
from .sections import Raw, Section, esc, fmt, fmt_count, fmt_estimate, ordinal, table

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
        ("prior of the initial conditions", _ic_prior_text(s.get("initial_condition_prior") or {})),
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



def _ic_prior_text(record: dict) -> str:
    """summary.json's ``initial_condition_prior`` in words: the prior and, for ``reference``, how closely its
    surrogate followed the exact prior at the posterior's draws and what the exact prior would change."""
    if not record:
        return "–"
    text = f"{record['initial_conditions']}: {record['description']}"
    check = record.get("posterior_check")
    if not check or not check.get("made"):
        return text + (f" (not checked at the posterior's draws: {check['why']})" if check else "")
    text += (f". At {check['draws']} posterior draws the surrogate the sampler used is within "
             f"{check['rms_error']:.2f} nats rms of the exact prior; reweighting the draws to the exact prior moves "
             f"the coefficients' means and sds by at most {check['largest_shift']:.2f} posterior sd")
    if not check["moves_intervals"]:
        return text + " (under the exact prior the intervals stand within that)"
    if not check["reweighted"]:
        return text + (f", and its weights cannot be trusted (Pareto k̂ {check['pareto_k']:.2f}): the intervals "
                       "follow the surrogate")
    moved = [n for n in check["mean_shift"] if max(abs(check["mean_shift"][n]), abs(check["sd_ratio"][n] - 1.0))
             > check["shift_tolerance"]]
    return text + ("; the intervals follow the surrogate. Under the exact prior: " + "; ".join(
        f"{n} median {check['reweighted'][n]['q50']:.4g}, 90 % {check['reweighted'][n]['q05']:.4g} … "
        f"{check['reweighted'][n]['q95']:.4g}" for n in moved))


def _lower_optimum_rows(ls: dict) -> list[tuple[str, str]]:
    """One appendix row per least-squares refit from a point below the optimum, found by a profile or by a
    published set's joint test (``lower_optima`` of ``least_squares.json``; none for runs written before that
    key)."""
    rows = []
    for k, low in enumerate(ls.get("lower_optima") or []):
        if "joint_test" in low:
            what = (f"the {LIT_LABELS.get(low['joint_test'], low['joint_test'])} values held together fitted better "
                    f"than the earlier optimum (W = {low['deviance']:.2f})")
        else:
            what = (f"the profile of {low['profile']} went below the earlier optimum (deviance {low['deviance']:.2f} "
                    f"at t = {low['t']:+.2f})")
        rows.append((f"refit {k + 1} from a lower point", f"{what}; that optimum's cost with the new noise scales: "
                     f"{low['earlier_cost']:.1f}, the new one's {ls['cost']:.1f}"))
    return rows


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


def _moves_table(conv: dict) -> str:
    """The sampler's moves after the warm-up: share of the proposals, proposals and acceptance; a sentence
    when some have stalled (:func:`stalled_moves`), with where the draws' mean lies (``log_prob_gap_at_mean``)
    against a Gaussian posterior of as many parameters (``dimension``). Empty for runs that do not record
    them."""
    moves = conv.get("moves") or {}
    if not moves:
        return ""
    gap, dim = conv.get("log_prob_gap_at_mean"), conv.get("dimension")
    shape = ("" if gap is None else
             f" The log-posterior at the draws' mean lies {fmt(abs(gap), 3)} nats {'below' if gap > 0 else 'above'} "
             "that of the median draw"
             + (f" (for a Gaussian posterior of {dim} parameters it lies about {dim / 2:g} above)" if dim else "")
             + (": the posterior is curved." if gap > 0 else "."))
    rows = [[label, fmt(m["share"], 2), fmt_count(m["proposals"]),
             "–" if m["acceptance"] is None else f"{100 * m['acceptance']:.1f} %"] for label, m in moves.items()]
    stalled = stalled_moves(moves)
    note = (f"<p><b>{esc(' and '.join(stalled))}</b> accepted less than {STALLED_ACCEPTANCE:.0%} of the time: "
            "these proposals (an approximation of the posterior drawn from afresh) do not fit it — typically a "
            "curved or very thin ridge — so the walkers moved by the local moves alone, and the autocorrelation "
            f"times are long.{esc(shape)}</p>" if stalled else "")
    return ("<h3>Moves after the warm-up</h3>" + table(["move", "share", "proposals", "accepted"], rows, "num")
            + note)


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
            + table(heads, [row(n) for n in main_names], "num") + _moves_table(conv)
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
