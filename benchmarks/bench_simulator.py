"""Benchmark of the compiled simulator against scipy's solve_ivp (DOP853), with accuracy.

Reports, in one run:

* time per simulated flight (2 s at 120 Hz, 241 samples, 3 markers, markers only) for the compiled
  kernel, single lane and batched (``--batch`` flights, default 1024, all on one time grid, initial
  states and coefficients of the typical_backhand case perturbed by ±5 % per lane), and for
  :func:`simulate_reference` (solve_ivp DOP853, rtol = atol = 1e-12, one flight per call);
  medians over repetitions of ``time.perf_counter`` (compile time excluded: warm-up calls first);
* the ratios solve_ivp / kernel;
* the maximum marker error [m] of both integrators against every reference case (docs/conventions.md) in the reference
  folder (``<repo>/../shared/reference`` unless ``--reference DIR``), on the exact grid k / rate.

Usage: ``python benchmarks/bench_simulator.py [--reference DIR] [--json] [--batch N] [--repeats N]
[--method NAME]``. Prints a table, or one JSON object with ``--json``; exit status 1 if a reference case
misses the 1e-5 m tolerance. Takes about 30–60 s (compilation ≈ 10–15 s and the solve_ivp runs ≈ 10 s
included). Timings on a shared machine vary with its load, which is reported alongside.
"""
from __future__ import annotations

import argparse
import csv
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
DEFAULT_REFERENCE = REPO.parent / "shared" / "reference"
if str(REPO) not in sys.path:
    sys.path.insert(0, str(REPO))

from bayes_disc.physics import (Coefficients, Disc, Environment, SimulatorSettings, simulate,  # noqa: E402
                                simulate_reference)

TOLERANCE_M = 1e-5          # reference cases must be reproduced to 0.01 mm
FLIGHT_S, RATE_HZ = 2.0, 120.0


def load_case(json_path: Path) -> dict:
    """A reference case: constants, coefficients, initial state, markers and the reference marker paths
    (n, n_markers, 3) from NAME_markers.csv on the exact grid k / rate."""
    meta = json.loads(json_path.read_text())
    d = meta["disc"]
    ic = meta["initial_state"]
    y0 = np.concatenate([ic["position_m"], ic["velocity_m_s"], ic["quaternion_wxyz_body_to_world"],
                         ic["omega_body_rad_s"]]).astype(float)
    marker_body = np.asarray(meta["marker_body_positions_m"], float)
    rate = float(meta["sample_rate_hz"])
    ids = [str(i) for i in range(len(marker_body))]
    rows = {}
    with open(json_path.with_name(json_path.stem + "_markers.csv"), newline="") as fh:
        for row in csv.DictReader(fh):
            k = int(round(float(row["t"]) * rate))   # the CSV time is rounded to 1 µs
            rows[(k, ids.index(row["marker"]))] = (float(row["x"]), float(row["y"]), float(row["z"]))
    n = max(k for k, _ in rows) + 1
    ref = np.full((n, len(ids), 3), np.nan)
    for (k, mk), xyz in rows.items():
        ref[k, mk] = xyz
    return dict(name=json_path.stem, y0=y0, coef=Coefficients.from_mapping(meta["coefficients"]),
                disc=Disc(mass=d["m"], Ia=d["Ia"], Id=d["Id"], diameter=d["d"], area=d["A"]),
                env=Environment(rho=d["rho"], g=d["g"]), marker_body=marker_body,
                times=np.arange(n) / rate, ref=ref)


def median_time(fn, repeats: int) -> float:
    """Median wall time [s] of fn() over ``repeats`` calls (time.perf_counter)."""
    out = []
    for _ in range(repeats):
        t = time.perf_counter()
        fn()
        out.append(time.perf_counter() - t)
    return float(np.median(out))


