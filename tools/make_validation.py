"""Build docs/validation.md from the result files committed in the repository.

Every number on that page is read from a JSON file under ``runs/`` or ``benchmarks/results/``; this script
holds the claims, the tables' layout and the rules of each verdict, never a result. Run from anywhere:

    python tools/make_validation.py            # (re)write docs/validation.md
    python tools/make_validation.py --check    # exit 1 and print a diff when docs/validation.md is stale
    python tools/make_validation.py --recovery RUN_DIR TRUTH.json   # print a recovery table for a sampled run

Needs numpy and scipy only (no bayes_disc import), so it runs in a few seconds.
"""
from __future__ import annotations

import argparse
import difflib
import json
import math
import sys
from pathlib import Path

import numpy as np
from scipy import stats

sys.path.insert(0, str(Path(__file__).resolve().parent))

from validation_common import (COEFFICIENTS, PREDICTION_HEADER, ROOT, binomial_band, familywise_mass,  # noqa: E402
                               fmt, fold_names, inside, load, outside_probability, prediction_rows, table)
from validation_fixed_truth import section_fixed_truth  # noqa: E402
from validation_profile import section_profile_intervals  # noqa: E402
from validation_wobble import nutation_blind, random_nutation_lines, real_wobble, section_real_wobble  # noqa: E402

OUT = ROOT / "docs" / "validation.md"
LEVELS = ("50", "90")

#: the calibration campaigns on the page: (file stem, what it holds). Results come from their folders.
CAMPAIGNS = [
    ("four_flights_white", "the demo's four flights, white marker noise, seed 16"),
    ("four_flights_white_seed17", "the same campaign on 100 other data sets, seed 17"),
    ("four_flights_ar1", "the four flights with AR(1) marker noise ρ = 0.85, fitted with `noise: {model: ar1}`, seed 161"),
    ("four_flights_ar1_seed162", "the AR(1) campaign on 100 other data sets, seed 162"),
    ("four_flights_per_point", "a quarter of every flight's samples 10× noisier and stated in `sigma_m`, "
                               "fitted with per-point errors"),
    ("four_flights_one_sigma", "the per-point campaign's data sets fitted with one σ per flight"),
    ("four_flights_ar1_default", "the four flights with AR(1) marker noise ρ = 0.85, fitted with the default "
                                 "configuration (`noise: auto`, the reference prior of the initial conditions), "
                                 "seed 163 (short sampler settings: 2 ensembles, at most 400 steps)"),
    ("four_flights_varied", "a varied design per replicate (a slow high-α throw, two fast low-α throws, a "
                            "wobbling release; 1–3 mm white noise), the default prior of the initial conditions "
                            "(`reference`); truths drawn around Hummel & Hubbard, fitted with the default coefficient "
                            "prior (`potts_crowther`), so the ranks need not be uniform: coverage of truths the prior "
                            "does not centre on, as a user's disc would be; seed 171, short sampler settings"),
    ("four_flights_varied_flat", "the same 100 data sets fitted with `prior.initial_conditions: flat`"),
]
#: campaigns that share template, prior and settings and differ only in their seed: pooled
POOLS = [("white noise", ["four_flights_white", "four_flights_white_seed17"]),
         ("AR(1) noise", ["four_flights_ar1", "four_flights_ar1_seed162"])]
#: a concealed form of nature and the library family that describes it (definitions, not results)
NATURE_FAMILY = {"ground_effect_power": "ground_effect", "wind_tunnel_aero": "nonlinear_aero",
                 "wind_power_shear": "wind", "side_force_saturating": "side_force"}


# ----------------------------------------------------------------------------------------- small helpers
# ----------------------------------------------------------------------------------------- calibration
def replicate_records(stem: str) -> list[dict]:
    folder = ROOT / "runs" / "calibration" / stem / "replicates"
    recs = [json.loads(p.read_text()) for p in sorted(folder.glob("replicate_*.json"))]
    return [r for r in recs if r.get("status", "ok") == "ok"]


def z_sd(recs: list[dict], c: str) -> float:
    """sd over the replicates (ddof 1) of z = (truth − posterior mean)/posterior sd, as ``calibrate`` computes it."""
    return float(np.std([(r["truth"][c] - r["posterior"][c]["mean"]) / r["posterior"][c]["sd"] for r in recs], ddof=1))


def coverage_stats(n: int, cov: dict) -> dict:
    """Bands and verdict inputs for K = 2 × coefficients coverages of N replicates."""
    k = len(COEFFICIENTS) * len(LEVELS)
    own = {lv: binomial_band(n, int(lv) / 100) for lv in LEVELS}
    fw = {lv: binomial_band(n, int(lv) / 100, familywise_mass(k)) for lv in LEVELS}
    outside_own = [(c, lv) for c in COEFFICIENTS for lv in LEVELS if not inside(cov[c][lv], own[lv])]
    outside_fw = [(c, lv) for c in COEFFICIENTS for lv in LEVELS if not inside(cov[c][lv], fw[lv])]
    expected = sum(outside_probability(n, int(lv) / 100) for lv in LEVELS) * len(COEFFICIENTS)
    return {"own": own, "fw": fw, "outside_own": outside_own, "outside_fw": outside_fw, "expected": expected}


