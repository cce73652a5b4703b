"""The sampler's chain store: emcee's HDF5 backend, written once per round of steps instead of once per step.

``emcee.backends.HDFBackend.save_step`` opens the HDF5 file, writes one step and closes it again; on the
demo (118 walkers, 58 parameters, 4 noise blobs) that costs ≈ 10 ms per step and ensemble — a sizeable share
of a sampling step whose log-posterior costs ≈ 15 ms for the whole ensemble —, and emcee's checks of every
step open it four more times (walkers, dimension, blobs, iteration). :class:`RoundBackend` keeps the steps
of one ``run_mcmc`` call in memory, remembers what it read of the file's layout, and writes the steps in one
go when the round ends (:meth:`flush`). The file is the same, value for value in its datasets and
attributes, as emcee's own after the same steps (the chain, log-probability, blobs, acceptance counts,
iteration and the random state of the last step; tested): the format, the resume and every reader are
unchanged. An interruption in the middle of a round keeps the steps done (the sampler flushes in a
``finally``); a killed process loses that round's steps (at most ``check_every``), and a resumed run starts
from the last step written.
"""
from __future__ import annotations

import emcee
import numpy as np


class RoundBackend(emcee.backends.HDFBackend):
    """``emcee.backends.HDFBackend`` that buffers steps in memory until :meth:`flush`.

    Parameters
    ----------
    filename : str
        HDF5 file of one ensemble (created on first use, as emcee does).
    """

    def __init__(self, filename: str, **kwargs):
        super().__init__(filename, **kwargs)
        self._steps: list[tuple] = []
        self._layout: dict = {}     # what was read of the file: shape, has_blobs, written steps

    def _read_once(self, key, read):
        if key not in self._layout:
            self._layout[key] = read()
        return self._layout[key]

    def reset(self, nwalkers, ndim) -> None:
        """emcee's ``reset`` (a new file), forgetting the buffer and what was read of the old one."""
        self._steps.clear()
        self._layout.clear()
        super().reset(nwalkers, ndim)

    @property
    def shape(self) -> tuple[int, int]:
        """(walkers, dimension) of the file, read once."""
        return self._read_once("shape", lambda: tuple(int(v) for v in emcee.backends.HDFBackend.shape.fget(self)))

    def has_blobs(self) -> bool:
        """Whether the file stores blobs, read once (``grow`` may add them)."""
        return self._read_once("has_blobs", lambda: bool(super(RoundBackend, self).has_blobs()))

    @property
    def iteration(self) -> int:
        """Steps stored: written to the file (read once, then counted) plus buffered."""
        written = self._read_once("written", lambda: int(emcee.backends.HDFBackend.iteration.fget(self)))
        return written + len(self._steps)

    def grow(self, ngrow, blobs) -> None:
        """Flush, then emcee's ``grow`` (it sizes the datasets from the file's iteration)."""
        self.flush()
        super().grow(ngrow, blobs)
        self._layout.pop("has_blobs", None)

    def get_value(self, name, flat=False, thin=1, discard=0):
        """Flush, then emcee's ``get_value`` (it reads the file)."""
        self.flush()
        return super().get_value(name, flat=flat, thin=thin, discard=discard)

    @property
    def accepted(self) -> np.ndarray:
        """Accepted proposals per walker, written and buffered."""
        self.flush()
        return super().accepted

    @property
    def random_state(self):
        """The random state of the last step, written or buffered."""
        return self._steps[-1][4] if self._steps else super().random_state

    def save_step(self, state, accepted) -> None:
        """Buffer one step (emcee's check of shapes first, as ``HDFBackend.save_step`` does).

        Parameters
        ----------
        state : emcee.State
            Walkers' coordinates (W, dim), log-probabilities (W,), blobs (W, ...) or None, random state.
        accepted : ndarray, shape (W,)
            Whether each walker's proposal was accepted at this step.
        """
        self._check(state, accepted)
        blobs = None if state.blobs is None else np.array(state.blobs, copy=True)
        self._steps.append((np.array(state.coords, copy=True), np.array(state.log_prob, copy=True), blobs,
                            np.asarray(accepted, dtype=int), state.random_state))

    def flush(self) -> None:
        """Write the buffered steps to the file with one open, as emcee would have written them one by one."""
        if not self._steps:
            return
        coords, log_prob, blobs, accepted, _ = zip(*self._steps)
        n = len(coords)
        with self.open("a") as f:
            g = f[self.name]
            first = int(g.attrs["iteration"])
            g["chain"][first: first + n] = np.stack(coords)
            g["log_prob"][first: first + n] = np.stack(log_prob)
            if blobs[0] is not None:
                g["blobs"][first: first + n] = np.stack(blobs)
            g["accepted"][:] += np.sum(accepted, axis=0)
            for i, v in enumerate(self._steps[-1][4]):
                g.attrs["random_state_{0}".format(i)] = v
            g.attrs["iteration"] = first + n
        self._layout["written"] = first + n
        self._steps.clear()