def run(reference: Path, batch: int, repeats: int, method: str | None) -> dict:
    cases = [load_case(p) for p in sorted(reference.glob("*.json"))]
    if not cases:
        raise SystemExit(f"no reference cases (*.json) in {reference}")
    settings = SimulatorSettings() if method is None else SimulatorSettings(method=method)

    # accuracy on every reference case
    err_kernel, err_ref = {}, {}
    for c in cases:
        kw = dict(disc=c["disc"], env=c["env"], marker_body=c["marker_body"])
        tr = simulate(c["y0"], c["coef"].as_array(), c["times"], settings=settings, want_states=False, **kw)
        err_kernel[c["name"]] = float(np.nanmax(np.abs(tr.markers[0] - c["ref"]))) if tr.ok[0] else float("nan")
        rr = simulate_reference(c["y0"], c["coef"], c["times"], **kw)
        err_ref[c["name"]] = float(np.nanmax(np.abs(rr.markers[0] - c["ref"])))

    # timing: a 2 s flight at 120 Hz from the first case; batched lanes perturbed by ±5 %
    base = next((c for c in cases if c["name"] == "typical_backhand"), cases[0])
    times = np.arange(int(round(FLIGHT_S * RATE_HZ)) + 1) / RATE_HZ
    kw = dict(disc=base["disc"], env=base["env"], marker_body=base["marker_body"])
    coef = base["coef"].as_array()
    rng = np.random.default_rng(0)
    y_batch = base["y0"] * rng.uniform(0.95, 1.05, (batch, 13))
    y_batch[:, 6:10] /= np.linalg.norm(y_batch[:, 6:10], axis=1, keepdims=True)
    c_batch = coef * rng.uniform(0.95, 1.05, (batch, 10))

    def single():
        return simulate(base["y0"], coef, times, settings=settings, want_states=False, **kw)

    def batched():
        return simulate(y_batch, c_batch, times, settings=settings, want_states=False, **kw)

    def reference_one():
        return simulate_reference(base["y0"], base["coef"], times, **kw)

    t = time.perf_counter()
    single()                                   # compiles the small-batch kernel
    compile_s = time.perf_counter() - t
    t = time.perf_counter()
    warm = batched()                           # compiles the batch kernel
    compile_s += time.perf_counter() - t
    single_s = median_time(single, 10 * repeats)
    batched_s = median_time(batched, repeats) / batch
    ref_s = median_time(reference_one, max(1, repeats // 2))
    return {
        "flight": {"duration_s": FLIGHT_S, "rate_hz": RATE_HZ, "samples": int(times.size),
                   "markers": int(len(base["marker_body"])), "from_case": base["name"], "batch": batch,
                   "batch_ok": int(warm.ok.sum())},
        "kernel": {"method": settings.method, "step_factor": settings.c, "compile_s": compile_s,
                   "single_us_per_flight": single_s * 1e6, "batched_us_per_flight": batched_s * 1e6},
        "solve_ivp": {"method": "DOP853", "rtol": 1e-12, "atol": 1e-12, "single_us_per_flight": ref_s * 1e6},
        "ratio": {"solve_ivp_over_kernel_single": ref_s / single_s,
                  "solve_ivp_over_kernel_batched": ref_s / batched_s},
        "max_marker_error_m": {"kernel": err_kernel, "solve_ivp": err_ref},
        "tolerance_m": TOLERANCE_M,
        "pass": bool(all(e <= TOLERANCE_M for e in err_kernel.values())),
        "reference_dir": str(reference),
        "repeats": {"single": 10 * repeats, "batched": repeats, "solve_ivp": max(1, repeats // 2)},
        "loadavg_1min": os.getloadavg()[0],
    }


def print_table(r: dict) -> None:
    f, k, s, ra = r["flight"], r["kernel"], r["solve_ivp"], r["ratio"]
    print(f"flight: {f['duration_s']:g} s at {f['rate_hz']:g} Hz ({f['samples']} samples, {f['markers']} markers, "
          f"from {f['from_case']}); kernel {k['method']} c={k['step_factor']:g}; compile {k['compile_s']:.1f} s "
          f"(excluded); load average {r['loadavg_1min']:.2f}")
    print(f"{'':28s}{'µs per flight':>16s}{'solve_ivp / this':>18s}")
    print(f"{'kernel, single lane':28s}{k['single_us_per_flight']:16.1f}{ra['solve_ivp_over_kernel_single']:18.0f}")
    print(f"{'kernel, batched (' + str(f['batch']) + ')':28s}{k['batched_us_per_flight']:16.1f}"
          f"{ra['solve_ivp_over_kernel_batched']:18.0f}")
    print(f"{'solve_ivp DOP853 1e-12':28s}{s['single_us_per_flight']:16.1f}{1.0:18.0f}")
    print()
    print(f"{'max marker error [m]':28s}{'kernel':>12s}{'solve_ivp':>12s}")
    for name, e in r["max_marker_error_m"]["kernel"].items():
        print(f"{name:28s}{e:12.2e}{r['max_marker_error_m']['solve_ivp'][name]:12.2e}")
    print(f"reference tolerance {r['tolerance_m']:g} m: {'PASS' if r['pass'] else 'FAIL'}")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--reference", type=Path, default=DEFAULT_REFERENCE, help="folder of reference cases")
    ap.add_argument("--json", action="store_true", help="print one JSON object instead of a table")
    ap.add_argument("--batch", type=int, default=1024, help="flights per batched call (default 1024)")
    ap.add_argument("--repeats", type=int, default=7, help="batched repetitions (single lane: 10×)")
    ap.add_argument("--method", default=None, help="integration method (default: the simulator's)")
    args = ap.parse_args(argv)
    result = run(args.reference, args.batch, args.repeats, args.method)
    if args.json:
        print(json.dumps(result, indent=2))
    else:
        print_table(result)
    return 0 if result["pass"] else 1


if __name__ == "__main__":
    sys.exit(main())