def coverage_verdict(n: int, cs: dict, z_sd: dict, z_se: float) -> str:
    own, fw = cs["outside_own"], cs["outside_fw"]
    wide = [c for c in COEFFICIENTS if z_sd[c] - 1 > 2 * z_se]
    narrow_words = (f" The sd of z is more than two standard errors above 1 for {', '.join(wide)}: "
                    f"intervals possibly too narrow there." if wide else
                    " Every sd of z is within two standard errors of 1 or below it.")
    listed = ", ".join(f"{c} {lv} %" for c, lv in own)
    if fw:
        return (f"**Not calibrated:** {len(fw)} of 20 coverages outside the family-wise band "
                f"({', '.join(f'{c} {lv} %' for c, lv in fw)})." + narrow_words)
    if not own:
        return (f"**Consistent with calibration:** all 20 coverages inside their own 95 % bands "
                f"(chance puts {cs['expected']:.2f} outside on average)." + narrow_words)
    return (f"**Consistent with calibration:** {len(own)} of 20 coverages outside their own 95 % band ({listed}) "
            f"where chance puts {cs['expected']:.2f} on average; all 20 inside the family-wise band."
            + narrow_words)


def campaign_rows(cov: dict, p: dict, z: dict, cs: dict) -> list[list[str]]:
    rows = []
    for c in COEFFICIENTS:
        cells = [c]
        for lv in LEVELS:
            mark = "" if inside(cov[c][lv], cs["own"][lv]) else (" (outside)" if inside(cov[c][lv], cs["fw"][lv])
                                                               else " (**outside family-wise**)")
            cells.append(f"{cov[c][lv]:.3f}{mark}")
        cells += [f"{p[c]:.3f}", f"{z[c]:.2f}"]
        rows.append(cells)
    return rows


def bands_line(n: int, cs: dict, z_se: float) -> str:
    o, f = cs["own"], cs["fw"]
    return (f"N = {n}: 95 % bands {o['50'][0]:.3f}–{o['50'][1]:.3f} (50 %) and {o['90'][0]:.3f}–{o['90'][1]:.3f} "
            f"(90 %); family-wise {f['50'][0]:.3f}–{f['50'][1]:.3f} and {f['90'][0]:.3f}–{f['90'][1]:.3f}; "
            f"sd of z ± {z_se:.3f}.")


def partial_line(cal: dict) -> str:
    """Says so when the campaign was stopped before all its replicates ran (summarised with --summary-only)."""
    n, asked = cal["replicates"] + len(cal["failed"]), cal.get("requested", cal["replicates"])
    return f"Stopped part-way: {n} of the {asked} replicates asked for were run. " if n < asked else ""


def noise_line(cal: dict) -> str:
    """How often each marker noise model was used over the campaign's flights (campaigns that record it)."""
    chosen = cal.get("noise_chosen") or {}
    if not chosen:
        return ""
    return ("Marker noise models used, over all flights: "
            + ", ".join(f"{label} {count}" for label, count in sorted(chosen.items(), key=lambda x: -x[1])) + ". ")


def ic_prior_line(stem: str) -> str:
    """The prior of the initial conditions the campaign's runs used, from its recorded key (``campaign.json``):
    the one its run settings name, else the default."""
    prior = load(f"runs/calibration/{stem}/campaign.json")["run"].get("prior", {})
    named = prior.get("initial_conditions") if isinstance(prior, dict) else None
    return f"Prior of the initial conditions: {named or 'the default (reference)'}. "


def sampler_line(recs: list[dict]) -> str:
    with_settings = [r for r in recs if "sampler" in r]
    steps = [r["convergence"]["total_steps"] for r in recs]
    converged = sum(bool(r["convergence"]["converged"]) for r in recs)
    fr = sorted({r["sampler"].get("independence_fraction") for r in with_settings})
    span = f"{min(steps)} steps" if min(steps) == max(steps) else \
        f"{min(steps)}–{max(steps)} steps, median {int(np.median(steps))}"
    s = f"{converged} of {len(recs)} replicates converged ({span})."
    if with_settings:
        s += (f" Sampler settings recorded by {len(with_settings)} of {len(recs)} replicates "
              f"(Metropolis–Hastings share {', '.join(str(x) for x in fr)}).")
    else:
        s += (" The replicates do not record their sampler settings: they predate that record, so they were "
              "fitted with an earlier version of the sampler.")
    return s


