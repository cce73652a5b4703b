"""Coverage and rank uniformity of several calibration campaigns pooled (their replicates together).

Two campaigns with the same template, prior and sampler but different seeds are one campaign of their
summed size: pooling 100 + 100 replicates halves the binomial band's width squared, which tells whether a
coverage just outside its band over 100 data sets (CLa's 90 % at 0.82 in ``cal4_stop31``) is chance.
The campaigns must agree on the coefficients and on the draws per replicate (the ranks' range); their
finished, converged and failed replicates are counted as ``bayes-disc calibrate`` counts them, and the
summary is :func:`bayes_disc.calibration.stats.summarize` of every successful replicate.

    python benchmarks/pool_campaigns.py runs/calibration/cal4_stop31.yaml runs/calibration/cal4_seed17.yaml [--json]
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bayes_disc.calibration import load_cal_config  # noqa: E402
from bayes_disc.calibration.campaign import read_records  # noqa: E402
from bayes_disc.calibration.stats import summarize  # noqa: E402


def pooled(paths: list[Path]) -> dict:
    """The pooled summary of the campaigns at ``paths`` (their configuration files)."""
    cals = [load_cal_config(p) for p in paths]
    names, draws = cals[0].names, cals[0].draws
    for cal in cals[1:]:
        if cal.names != names or cal.draws != draws:
            raise SystemExit(f"{cal.name}: coefficients or draws per replicate differ from {cals[0].name}'s; "
                             "cannot pool")
    records, per = [], {}
    for cal in cals:
        got = read_records(cal)
        ok = [r for r in got if r["status"] == "ok"]
        per[cal.name] = {"requested": cal.replicates, "finished": len(got), "ok": len(ok),
                         "not_converged": sum(not r["convergence"]["converged"] for r in ok), "seed": cal.seed}
        records += ok
    out = summarize(records, names, draws)
    out["campaigns"] = per
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("configs", nargs="+", type=Path)
    ap.add_argument("--json", action="store_true")
    a = ap.parse_args()
    res = pooled(a.configs)
    if a.json:
        print(json.dumps(res, indent=1))
        return
    for name, c in res["campaigns"].items():
        print(f"{name}: seed {c['seed']}, {c['finished']} of {c['requested']} finished, {c['ok']} ok, "
              f"{c['not_converged']} not converged")
    band, fam = res["coverage_band_95"], res["coverage_band_familywise_95"]
    print(f"pooled: {res['replicates']} replicates; 95 % bands: 50 % {band['50'][0]:.3f}–{band['50'][1]:.3f}, "
          f"90 % {band['90'][0]:.3f}–{band['90'][1]:.3f}; family-wise 50 % {fam['50'][0]:.3f}–{fam['50'][1]:.3f}, "
          f"90 % {fam['90'][0]:.3f}–{fam['90'][1]:.3f}; sd of z ± {res['z_sd_se']:.3f}")
    print(f"{'coefficient':>11} {'cover 50':>9} {'cover 90':>9} {'rank p':>7} {'sd of z':>8}")
    outside = 0
    for name, c in res["coefficients"].items():
        flags = ""
        for lv in ("50", "90"):
            lo, hi = band[lv]
            if not lo <= c[f"coverage_{lv}"] <= hi:
                flags += f" {lv} % outside its band"
                outside += 1
        print(f"{name:>11} {c['coverage_50']:9.3f} {c['coverage_90']:9.3f} {c['rank_uniformity_p']:7.3f} "
              f"{c['z_sd']:8.3f}{flags}")
    print(f"{outside} of {2 * len(res['coefficients'])} coverages outside their own 95 % band "
          f"({res['coverage_outside_expected']:.2f} expected by chance)")


if __name__ == "__main__":
    main()
