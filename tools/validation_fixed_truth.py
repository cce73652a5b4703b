"""The fixed-truth section of docs/validation.md: the posterior's intervals at one truth with only the noise
redrawn, on designs of the varied four-flight template (benchmarks/bench_fixed_truth_posterior.py writes the
files read here, runs/calibration/fixed_truth/*.json), and the least-squares fits of the same data
(benchmarks/bench_fixed_truth.py, runs/calibration/fixed_truth/least_squares/*.json)."""
from __future__ import annotations

import json

import numpy as np

from validation_common import COEFFICIENTS, ROOT, binomial_band, familywise_mass, fmt, table

FOLDER = ROOT / "runs" / "calibration" / "fixed_truth"
LEAST_SQUARES = FOLDER / "least_squares"
#: sd(z) of every coefficient must lie within 1 ± this
SD_Z_TOLERANCE = 0.15
PRIOR_WORDS = {"flat": "flat", "reference": "reference (default)"}
#: the label of reference-prior figures from a file that records no ``reference_surrogate`` (runs whose surrogate
#: was fitted by plain least squares, without the check where its posterior goes)
PLAIN_SURROGATE = "reference, plain surrogate"
#: simulated sets of K standard-normal z vectors (with a file's own correlation of z) behind the chance that
#: calibrated intervals meet the sd(z) criterion, and their seed
PASS_SIMULATIONS = 4000
PASS_SEED = 20261129


def design_text(flights: list[dict]) -> str:
    """'7.6 m/s α 29°, 16.9 m/s α 5°, …' with p, q where the release wobbles."""
    parts = []
    for f in flights:
        s = f"{f['speed']:.1f} m/s α {round(f['alpha_deg']) + 0:d}°".replace("-", "−")
        if abs(f.get("p", 0.0)) >= 1 or abs(f.get("q", 0.0)) >= 1:
            s += f" p, q {f['p']:+.1f}, {f['q']:+.1f} rad/s".replace("-", "−")
        parts.append(s)
    return "; ".join(parts)


def prior_label(result: dict, prior: str) -> str:
    """How a file's figures under ``prior`` are named: the default reference prior, the reference prior with the
    plain least-squares surrogate (files without ``reference_surrogate``), or flat; with the sampler settings
    that replaced the campaign's short ones, if any (``sampler``)."""
    if prior == "reference" and "reference_surrogate" not in result:
        label = PLAIN_SURROGATE
    else:
        label = PRIOR_WORDS[prior]
    if result.get("sampler"):
        label += ", sampler " + ", ".join(f"{k} {v}" for k, v in result["sampler"].items())
    return label


def design_name(result: dict, label: str, form: str) -> str:
    """The design's number, with ``label`` (``form``: design, label) unless it is the default prior's."""
    d = str(result["replicate"])
    return d if label == PRIOR_WORDS["reference"] else form.format(d, label)


def pass_chance(z: np.ndarray) -> float:
    """The probability that calibrated intervals meet the sd(z) criterion with as many draws as ``z`` (K, 10) has:
    K draws of N(0, C), C the correlation of the file's own z (the coefficients' z move together), simulated
    :data:`PASS_SIMULATIONS` times."""
    k = z.shape[0]
    factor = np.linalg.cholesky(np.corrcoef(z.T) + 1e-9 * np.eye(z.shape[1]))
    rng = np.random.default_rng(PASS_SEED)
    sims = rng.standard_normal((PASS_SIMULATIONS, k, z.shape[1])) @ factor.T
    sd = sims.std(axis=1, ddof=1)
    return float(np.mean(np.all(np.abs(sd - 1.0) <= SD_Z_TOLERANCE, axis=1)))


def coverage_judgement(fig: dict, k: int) -> list[str]:
    """Coverages of the central 50 % and 90 % intervals outside their family-wise binomial band at ``k`` draws
    ('CM0 90 %', …)."""
    mass = familywise_mass(2 * len(COEFFICIENTS))
    out = []
    for level in ("50", "90"):
        lo, hi = binomial_band(k, int(level) / 100, mass)
        out += [f"{c} {level} %" for c in COEFFICIENTS if not lo <= fig[f"coverage_{level}"][c] <= hi]
    return out


def judge(fig: dict) -> tuple[bool, list[str]]:
    """(mean distance² inside its band, coefficients whose sd(z) is outside 1 ± SD_Z_TOLERANCE)."""
    lo, hi = fig["band"]
    off = [c for c in COEFFICIENTS if abs(fig["sd_z"][c] - 1.0) > SD_Z_TOLERANCE]
    return lo <= fig["mean_distance2"] <= hi, off