def section_calibration() -> list[str]:
    L = ["## Calibration: interval coverage over many data sets", "",
         "**Claim.** The posterior intervals are calibrated: over data sets whose truths are drawn from the fit's "
         "prior, the central 50 % and 90 % intervals contain the truth in 50 % and 90 % of the data sets (up to "
         "binomial scatter), the truth's rank among the posterior draws is uniform, and the standardised error "
         "z = (truth − posterior mean)/posterior sd has sd 1 ([simulation-based calibration](calibration.md)).",
         "",
         "Each campaign fits every replicate exactly as `bayes-disc sample` does. A coverage outside its own 95 % "
         "band happens by chance with the probability shown; the family-wise band holds all 20 coverages of "
         "calibrated intervals with probability ≥ 95 %. Columns: coverage of the 50 % and 90 % intervals, "
         "rank-uniformity p (χ²), sd of z.", ""]
    for stem, what in CAMPAIGNS:
        cal = load(f"runs/calibration/{stem}/calibration.json")
        recs = replicate_records(stem)
        n = cal["replicates"]
        cov = {c: {lv: cal["coefficients"][c][f"coverage_{lv}"] for lv in LEVELS} for c in COEFFICIENTS}
        p = {c: cal["coefficients"][c]["rank_uniformity_p"] for c in COEFFICIENTS}
        z = {c: cal["coefficients"][c].get("z_sd", z_sd(recs, c)) for c in COEFFICIENTS}
        z_se = 1.0 / math.sqrt(2 * (n - 1))
        cs = coverage_stats(n, cov)
        L += [f"### `{stem}`: {what}", "",
              f"Files: [`runs/calibration/{stem}.yaml`](../runs/calibration/{stem}.yaml), "
              f"`runs/calibration/{stem}/calibration.json` and `replicates/`. {sampler_line(recs)} "
              + partial_line(cal) + ic_prior_line(stem) + noise_line(cal) + bands_line(n, cs, z_se), ""]
        L += table(["coefficient", "50 % coverage", "90 % coverage", "rank p", "sd of z"], campaign_rows(cov, p, z, cs))
        L += ["", "Verdict: " + coverage_verdict(n, cs, z, z_se), ""]
    for title, stems in POOLS:
        recs = [r for s in stems for r in replicate_records(s)]
        n = len(recs)
        cov = {c: {lv: float(np.mean([r["covered"][lv][c] for r in recs])) for lv in LEVELS} for c in COEFFICIENTS}
        counts = {c: np.sum([load(f"runs/calibration/{s}/calibration.json")["coefficients"][c]["rank_counts"]
                             for s in stems], axis=0) for c in COEFFICIENTS}
        p = {c: float(stats.chisquare(counts[c]).pvalue) for c in COEFFICIENTS}
        z = {c: z_sd(recs, c) for c in COEFFICIENTS}
        z_se = 1.0 / math.sqrt(2 * (n - 1))
        cs = coverage_stats(n, cov)
        L += [f"### Pooled, {title}: {' + '.join(f'`{s}`' for s in stems)}", "",
              "The two campaigns differ only in their seed, so together they are one campaign of their summed "
              "size (ranks binned as in each). " + bands_line(n, cs, z_se), ""]
        L += table(["coefficient", "50 % coverage", "90 % coverage", "rank p", "sd of z"], campaign_rows(cov, p, z, cs))
        L += ["", "Verdict: " + coverage_verdict(n, cs, z, z_se), ""]
    # what per-point errors gain: 90 % interval widths, same data sets
    a, b = replicate_records("four_flights_per_point"), replicate_records("four_flights_one_sigma")
    by_b = {r["index"]: r for r in b}
    pairs = [(r, by_b[r["index"]]) for r in a if r["index"] in by_b]
    rows, ratios = [], {}
    for c in COEFFICIENTS:
        rr = np.array([(x["posterior"][c]["q95"] - x["posterior"][c]["q05"]) /
                       (y["posterior"][c]["q95"] - y["posterior"][c]["q05"]) for x, y in pairs])
        ratios[c] = float(np.median(rr))
        rows.append([c, f"{np.median(rr):.2f}", f"{rr.min():.2f}–{rr.max():.2f}"])
    narrower = [c for c in COEFFICIENTS if ratios[c] < 0.9]
    L += ["### What per-point errors gain", "",
          f"The {len(pairs)} data sets of `four_flights_per_point` fitted with per-point errors and with one σ per "
          "flight (`four_flights_one_sigma`): ratio of the 90 % interval widths, per-point / one σ.", ""]
    L += table(["coefficient", "median ratio", "range over data sets"], rows)
    L += ["", f"Verdict: per-point errors narrow the 90 % intervals (median ratio below 0.9) for "
              f"{len(narrower)} of 10 coefficients ({', '.join(narrower) or 'none'}); the per-point campaign's "
              "coverage is in its table above.", "",
          "Reproduce (hours on two cores; a Dask cluster with `--scheduler`): "
          "`bayes-disc calibrate runs/calibration/<campaign>.yaml --workers 2`. A finished campaign is not rerun: "
          "only replicates without a record are fitted.", ""]
    return L


# ----------------------------------------------------------------------------------------- recovery
def recovery_rows(params: dict, truth: dict, names: list[str]) -> tuple[list[list[str]], int]:
    rows, n_in = [], 0
    for c in names:
        e = params[c]
        lo, hi = e.get("q025"), e.get("q975")
        mean = e.get("mean", e.get("value"))
        z = (truth[c] - mean) / e["sd"]
        ok = lo <= truth[c] <= hi
        n_in += ok
        rows.append([c, fmt(truth[c]), fmt(mean, 4), f"{fmt(lo, 4)} … {fmt(hi, 4)}", f"{z:+.2f}".replace("-", "−"),
                     "yes" if ok else "**no**"])
    return rows, n_in


def section_recovery() -> list[str]:
    truth = load("runs/concealed/truth.json")
    diag = load("runs/concealed/out/diagnosis.json")
    after = diag["coefficients_after"]
    params = dict(after)
    extra = {}
    for term, values in truth.get("physics", {}).items():
        for k, v in values.items():
            extra[k] = v
            for e in diag["effects"]:
                if k in e["estimate"]:
                    params[k] = e["estimate"][k]
    names = COEFFICIENTS + [k for k in extra if k in params]
    tv = {**truth["coefficients"], **extra}
    rows, n_in = recovery_rows(params, tv, names)
    source = sorted({after[c]["source"] for c in COEFFICIENTS})
    n = len(names)
    expected = stats.binom.ppf(0.025, n, 0.95)
    verdict = (f"**Recovered:** {n_in} of {n} truths inside their 95 % intervals" if n_in >= expected else
               f"**Not recovered:** only {n_in} of {n} truths inside their 95 % intervals")
    return ["## Recovery of known coefficients", "",
            "**Claim.** On synthetic flights made with known coefficients, the posterior's intervals contain the "
            "values the data were made with.", "",
            "Data: `runs/concealed/` — the demo's four flights with a side force C_Y the configuration does not "
            f"mention ([synth file](../runs/concealed/synth.yaml)); after `bayes-disc diagnose` named the term, the "
            f"run was resampled with it. Estimates: `runs/concealed/out/diagnosis.json` → `coefficients_after` and "
            f"the effect's estimate ({', '.join(source)}); truth: `runs/concealed/truth.json`.", ""] + \
        table(["parameter", "truth", "posterior mean", "95 % interval", "z", "inside"], rows) + \
        ["", f"Verdict: {verdict} (for calibrated intervals, at least {int(expected)} of {n} with probability "
             f"97.5 %). The coverage over hundreds of data sets is in the next section.", "",
         "Reproduce: `bayes-disc sample runs/concealed/config.yaml` then `bayes-disc diagnose "
         "runs/concealed/config.yaml --overwrite` (replacing the committed diagnosis). The demo itself (`bayes-disc sample runs/demo/config.yaml`) writes "
         "`runs/demo/out/summary.json`, which is not committed; `python tools/make_validation.py --recovery "
         "runs/demo/out runs/demo/truth.json` prints this table for it.", ""]


