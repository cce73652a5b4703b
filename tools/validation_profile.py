"""The profile-interval section of docs/validation.md: coverage of the profile intervals `sample` reports beside
the credible ones (summary.json ``profile_intervals``), at fixed truths of the varied designs and over a
campaign's replicates (benchmarks/bench_profile_coverage.py writes the files read here,
runs/calibration/profile/*.json), with the posterior's figures on the same noise draws where the fixed-truth
posterior files hold them (runs/calibration/fixed_truth/*.json)."""
from __future__ import annotations

import json

import numpy as np
from scipy.stats import chi2, norm

from validation_common import COEFFICIENTS, ROOT, binomial_band, familywise_mass, fmt, table
from validation_fixed_truth import FOLDER as POSTERIOR_FOLDER, SD_Z_TOLERANCE, design_text, pass_chance

FOLDER = ROOT / "runs" / "calibration" / "profile"
#: the truth's quantile is clipped to this distance from 0 and 1 before Φ⁻¹
CLIP = 1e-6


def z_of(u) -> np.ndarray:
    """Φ⁻¹ of the truth's quantiles (K, 10), clipped by :data:`CLIP`."""
    return norm.ppf(np.clip(np.asarray(u, float), CLIP, 1 - CLIP))


def coverage_misses(u: np.ndarray) -> list[str]:
    """Coverages of the central 50 % and 90 % intervals outside their family-wise binomial band ('CM0 90 %', …)."""
    mass = familywise_mass(2 * len(COEFFICIENTS))
    out = []
    for level, half in (("50", 0.25), ("90", 0.45)):
        lo, hi = binomial_band(u.shape[0], int(level) / 100, mass)
        cov = np.mean(np.abs(u - 0.5) < half, axis=0)
        out += [f"{c} {level} %" for c, v in zip(COEFFICIENTS, cov) if not lo - 1e-12 <= v <= hi + 1e-12]
    return out


def sd_z_misses(u: np.ndarray) -> list[str]:
    """Coefficients whose sd of Φ⁻¹(u) lies outside 1 ± SD_Z_TOLERANCE."""
    sd = z_of(u).std(axis=0, ddof=1)
    return [c for c, s in zip(COEFFICIENTS, sd) if abs(s - 1.0) > SD_Z_TOLERANCE]


def deviance_figures(w, k: int = len(COEFFICIENTS)) -> tuple[float, tuple[float, float], float]:
    """Mean of the profile deviances W at the truth (K,), its Monte-Carlo band k ± 2·√(2k/K) (W ~ χ²_k when the
    profile likelihood's joint regions are calibrated) and the share of W below χ²_k's 90 % point."""
    w = np.asarray(w, float)
    half = 2.0 * np.sqrt(2.0 * k / w.size)
    return float(w.mean()), (k - half, k + half), float(np.mean(w < chi2.ppf(0.9, k)))


def posterior_quantiles(campaign: str, replicate: int, draws: int) -> np.ndarray | None:
    """The default-prior posterior's truth quantiles on the first ``draws`` noise draws of the same design, from
    a fixed-truth posterior file sampled with the campaign's own settings (None if no file holds them)."""
    for path in sorted(POSTERIOR_FOLDER.glob("*.json")):
        r = json.loads(path.read_text())
        post = r.get("per_draw", {}).get("reference", {})
        if (r["campaign"] == campaign and r["replicate"] == replicate and not r.get("sampler")
                and "reference_surrogate" in r and len(post.get("quantile", [])) >= draws):
            return np.asarray(post["quantile"][:draws], float)
    return None


