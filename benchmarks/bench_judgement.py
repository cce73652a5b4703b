"""Benchmark of the posterior averaged over the robust model's judgement: what averaging over
every outlier/swap judgement changes, and what it costs.

Four synthetic flights (0.6 s each at 120 Hz, 1.5 mm noise; the slow robust test's launches) get gross
errors of a chosen size on a share of their points (default 5–10 mm on 2 %: at 1.5 mm noise a 7 mm error is
about as probable an outlier as an inlier, so the judgement is uncertain), and a few label swaps. The run
is ``bayes-disc sample`` with ``noise: {model: robust}``; then the averaging stage is timed again on the
run's draws (median of ``--repeats``, the compiled kernel cached). Prints the judgement (flagged points and
frames against the injected ones), the weights' Pareto k̂ and ESS, and per coefficient the median and sd
given the judgement and averaged over it, with the truth.

    python benchmarks/bench_judgement.py [--size-mm 5 10] [--share 0.02] [--swaps 3] [--draws 2000]
                                         [--repeats 3] [--seed 16] [--keep DIR]
"""
from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bayes_disc.inference.model.config import load_config  # noqa: E402
from bayes_disc.inference.model.data import build_problem  # noqa: E402
from bayes_disc.inference.fitting.robust import average_over_judgement, with_saved_flags  # noqa: E402
from bayes_disc.jobs.sample import run_sample  # noqa: E402
from bayes_disc.inference.sampling.chains import _read, chain_paths  # noqa: E402
from bayes_disc.observation.markers import read_marker_csv, write_marker_csv  # noqa: E402
from bayes_disc.observation.synth import LaunchSpec, SynthSpec, synthesize, write_synth  # noqa: E402

FLIGHTS = (LaunchSpec(name="f1", speed=13.0, launch_angle_deg=4, alpha_deg=6, spin=60, duration=0.6, noise_mm=1.5),
           LaunchSpec(name="f2", speed=11.0, launch_angle_deg=8, alpha_deg=14, spin=55, duration=0.6, noise_mm=1.5),
           LaunchSpec(name="f3", speed=14.0, launch_angle_deg=2, alpha_deg=2, spin=65, duration=0.6, noise_mm=1.5),
           LaunchSpec(name="f4", speed=12.0, launch_angle_deg=6, alpha_deg=10, spin=58, duration=0.6, noise_mm=1.5))
CONFIG = """name: judgement
flights:
  - file: flights.csv
markers:
  "0": [0.100, 0.000, -0.015]
  "1": [-0.0308, 0.0846, -0.015]
  "2": [-0.0707, -0.0778, -0.015]
output: out
noise: {{model: robust}}
sampler: {{seed: {seed}, max_steps: 1500}}
"""


def make_data(d: Path, size_mm, share: float, swaps: int, seed: int):
    """The flights with gross errors of |e| ~ U(size_mm) on ``share`` of the points and ``swaps`` swapped frames."""
    write_synth(synthesize(SynthSpec(name="s", flights=FLIGHTS, seed=seed)), d / "flights.csv", d / "truth.json")
    table = read_marker_csv(d / "flights.csv")
    rng = np.random.default_rng(seed)
    rows = rng.choice(len(table), size=max(1, int(share * len(table))), replace=False)
    u = rng.normal(size=(rows.size, 3))
    table.xyz[rows] += u / np.linalg.norm(u, axis=1, keepdims=True) * rng.uniform(*size_mm, (rows.size, 1)) * 1e-3
    swapped = []
    for name in [f.name for f in FLIGHTS][:swaps]:
        fr = np.flatnonzero(table.flight == name)
        t = np.unique(table.t[fr])[rng.integers(10, 60)]
        frame = [r for r in fr if table.t[r] == t and r not in rows][:2]
        table.xyz[frame] = table.xyz[frame[::-1]]
        swapped.append((name, round(float(t), 6)))
    write_marker_csv(d / "flights.csv", table)
    injected = {(str(table.flight[r]), round(float(table.t[r]), 6), str(table.marker[r])) for r in rows}
    return injected, set(swapped)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size-mm", type=float, nargs=2, default=(5.0, 10.0))
    ap.add_argument("--share", type=float, default=0.02)
    ap.add_argument("--swaps", type=int, default=3)
    ap.add_argument("--draws", type=int, default=2000)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--seed", type=int, default=16)
    ap.add_argument("--keep", type=Path)
    a = ap.parse_args()
    d = a.keep or Path(tempfile.mkdtemp(prefix="bench_judgement_"))
    d.mkdir(parents=True, exist_ok=True)
    injected, swapped = make_data(d, a.size_mm, a.share, a.swaps, a.seed)
    (d / "config.yaml").write_text(CONFIG.format(seed=a.seed))
    t0 = time.perf_counter()
    summary = run_sample(load_config(d / "config.yaml"), progress=False)
    run_s = time.perf_counter() - t0
    out = d / "out"
    flags = json.loads((out / "flagged.json").read_text())
    listed = {(o["flight"], round(o["t"], 6), o["marker"]) for f in flags.values() for o in f["outliers"]}
    found = {(w["flight"], round(w["t"], 6)) for f in flags.values() for w in f["swaps"]}
    print(f"gross errors of {a.size_mm[0]:g}–{a.size_mm[1]:g} mm on {len(injected)} points, {len(swapped)} swaps; "
          f"flagged {len(listed)} points ({len(listed & injected)} of them injected), {len(found)} swaps "
          f"({len(found & swapped)} injected); run {run_s:.1f} s")
    cfg = load_config(d / "config.yaml")
    raw = build_problem(cfg)
    clean = with_saved_flags(raw, out)
    burn = json.loads((out / "summary.json").read_text())["convergence"]["burn_in_steps"]
    chain, _, _, ss = _read(chain_paths(out, cfg.sampler.ensembles), blobs=True, start=burn)
    names = clean.names[: clean.n_coef + clean.n_ext]
    times = []
    for _ in range(a.repeats):
        t = time.perf_counter()
        avg = average_over_judgement(raw, clean, chain.reshape(-1, clean.dim), ss.reshape(-1, clean.n_groups), names,
                                     np.random.default_rng(cfg.sampler.seed), json.loads((out / "flagged.json").read_text()),
                                     draws=a.draws)
        times.append(time.perf_counter() - t)
    print(f"averaging over the judgement: {avg.draws} draws, median {np.median(times):.2f} s of {a.repeats} "
          f"({min(times):.2f}–{max(times):.2f} s); Pareto k̂ {avg.pareto_k:.2f}, ESS {avg.ess:.0f}, "
          f"reliable {avg.reliable}")
    truth = json.loads((d / "truth.json").read_text())["coefficients"]
    print(f"{'':>5} {'truth':>10} {'median given':>13} {'median avg':>11} {'sd given':>10} {'sd avg':>10} {'ratio':>6}")
    for n in names:
        c, v = avg.conditional[n], avg.averaged.get(n)
        print(f"{n:>5} {truth[n]:10.5g} {c['q50']:13.5g} {v['q50'] if v else float('nan'):11.5g} {c['sd']:10.3g} "
              f"{v['sd'] if v else float('nan'):10.3g} {v['sd'] / c['sd'] if v else float('nan'):6.3f}")
    print(f"(summary.json medians are over all {chain.shape[0] * chain.shape[1] * chain.shape[2]} draws; "
          f"CLa {summary['parameters']['CLa']['q50']:.5g})")


if __name__ == "__main__":
    main()