# ----------------------------------------------------------------------------------------- fixed truths
# ----------------------------------------------------------------------------------------- identifiability
def section_identifiability() -> list[str]:
    summ = load("runs/flatball/out/summary.json")
    ident = load("runs/flatball/out/identifiability.json")
    post = summ["parameters"]
    folds = fold_names("runs/flatball/loo")
    fold_ls = {f: load(f"runs/flatball/loo/{f}/out_fit/least_squares.json")["parameters"] for f in folds}
    fold_id = {f: load(f"runs/flatball/loo/{f}/out_fit/identifiability.json") for f in folds}
    rows, far = [], []
    for c in COEFFICIENTS:
        vals = [fold_ls[f][c]["value"] for f in folds]
        spread = (max(vals) - min(vals)) / post[c]["sd"]
        if spread > 10:
            far.append(c)
        rows.append([c, ident[c]["verdict"], " / ".join(fold_id[f][c]["verdict"] for f in folds),
                     f"{fmt(post[c]['q50'])} ({fmt(post[c]['q05'])} … {fmt(post[c]['q95'])})",
                     " / ".join(fmt(v) for v in vals), f"{spread:.0f}"])
    n_ident = sum(ident[c]["verdict"] == "identified" for c in COEFFICIENTS)
    agree = ident.get("posterior", {}).get("agreement", {})
    n_agree = sum(bool(agree.get(c)) for c in COEFFICIENTS)
    L = ["## Identifiability", "",
         "**Claim.** `bayes-disc identifiability` says which coefficients the flights determine "
         "([how](identifiability.md)). On synthetic flights its verdicts are checked by the test suite "
         "(`tests/test_identifiability.py`: a single narrow-α flight makes the offset–slope pairs `weak`, the "
         "recommended throw makes them `identified`, and with `--profiles` the verdicts agree with the "
         "posterior's). No result files of those runs are committed. What the committed files show is the "
         "verdicts' limit on real throws:", "",
         "Data: `runs/flatball/out/identifiability.json` (all three throws) and "
         f"`runs/flatball/loo/<throw>/out_fit/` (least squares without that throw: {', '.join(folds)} left out).", ""]
    L += table(["coefficient", "verdict, all throws", "verdicts of the folds", "posterior median (90 %)",
                "fold estimates", "fold spread / posterior sd"], rows)
    L += ["", f"Verdict: the local (Fisher) analysis calls {n_ident} of 10 coefficients identified and agrees with "
              f"the posterior's own width for {n_agree} of 10, but for {len(far)} of 10 ({', '.join(far) or 'none'}) "
              "the estimates without one throw lie more than 10 posterior sds apart. **Local identifiability is no "
              "guarantee when the model misfits (next sections): on these throws the fold-to-fold spread, not the "
              "verdict, is the honest measure.**"
          + launch_speeds(post, fold_ls), "",
          "Reproduce: `bayes-disc identifiability runs/flatball/config.yaml --overwrite` (after `sample`), and per "
          "fold `bayes-disc identifiability runs/flatball/loo/<throw>/fit.yaml --overwrite` (`--overwrite` replaces "
          "the committed results).", ""]
    return L


def launch_speeds(post: dict, fold_ls: dict) -> str:
    """A sentence on the release airspeeds |u| [m/s] of the inertial throws in the full run (posterior medians of
    u1…u3) and in each fold's least-squares optimum; empty without inertial throws."""
    def speeds(params, key):
        return {n[3:]: float(np.linalg.norm([params[f"u{i}_{n[3:]}"][key] for i in (1, 2, 3)]))
                for n in params if n.startswith("u1_")}
    full = speeds(post, "q50")
    folds = {f: speeds(v, "value") for f, v in fold_ls.items()}
    every = [s for v in folds.values() for s in v.values()]
    if not full or not every:
        return ""
    def span(values):
        lo, hi = f"{min(values):.0f}", f"{max(values):.0f}"
        return lo if lo == hi else f"{lo}–{hi}"
    return (f" The release airspeeds show why: the run flies the throws at {span(full.values())} m/s, the folds at "
            f"{span(every)} m/s. An inertial log does "
            "not measure the airspeed, and the coefficients scale with it "
            "([inertial recordings](inertial.md#measurement-model)).")


