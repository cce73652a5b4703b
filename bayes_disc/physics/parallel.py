"""Process start method for worker pools that run the compiled integrator.

Workers must not rely on ``fork`` to inherit compiled kernels or globals: every pool passes its data
as pickled arguments (or initializer arguments) and each worker builds its kernels itself, which takes
seconds once :mod:`.kernel_cache` holds them. The start method is ``$BAYES_DISC_MP_START`` if set
(``fork``, ``spawn`` or ``forkserver``), else ``fork`` where the platform offers it (Linux: no worker
start-up cost) and ``spawn`` elsewhere (macOS, Windows).
"""
from __future__ import annotations

import multiprocessing as mp
import os

ENV_START_METHOD = "BAYES_DISC_MP_START"


def start_method() -> str:
    """The start method worker pools use (module docstring).

    Returns
    -------
    str
        ``"fork"``, ``"spawn"`` or ``"forkserver"``.

    Raises
    ------
    ValueError
        If ``$BAYES_DISC_MP_START`` names a method this platform does not offer.
    """
    available = mp.get_all_start_methods()
    chosen = os.environ.get(ENV_START_METHOD)
    if chosen:
        if chosen not in available:
            raise ValueError(f"{ENV_START_METHOD}={chosen!r}: not a start method of this platform "
                             f"(available: {available})")
        return chosen
    return "fork" if "fork" in available else "spawn"


def mp_context():
    """A :mod:`multiprocessing` context with :func:`start_method`.

    Returns
    -------
    multiprocessing.context.BaseContext
    """
    return mp.get_context(start_method())
