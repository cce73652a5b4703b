"""Benchmark of the demo job as a user waits for it (target: the four-flight demo in ≤ 60 s): the command
``bayes-disc sample runs/demo/config.yaml --output DIR`` in a fresh process, imports, least squares,
profiles, sampling, outputs and the HTML report included (the compiled kernel cached on disk, as after the
first run). With ``--config runs/flatball/config.yaml`` it measures the real inertial throws the same way:
the wall time to the sampler's own convergence rule, with the steps and R-hat it stopped at.

Each repeat runs the command in a new process and a new output folder; the wall time is the process's,
the stage times are those the job logs ("<stage> done in X s"). Prints every repeat, then the medians.
With ``--report RUN_DIR`` it times ``bayes-disc report RUN_DIR`` instead, alternating ``--processes 1`` and
``--processes 2`` on the same run (the same figures; only the drawing is split), and prints both medians
and their ratio.

    python benchmarks/bench_demo.py [--repeats 3] [--config runs/demo/config.yaml] [--json]
    python benchmarks/bench_demo.py --report RUN_DIR [--repeats 3]
"""
from __future__ import annotations

import argparse
import json
import re
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
STAGE = re.compile(r"^(?P<stage>[a-z][a-z -]*?) done in (?P<s>[0-9.]+) s", re.M)


def run(cmd: list[str]) -> tuple[float, str]:
    """Wall time [s] and combined output of one command (raises if it fails)."""
    t0 = time.perf_counter()
    res = subprocess.run(cmd, capture_output=True, text=True, cwd=ROOT)
    wall = time.perf_counter() - t0
    if res.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd)} failed (exit {res.returncode}):\n{res.stderr[-2000:]}")
    return wall, res.stdout + res.stderr


def demo_job(config: Path, repeats: int) -> list[dict]:
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for i in range(repeats):
            out = Path(tmp) / f"out{i}"
            wall, log = run([sys.executable, "-m", "bayes_disc", "sample", str(config), "--output", str(out),
                             "--no-progress"])
            stages = {m["stage"]: float(m["s"]) for m in STAGE.finditer(log)}
            conv = json.loads((out / "summary.json").read_text())["convergence"]
            rows.append({"wall_s": wall, "stages_s": stages, "converged": bool(conv["converged"]),
                         "steps": conv.get("total_steps"), "r_hat_max": conv.get("r_hat_max"),
                         "ess_bulk_min_coefficient": conv.get("ess_bulk_min_coefficient")})
            shutil.rmtree(out)
            print(f"repeat {i + 1}: {wall:.1f} s, {conv.get('total_steps')} steps, converged {conv['converged']} "
                  f"(R-hat max {conv.get('r_hat_max', float('nan')):.4f})  "
                  + ", ".join(f"{k} {v:.1f}" for k, v in stages.items()), flush=True)
    return rows


def report_only(run_dir: Path, repeats: int) -> dict:
    times = {1: [], 2: []}
    with tempfile.TemporaryDirectory() as tmp:
        for i in range(repeats):
            for n in (1, 2):
                wall, _ = run([sys.executable, "-m", "bayes_disc", "report", str(run_dir), "--reports-dir",
                               str(Path(tmp) / f"r{n}_{i}"), "--processes", str(n)])
                times[n].append(wall)
                print(f"repeat {i + 1}, --processes {n}: {wall:.1f} s", flush=True)
    return {f"processes_{n}_s": t for n, t in times.items()}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--config", type=Path, default=ROOT / "runs" / "demo" / "config.yaml")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--report", type=Path, default=None, metavar="RUN_DIR",
                    help="time `bayes-disc report RUN_DIR` with 1 and 2 processes instead")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args(argv)
    if args.report is not None:
        res = report_only(args.report.resolve(), args.repeats)
        one, two = (statistics.median(res[f"processes_{n}_s"]) for n in (1, 2))
        res.update(median_processes_1_s=one, median_processes_2_s=two, ratio=one / two)
        print(json.dumps(res, indent=1) if args.json else
              f"report, median of {args.repeats}: 1 process {one:.1f} s, 2 processes {two:.1f} s (×{one / two:.2f})")
        return 0
    rows = demo_job(args.config.resolve(), args.repeats)
    stages = sorted({k for r in rows for k in r["stages_s"]}, key=lambda k: list(rows[0]["stages_s"]).index(k)
                    if k in rows[0]["stages_s"] else 99)
    med = {k: statistics.median(r["stages_s"].get(k, float("nan")) for r in rows) for k in stages}
    wall = statistics.median(r["wall_s"] for r in rows)
    if args.json:
        print(json.dumps({"repeats": rows, "median_wall_s": wall, "median_stages_s": med}, indent=1))
    else:
        print(f"median of {len(rows)}: {wall:.1f} s wall (every repeat converged: "
              f"{all(r['converged'] for r in rows)}); stages " + ", ".join(f"{k} {v:.1f} s" for k, v in med.items())
              + f"; outside the stages (imports, start-up, exit) {wall - sum(med.values()):.1f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