# ----------------------------------------------------------------------------------------- missing physics
def section_missing_physics() -> list[str]:
    L = ["## Missing physics: blind tests", "",
         "**Claim.** When the data contain an effect the fitted model lacks, `bayes-disc diagnose` says so, names "
         "the effect (or, for a form no library term has, the family that describes it) and brings the residuals "
         "down to the noise ([how](missing-physics.md)). The configurations do not mention the effect; the "
         "truth files say what the data were made with.", ""]
    # side force
    truth = load("runs/concealed/truth.json")
    diag = load("runs/concealed/out/diagnosis.json")
    concealed = sorted(truth["physics"])
    named = [e["id"] for e in diag["effects"]]
    rows = []
    for f, t in truth["flights"].items():
        noise = t["noise_m"] * 1e3
        rows.append([f, f"{noise:.2f}", f"{diag['rms_before_mm'][f]:.2f}", f"{diag['rms_after_mm'][f]:.2f}",
                     f"{diag['rms_after_mm'][f] / noise:.2f}"])
    est = []
    for term in concealed:
        for k, v in truth["physics"][term].items():
            e = next((x["estimate"][k] for x in diag["effects"] if k in x["estimate"]), None)
            if e:
                est.append((k, v, e))
    cover = all(e["q025"] <= v <= e["q975"] for _, v, e in est) and bool(est)
    ok = diag["verdict"] == "missing_physics" and named[:1] == concealed[:1]
    L += ["### A concealed side force (`runs/concealed/`)", "",
          f"Concealed: {', '.join(f'`{t}`' for t in concealed)} "
          f"({', '.join(f'{k} = {fmt(v)}' for t in concealed for k, v in truth['physics'][t].items())}). "
          f"Result (`runs/concealed/out/diagnosis.json`): verdict `{diag['verdict']}`, effects "
          f"{', '.join(f'`{i}`' for i in named) or 'none'}"
          + (f", ΔBIC {diag['effects'][0]['evidence']:.0f}" if diag["effects"] else "") + "; "
          + "; ".join(f"{k} {fmt(e['value'])} (95 % {fmt(e['q025'])} … {fmt(e['q975'])}) for a truth of {fmt(v)}"
                      for k, v, e in est) + ".", ""]
    L += table(["flight", "noise (mm)", "RMS base model (mm)", "RMS with the term (mm)", "after / noise"], rows)
    L += ["", "Verdict: " + ("**named correctly**" if ok else "**not named**")
          + (", the interval covers the truth" if cover else ", the interval misses the truth")
          + f"; RMS after / noise {min(r[4] for r in rows)}–{max(r[4] for r in rows)}.", ""]
    # nature
    truth = load("runs/concealed_nature/truth.json")
    diag = load("runs/concealed_nature/out/diagnosis.json")
    forms = sorted(truth.get("nature", {}))
    families = sorted({NATURE_FAMILY.get(f, "?") for f in forms})
    ranked = sorted(diag["candidates"], key=lambda c: -c["evidence"])
    first = ranked[0]["id"] if ranked else None
    partial = (diag.get("partial_explanation") or {}).get("ids", [])
    ld = diag.get("learned_discrepancy") or {}
    rows = []
    for f, t in truth["flights"].items():
        noise = t["noise_m"] * 1e3
        rows.append([f, f"{noise:.2f}", f"{diag['rms_before_mm'][f]:.2f}", f"{diag['rms_after_mm'][f]:.2f}",
                     f"{diag['rms_after_mm'][f] / noise:.2f}"])
    params = "; ".join(f"`{f}` " + ", ".join(f"{k} {fmt(v)}" for k, v in truth["nature"][f].items()) for f in forms)
    L += ["### A ground effect of another law (`runs/concealed_nature/`)", "",
          f"Concealed: a form no library term has ({params}: a ground effect fading as a Gaussian in height, "
          f"[synth file](../runs/concealed_nature/synth.yaml)); its family is {', '.join(f'`{x}`' for x in families)}. "
          f"Result (`runs/concealed_nature/out/diagnosis.json`): verdict `{diag['verdict']}`; ranked first "
          f"`{first}` (ΔBIC {ranked[0]['evidence']:.0f}); adopted as a partial explanation: "
          f"{', '.join(f'`{i}`' for i in partial) or 'none'} "
          f"(share of the excess misfit {fmt((diag.get('partial_explanation') or {}).get('share_explained'))}); "
          f"the learned correction selects {ld.get('selected')} functions, holds its evidence in "
          f"`{ld.get('variable')}` and names the family `{ld.get('family')}` "
          f"(share explained {fmt(ld.get('share_explained'))}; residuals left "
          f"{'white' if ld.get('white') else 'structured'}).", ""]
    L += table(["flight", "noise (mm)", "RMS base model (mm)", "RMS after (mm)", "after / noise"], rows)
    named_ok = first in families and ld.get("family") in families
    L += ["", "Verdict: " + ("**the right family is ranked first and named by the learned correction**" if named_ok
                             else "**the family is not named**")
          + f"; RMS after / noise {min(r[4] for r in rows)}–{max(r[4] for r in rows)}"
          + ("; residuals still structured, as expected for a form the family does not contain."
             if not ld.get("white") else "."), "",
          "Reproduce (`--overwrite` replaces the committed diagnosis): `bayes-disc sample "
          "runs/concealed/config.yaml && bayes-disc diagnose runs/concealed/config.yaml --overwrite`; "
          "`bayes-disc sample runs/concealed_nature/config.yaml && bayes-disc diagnose "
          "runs/concealed_nature/config.yaml --no-sample --overwrite`. The test suite's blind tests "
          "(`tests/test_missing_physics.py`, `tests/test_families.py`, `tests/test_discrepancy.py`; slow ones with "
          "`-m slow`) cover every term, both data explanations, ten data sets with nothing missing and a gust.", ""]
    return L + nutation_blind()


