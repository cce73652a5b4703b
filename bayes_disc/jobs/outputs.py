"""Where a job writes: its run folder, the report inside it, and what an existing folder already holds.

Every job writes into the run's output folder (the configuration's ``output``, or ``--output DIR``), and
its HTML report goes with it, ``<output>/reports/<name>.html``: no command writes outside its run folder, so
a run never overwrites another run's report or a file of the working directory.

A folder that already holds a job's results is not silently written over: :func:`check_fresh_output`
names what is there and how to go on (``--resume`` for ``sample``, ``--overwrite`` to replace it, or
another ``--output``).
"""
from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path

from ..observation.config_io import ConfigError
from ..report import build_report
from ..report.run import REPORTS_DIR
from .progress import stage

logger = logging.getLogger(__name__)

#: per job, the files whose presence means the folder already holds that job's results
JOB_FILES = {"sample": ("summary.json", "posterior.nc", "chains"),
             "identifiability": ("identifiability.json",),
             "diagnose": ("diagnosis.json",),
             "predict": ("prediction.json",)}


@dataclass(frozen=True)
class Outcome:
    """What a job returned and the report built after it.

    Attributes
    ----------
    result : dict
        The job's JSON content (summary.json, identifiability.json, diagnosis.json or prediction.json).
    report : Path or None
        The HTML report written, or None when none was built.
    """

    result: dict
    report: Path | None


def reports_dir(output) -> Path:
    """Folder of a run's HTML report: ``<output>/reports``.

    Parameters
    ----------
    output : str or Path
        The run folder.

    Returns
    -------
    Path
    """
    return Path(output) / REPORTS_DIR


def build_run_report(run_dir, seed: int, processes: int) -> Path:
    """Build ``<run_dir>/reports/<name>.html`` and the figures in ``<run_dir>/figures/`` (a timed stage).

    Parameters
    ----------
    run_dir : str or Path
        A sampled run folder.
    seed : int
        Seed of the report's random draws (the run's sampler seed).
    processes : int
        Worker processes drawing the figures.

    Returns
    -------
    Path
        The HTML file written.
    """
    reports = reports_dir(run_dir)
    with stage("report", f"HTML into {reports}/, figures into {Path(run_dir) / 'figures'}/"):
        return build_report(run_dir, reports_dir=reports, seed=seed, processes=processes)


def existing_results(output, job: str) -> list[str]:
    """The files of ``job``'s results that ``output`` already holds.

    Parameters
    ----------
    output : str or Path
        The run folder.
    job : str
        A key of :data:`JOB_FILES`.

    Returns
    -------
    list of str
        File or folder names, empty for a new or empty folder.
    """
    out = Path(output)
    return [name for name in JOB_FILES[job] if (out / name).exists()]


def check_fresh_output(cfg, job: str, *, overwrite: bool = False, resume: bool = False) -> None:
    """Refuse to write ``job``'s results over earlier ones in the run folder, unless asked to.

    Parameters
    ----------
    cfg : RunConfig
        The run configuration (``cfg.output``, ``cfg.path`` for the message).
    job : str
        ``sample``, ``identifiability``, ``diagnose`` or ``predict``.
    overwrite : bool
        Replace the earlier results (said in the log).
    resume : bool
        ``sample --resume``: continuing the run in the folder is what was asked.

    Raises
    ------
    ConfigError
        When the folder holds that job's results and neither ``overwrite`` nor ``resume`` is given; the
        message names the folder, what it holds and the ways on.
    """
    found = existing_results(cfg.output, job)
    if not found or resume:
        return
    if overwrite:
        logger.warning(f"{cfg.output} already holds {', '.join(found)} of an earlier `{job}`: replacing them "
                       "(--overwrite)")
        return
    ways = ("--resume to continue that run, " if job == "sample" else "") + \
        "--overwrite to replace it, or --output DIR for another folder"
    raise ConfigError(cfg.path, "output", f"{cfg.output} already holds the results of an earlier `{job}` "
                                          f"({', '.join(found)}); use {ways}")
