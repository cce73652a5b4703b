"""Logging for the command line.

Every module logs to its own ``logging.getLogger(__name__)`` under the ``bayes_disc`` logger. Records
that carry ``result=True`` (``extra={"result": True}``: results tables, the diagnosis in words) are results;
all others are progress. The command line shows them as plain messages:

============  ==============================  ==========================
verbosity     progress (stderr)               results (stdout)
============  ==============================  ==========================
``-qq``       warnings and errors only        not shown
``-q``        warnings and errors only        shown
(default)     INFO and above                  shown
``-v``        DEBUG and above                 shown
============  ==============================  ==========================

Library users (notebooks) configure logging as they like, for example
``logging.basicConfig(level=logging.INFO)``; by default Python shows only warnings.
"""
from __future__ import annotations

import contextlib
import logging
import sys
from typing import Iterator

ROOT = "bayes_disc"


def is_result(record: logging.LogRecord) -> bool:
    """Whether a log record is a result (``extra={"result": True}``) rather than progress.

    Parameters
    ----------
    record : logging.LogRecord
        Any record.

    Returns
    -------
    bool
    """
    return bool(getattr(record, "result", False))


def levels(verbosity: int) -> tuple[int, int]:
    """Levels of the progress (stderr) and results (stdout) handlers.

    Parameters
    ----------
    verbosity : int
        Number of ``-v`` minus number of ``-q``.

    Returns
    -------
    (int, int)
        ``logging`` levels for progress and for results.
    """
    progress = logging.DEBUG if verbosity >= 1 else logging.INFO if verbosity == 0 else logging.WARNING
    results = logging.INFO if verbosity >= -1 else logging.WARNING
    return progress, results


@contextlib.contextmanager
def cli_logging(verbosity: int = 0) -> Iterator[logging.Logger]:
    """Send the package's log records to the terminal while the block runs, then restore the logger.

    Parameters
    ----------
    verbosity : int
        Number of ``-v`` minus number of ``-q`` (see the module docstring).

    Yields
    ------
    logging.Logger
        The package's root logger (``bayes_disc``) with a stderr handler for progress and a stdout
        handler for results, both printing the bare message.
    """
    logger = logging.getLogger(ROOT)
    progress_level, result_level = levels(verbosity)
    err = logging.StreamHandler(sys.stderr)
    err.setLevel(progress_level)
    err.addFilter(lambda r: not is_result(r))
    out = logging.StreamHandler(sys.stdout)
    out.setLevel(result_level)
    out.addFilter(is_result)
    for h in (err, out):
        h.setFormatter(logging.Formatter("%(message)s"))
        logger.addHandler(h)
    saved = logger.level, logger.propagate
    logger.setLevel(min(progress_level, result_level))
    logger.propagate = False
    try:
        yield logger
    finally:
        for h in (err, out):
            logger.removeHandler(h)
            h.flush()
        logger.setLevel(saved[0])
        logger.propagate = saved[1]