# ----------------------------------------------------------------------------------------- real throws
def section_real() -> list[str]:
    summ = load("runs/flatball/out/summary.json")
    diag = load("runs/flatball/out/diagnosis.json")
    conv = summ["convergence"]
    lit = summ["literature"]
    post = summ["parameters"]
    rows, opposite = [], []
    for c in COEFFICIENTS:
        pub = [lit[s].get(c) for s in ("hummel2002", "potts_crowther")]
        signs = [np.sign(v) for v in pub if v not in (None, 0)]
        if signs and all(np.sign(post[c]["q95"]) != s and np.sign(post[c]["q05"]) != s for s in signs):
            opposite.append(c)
        rows.append([c, f"{fmt(post[c]['q50'])} ({fmt(post[c]['q05'])} … {fmt(post[c]['q95'])})",
                     fmt(pub[0]), fmt(pub[1])])
    L = ["## Real throws (`runs/flatball/`)", "",
         "**Claim.** None: these throws test what the tool says when its model does not describe the data. "
         "Data: four throws of an Ultra-Star carrying an inertial logger, from Michael V. Schaefer's "
         "[Flatball Inertial Navigation System](https://github.com/misc-protolabs/flatball-ins), CC-BY "
         "([source and licence](../runs/flatball/data/README.md)); one throw is flown upside down and is "
         "reported out of model. Files: `runs/flatball/out/` (`sample`, `diagnose`) and `runs/flatball/loo/` "
         "(leave one throw out, then `predict`).", "",
         f"Sampler: {conv['reason']} (R-hat max {conv['r_hat_max']:.4f}, N/τ {conv['n_over_tau']:.1f}, smallest "
         f"coefficient bulk ESS {conv['ess_bulk_min_coefficient']:.0f}).{sampler_moves(conv)}", ""]
    L += table(["coefficient", "posterior median (90 %)", "Hummel & Hubbard 2002", "Potts & Crowther 2000"], rows)
    L += real_time_base(summ) + real_wobble(diag)
    # misfit against the noise floor
    floor = diag["noise_floor"]
    rows, ratios = [], []
    for name, e in floor.items():
        s = post[name]["q50"] if name in post else None
        if s is None:
            continue
        r = s / e["value"]
        ratios.append(r)
        rows.append([name.replace("sigma_", ""), e["unit"], fmt(s), fmt(e["value"]), f"{r:.1f}"])
    trans = [(n.split("transverse_")[-1], post[n]["q50"]) for n in post if n.startswith("sigma_gyro_transverse")]
    vs_axial = [s / floor[f"sigma_gyro_axial_{f}"]["value"] for f, s in trans]
    L += ["", "Misfit against the sensors' noise: the fitted noise scale of every sensor group (posterior median) "
              "beside the noise floor estimated from the residuals' second differences (`diagnosis.json` → "
              "`noise_floor`; white noise passes through, a smooth model error does not).", ""]
    L += table(["group", "unit", "fitted σ", "noise floor", "ratio"], rows)
    # held-out prediction
    prow = prediction_rows("runs/flatball/loo")
    L += ["", "Held-out prediction (`bayes-disc predict`): each throw fitted with the coefficients and logger "
              "parameters of the other two throws' fit (fixed) and with everything free.", ""]
    L += table(PREDICTION_HEADER, prow)
    cands = sorted(diag["candidates"], key=lambda c: -c["evidence"])
    best_share = max([c.get("share_explained") or 0 for c in diag["candidates"]] + [0])
    ld = diag.get("learned_discrepancy") or {}
    L += ["", f"Missing physics (`diagnosis.json`): verdict `{diag['verdict']}`, "
              f"{len(diag['effects'])} effects accepted; the strongest candidate `{cands[0]['id']}` gains ΔBIC "
              f"{cands[0]['evidence']:.0f}; the largest share of the excess misfit any candidate removes is "
              f"{best_share:.2f}; "
              + (f"the learned correction removes {fmt(ld.get('share_explained'))} of it and leaves the residuals "
                 f"{'white' if ld.get('white') else 'structured'}." if ld else
                 "the learned correction was not run (`--no-learn`)."), ""]
    crow = [[c["id"], f"{c['evidence']:.0f}", fmt(c.get("share_explained")), c["status"],
             ", ".join(f"{f.split('-')[-2]}-{f.split('-')[-1]} " + f"{g:+.0f}".replace("-", "−") for f, g in (c.get("per_flight_gain") or {}).items())]
            for c in cands[:6]]
    L += table(["candidate", "ΔBIC", "share of the excess removed", "status", "gain per throw"], crow)
    L += [""] + real_lines(diag)
    L += random_nutation_lines(diag)[1:] + ([""] if diag.get("random_nutation") else [])
    far = max(ratios) if ratios else float("nan")
    L += [f"Verdict: **the misfit is far above the sensor noise** — every sensor group's fitted σ is "
          f"{min(ratios):.1f}–{max(ratios):.1f}× its noise floor, and the transverse gyro misfit is "
          f"{min(vs_axial):.0f}–{max(vs_axial):.0f}× the same gyro's axial noise floor — "
          f"{'and no term explains it' if not diag['effects'] else 'although a term was accepted'}"
          f"{'; the sampler did not converge' if not conv['converged'] else ''}. "
          + (f"{len(opposite)} of 10 coefficients ({', '.join(opposite)}) have a 90 % interval of the opposite sign to "
             f"every published value. " if opposite else "")
          + "The coefficients from these throws are **not findings**: the model lacks the physics of this "
            "instrumented disc, and an inertial log does not determine the airspeed the coefficients scale with "
            "(identifiability section)." if far > 1.5 else
          f"Verdict: the misfit is within {max(ratios):.1f}× the noise floor.", "",
          f"Reproduce (the committed runs took {load('runs/flatball/out/run_info.json')['wall_time_s'] / 60:.0f} min "
          f"for `sample` and {diag['wall_time_s'] / 60:.0f} min for `diagnose` on two shared cores): "
          "`bayes-disc sample runs/flatball/config.yaml --overwrite`, `bayes-disc diagnose runs/flatball/config.yaml "
          f"--no-sample{' --no-learn' if not ld else ''} --overwrite`, and per fold `bayes-disc identifiability "
          "runs/flatball/loo/<throw>/fit.yaml --overwrite` then `bayes-disc predict "
          "runs/flatball/loo/<throw>/held.yaml --from runs/flatball/loo/<throw>/out_fit --overwrite` "
          "(`--overwrite` replaces the committed results).", ""]
    return L


