"""The ensembles' move mixture and walkers: the shares of block moves, Metropolis–Hastings moves (independence
jumps, ridge carries) and differential-evolution moves, the walkers per ensemble and their starting positions.
"""
from __future__ import annotations

import emcee
import numpy as np
from emcee.moves.move import Move

from ..model.config import SamplerSettings
from ..model.problem import Problem
from .moves import (FlightBlockMove, IndependenceJump, RidgeCarry, RidgeFlightRefresh, SharedShift, block_factors,
                    observation_shift, shared_conditional)
from .proposals import CompositeProposal, Proposal, RidgeProposal


# The Metropolis–Hastings share is all independence jumps. Preconditioned Crank–Nicolson steps (ρ = 0.97)
# on the Gaussian reference once had half of it; measured from stationary walkers of
# benchmarks/bench_scale.py's kept runs (acceptance and mean squared jump in posterior sds),
# they were accepted 0.7 % (4 flights), 0.3 % (12) and 0.0 % (24) of the time and moved the coefficients
# by 0.005 sd² per proposal, against 10 %, 10 % and 3 % and 1.7, 1.9 and 0.6 sd² for the independence
# jumps (the posterior's curved valley is not the Gaussian the pCN steps are reversible for). With their
# share given to the independence jumps, the coefficients' smallest bulk ESS rose by about a quarter and τ
# fell by a tenth to a sixth on the same steps of the same data.

#: Share of the Metropolis–Hastings moves given to ridge carries (:class:`.moves.RidgeCarry`) when the
#: independence proposal has ridge proposals; the rest are independence jumps. Measured from the
#: stationary walkers of seed 18's kept runs (benchmarks/bench_scale.py, one move alone for 20 steps):
#: ridge carries accepted 27 %, 36 %, 35 % at 4, 12, 24 flights with mean squared jumps of 0.41–0.71,
#: 0.44–0.88, 0.36–0.76 posterior variances per coefficient and step, independence jumps 13 %, 14 %, 6 %
#: with 0.20–0.31, 0.22–0.30, 0.09–0.18. Carries keep the flights' whitened places, which the independence
#: jumps redraw: at 4 flights (no flight-block sweeps) those jumps keep half of the share. (With this
#: share and the old block moves, random-walk sweeps and shared shifts, seed 18's 24-flight chain needed
#: 700 steps, τ 30 steps in the initial conditions; with the refresh sweeps below, 300.)
CARRY_SHARE = 0.5

#: Within the ridge carries' share: carries that draw the other shared parameters' whitened places afresh
#: (``fresh`` = the shared parameters), and carries that keep every whitened place (``fresh`` = 0: the walker
#: is transported along the ridge's path, its place across the valley unchanged). On the real logger
#: throws, where the valley bends in several shared directions at once, the first were accepted 0.2 % of
#: the time and the second 48 % (4 × 128 proposals from the last walkers of one ensemble of a run with
#: the first kind only, which had accepted it 0.07 % of the time); on the demo, 39 % and 64 %.
CARRY_MIX = (("shared redrawn", 0.5), ("all kept", 0.5))

#: Within the DE share: emcee's DE move with γ scaled down (accepted ~30 % on the demo posterior,
#: against ~4 % for the default γ = 2.38/√(2·dim)), the default DE move and the snooker move.
DE_SCALE = 0.35
DE_MIX = ((DE_SCALE, 0.7), (1.0, 0.15), ("snooker", 0.15))


#: Within the block share: Metropolis-within-Gibbs sweeps over the flights' own blocks, and shared shifts
#: that carry the flights along (:mod:`.moves`).
BLOCK_MIX = (("gibbs", 0.6), ("shift", 0.4))
#: The block share when the independence proposal has ridge proposals: sweeps that draw every flight afresh
#: from a ridge's conditional (:class:`.moves.RidgeFlightRefresh`), the random-walk sweeps, and random walks
#: of the shared parameters with the flights held (:class:`.moves.SharedShift` without a regression: the
#: sweeps' counterpart for the shared block, which no other block move changes) and of the observation
#: models' shared parameters carrying the flights (:func:`.moves.observation_shift`). The shared shifts that
#: carry the flights are left out: on seed 18's 24-flight walkers they were accepted 0.5 % of the time
#: (their regression is linear, the valley is not), while the refresh sweeps moved the flights' initial
#: conditions by 1.27 posterior variances per step (median; random-walk sweeps 0.056, independence jumps
#: 0.11).
RIDGE_BLOCK_MIX = (("refresh", 0.5), ("gibbs", 0.2), ("held", 0.15), ("observation", 0.15))

