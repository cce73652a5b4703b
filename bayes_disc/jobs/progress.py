"""Progress of a job: timed stages, and the mark of log records that are results.

Progress goes to the job module's logger (INFO): a line when a stage starts and one when it ends, with its
duration (:func:`stage`). Records marked with :data:`RESULT` (tables, verdicts, the diagnosis in words) are
results: the command line prints them on stdout, everything else on stderr.
"""
from __future__ import annotations

import contextlib
import logging
import time
from types import MappingProxyType
from typing import Iterator

logger = logging.getLogger("bayes_disc.jobs")
#: ``extra`` of log records that are results (tables, verdicts), not progress
RESULT = MappingProxyType({"result": True})


class Stage:
    """A stage of a job, timed from its creation; ``result`` is added to the line logged at its end."""

    def __init__(self, name: str):
        self.name, self.result, self.t0 = name, "", time.perf_counter()

    @property
    def elapsed(self) -> float:
        """Seconds since the stage started."""
        return time.perf_counter() - self.t0


@contextlib.contextmanager
def stage(name: str, what: str = "") -> Iterator[Stage]:
    """Log (INFO) the start of a stage, and its end with the duration and the stage's ``result``.

    Parameters
    ----------
    name : str
        The stage, e.g. ``"least squares"``.
    what : str
        Details for the start line.

    Yields
    ------
    Stage
        Set ``.result`` to words for the end line. When the block raises, no end line is logged.
    """
    logger.info(f"{name}{': ' + what if what else ''} …")
    s = Stage(name)
    yield s
    logger.info(f"{name} done in {s.elapsed:.1f} s" + (f": {s.result}" if s.result else ""))