def real_lines(diag: dict) -> list[str]:
    """The oscillations the base fit leaves in the real throws' residuals (``diagnosis.json`` → ``lines``)."""
    lines = diag.get("lines") or {}
    if not lines:
        return []
    rows = [[f.split("-", 3)[-1], n, f"{x['amplitude']:.3g} {x['unit']}", f"{x['frequency_hz']:.2f}",
             f"{x['per_spin']:.3f}" if x.get("per_spin") else "–", f"{x['cycles']:.1f}", f"{100 * x['share']:.0f} %"]
            for f, per in lines.items() for n, x in per.items()]
    return (["Oscillations left in the residuals (`diagnosis.json` → `lines`): per throw, every residual series whose "
             "strongest sinusoid holds at least 30 % of it (white residuals: about 4 %).", ""]
            + table(["throw", "series", "amplitude", "frequency [Hz]", "× spin", "cycles", "share"], rows) + [""])


def sampler_moves(conv: dict) -> str:
    """The moves' acceptance after the warm-up and where the draws' mean lies (summary.json ``convergence``),
    as a sentence; empty for a run that does not record them."""
    moves = conv.get("moves") or {}
    if not moves:
        return ""
    parts = ", ".join(f"{label} {100 * m['acceptance']:.1f} %" for label, m in
                      sorted(moves.items(), key=lambda kv: -kv[1]["share"]) if m["acceptance"] is not None)
    text = f" Moves after the warm-up, share of their proposals accepted (largest share first): {parts}."
    gap, dim = conv.get("log_prob_gap_at_mean"), conv.get("dimension")
    if gap is not None and dim:
        text += (f" The log-posterior at the draws' mean lies {abs(gap):.0f} nats {'below' if gap > 0 else 'above'} "
                 "the median draw's; for a "
                 f"Gaussian posterior of {dim} parameters it would lie about {dim / 2:.0f} above"
                 + (": the posterior is curved, and a Gaussian fitted to the draws centres where it is low." if gap > 0
                    else "."))
    return text


def real_time_base(summ: dict) -> list[str]:
    """The row period of every fitted throw against the magnetometer's own estimate (one turn of the field
    per revolution of the gyro's spin), which has its own standard error."""
    post, rows, near, inside, narrower = summ["parameters"], [], [], [], True
    for name, rec in summ.get("inertial_throws", {}).items():
        key = f"imu_period_{name}"
        if rec.get("status") != "ok" or key not in post or not rec.get("period_mag_gyro_s"):
            continue
        p, m, m_sd = post[key], rec["period_mag_gyro_s"], rec["period_mag_gyro_sd_s"]
        off = p["q50"] / m - 1
        z = (p["q50"] - m) / np.hypot(p["sd"], m_sd)
        narrower = narrower and p["sd"] < m_sd
        near.append(abs(off) <= 0.01)
        inside.append(p["q05"] <= m <= p["q95"])
        rows.append([name, f"{p['q50'] * 1e3:.3f} ({p['q05'] * 1e3:.3f} … {p['q95'] * 1e3:.3f})",
                     f"{m * 1e3:.3f} ± {m_sd * 1e3:.3f}", f"{100 * off:+.2f} %".replace("-", "−"),
                     f"{z:+.1f}".replace("-", "−"), "yes" if inside[-1] else "no"])
    if not rows:
        return []
    L = ["", "Time base: the logs carry no time column; the row period is a parameter of every throw, and the "
             "magnetometer, turning once per revolution, fixes it independently of the flight dynamics. Beside "
             "it, the period the magnetometer and gyro give on their own (`period_from_mag_gyro`, with its "
             "standard error).", ""]
    L += table(["throw", "row period [ms], posterior median (90 %)", "magnetometer vs gyro [ms]", "difference",
                "difference / combined sd", "estimate inside the 90 % interval"], rows)
    L += ["", f"Verdict: {sum(near)} of {len(near)} row periods lie within 1 % of the magnetometer's estimate; "
              f"the estimate lies inside the 90 % interval for {sum(inside)} of {len(inside)}"
              + (" (every posterior sd is smaller than the estimate's own standard error, so the combined-sd "
                 "column is the fairer test)." if narrower else "."), ""]
    return L


