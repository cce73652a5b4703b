"""Benchmark of the kernel that carries every physics term, as the missing-physics search uses it.

The search fits every candidate term with one compiled kernel holding all of them
(``diagnostics.missing_physics.fit_candidates``); a lane whose term parameters sit at their off values skips
that term's hook. Reports, in one run, the time of one batched simulation (``--batch`` lanes, 1 s of a
typical flight at 120 Hz, three markers) with:

* the base kernel (no terms);
* the kernel of every term, with no term switched on;
* the same kernel with one term switched on in every lane (each term of the registry in turn), beside the
  kernel compiled for that term alone, and their ratio.

Medians over ``--repeats`` rounds, each timing every variant once in turn (``time.perf_counter``; compilation
excluded by a warm-up call; the first run on a machine compiles one kernel per term, about 20 s each, then
loads them from the disk cache).

Usage: ``python benchmarks/bench_terms_kernel.py [--batch N] [--repeats N] [--json]``.
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
if str(REPO) not in sys.path:
    sys.path.insert(0, str(REPO))

from bayes_disc.physics import literature_coefficients, simulate  # noqa: E402
from bayes_disc.physics.terms import TERMS  # noqa: E402

#: a value per parameter that switches each term on (small loads: the flight stays a typical one)
ON = 0.01


def _interleaved_medians_ms(calls: dict, repeats: int) -> dict:
    """Median time [ms] of each call, timed in ``repeats`` rounds that call each once in turn (a machine
    whose speed drifts slows every call of a round alike)."""
    for fn in calls.values():
        fn()
    times = {k: [] for k in calls}
    for _ in range(repeats):
        for k, fn in calls.items():
            t = time.perf_counter()
            fn()
            times[k].append(time.perf_counter() - t)
    return {k: 1e3 * float(np.median(v)) for k, v in times.items()}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--batch", type=int, default=16)
    ap.add_argument("--repeats", type=int, default=15)
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args(argv)

    y0 = np.array([0.0, 0.0, 1.0, 13.0, 0.0, 1.0, 1.0, 0.0, 0.0, 0.0, 0.5, -0.3, 50.0])
    lanes = np.repeat(y0[None], args.batch, axis=0)
    coef = literature_coefficients("hummel2002").as_array()
    times = np.linspace(0.0, 1.0, 121)
    markers = np.array([[0.1, 0.0, 0.0], [0.0, 0.1, 0.0], [-0.1, 0.0, 0.0]])
    every = tuple(TERMS.values())
    off = np.array([p.off_value for t in every for p in t.parameters])

    def run(terms, ext):
        return lambda: simulate(lanes, coef, times, marker_body=markers, terms=terms, extension=ext,
                                want_states=False)

    calls = {"base": run((), None), "all_terms_off": run(every, off)}
    start = 0
    for term in every:
        ext = off.copy()
        ext[start] = term.parameters[0].off_value + ON
        own = np.array([p.off_value for p in term.parameters])
        own[0] += ON
        calls[f"shared:{term.id}"], calls[f"own:{term.id}"] = run(every, ext), run((term,), own)
        start += len(term.parameters)
    ms = _interleaved_medians_ms(calls, args.repeats)
    rows = {"base": ms["base"], "all_terms_off": ms["all_terms_off"], "terms": {}}
    for term in every:
        shared, alone = ms[f"shared:{term.id}"], ms[f"own:{term.id}"]
        rows["terms"][term.id] = {"shared_kernel_ms": shared, "own_kernel_ms": alone, "ratio": shared / alone}
    rows.update(batch=args.batch, repeats=args.repeats, load_average=os.getloadavg()[0])
    if args.json:
        print(json.dumps(rows, indent=1))
        return 0
    print(f"{args.batch} lanes, 1 s at 120 Hz, medians of {args.repeats} (load average {rows['load_average']:.2f})")
    print(f"base kernel                    {rows['base']:7.2f} ms")
    print(f"every term, all off            {rows['all_terms_off']:7.2f} ms")
    print(f"{'term switched on':<24} {'shared':>8} {'own':>8} {'ratio':>6}")
    for tid, r in rows["terms"].items():
        print(f"{tid:<24} {r['shared_kernel_ms']:8.2f} {r['own_kernel_ms']:8.2f} {r['ratio']:6.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
