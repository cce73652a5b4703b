"""Benchmark of the rank transforms in the sampler's convergence check (issue 18): R-hat across ensembles and
bulk ESS on a run's stored chains, computed by sorting every draw (the reference, ``_z_scale_sorted``) and
by ranking only the runs of repeated draws (``_z_and_median``, what the sampler uses), alternating, on the
same parameters. Prints the medians, their ratios, whether the results are identical, and how often a
walker's parameter changed from one step to the next (the share of draws that start a run).

    python benchmarks/bench_ranks.py OUT_DIR [--start 150] [--params 24] [--repeats 3]

OUT_DIR: a run's output folder with ``chains/ensemble_*.h5`` (``bayes-disc sample``, or a case kept by
``benchmarks/bench_scale.py --keep DIR``: DIR/f24/out). ``--start``: first step read (the warm-up before it
is skipped, as the sampler's check does); ``--params``: the first this many parameters.
"""
from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bayes_disc.inference.sampling import mcmc_stats as dm  # noqa: E402
from bayes_disc.inference.sampling.chains import StoredChains  # noqa: E402


def sorted_rhat(chain: np.ndarray) -> np.ndarray:
    """R-hat across ensembles with every draw sorted (the computation before the run-length ranks)."""
    n_ens, n_steps, n_w, dim = chain.shape
    s = dm._split(np.moveaxis(chain.reshape(n_ens, n_steps * n_w, dim), 2, 0))
    folded = np.abs(s - np.median(s.reshape(dim, -1), axis=1)[:, None, None])
    return np.maximum(dm._psrf(dm._z_scale_sorted(s)), dm._psrf(dm._z_scale_sorted(folded)))


def sorted_ess(chain: np.ndarray) -> np.ndarray:
    """Bulk ESS, every walker a chain, with every draw sorted."""
    n_ens, n_steps, n_w, dim = chain.shape
    y = np.moveaxis(np.moveaxis(chain, 2, 1).reshape(n_ens * n_w, n_steps, dim), 2, 0)
    return dm._effective_draws(dm._z_scale_sorted(dm._split(y)))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out_dir", type=Path)
    ap.add_argument("--start", type=int, default=150)
    ap.add_argument("--params", type=int, default=24)
    ap.add_argument("--repeats", type=int, default=3)
    a = ap.parse_args(argv)
    paths = sorted((a.out_dir / "chains").glob("ensemble_*.h5"))
    if not paths:
        ap.error(f"{a.out_dir / 'chains'}: no ensemble_*.h5 chain files")
    stored = StoredChains(paths, start=a.start)
    x = stored.block(0, slice(0, min(a.params, stored.shape[-1])))
    fresh = np.ones(x.shape, bool)
    fresh[:, 1:] = x[:, 1:] != x[:, :-1]
    pairs = {"R-hat across ensembles": (sorted_rhat, lambda c: dm.rhat(c, layout="ensembles")),
             "bulk ESS": (sorted_ess, lambda c: dm.ess(c, layout="walkers"))}
    print(f"{a.out_dir}: {x.shape[0]} ensembles × {x.shape[1]} steps × {x.shape[2]} walkers, {x.shape[3]} parameters; "
          f"draws starting a run (the walker moved): {fresh.mean():.3f}")
    for name, (ref, new) in pairs.items():
        t_ref, t_new = [], []
        for _ in range(a.repeats):
            t0 = time.perf_counter()
            r = ref(x)
            t_ref.append(time.perf_counter() - t0)
            t0 = time.perf_counter()
            n = new(x)
            t_new.append(time.perf_counter() - t0)
        print(f"  {name:24s} sorting every draw {statistics.median(t_ref):.2f} s, runs {statistics.median(t_new):.2f} s "
              f"(×{statistics.median(t_ref) / statistics.median(t_new):.1f}, medians of {a.repeats}); "
              f"identical: {np.array_equal(r, n, equal_nan=True)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
