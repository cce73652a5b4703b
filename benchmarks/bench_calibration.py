"""Benchmark of one replicate of the four-flight calibration campaign (runs/calibration/four_flights_white.yaml).

Runs replicate ``--index`` (default 0) of the campaign in this process, exactly as a Dask worker runs it
(:func:`bayes_disc.calibration.replicate.run_replicate`: truth, synthetic flights, least squares and the
sampler with ``processes: 1``, ranks), after compiling the kernels once (a worker pays that once, not
per replicate). Prints the replicate's wall time, its convergence, and what the whole campaign costs on
``--workers`` workers (N × time / workers). The full campaign itself is
``bayes-disc calibrate runs/calibration/four_flights_white.yaml --workers W``; this script does not run it.

    python benchmarks/bench_calibration.py [--config runs/calibration/four_flights_white.yaml] [--index 0] [--workers 2] [--json]
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bayes_disc.calibration import load_cal_config  # noqa: E402
from bayes_disc.calibration.replicate import replicate_data, run_replicate  # noqa: E402
from bayes_disc.physics import simulate  # noqa: E402


def warm_up(cal) -> float:
    """Compile (or load from the kernel cache) the simulator kernels of the campaign's model; seconds."""
    import numpy as np
    t0 = time.perf_counter()
    result, truth, _, _ = replicate_data(cal, 0)
    y0 = np.concatenate([np.ravel(v) for k, v in result.truth["flights"][cal.template.flights[0].name]
                         ["initial_state"].items() if k != "t"])
    simulate(y0, np.array(list(truth.values())), np.linspace(0, 0.1, 5),
             marker_body=np.array(list(cal.template.markers.values())))
    return time.perf_counter() - t0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--config", default=str(ROOT / "runs/calibration/four_flights_white.yaml"))
    ap.add_argument("--index", type=int, default=0)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    cal = load_cal_config(args.config)
    compile_s = warm_up(cal)
    rec = run_replicate(cal, args.index)
    out = {"config": args.config, "replicate": args.index, "compile_s": compile_s,
           "replicate_wall_time_s": rec["wall_time_s"], "convergence": rec["convergence"],
           "redraws": rec["redraws"], "ranks": rec["ranks"], "draws": rec["draws"],
           "campaign_replicates": cal.replicates, "workers": args.workers,
           "campaign_estimate_h": cal.replicates * rec["wall_time_s"] / args.workers / 3600}
    if args.json:
        print(json.dumps(out, indent=1))
        return
    c = rec["convergence"]
    print(f"{cal.name}: replicate {args.index}: {rec['wall_time_s']:.0f} s (kernels {compile_s:.0f} s once per worker); "
          f"{c['reason']} after {c['total_steps']} steps, τ max {c['tau_max_steps']:.1f}, R-hat max "
          f"{c['r_hat_max']:.4f}, min ESS {c['ess_bulk_min_coefficient']:.0f}; {rec['redraws']} truth redraws")
    print(f"ranks (of {rec['draws']}): " + ", ".join(f"{k} {v}" for k, v in rec["ranks"].items()))
    print(f"whole campaign: {cal.replicates} × {rec['wall_time_s']:.0f} s / {args.workers} workers ≈ "
          f"{out['campaign_estimate_h']:.1f} h")


if __name__ == "__main__":
    main()
