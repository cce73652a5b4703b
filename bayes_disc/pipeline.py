"""Orchestration at the top of the layers: a job, then the HTML report of its run folder.

The jobs themselves live lower down and know nothing of the report: :func:`~.inference.run.run_sample`
(least squares and emcee), :func:`~.diagnostics.run.run_identifiability`,
:func:`~.diagnostics.diagnosis.run_diagnose` (candidate terms, and the resampling with the accepted ones).
The command line (:mod:`.cli`) and the Python API (:mod:`.api`) both call these functions.
"""
from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path

from .diagnostics.diagnosis import run_diagnose
from .diagnostics.run import run_identifiability
from .inference.model.config import RunConfig
from .inference.run import run_sample, stage
from .report import build_report

logger = logging.getLogger(__name__)

#: where ``reports/<name>.html`` goes by default (relative to the working directory, SPEC §6)
DEFAULT_REPORTS_DIR = Path("reports")
#: sub-folder of an ``--output DIR`` that holds the report when the output folder is given explicitly
RUN_REPORTS_DIR = "reports"


def reports_dir(output=None) -> Path:
    """Folder of a run's HTML report ``<name>.html``, as the command line chooses it.

    Without ``--output`` the report is ``reports/<name>.html`` in the working directory (SPEC §6); with
    ``--output DIR`` it goes with the run, ``DIR/reports/<name>.html``, so that a run written elsewhere
    never overwrites the working directory's reports (such as the repository's committed demo report).

    Parameters
    ----------
    output : str or Path, optional
        The ``--output`` folder given on the command line, or None.

    Returns
    -------
    Path
        The folder (relative paths: to the working directory).
    """
    return DEFAULT_REPORTS_DIR if output is None else Path(output) / RUN_REPORTS_DIR


def _report(run_dir, reports: Path, seed: int, processes: int) -> Path:
    with stage("report", f"HTML into {Path(reports)}/, figures into {Path(run_dir) / 'figures'}/"):
        return build_report(run_dir, reports_dir=Path(reports), seed=seed, processes=processes)


@dataclass(frozen=True)
class Outcome:
    """What a job returned and the report built after it.

    Attributes
    ----------
    result : dict
        The job's JSON content (summary.json, identifiability.json or diagnosis.json).
    report : Path or None
        The HTML report written, or None when none was built.
    """

    result: dict
    report: Path | None


def sample(cfg: RunConfig, *, resume: bool = False, progress: bool = True, report: bool = True,
           reports_dir=DEFAULT_REPORTS_DIR) -> Outcome:
    """``bayes-disc sample``: sample the posterior, then build ``<reports_dir>/<name>.html``.

    Parameters
    ----------
    cfg : RunConfig
        The validated run configuration.
    resume : bool
        Continue an interrupted run from its chain files.
    progress : bool
        Show progress bars (least-squares starts and stages are logged in any case).
    report : bool
        Build the HTML report after sampling.
    reports_dir : str or Path
        Folder of the HTML report (relative: to the working directory); the command line passes
        :func:`reports_dir` of its ``--output``.

    Returns
    -------
    Outcome
        ``result``: the summary.json content; ``report``: the HTML file (None without ``report``).
    """
    logger.debug(f"sample: configuration {cfg.path}, output {cfg.output}")
    summary = run_sample(cfg, resume=resume, progress=progress)
    path = _report(cfg.output, reports_dir, cfg.sampler.seed, cfg.sampler.processes) if report else None
    return Outcome(summary, path)


def identifiability(cfg: RunConfig, *, profiles: bool = False, design: bool = True) -> Outcome:
    """``bayes-disc identifiability``: which coefficients the flights determine (no report of its own).

    Parameters
    ----------
    cfg : RunConfig
        The validated run configuration.
    profiles : bool
        Also profile the likelihood of every coefficient.
    design : bool
        Rank candidate throws.

    Returns
    -------
    Outcome
        ``result``: the identifiability.json content; ``report``: None (the report of a sampled run
        includes the identifiability section once this file exists).
    """
    logger.debug(f"identifiability: configuration {cfg.path}, output {cfg.output}")
    return Outcome(run_identifiability(cfg, profiles=profiles, design=design), None)


def diagnose(cfg: RunConfig, *, sample: bool = True, processes: int = 2, progress: bool = True,
             report: bool = True, reports_dir=DEFAULT_REPORTS_DIR, learn: bool = True) -> Outcome:
    """``bayes-disc diagnose``: name the missing physics (and resample), then rebuild the run's report.

    Parameters
    ----------
    cfg : RunConfig
        The validated run configuration.
    sample : bool
        Resample with the accepted terms (otherwise least-squares estimates only).
    processes : int
        Parallel candidate fits.
    progress : bool
        Show a progress bar while resampling.
    report : bool
        Rebuild ``<reports_dir>/<name>.html`` when the output folder holds a sampled run (the report then
        includes the diagnosis); otherwise say how to get one.
    reports_dir : str or Path
        Folder of the HTML report (relative: to the working directory).
    learn : bool
        Learn a correction when the base model leaves structure (``learned_discrepancy``).

    Returns
    -------
    Outcome
        ``result``: the diagnosis.json content; ``report``: the HTML file or None.
    """
    logger.debug(f"diagnose: configuration {cfg.path}, output {cfg.output}")
    result = run_diagnose(cfg, sample=sample, processes=processes, progress=progress, learn=learn)
    out = Path(cfg.output)
    path = None
    if report:
        if (out / "summary.json").is_file() and (out / "posterior.nc").is_file():
            path = _report(out, reports_dir, cfg.sampler.seed, cfg.sampler.processes)
        else:
            logger.info(f"no sampled run in {out}: run `bayes-disc sample {cfg.path}` for the HTML report "
                        "(it then includes this diagnosis)")
    return Outcome(result, path)
