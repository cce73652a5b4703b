"""Benchmark of reading and validating a large marker file (docs/data-formats.md): the cost must be linear in rows.

Writes, in a temporary folder, a file of ``--rows`` rows (default 1e6; 3 markers per sample, 120 Hz,
coordinates with 9 decimals as :func:`write_marker_csv` writes them) split into ``--flights`` flights
(default 3,000) and the same number of rows in 4 flights, then times :func:`read_marker_csv` (parse and
validate) and :func:`flights_from_table` (arrange per flight) for each, median of ``--repeats`` runs of
``time.perf_counter``. Prints seconds and microseconds per row; the two per-row costs should agree
(validation grouped once, not scanned once per flight). Before the grouping, 1e6 rows in 3,000 flights
took 284 s and in 4 flights 11 s.

Usage: ``python benchmarks/bench_read_markers.py [--rows N] [--flights N] [--repeats N] [--json]``.
Takes about a minute for the defaults on one core.
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from bayes_disc.observation.markers import flights_from_table, read_marker_csv  # noqa: E402

IDS = ("0", "1", "2")
LAYOUT = np.array([[0.100, 0.000, -0.015], [-0.0308, 0.0846, -0.015], [-0.0707, -0.0778, -0.015]])


def write_file(path: Path, rows: int, flights: int, seed: int = 0) -> None:
    """A marker file of about ``rows`` rows in ``flights`` flights of equal length (straight throws with noise)."""
    rng = np.random.default_rng(seed)
    samples = max(rows // (len(IDS) * flights), 1)
    t = np.arange(samples) / 120.0
    tt = t % 1.0  # long flights repeat a 1 s throw so that coordinates stay in metres
    centre = np.stack([12.0 * tt, 0.5 * tt, 1.0 + 2.0 * tt - 4.9 * tt ** 2], axis=1)
    with path.open("w") as fh:
        fh.write("flight,t,marker,x,y,z\n")
        for f in range(flights):
            pos = centre[:, None, :] + LAYOUT[None] + rng.normal(0, 0.002, (samples, len(IDS), 3))
            lines = [f"f{f},{t[i]:.9g},{m},{p[0]:.9f},{p[1]:.9f},{p[2]:.9f}\n"
                     for i in range(samples) for m, p in zip(IDS, pos[i])]
            fh.writelines(lines)


def time_read(path: Path, repeats: int) -> dict:
    read, arrange, n = [], [], 0
    for _ in range(repeats):
        t0 = time.perf_counter()
        table = read_marker_csv(path, IDS)
        t1 = time.perf_counter()
        flights_from_table(table, IDS, str(path))
        t2 = time.perf_counter()
        read.append(t1 - t0)
        arrange.append(t2 - t1)
        n = len(table)
    r, a = float(np.median(read)), float(np.median(arrange))
    return {"rows": n, "flights": len(table.flights), "read_validate_s": r, "arrange_s": a,
            "us_per_row": 1e6 * (r + a) / n}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rows", type=int, default=1_000_000)
    ap.add_argument("--flights", type=int, default=3000)
    ap.add_argument("--repeats", type=int, default=1)
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args(argv)
    out = {"load_average": os.getloadavg()[0]}
    with tempfile.TemporaryDirectory() as tmp:
        for flights in (args.flights, 4):
            path = Path(tmp) / f"markers_{flights}.csv"
            write_file(path, args.rows, flights)
            out[f"{flights}_flights"] = time_read(path, args.repeats)
            path.unlink()
    if args.json:
        print(json.dumps(out, indent=1))
        return 0
    print(f"load average {out['load_average']:.1f}")
    for key, r in out.items():
        if key == "load_average":
            continue
        print(f"{r['rows']:>9d} rows in {r['flights']:>5d} flights: read+validate {r['read_validate_s']:6.2f} s, "
              f"arrange per flight {r['arrange_s']:5.2f} s, {r['us_per_row']:.2f} µs per row")
    return 0


if __name__ == "__main__":
    sys.exit(main())
