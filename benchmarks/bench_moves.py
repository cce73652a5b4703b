"""Benchmark of the sampler's moves one at a time (issue 18): from the stationary walkers of a kept run,
each move's acceptance rate and mean squared jump, in posterior sds, of the shared parameters and of the
flights' own parameters.

A kept run is a folder written by ``benchmarks/bench_scale.py --keep DIR`` (DIR/f<flights>, with its
config.yaml and out/chains). The walkers are every ensemble's last step; the posterior sds those of the
second half of the chains; the Gaussian reference and the independence proposal those saved with the
chains. Each move is applied once to all walkers, ``--repeats`` times with different seeds. This is how
stop 31 found the pCN steps (dropped since) accepted < 1 % of the time. Then the independence
proposal's coverage of the walkers (ln p/q quantiles) and how often each walker's shared parameters moved.

    python benchmarks/bench_moves.py DIR/f12 [--repeats 2]
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import emcee
import numpy as np
from emcee.state import State

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bayes_disc.inference.model.config import load_config  # noqa: E402
from bayes_disc.inference.model.data import build_problem  # noqa: E402
from bayes_disc.inference.sampling.moves import (FlightBlockMove, IndependenceJump, RidgeCarry, RidgeFlightRefresh,
                                                 SharedShift, block_factors)
from bayes_disc.inference.sampling.proposals import CompositeProposal, Proposal, RidgeProposal  # noqa: E402


class _Model:
    """The part of emcee's model a move uses: the log-probability with blobs and a random state."""

    def __init__(self, problem, seed: int):
        self.problem = problem
        self.random = np.random.RandomState(seed)

    def compute_log_prob_fn(self, coords):
        b = self.problem.log_prob_blobs(coords)
        return b[:, 0], b[:, 1:]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("case", type=Path, help="a kept bench_scale case, e.g. DIR/f12")
    ap.add_argument("--repeats", type=int, default=2)
    args = ap.parse_args(argv)
    problem = build_problem(load_config(args.case / "config.yaml"))
    chains_dir = args.case / "out" / "chains"
    reference = Proposal.load(chains_dir / "proposal.npz")
    independence = CompositeProposal.load(chains_dir / "independence.npz")
    chains = np.stack([emcee.backends.HDFBackend(str(f), read_only=True).get_chain()
                       for f in sorted(chains_dir.glob("ensemble_*.h5"))])
    sd = chains[:, chains.shape[1] // 2:].reshape(-1, problem.dim).std(axis=0)
    x0 = chains[:, -1].reshape(-1, problem.dim)
    blobs = problem.log_prob_blobs(x0)
    s = problem.ic_start
    conditional, shared, regression = block_factors(problem, reference.cov)
    moves = {"independence jump": IndependenceJump(independence),
             "flight-block Gibbs sweep": FlightBlockMove(problem, conditional),
             "shared shift": emcee.moves.MHMove(SharedShift(shared, regression))}
    ridges = [j for j, q in enumerate(independence.parts) if isinstance(q, RidgeProposal)]
    if ridges:
        parts, weights = tuple(independence.parts[j] for j in ridges), independence.log_weights[ridges]
        moves["ridge carry"] = emcee.moves.MHMove(RidgeCarry(parts, weights, fresh=s - 1))
        moves["ridge flight refresh"] = RidgeFlightRefresh(problem, parts, weights)
    print(f"{args.case}: {problem.n_flights} flights, {problem.dim} parameters ({s} shared), {x0.shape[0]} walkers")
    for name, move in moves.items():
        acc, js, jf, t0 = [], [], [], time.perf_counter()
        for r in range(args.repeats):
            state = State(x0.copy(), log_prob=blobs[:, 0].copy(), blobs=blobs[:, 1:].copy())
            new, accepted = move.propose(_Model(problem, r), state)
            d = (new.coords - x0) / sd
            acc.append(accepted.mean())
            js.append(np.mean(np.sum(d[:, :s] ** 2, axis=1)))
            jf.append(np.mean(np.sum(d[:, s:] ** 2, axis=1)))
        print(f"  {name:26s} accepted {np.mean(acc):.3f} (sweeps: any flight)  mean squared jump: shared "
              f"{np.mean(js):.3f} of {s} sd², flights {np.mean(jf):.2f} of {problem.dim - s} sd²  "
              f"({(time.perf_counter() - t0) / args.repeats:.2f} s per application)")
    coverage(problem, independence, chains, x0, blobs[:, 0])
    return 0


def coverage(problem, independence, chains: np.ndarray, x0: np.ndarray, log_prob: np.ndarray) -> None:
    """How well the independence proposal covers where the walkers are: w = p(x | y) / q(x) at every walker
    (relative to the median walker's). A walker whose ln w exceeds a typical proposal's by Δ accepts a
    jump with probability ≈ e^−Δ, so it moves only by the local moves; the share of steps in which each
    walker's shared parameters changed (second half of the chains) shows it."""
    lw = log_prob - independence.log_density(x0)
    lw -= np.median(lw)
    q = np.percentile(lw, [5, 25, 75, 95, 99])
    shared = chains[:, chains.shape[1] // 2:, :, :problem.ic_start]
    rate = (np.abs(np.diff(shared, axis=1)).sum(axis=-1) > 0).mean(axis=1).ravel()
    print(f"  independence proposal's coverage: ln p/q at the walkers minus its median: 5 % {q[0]:.1f}, "
          f"25 % {q[1]:.1f}, 75 % {q[2]:.1f}, 95 % {q[3]:.1f}, 99 % {q[4]:.1f}, max {lw.max():.1f}; "
          f"{np.mean(lw > np.log(20)):.1%} of the walkers above ln 20 (a median proposal accepted < 5 %)")
    print(f"  share of steps that moved a walker's shared parameters (second half): median {np.median(rate):.3f}, "
          f"5 % {np.percentile(rate, 5):.3f}, least {rate.min():.3f}")


if __name__ == "__main__":
    sys.exit(main())