def section_fixed_truth() -> list[str]:
    found = [json.loads(p.read_text()) for p in sorted(FOLDER.glob("*.json"))]
    L = ["## Coverage at fixed truths", "",
         "**Claim.** At one fixed truth, with only the noise redrawn, the posterior's intervals have the width "
         "the noise implies: the truth's Mahalanobis distance² under the posterior mean and covariance of the "
         "ten coefficients averages 10 (χ² with 10 degrees of freedom), and every coefficient's "
         "z = (truth − posterior mean)/posterior sd has sd 1 ± 0.15 — on varied four-flight designs (a slow "
         "high-α throw, two fast low-α throws and a wobbling release, 1–3 mm marker noise) with the default "
         "coefficient prior and the default (reference) prior of the initial conditions; and the central 50 % and "
         "90 % intervals contain the truth at those rates.", ""]
    if not found:
        L += ["No result files of this measurement are committed, so this page states no numbers for it.", "",
              "Measured by `python benchmarks/bench_fixed_truth_posterior.py "
              "runs/calibration/four_flights_varied.yaml --replicate I --draws 50 --out FILE`.", "",
              "Verdict: not established by committed files.", ""]
        return L
    found.sort(key=lambda r: (r["replicate"], "reference_surrogate" in r))
    entries = [(r, p, prior_label(r, p)) for r in found for p in PRIOR_WORDS if p in r]
    rows, verdicts, draws = [], {}, {}
    for r, p, label in entries:
        fig = r[p]
        ok_d2, off = judge(fig)
        worst = max(COEFFICIENTS, key=lambda c: abs(fig["mean_z"][c]))
        verdicts.setdefault(label, []).append(ok_d2 and not off)
        draws.setdefault(label, set()).add(r["draws"])
        rows.append([str(r["replicate"]), label, str(r["draws"]),
                     f"{fmt(fig['mean_distance2'], 4)} [{fmt(fig['band'][0], 4)}, {fmt(fig['band'][1], 4)}]",
                     "yes" if ok_d2 else "**no**", ", ".join(off) or "none",
                     f"{worst} {fmt(fig['mean_z'][worst], 2)}", str(fig["not_converged"])])
    L += ["Each design is one replicate of `runs/calibration/four_flights_varied.yaml`: a truth drawn around "
          "Hummel & Hubbard (sd 0.1·|value|) and jittered launches, then the marker noise drawn again and again "
          "(synthesis seeds 5000 …) and every data set sampled under each prior of the initial conditions the "
          "file holds (same data, same sampler seed; [the priors](configuration.md)). The band is 10 ± 2·√(20/K) "
          "for K draws.", ""]
    L += ["Designs (launch speed and angle of attack per flight):", ""]
    seen = {}
    for r in found:
        seen.setdefault(r["replicate"], r["flights"])
    L += [f"- design {i}: {design_text(flights)}" for i, flights in seen.items()]
    L += [""]
    L += table(["design", "initial-condition prior", "draws", "mean distance² [band]", "in band",
                "sd(z) outside 1 ± 0.15", "largest mean z", "unconverged runs"], rows)
    L += ["", "A run that stopped at the template's step cap before its convergence rule was met is counted as "
          "unconverged; its draws are used all the same."]
    ks = sorted({r["draws"] for r in found})
    L += ["", "sd(z) per coefficient (its Monte-Carlo standard error with K draws is about 1/√(2(K − 1)): " +
          ", ".join(f"{fmt(1 / np.sqrt(2 * (k - 1)), 2)} at K = {k}" for k in ks) + "; so ± 0.15 is " +
          ", ".join(f"{fmt(0.15 * np.sqrt(2 * (k - 1)), 2)}" for k in ks) + " standard errors):", ""]
    L += table(["design", "prior"] + COEFFICIENTS,
               [[str(r["replicate"]), label] + [fmt(r[p]["sd_z"][c], 3) for c in COEFFICIENTS]
                for r, p, label in entries])
    L += ["", "mean z per coefficient (0 ± 2/√K when unbiased: " +
          ", ".join(f"{fmt(2 / np.sqrt(k), 2)} at K = {k}" for k in ks) + "):", ""]
    L += table(["design", "prior"] + COEFFICIENTS,
               [[str(r["replicate"]), label] + [fmt(r[p]["mean_z"][c], 2) for c in COEFFICIENTS]
                for r, p, label in entries])
    chances = [(r["replicate"], label, r["draws"], pass_chance(np.asarray(r["per_draw"][p]["z"], float)))
                for r, p, label in entries]
    L += ["", "The sd(z) criterion needs many draws: with K draws each sd(z) scatters by about 1/√(2(K − 1)) even "
          "when the intervals are exactly right, and ten of them must all land inside 1 ± 0.15. The chance that "
          "exactly calibrated intervals meet it with each file's draws (simulated with the file's own correlation "
          "of z between coefficients, which is strong: CM0 with CMq, CRr with CRp):", ""]
    L += table(["design", "prior", "draws", "chance calibrated intervals meet the sd(z) criterion"],
               [[str(d), label, str(k), f"{100 * c:.0f} %"] for d, label, k, c in chances])
    with_u = [(r, p, label) for r, p, label in entries if "coverage_90" in r[p]]
    coverage_verdicts = {}
    if with_u:
        L += coverage_tables(with_u, coverage_verdicts)
    fits = {(f["campaign"], f["replicate"]): f
            for f in (json.loads(path.read_text()) for path in sorted(LEAST_SQUARES.glob("*.json")))}
    paired = [(r, fits[r["campaign"], r["replicate"]], label) for r, p, label in entries
              if p == "reference" and label != PLAIN_SURROGATE and (r["campaign"], r["replicate"]) in fits]
    if paired:
        L += least_squares_tables(paired)
    if any(label == PLAIN_SURROGATE for _, _, label in entries):
        L += ["", f"*{PLAIN_SURROGATE}*: files that do not record how the reference prior's surrogate was fitted "
              "(`reference_surrogate`) come from runs whose surrogate was fitted by plain least squares, without "
              "the check where its posterior goes; `sample` fits it by Huber's estimate and refines it there "
              "([how it works](how-it-works.md#3-priors)). *reference (default)* is the surrogate `sample` "
              "builds."]
    L += ["", "Reproduce:", "", "```bash"] + [r["command"] + " --out FILE" for r in found]
    L += [f["command"] + " --out FILE" for f in fits.values()] + ["```", ""]
    words = [f"{label}: the sd(z) criterion holds on {sum(v)} of {len(v)} designs "
             f"({'/'.join(str(k) for k in sorted(draws[label]))} draws)" for label, v in verdicts.items()]
    words += [f"{label}: every interval's coverage inside its family-wise band on {sum(v)} of {len(v)} designs"
              for label, v in coverage_verdicts.items()]
    L += ["Verdict: by prior of the initial conditions — " + "; ".join(words) + ". " +
          ("A design where a criterion fails shows intervals that do not yet have the width the noise implies at "
           "that truth." if not all(all(v) for v in verdicts.values()) else "Established on these designs."), ""]
    return L


