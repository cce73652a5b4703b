"""The ensembles' chain files: their paths, the steps saved for a resume, reading them whole or a block of
parameters at a time, and the post-burn-in :class:`Chains` a run returns.
"""
from __future__ import annotations

import json
import threading
from dataclasses import dataclass, field
from pathlib import Path

import emcee
import numpy as np


@dataclass
class Chains:
    """Post-burn-in samples: chain (n_ensembles, n_steps, n_walkers, dim), log_prob alike without dim,
    σ per noise group (n_ensembles, n_steps, n_walkers, n_groups) drawn from its exact conditional, and the
    effective sums of squares S̃_g it was drawn from (alike; the sampler's blobs; None when not kept)."""

    chain: np.ndarray
    log_prob: np.ndarray
    sigma: np.ndarray
    acceptance: np.ndarray          # (n_ensembles, n_walkers)
    burn: int
    total_steps: int
    tau: np.ndarray                 # (n_ensembles, dim) steps
    converged: bool
    reason: str
    history: list = field(default_factory=list)
    wall_time_s: float = 0.0
    ss: np.ndarray | None = None
    moves: dict = field(default_factory=dict)   # {label: [share, proposed, accepted]} since the warm-up


class StoredChains:
    """The ensembles' stored steps from ``start`` on, read a block of parameters at a time, so that a
    convergence check holds one block of the chain in memory, not the whole chain (at 24 flights the
    chain after the warm-up was 1.0 GB at step 950 and grew with every step).

    Parameters
    ----------
    paths : list of Path
        The ensembles' chain files (:func:`chain_paths`).
    start : int
        First step read.

    Attributes
    ----------
    shape : tuple
        (n_ensembles, n_steps, n_walkers, dim): n_steps the shortest ensemble's steps after ``start``.
    """

    def __init__(self, paths, start: int = 0):
        self.backends = [emcee.backends.HDFBackend(str(p), read_only=True) for p in paths]
        n = min(b.iteration for b in self.backends) - start
        if n <= 0:
            raise ValueError(f"{Path(paths[0]).parent}: no stored step after step {start}")
        self.start = start
        self.shape = (len(paths), n, *self.backends[0].shape)
        self._lock = threading.Lock()      # one HDF5 read at a time (the check's threads share the files)

    def block(self, skip: int, cols: slice) -> np.ndarray:
        """Steps ``skip`` … of the parameters ``cols``: (n_ensembles, n_steps − skip, n_walkers, len(cols))."""
        first, n = self.start + skip, self.shape[1] - skip
        with self._lock:
            out = np.empty((self.shape[0], n, self.shape[2], len(range(self.shape[3])[cols])))
            for e, b in enumerate(self.backends):
                with b.open() as f:
                    out[e] = f[b.name]["chain"][first: first + n, :, cols]
        return out


class _InMemoryChains:
    """An in-memory chain (n_ensembles, n_steps, n_walkers, dim) behind :class:`StoredChains`' interface."""

    def __init__(self, chain: np.ndarray):
        self.chain = chain
        self.shape = chain.shape

    def block(self, skip: int, cols: slice) -> np.ndarray:
        return self.chain[:, skip:, :, cols]


def _read(paths, blobs: bool = False, start: int = 0):
    """The ensembles' stored steps from ``start`` on: chain (n_ens, n, walkers, dim), log-probabilities
    (n_ens, n, walkers), acceptance fractions (n_ens, walkers) and, with ``blobs``, S_g (n_ens, n, walkers,
    n_groups); n the shortest ensemble's steps after ``start``. Read into one preallocated array per
    quantity, only the steps asked for (memory: the part of the chain in use, not the whole run)."""
    stored = StoredChains(paths, start)
    backends = stored.backends
    _, n, walkers, dim = stored.shape
    chain = np.empty(stored.shape)
    lp = np.empty((len(paths), n, walkers))
    acc = np.stack([b.accepted / max(b.iteration, 1) for b in backends])
    ss = None
    for e, b in enumerate(backends):
        with b.open() as f:
            g = f[b.name]
            chain[e] = g["chain"][start: start + n]
            lp[e] = g["log_prob"][start: start + n]
            if blobs:  # S_g per noise group; emcee drops the last axis when there is one
                x = np.asarray(g["blobs"][start: start + n], float).reshape(n, walkers, -1)
                if ss is None:
                    ss = np.empty((len(paths), n, walkers, x.shape[-1]))
                ss[e] = x
    return (chain, lp, acc, ss) if blobs else (chain, lp, acc)


def chain_paths(out_dir: Path, ensembles: int) -> list[Path]:
    """The emcee chain files ``<out_dir>/chains/ensemble_<k>.h5`` of a run.

    Parameters
    ----------
    out_dir : Path
        The run's output folder.
    ensembles : int
        Number of ensembles.

    Returns
    -------
    list of Path
    """
    return [Path(out_dir) / "chains" / f"ensemble_{e}.h5" for e in range(ensembles)]


def saved_steps(out_dir: Path, ensembles: int) -> list[int] | None:
    """Steps saved in each ensemble's chain file, when the run folder holds everything a resume needs.

    Parameters
    ----------
    out_dir : Path
        The run's output folder.
    ensembles : int
        Number of ensembles of the configuration.

    Returns
    -------
    list of int or None
        Steps per ensemble; None when no chain file exists.

    Raises
    ------
    ValueError
        Some but not all chain files, or the proposals saved beside them, are missing.
    """
    chain_dir = Path(out_dir) / "chains"
    paths = chain_paths(out_dir, ensembles)
    present = [p.exists() for p in paths]
    if not any(present):
        return None
    missing = [p.name for p, ok in zip(paths, present) if not ok]
    missing += [n for n in ("proposal.npz", "independence.npz") if not (chain_dir / n).exists()]
    if missing:
        raise ValueError(f"{chain_dir}: incomplete chain files (no {', '.join(missing)}); cannot resume "
                         "(remove the folder to restart)")
    return [int(emcee.backends.HDFBackend(str(p), read_only=True).iteration) for p in paths]


def _read_history(path: Path) -> list:
    return json.loads(path.read_text()) if path.is_file() else []
