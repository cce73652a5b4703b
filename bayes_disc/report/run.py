"""``build_report``: a run folder → ``reports/<name>.html`` plus every figure as PNG and PDF.

Drawing the figures dominates a report's time (matplotlib lays out and draws every axis twice: PNG, then PDF).
The section builders are independent given the run, so with ``processes > 1`` they run in a worker pool
(:func:`~bayes_disc.physics.parallel.mp_context`: forked on Linux, so the workers inherit the loaded run
without copying it); the state several sections share (the simulated posterior draws) is computed once
before, and the sections come back in report order, equal to those built in one process.
"""
from __future__ import annotations

import logging
import time
import warnings
from pathlib import Path

from ..physics.parallel import mp_context
from .builders import default_builders
from .context import ReportContext, load_run
from .html import render_document
from .sections import Section, SectionBuilder

logger = logging.getLogger(__name__)


#: the report pool's worker state: the context and builders it was started with (one per worker process)
_WORKER: dict = {}


def _init_worker(ctx: ReportContext, builders: list[SectionBuilder]) -> None:
    _WORKER.update(ctx=ctx, builders=builders)


def _build_one(i: int) -> tuple[Section | None, list]:
    """Builder i on the worker's context: its section and the figures it wrote."""
    ctx = _WORKER["ctx"]
    n0 = len(ctx.figures_written)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)     # all-NaN slices of failed lanes, NaN τ
        section = _WORKER["builders"][i](ctx)
    return section, ctx.figures_written[n0:]


def build_sections(ctx: ReportContext, builders: list[SectionBuilder] | None = None,
                   processes: int = 1) -> list[Section]:
    """Run the section builders; the sections in builder order.

    Parameters
    ----------
    ctx : ReportContext
        The run being reported.
    builders : list of callable, optional
        Section builders (default :func:`~.builders.default_builders`); a builder returning None is left out.
    processes : int
        Worker processes drawing the sections (module docstring); 1: in this process, one after the other.
        The sections are the same either way.

    Returns
    -------
    list of Section
        The sections in order.

    Raises
    ------
    ValueError
        If two sections share an id, or ``processes`` < 1.
    """
    builders = default_builders() if builders is None else list(builders)
    if processes < 1:
        raise ValueError(f"report processes must be ≥ 1, got {processes}")
    if processes == 1 or len(builders) < 2:
        built = [b(ctx) for b in builders]
    else:
        ctx.prepare()       # shared state once, inherited by every worker
        with mp_context().Pool(min(processes, len(builders)), initializer=_init_worker,
                               initargs=(ctx, builders)) as pool:
            results = pool.map(_build_one, range(len(builders)), chunksize=1)
        built = []
        for section, figures in results:
            built.append(section)
            ctx.figures_written.extend(figures)
    sections = [s for s in built if s is not None]
    ids = [s.id for s in sections]
    dup = sorted({i for i in ids if ids.count(i) > 1})
    if dup:
        raise ValueError(f"report sections with duplicate id(s): {dup}")
    return sections


#: sub-folder of a run folder that holds its HTML report ``<name>.html`` by default
REPORTS_DIR = "reports"


def build_report(run_dir, reports_dir=None, builders: list[SectionBuilder] | None = None,
                 seed: int = 0, processes: int = 2) -> Path:
    """Write ``<reports_dir>/<name>.html`` (self-contained) and ``<run_dir>/figures/*.png|pdf``.

    Parameters
    ----------
    run_dir : str or Path
        A ``bayes-disc sample`` output folder (summary.json, posterior.nc, run_info.json).
    reports_dir : str or Path, optional
        Folder of the HTML file; relative paths resolve against the current working directory (default:
        ``<run_dir>/reports``, so that the report goes with its run).
    builders : list of callable, optional
        Section builders (default :func:`~.builders.default_builders`).
    seed : int
        Seed of every random choice (posterior draws, noise).
    processes : int
        Worker processes drawing the sections (:func:`build_sections`); the report is the same for any number.

    Returns
    -------
    Path
        The HTML file written. Its path, section and figure counts are logged at INFO level.

    Raises
    ------
    ReportInputError
        For a missing or invalid run folder.
    """
    t0 = time.perf_counter()
    run = load_run(run_dir)
    ctx = ReportContext(run, Path(run_dir) / "figures", seed=seed)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)     # all-NaN slices of failed lanes, NaN τ
        sections = build_sections(ctx, builders, processes)
    name = run.summary["name"]
    out = (Path(run_dir) / REPORTS_DIR if reports_dir is None else Path(reports_dir)) / f"{name}.html"
    out.parent.mkdir(parents=True, exist_ok=True)
    elapsed = time.perf_counter() - t0
    subtitle = f"Flying-disc coefficients from tracked flights (bayes-disc). Run folder: {run_dir}"
    html = render_document(f"{name}: bayes-disc report", subtitle, sections,
                           footer=f"Report built in {elapsed:.1f} s; figures in {ctx.figure_dir}.")
    out.write_text(html, encoding="utf-8")
    logger.info(f"wrote {out} ({len(sections)} sections, {len(ctx.figures_written)} figures, {elapsed:.1f} s)")
    return out
