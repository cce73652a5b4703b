"""Interval widths of two calibration campaigns on the same data sets (issue 16: per-point errors).

Two campaigns with the same seed and template fit the same data sets (replicate i's data come from its own
random stream), for example ``cal4_pp.yaml`` (per-point errors) and ``cal4_pp_one.yaml`` (one σ per flight).
For every replicate both have finished, prints per coefficient the ratio of the 90 % posterior intervals'
widths (first campaign / second: median and range over the replicates) and how often each campaign's 90 %
interval covered the truth.

    python benchmarks/compare_widths.py runs/calibration/cal4_pp.yaml runs/calibration/cal4_pp_one.yaml
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bayes_disc.calibration import load_cal_config  # noqa: E402
from bayes_disc.calibration.campaign import read_records  # noqa: E402


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("first", type=Path)
    ap.add_argument("second", type=Path)
    a = ap.parse_args(argv)
    cals = [load_cal_config(p) for p in (a.first, a.second)]
    if cals[0].seed != cals[1].seed:
        raise SystemExit(f"{cals[0].name} (seed {cals[0].seed}) and {cals[1].name} (seed {cals[1].seed}) fit "
                         "different data sets")
    recs = [{r["index"]: r for r in read_records(c) if r["status"] == "ok"} for c in cals]
    common = sorted(set(recs[0]) & set(recs[1]))
    if not common:
        raise SystemExit("no replicate finished in both campaigns")
    names = cals[0].names
    print(f"{len(common)} data sets in both ({cals[0].name} / {cals[1].name}): replicates {common}")
    print(f"{'':5s} {'90 % width ratio: median':>25s} {'range':>15s}   covered 90 %: {cals[0].name}, {cals[1].name}")
    for n in names:
        w = np.array([[recs[k][i]["posterior"][n]["q95"] - recs[k][i]["posterior"][n]["q05"] for k in (0, 1)]
                      for i in common])
        ratio = w[:, 0] / w[:, 1]
        cov = [sum(bool(recs[k][i]["covered"]["90"][n]) for i in common) for k in (0, 1)]
        print(f"{n:5s} {np.median(ratio):25.3f} {ratio.min():7.3f}–{ratio.max():<7.3f}   {cov[0]}/{len(common)}, "
              f"{cov[1]}/{len(common)}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
