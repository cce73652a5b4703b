"""The ``diagnose`` job: is the model missing physics? Name it, resample with it, rebuild the report.

The analysis is :mod:`bayes_disc.diagnostics.diagnosis` (base fit, candidate terms ranked by ΔBIC, correlated
noise, the learned correction); this job adds what needs a sampling run: the resampling with the accepted
terms into ``<output>/diagnosis_refit/`` (whose posterior then gives the estimates after), the files
``diagnosis.json`` and ``diagnosis_residuals.npz``, and the HTML report of a sampled run in the same folder.
"""
from __future__ import annotations

import logging
import time
from pathlib import Path

from ..diagnostics.diagnosis import analyse, diagnosis_record, estimates_after, estimates_before, refit_config, \
    write_diagnosis
from ..inference.model.config import RunConfig
from .outputs import Outcome, build_run_report
from .progress import RESULT
from .sample import run_sample

logger = logging.getLogger(__name__)
#: sub-folder of the run folder that holds the resampled run with the accepted terms
REFIT_DIR = "diagnosis_refit"


def run_diagnose(cfg: RunConfig, sample: bool = True, processes: int = 2, progress: bool = True,
                 candidates=None, learn: bool = True) -> dict:
    """The ``diagnose`` command without its report.

    Parameters
    ----------
    cfg : RunConfig
        The validated run configuration; files go to ``cfg.output``.
    sample : bool
        Resample (emcee) with the accepted terms into ``<output>/diagnosis_refit``; otherwise the
        estimates after are least-squares (Laplace) ones.
    processes : int
        Parallel candidate fits.
    progress : bool
        Show a progress bar while resampling.
    candidates : sequence of str, optional
        The candidate ids to try (default: every candidate); an unknown id is an error.
    learn : bool
        When the base model leaves structure, learn a correction and report it under ``learned_discrepancy``.

    Returns
    -------
    dict
        The content of ``diagnosis.json`` (docs/outputs.md): ``verdict``, ``effects`` ranked best first, RMS
        per flight before and after [mm] (``rms_before_mm``, ``rms_after_mm``), and the details of
        :func:`bayes_disc.diagnostics.diagnosis.diagnosis_record` (``words``: the diagnosis in words).
    """
    t0 = time.perf_counter()
    out = Path(cfg.output)
    out.mkdir(parents=True, exist_ok=True)
    analysis = analyse(cfg, processes=processes, candidates=candidates)
    before = estimates_before(analysis, out)
    refit_dir = None
    if analysis.diag.accepted and sample:
        refit_dir = out / REFIT_DIR
        logger.info(f"resampling with {', '.join(c.id for c in analysis.diag.accepted)} → {refit_dir}")
        run_sample(refit_config(analysis, refit_dir), progress=progress)
    result = diagnosis_record(analysis, before, estimates_after(analysis, refit_dir), refit_dir, learn=learn)
    result["wall_time_s"] = time.perf_counter() - t0
    write_diagnosis(out, result, analysis.diag)
    logger.info(result["words"], extra=RESULT)
    logger.info(f"wrote {out / 'diagnosis.json'} ({result['wall_time_s']:.0f} s)")
    return result


def diagnose(cfg: RunConfig, *, sample: bool = True, processes: int = 2, progress: bool = True,
             report: bool = True, learn: bool = True) -> Outcome:
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
        Rebuild ``<output>/reports/<name>.html`` when the output folder holds a sampled run (the report then
        includes the diagnosis); otherwise say how to get one.
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
            path = build_run_report(out, cfg.sampler.seed, cfg.sampler.processes)
        else:
            logger.info(f"no sampled run in {out}: run `bayes-disc sample {cfg.path}` for the HTML report "
                        "(it then includes this diagnosis)")
    return Outcome(result, path)