#: Step of the observation-model shifts (:func:`.moves.observation_shift`) as a share of 2.38/√m: on the
#: real logger throws' walkers accepted 7 %, 27 %, 47 % at 1, 0.5, 0.25 (mean squared jumps 0.07, 0.07,
#: 0.03 of the conditional variances), moving the logger's position 15 times and the magnetometer's vertical
#: field and hard iron 90 times their sd given everything else.
OBSERVATION_SHIFT_SCALE = 0.5


class CountedMove(Move):
    """A move that counts its proposals and acceptances, one per walker it proposes for, and otherwise does
    exactly what ``move`` does (it draws no random numbers of its own).

    Parameters
    ----------
    move : emcee.moves.Move
        The move counted.
    label : str
        Its name in the run's records (``summary.json`` → ``convergence.moves``).
    """

    def __init__(self, move: Move, label: str):
        self.move, self.label = move, label
        self.proposed = self.accepted = 0

    def propose(self, model, state):
        new, accepted = self.move.propose(model, state)
        self.proposed += int(np.size(accepted))
        self.accepted += int(np.sum(accepted))
        return new, accepted


def move_counts(moves) -> dict:
    """{label: [share, proposed, accepted]} of a list of (:class:`CountedMove`, share)."""
    return {m.label: [w, m.proposed, m.accepted] for m, w in moves}


def add_counts(total: dict, counts: dict) -> dict:
    """``total`` plus ``counts`` ({label: [share, proposed, accepted]}), as a new dict."""
    out = {k: list(v) for k, v in total.items()}
    for label, (share, proposed, accepted) in counts.items():
        old = out.get(label, [share, 0, 0])
        out[label] = [share, old[1] + proposed, old[2] + accepted]
    return out


def uses_block_moves(block_fraction: float, walkers: int, dim: int) -> bool:
    """Whether the ensembles get block moves: when they are enabled (``block_fraction`` > 0) and the walkers
    are fewer than 2·dim + 2, too few for the DE moves to span every direction. With enough walkers the
    ensemble's own moves do better per step (demo, 4 flights, 118 walkers on a quiet machine: 1650 steps
    to the stopping rule with a 0.3 block share, 950 without, same data)."""
    return block_fraction > 0 and walkers < 2 * dim + 2


def _block_moves(problem: Problem, proposal: Proposal, independence: CompositeProposal, ridge_parts: tuple,
                 ridge_weights: np.ndarray) -> list:
    """The block moves of :data:`RIDGE_BLOCK_MIX` (with ridge proposals) or :data:`BLOCK_MIX`, as (move, share)
    with the shares summing to 1 (a run without shared observation-model parameters has no observation
    shifts)."""
    conditional, shared, regression = block_factors(problem, proposal.cov)
    laplace = independence.laplace_covariance()
    out = []
    for kind, share in (RIDGE_BLOCK_MIX if ridge_parts else BLOCK_MIX):
        if kind == "gibbs":
            move = CountedMove(FlightBlockMove(problem, conditional), "flight sweep, random walk")
        elif kind == "refresh":
            move = CountedMove(RidgeFlightRefresh(problem, ridge_parts, ridge_weights), "flight sweep, ridge refresh")
        elif kind == "observation":
            columns, chol, carried = observation_shift(problem, laplace)
            if columns.size == 0:
                continue
            move = CountedMove(emcee.moves.MHMove(SharedShift(chol, carried, OBSERVATION_SHIFT_SCALE, columns)),
                               "observation shift, flights carried")
        elif kind == "held":
            move = CountedMove(emcee.moves.MHMove(SharedShift(shared_conditional(problem, laplace), None)),
                               "shared walk, flights held")
        else:
            move = CountedMove(emcee.moves.MHMove(SharedShift(shared, regression)), "shared shift")
        out.append((move, share))
    total = sum(share for _, share in out)
    return [(move, share / total) for move, share in out]


