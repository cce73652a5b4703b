"""Compile time of the integrator in a new process: cold (empty kernel cache) vs warm (cache filled).

Each repeat makes an empty temporary cache directory (``BAYES_DISC_CACHE_DIR``), then times, in fresh
Python subprocesses, the first ``simulate()`` call twice: the first process compiles the kernel and
writes it to the cache (cold), the second loads it (warm). Prints the medians and their ratio.

    python benchmarks/bench_compile.py [--repeats 3] [--terms wind,side_force] [--batch 1]
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]

CHILD = """
import sys, time
sys.path.insert(0, {repo!r})
import numpy as np
t_import = time.perf_counter()
from bayes_disc.physics import get_terms, literature_coefficients, simulate
from bayes_disc.physics.frames import attitude_from_yaw_pitch_roll
q = attitude_from_yaw_pitch_roll(0.0, 0.1, 0.0)
y0 = np.concatenate([[0, 0, 1.5], [13.0, 0.0, 2.0], q, [0.0, 0.0, -60.0]])
terms = get_terms({terms!r})
t0 = time.perf_counter()
tr = simulate(np.repeat(y0[None], {batch}, axis=0), literature_coefficients("hummel2002"),
              np.arange(0.0, 1.0, 1 / 120), terms=terms)
t1 = time.perf_counter()
assert tr.ok.all()
print(t1 - t0)
"""


def first_call_seconds(cache_dir: str, terms: list[str], batch: int) -> float:
    """Seconds of the first simulate() call in a fresh interpreter using ``cache_dir``."""
    env = {**os.environ, "BAYES_DISC_CACHE_DIR": cache_dir}
    out = subprocess.run([sys.executable, "-c", CHILD.format(repo=str(REPO), terms=terms, batch=batch)],
                         env=env, capture_output=True, text=True)
    if out.returncode:
        raise RuntimeError(f"benchmark child failed:\n{out.stderr}")
    return float(out.stdout.strip().splitlines()[-1])


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--terms", default="", help="comma-separated physics term ids (default: none)")
    ap.add_argument("--batch", type=int, default=1, help="lanes (≤ 4: 4-lane kernel, else 8-lane)")
    args = ap.parse_args(argv)
    terms = [t for t in args.terms.split(",") if t]
    cold, warm = [], []
    for _ in range(args.repeats):
        with tempfile.TemporaryDirectory(prefix="bd-bench-cache-") as d:
            cold.append(first_call_seconds(d, terms, args.batch))
            warm.append(first_call_seconds(d, terms, args.batch))
    result = {"terms": terms, "batch": args.batch, "repeats": args.repeats, "cold_s": cold, "warm_s": warm,
              "cold_median_s": statistics.median(cold), "warm_median_s": statistics.median(warm)}
    result["ratio_cold_over_warm"] = result["cold_median_s"] / result["warm_median_s"]
    print(json.dumps(result, indent=1))
    print(f"first simulate() in a new process: cold {result['cold_median_s']:.2f} s, warm "
          f"{result['warm_median_s']:.3f} s (medians of {args.repeats}); cold/warm = "
          f"{result['ratio_cold_over_warm']:.0f}x")
    return result


if __name__ == "__main__":
    main()