def coverage_tables(entries: list, verdicts: dict) -> list[str]:
    """The truth's posterior quantile u over the draws of files that record it: coverage of the central 50 % and
    90 % intervals against their binomial bands, and the sd of Φ⁻¹(u); ``verdicts`` gets, per prior label, whether
    every coverage is inside its family-wise band."""
    mass = familywise_mass(2 * len(COEFFICIENTS))

    def bands(k):
        b = {lv: binomial_band(k, int(lv) / 100) for lv in ("50", "90")}
        f = {lv: binomial_band(k, int(lv) / 100, mass) for lv in ("50", "90")}
        return (f"{k} draws: {fmt(b['50'][0])}–{fmt(b['50'][1])} and {fmt(b['90'][0])}–{fmt(b['90'][1])}; "
                f"family-wise over the 20, {fmt(f['50'][0])}–{fmt(f['50'][1])} and "
                f"{fmt(f['90'][0])}–{fmt(f['90'][1])}")
    ks = sorted({r["draws"] for r, _, _ in entries}, reverse=True)
    L = ["", "Coverage at the fixed truth. The intervals `sample` reports are the posterior's quantiles, so the direct "
         "check of them is where the truth falls among the posterior draws: its posterior quantile u, uniform on "
         "(0, 1) when the intervals cover as they claim, whatever the posterior's shape (z assumes a Gaussian "
         "posterior; u does not). Coverage of the central 50 % and 90 % intervals over the draws (95 % bands with "
         + "; with ".join(bands(k) for k in ks) + "), and the sd of Φ⁻¹(u) (1 when calibrated):", ""]
    rows = []
    for r, p, label in entries:
        fig = r[p]
        off = coverage_judgement(fig, r["draws"])
        verdicts.setdefault(label, []).append(not off)
        for level in ("50", "90"):
            rows.append([str(r["replicate"]), label, f"{level} %"] +
                        [fmt(fig[f"coverage_{level}"][c], 2) for c in COEFFICIENTS])
        rows.append([str(r["replicate"]), label, "sd Φ⁻¹(u)"] + [fmt(fig["sd_quantile_z"][c], 3) for c in COEFFICIENTS])
    L += table(["design", "prior", "statistic"] + COEFFICIENTS, rows)
    outside = [(design_name(r, label, "{} ({})"), coverage_judgement(r[p], r["draws"])) for r, p, label in entries]
    L += ["", "Outside the family-wise band: " + "; ".join(f"design {d}: {', '.join(o) or 'none'}"
                                                          for d, o in outside) + "."]
    return L