def section_profile_intervals() -> list[str]:
    found = [json.loads(p.read_text()) for p in sorted(FOLDER.glob("*.json"))]
    L = ["## Profile intervals", "",
         "**Claim.** The profile 90 % interval `sample` reports beside the credible one (`profile_intervals` in "
         "summary.json: quantiles of the coefficient's normalised profile likelihood, every other parameter "
         "re-optimised; [how it works](how-it-works.md#profile-intervals)) covers at its nominal rate at fixed "
         "truths of the varied four-flight designs — z = Φ⁻¹(u), u the truth's quantile under the profile, has sd "
         "1 ± 0.15 for every coefficient and the central 50 % and 90 % intervals contain the truth at those "
         "rates — and over the varied campaign's replicates, each with its own truth. Their joint counterpart is "
         "the profile deviance of the whole coefficient vector, W(c) = 2 [cost(c, x̂(c)) − cost(θ̂)] with every "
         "flight's initial conditions re-optimised at c: the likelihood-ratio statistic, χ² with 10 degrees of "
         "freedom at the truth when the profile likelihood's joint regions W(c) ≤ 15.99 are 90 % regions (for a "
         "Gaussian likelihood W is the Mahalanobis distance² under the least-squares covariance). At a fixed "
         "truth its mean over the noise draws lies within its Monte-Carlo band of 10.", ""]
    if not found:
        L += ["No result files of this measurement are committed, so this page states no numbers for it.", "",
              "Measured by `python benchmarks/bench_profile_coverage.py runs/calibration/four_flights_varied.yaml "
              "--replicate I --draws 150 --out FILE`.", "", "Verdict: not established by committed files.", ""]
        return L
    fixed = sorted((r for r in found if "replicate" in r), key=lambda r: r["replicate"])
    campaigns = [r for r in found if "replicates" in r]
    verdicts = []
    if fixed:
        rows, sd_rows, chances = [], [], []
        for r in fixed:
            u = np.asarray(r["quantile"], float)
            off, miss = sd_z_misses(u), coverage_misses(u)
            mean_w, (lo, hi), joint90 = deviance_figures(r["deviance"])
            verdicts.append(not off and not miss and lo <= mean_w <= hi)
            chances.append(pass_chance(z_of(u)))
            rows.append([str(r["replicate"]), str(u.shape[0]), ", ".join(off) or "none", ", ".join(miss) or "none",
                         f"{100 * chances[-1]:.0f} %", f"{fmt(mean_w, 4)} [{fmt(lo, 4)}, {fmt(hi, 4)}]",
                         fmt(joint90, 3)])
            sd_rows.append([str(r["replicate"]), "profile"] + [fmt(s, 3) for s in z_of(u).std(axis=0, ddof=1)])
            post = posterior_quantiles(r["campaign"], r["replicate"], u.shape[0])
            if post is not None:
                sd_rows.append([str(r["replicate"]), "posterior (same draws)"]
                               + [fmt(s, 3) for s in z_of(post).std(axis=0, ddof=1)])
        L += ["Each design is one replicate of `runs/calibration/four_flights_varied.yaml` with the marker noise "
              "drawn again and again (synthesis seeds 5000 …, the noise draws of the posterior's fixed-truth files "
              "above), every data set fitted as `sample` fits it before sampling: least squares with the campaign's "
              "run settings, then the profile path of every coefficient.", ""]
        L += [f"- design {r['replicate']}: {design_text(r['flights'])}" for r in fixed]
        L += [""] + table(["design", "draws", "sd(z) outside 1 ± 0.15", "coverage outside its family-wise band",
                           "chance exact intervals meet the sd(z) criterion", "mean W at the truth [band]",
                           "share W < 15.99 (joint 90 % region)"], rows)
        L += ["", "The last column is the chance that exactly calibrated intervals meet the sd(z) criterion with "
              "this many draws (simulated with the file's own correlation of z, as above): over these designs "
              f"they would meet it on {fmt(sum(chances), 2)} of {len(fixed)} on average. A design passes when "
              "no sd(z) and no coverage is outside and the mean W lies in its band."]
        L += ["", "sd(z) per coefficient, the posterior's (sd of Φ⁻¹ of the truth's posterior quantile, default "
              "configuration) on the same noise draws beside it where its file holds them:", ""]
        L += table(["design", "interval"] + COEFFICIENTS, sd_rows)
        L += ["", "90 % coverage per coefficient (family-wise band " + ", ".join(sorted({
            "[{}, {}] at K = {}".format(*(fmt(b, 3) for b in binomial_band(len(r["quantile"]), 0.9,
                                                                             familywise_mass(2 * len(COEFFICIENTS)))),
                                        len(r["quantile"])) for r in fixed})) + "):", ""]
        L += table(["design"] + COEFFICIENTS,
                   [[str(r["replicate"])] + [fmt(r["coverage_90"][c], 3) for c in COEFFICIENTS] for r in fixed])
        pooled = np.concatenate([np.asarray(r["quantile"], float) for r in fixed])
        sds = np.array([z_of(r["quantile"]).std(axis=0, ddof=1) for r in fixed])
        L += ["", f"Pooled over the {len(fixed)} designs and ten coefficients: 90 % coverage "
              f"{fmt(float(np.mean(np.abs(pooled - 0.5) < 0.45)), 3)} and 50 % coverage "
              f"{fmt(float(np.mean(np.abs(pooled - 0.5) < 0.25)), 3)} (nominal 0.9 and 0.5), mean sd(z) "
              f"{fmt(float(sds.mean()), 3)}."]
    for r in campaigns:
        u = np.asarray(r["quantile"], float)
        miss = coverage_misses(u)
        verdicts.append(not miss)
        mass = familywise_mass(2 * len(COEFFICIENTS))
        b50, b90 = binomial_band(u.shape[0], 0.5, mass), binomial_band(u.shape[0], 0.9, mass)
        mean_w, (lo, hi), joint90 = deviance_figures(r["deviance"])
        L += ["", f"Over the first {u.shape[0]} replicates of the campaign `{r['campaign']}` (each its own truth "
              f"and design): coverage of the central 50 % interval (band [{fmt(b50[0], 3)}, {fmt(b50[1], 3)}]) and "
              f"of the 90 % interval (band [{fmt(b90[0], 3)}, {fmt(b90[1], 3)}]); outside: "
              f"{', '.join(miss) or 'none'}. The profile deviance at the truth has mean {fmt(mean_w, 4)} (band "
              f"[{fmt(lo, 4)}, {fmt(hi, 4)}]) and lies below 15.99 in {fmt(joint90, 3)} of the replicates.", ""]
        L += table(["level"] + COEFFICIENTS,
                   [["50 %"] + [fmt(r["coverage_50"][c], 3) for c in COEFFICIENTS],
                    ["90 %"] + [fmt(r["coverage_90"][c], 3) for c in COEFFICIENTS]])
    L += ["", "Reproduce:", "", "```bash"] + [r["command"] + " --processes 2 --out FILE" for r in found] + ["```", ""]
    n_fixed = sum(1 for r in fixed if verdicts[fixed.index(r)])
    words = []
    if fixed:
        words.append(f"at fixed truths the criteria hold on {n_fixed} of {len(fixed)} designs")
    if campaigns:
        words.append(f"over the campaign's replicates every coverage lies inside its band in "
                     f"{sum(verdicts[len(fixed):])} of {len(campaigns)} file(s)")
    L += ["Verdict: " + "; ".join(words) + ". " + ("Established on these designs." if all(verdicts) else
          "Where a criterion fails, the profile intervals do not cover as they claim there."), ""]
    return L