# ----------------------------------------------------------------------------------------- speed
def section_speed() -> list[str]:
    L = ["## Speed", "",
         "**Claim.** The compiled simulator is fast enough for MCMC (≤ 50 µs per flight in a batch) at the "
         "reference accuracy (≤ 1e-5 m against independent reference trajectories), and reading marker files is "
         "linear in their rows. Timings depend on the machine and its load, which each result file records.", ""]
    res = ROOT / "benchmarks" / "results"
    sim = res / "simulator.json"
    if sim.exists():
        s = json.loads(sim.read_text())
        k = s["kernel"]
        rows = [[f"kernel ({k['method']}), single flight", f"{k['single_us_per_flight']:.1f}"],
                [f"kernel, batched ({s['flight']['batch']} flights)", f"{k['batched_us_per_flight']:.1f}"],
                [f"scipy solve_ivp {s['solve_ivp']['method']}, rtol = atol = {s['solve_ivp']['rtol']:g}",
                 f"{s['solve_ivp']['single_us_per_flight']:.0f}"]]
        errs = s["max_marker_error_m"]["kernel"]
        worst = max(errs.values())
        L += ["### Simulator (`benchmarks/results/simulator.json`)", "",
              f"A {s['flight']['duration_s']:g} s flight at {s['flight']['rate_hz']:g} Hz, {s['flight']['markers']} "
              f"markers; load average {s['loadavg_1min']:.2f} during the run.", ""]
        L += table(["integrator", "µs per flight"], rows)
        L += ["", "Largest marker error against the reference cases: "
                  + ", ".join(f"{c} {fmt(v, 2)} m" for c, v in sorted(errs.items())) + ".", "",
              f"Verdict: batched {k['batched_us_per_flight']:.1f} µs per flight "
              f"({'within' if k['batched_us_per_flight'] <= 50 else '**above**'} 50 µs), largest error "
              f"{fmt(worst, 2)} m ({'within' if worst <= s['tolerance_m'] else '**above**'} "
              f"{fmt(s['tolerance_m'], 1)} m).", "",
              "Reproduce: `python benchmarks/bench_simulator.py --json` (needs the reference cases, "
              "`--reference DIR`).", ""]
    rd = res / "read_markers.json"
    if rd.exists():
        r = json.loads(rd.read_text())
        cases = [v for v in r.values() if isinstance(v, dict)]
        rows = [[str(c["flights"]), str(c["rows"]), f"{c['read_validate_s']:.2f}", f"{c['arrange_s']:.2f}",
                 f"{c['us_per_row']:.1f}"] for c in cases]
        per_row = [c["us_per_row"] for c in cases]
        L += ["### Reading marker files (`benchmarks/results/read_markers.json`)", "",
              f"About a million rows, in many flights and in four; load average {r['load_average']:.2f}.", ""]
        L += table(["flights", "rows", "read and validate (s)", "arrange per flight (s)", "µs per row"], rows)
        L += ["", f"Verdict: {min(per_row):.1f}–{max(per_row):.1f} µs per row for {min(c['flights'] for c in cases)} to "
                  f"{max(c['flights'] for c in cases)} flights: the cost follows the rows, not the flights "
                  f"(ratio {max(per_row) / min(per_row):.1f}).", "",
              "Reproduce: `python benchmarks/bench_read_markers.py --json`.", ""]
    L += ["### Measured by command, not committed", "",
          "These figures depend on the machine and are not committed as result files; each command prints them:", "",
          "| what | command |", "|---|---|",
          "| the demo job as a user waits for it (imports, fit, sampling, outputs, report) | `python benchmarks/bench_demo.py` |",
          "| `sample` alone on the demo: wall time, ESS per second | `python benchmarks/bench_sample.py` |",
          "| growth with the number of flights (4, 12, 24) | `python benchmarks/bench_scale.py --flights 4 12 24 --no-dense` |",
          "| one calibration replicate, and a campaign's duration | `python benchmarks/bench_calibration.py` |",
          "| compiling the kernels, cold and cached | `python benchmarks/bench_compile.py` |",
          "| video detection, full frame and ROI | `python benchmarks/bench_video.py` |",
          "| averaging over the robust judgement | `python benchmarks/bench_judgement.py` |",
          "| markers and an inertial logger on the same throws | `python benchmarks/bench_mixed.py` |",
          "| a log-posterior evaluation with white gyro noise and with the randomly forced nutation | "
          "`python benchmarks/bench_nutation.py` |", ""]
    return L


# ----------------------------------------------------------------------------------------- page
def build() -> str:
    head = ["# What is validated", "",
            "<!-- Generated by tools/make_validation.py from the result files committed under runs/ and "
            "benchmarks/results/; do not edit by hand. -->", "",
            "Each section states a claim, shows the committed results that test it, says how to reproduce them "
            "and gives the verdict the generator computes from those files. A section without committed results "
            "says so and gives the command that measures it.", "",
            "- [Recovery of known coefficients](#recovery-of-known-coefficients)",
            "- [Calibration: interval coverage over many data sets](#calibration-interval-coverage-over-many-data-sets)",
            "- [Coverage at fixed truths](#coverage-at-fixed-truths)",
            "- [Profile intervals](#profile-intervals)",
            "- [Identifiability](#identifiability)",
            "- [Missing physics: blind tests](#missing-physics-blind-tests)",
            "- [Real throws: the wobble terms](#real-throws-the-wobble-terms-runsflatballbarometer-runsflatballwobble)",
            "- [Real throws](#real-throws-runsflatball)",
            "- [Speed](#speed)", ""]
    body = (section_recovery() + section_calibration() + section_fixed_truth() + section_profile_intervals()
            + section_identifiability()
            + section_missing_physics() + section_real_wobble() + section_real() + section_speed())
    text = "\n".join(head + body).rstrip() + "\n"
    return text


def recovery_main(run_dir: Path, truth_path: Path) -> int:
    summ = json.loads((run_dir / "summary.json").read_text())["parameters"]
    truth = json.loads(truth_path.read_text())["coefficients"]
    rows, n_in = recovery_rows(summ, truth, [c for c in COEFFICIENTS if c in summ])
    print("\n".join(table(["parameter", "truth", "posterior mean", "95 % interval", "z", "inside"], rows)))
    print(f"\n{n_in} of {len(rows)} truths inside their 95 % intervals")
    return 0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--check", action="store_true", help="compare with docs/validation.md; exit 1 with a diff if stale")
    ap.add_argument("--recovery", nargs=2, metavar=("RUN_DIR", "TRUTH"), type=Path,
                    help="print the recovery table of a sampled run against a truth file, and exit")
    a = ap.parse_args(argv)
    if a.recovery:
        return recovery_main(*a.recovery)
    text = build()
    if a.check:
        old = OUT.read_text() if OUT.exists() else ""
        if old == text:
            print(f"{OUT.relative_to(ROOT)} is up to date")
            return 0
        sys.stdout.writelines(difflib.unified_diff(old.splitlines(True), text.splitlines(True),
                                                   "docs/validation.md (committed)", "docs/validation.md (from the files)"))
        print("\ndocs/validation.md differs from the committed result files: run python tools/make_validation.py")
        return 1
    OUT.write_text(text)
    print(f"wrote {OUT.relative_to(ROOT)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
