"""Worker processes that advance one ensemble by n steps each; the problem and proposals reach them through the
pool's initializer (or this process alone with ``processes: 1``).
"""
from __future__ import annotations

import emcee
import numpy as np

from ...physics.parallel import mp_context
from .backend import RoundBackend
from .mixing import _moves, move_counts


# ------------------------------------------------------------------------------------------------------
# workers: one ensemble advanced by n steps; the problem reaches them through the initializer
_WORKER: dict = {}


def _init_worker(problem, proposal, independence, fraction, block_fraction=0.0):
    _WORKER.update(problem=problem, proposal=proposal, independence=independence, fraction=fraction,
                   block_fraction=block_fraction)


class _InProcessPool:
    """The worker-pool interface run in this process, for ``processes: 1``: no child process, so that a
    run can itself be a task of a daemonic worker (a Dask worker, which may not start children)."""

    def __init__(self, initargs):
        self.initargs = initargs

    def __enter__(self):
        _init_worker(*self.initargs)
        return self

    def __exit__(self, *exc):
        _WORKER.clear()
        return False

    def map(self, fn, tasks):
        return [fn(t) for t in tasks]


def _pool(settings, initargs):
    """Worker pool advancing the ensembles: ``min(processes, ensembles)`` processes, or this process alone."""
    if settings.processes <= 1:
        return _InProcessPool(initargs)
    return mp_context().Pool(min(settings.processes, settings.ensembles), initializer=_init_worker,
                             initargs=initargs)


def _advance(task) -> tuple[int, dict]:
    """Advance one ensemble's file by ``n_steps``; its steps stored and its moves' counts
    ({label: [share, proposed, accepted]}: :func:`.mixing.move_counts`) over these steps."""
    path, n_steps, start, seed = task
    problem, proposal, independence = _WORKER["problem"], _WORKER["proposal"], _WORKER["independence"]
    backend = RoundBackend(str(path))
    nw = start.shape[0] if start is not None else backend.shape[0]
    moves = _moves(problem, proposal, independence, _WORKER["fraction"], _WORKER["block_fraction"], nw)
    sampler = emcee.EnsembleSampler(nw, problem.dim, problem.log_prob_blobs, vectorize=True, backend=backend,
                                    moves=moves, blobs_dtype=float)
    # fewer walkers than parameters (block moves on): they cannot be linearly independent, which emcee's
    # start check demands; the block moves, not the ensemble's span, make the chain move in every direction
    skip = nw <= problem.dim
    try:
        if start is not None:
            sampler.random_state = np.random.RandomState(seed).get_state()
            sampler.run_mcmc(start, n_steps, progress=False, skip_initial_state_check=skip)
        else:
            sampler.run_mcmc(None, n_steps, progress=False, skip_initial_state_check=skip)
    finally:
        backend.flush()     # the steps done, also when interrupted
    return backend.iteration, move_counts(moves)