def paired_figures(z_post: np.ndarray, optima: np.ndarray, laplace_sd: np.ndarray, truth: np.ndarray) -> dict:
    """The posterior's z against the least-squares z of the same data sets, per coefficient.

    Parameters
    ----------
    z_post : (K, n) array
        (truth − posterior mean)/posterior sd of each data set.
    optima, laplace_sd : (K, n) arrays
        The least-squares optimum of the same data sets and its Laplace (Gauss–Newton) sd.
    truth : (n,) array

    Returns
    -------
    dict
        ``sd_z_ls`` (n,): sd of z_LS = (truth − optimum)/Laplace sd, the least-squares estimate's scatter in its
        own Laplace sds (1 when the Laplace width is the noise's); ``slope`` (n,): the least-squares slope of
        z_post on z_LS, Laplace sd / posterior sd where the posterior mean follows the optimum (> 1: the
        posterior is narrower than the Laplace approximation at the same data); ``correlation`` (n,).
    """
    z_ls = (truth - optima) / laplace_sd
    zc, pc = z_ls - z_ls.mean(axis=0), z_post - z_post.mean(axis=0)
    slope = np.sum(zc * pc, axis=0) / np.sum(zc * zc, axis=0)
    corr = np.sum(zc * pc, axis=0) / np.sqrt(np.sum(zc * zc, axis=0) * np.sum(pc * pc, axis=0))
    return {"sd_z_ls": z_ls.std(axis=0, ddof=1), "slope": slope, "correlation": corr}


def least_squares_tables(paired: list) -> list[str]:
    """The posterior (default prior) against least squares on the same noise draws of each design: the
    least-squares scatter in Laplace sds, and how the posterior's z follows the least-squares z."""
    rows, corr, slopes = [], [], []
    narrower, corrected = {}, {}
    for r, f, label in paired:
        k = min(r["draws"], f["fits"])
        fig = paired_figures(np.asarray(r["per_draw"]["reference"]["z"], float)[:k],
                             np.asarray(f["per_draw"]["theta"], float)[:k],
                             np.asarray(f["per_draw"]["laplace_sd"], float)[:k],
                             np.array([f["truth"][c] for c in COEFFICIENTS]))
        d = str(r["replicate"])
        corr += list(fig["correlation"])
        slopes.append(fig["slope"])
        rows.append([d, label, str(k), "sd of least-squares z"] + [fmt(v, 3) for v in fig["sd_z_ls"]])
        rows.append([d, label, str(k), "slope of posterior z on least-squares z"] + [fmt(v, 3) for v in fig["slope"]])
        d = design_name(r, label, "{}, {}")
        for c, sd_ls, b in zip(COEFFICIENTS, fig["sd_z_ls"], fig["slope"]):
            post_off = abs(r["reference"]["sd_z"][c] - 1.0) > SD_Z_TOLERANCE
            ls_off = abs(sd_ls - 1.0) > SD_Z_TOLERANCE
            if post_off and not ls_off and b > 1.0:
                narrower.setdefault(c, []).append(d)
            if ls_off and not post_off:
                corrected.setdefault(c, []).append(d)
    wider = [c for c, b in zip(COEFFICIENTS, np.max(slopes, axis=0)) if b < 0.95]
    L = ["", "The same noise draws fitted by least squares (the starting fit of `sample`), each optimum standardised "
         "by its own Laplace sd: the scatter of that z says whether the Laplace approximation has the width the "
         f"noise implies, and the slope of the posterior's z on it (correlations {fmt(min(corr), 2)}–"
         f"{fmt(max(corr), 2)}) how the posterior departs from that approximation — above 1 the posterior is "
         "narrower than the Laplace approximation of the same data, below 1 wider" +
         (f" (on every design: {', '.join(wider)})" if wider else "") + ":", ""]
    L += table(["design", "prior", "draws", "statistic"] + COEFFICIENTS, rows)

    def listed(found):
        return "; ".join(f"{c} (design {', '.join(ds)})" for c, ds in found.items())
    if corrected:
        L += ["", "Where the least-squares z has sd outside 1 ± 0.15 and the posterior's inside it, the posterior "
              "corrects the Laplace approximation's width: " + listed(corrected) + "."]
    if narrower:
        L += ["", "Where the posterior's sd(z) is outside 1 ± 0.15 while the least-squares z is inside it, the "
              "intervals are too narrow because the posterior is narrower than the Laplace approximation of the "
              "same data (slope above 1), while the least-squares optimum scatters within 1 ± 0.15 of its Laplace "
              "width: " + listed(narrower) + "."]
    return L