def _moves(problem: Problem, proposal: Proposal, independence: CompositeProposal, fraction: float,
           block_fraction: float = 0.0, walkers: int | None = None):
    """emcee's (move, weight) list: a ``block_fraction`` share of block moves (when :func:`uses_block_moves`;
    ``walkers`` None: whenever enabled), then of the rest a ``fraction`` share of Metropolis–Hastings moves
    (independence jumps) and DE moves, each a :class:`CountedMove` named for what it does. With fewer than
    2·dim ``walkers`` (block moves on), the DE moves propose within the walkers' span only: still exact, so
    emcee's guard against them is lifted (``live_dangerously``)."""
    dangerous = walkers is not None and walkers < 2 * problem.dim
    if walkers is not None and not uses_block_moves(block_fraction, walkers, problem.dim):
        block_fraction = 0.0
    moves = []
    ridges = [j for j, q in enumerate(independence.parts) if isinstance(q, RidgeProposal)]
    ridge_parts = tuple(independence.parts[j] for j in ridges)
    ridge_weights = independence.log_weights[ridges]
    if block_fraction > 0:
        moves += [(move, block_fraction * share)
                  for move, share in _block_moves(problem, proposal, independence, ridge_parts, ridge_weights)]
    rest = 1.0 - block_fraction
    if fraction > 0:
        carry = CARRY_SHARE if ridges else 0.0
        jump = CountedMove(IndependenceJump(independence), "independence jump")
        moves.append((jump, rest * fraction * (1 - carry)))
        for kind, share in CARRY_MIX if carry else ():
            fresh = problem.ic_start - 1 if kind == "shared redrawn" else 0
            move = emcee.moves.MHMove(RidgeCarry(ridge_parts, ridge_weights, fresh=fresh))
            moves.append((CountedMove(move, f"ridge carry, {kind}"), rest * fraction * carry * share))
    if fraction < 1:
        g0 = 2.38 / np.sqrt(2 * problem.dim)
        for kind, share in DE_MIX:
            if kind == "snooker":
                move = CountedMove(emcee.moves.DESnookerMove(live_dangerously=dangerous), "DE snooker")
            else:
                move = CountedMove(emcee.moves.DEMove(gamma0=kind * g0, live_dangerously=dangerous),
                                   f"DE, γ × {kind:g}")
            moves.append((move, rest * (1 - fraction) * share))
    return moves


#: most default walkers per ensemble with block moves enabled: below it every run gets 2·dim + 2 walkers
#: and the ensemble's own moves (small runs: fewer walkers were not cheaper, the demo's 4 flights took twice
#: as long with 46 walkers and block moves as with 118 without); above it, the walkers stay at this many
#: (or the block minimum) and the block moves (:func:`uses_block_moves`) make up for them, so a step's cost
#: grows with the flights only through their simulations
WALKERS_CAP = 128


def n_walkers(settings: SamplerSettings, problem: Problem) -> int:
    """Walkers per ensemble: ``settings.walkers`` (made even), at least the minimum; by default (``walkers:
    0``) 2·dim + 2, or with block moves enabled max(minimum, :data:`WALKERS_CAP`) when 2·dim + 2 is more.

    The minimum is 2·dim + 2 when the ensemble's own moves (DE) must span the whole space; with block moves
    enabled (``block_fraction`` > 0: every flight's block and the shared block have full-rank moves of their
    own, used whenever the walkers are fewer than 2·dim + 2) it is 2·(s + p_max) + 2, s the shared parameters
    and p_max the largest flight block.

    Parameters
    ----------
    settings : SamplerSettings
    problem : Problem

    Returns
    -------
    int
    """
    if settings.block_fraction > 0:
        block = max(problem.layout.flight_slice(k).stop - problem.layout.flight_slice(k).start
                    for k in range(problem.n_flights))
        least = 2 * (problem.ic_start + block) + 2
        default = max(least, min(2 * problem.dim + 2, WALKERS_CAP))
    else:
        least = default = 2 * problem.dim + 2
    w = settings.walkers or default
    return max(w + (w % 2), least)


def initial_walkers(start: CompositeProposal, n: int, problem: Problem, rng: np.random.Generator) -> np.ndarray:
    """Draws from ``start`` with finite log-posterior (redrawn otherwise), linearly independent."""
    random = np.random.RandomState(rng.integers(2**32))
    out = np.empty((n, problem.dim))
    filled = 0
    for _ in range(50):
        cand = start.draw(n, random)
        ok = np.isfinite(problem.log_prob(cand))
        take = min(int(ok.sum()), n - filled)
        out[filled: filled + take] = cand[ok][:take]
        filled += take
        if filled == n:
            return out
    raise RuntimeError("could not place walkers with finite posterior around the least-squares optimum")
