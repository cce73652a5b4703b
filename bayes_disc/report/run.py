"""``build_report``: a run folder → ``reports/<name>.html`` plus every figure as PNG and PDF."""
from __future__ import annotations

import logging
import time
import warnings
from pathlib import Path

from .builders import default_builders
from .context import ReportContext, load_run
from .html import render_document
from .sections import Section, SectionBuilder

logger = logging.getLogger(__name__)


def build_sections(ctx: ReportContext, builders: list[SectionBuilder] | None = None) -> list[Section]:
    """Run the section builders in order.

    Parameters
    ----------
    ctx : ReportContext
        The run being reported.
    builders : list of callable, optional
        Section builders (default :func:`~.builders.default_builders`); a builder returning None is left out.

    Returns
    -------
    list of Section
        The sections in order.

    Raises
    ------
    ValueError
        If two sections share an id.
    """
    sections = []
    for b in (default_builders() if builders is None else builders):
        s = b(ctx)
        if s is not None:
            sections.append(s)
    ids = [s.id for s in sections]
    dup = sorted({i for i in ids if ids.count(i) > 1})
    if dup:
        raise ValueError(f"report sections with duplicate id(s): {dup}")
    return sections


def build_report(run_dir, reports_dir=Path("reports"), builders: list[SectionBuilder] | None = None,
                 seed: int = 0) -> Path:
    """Write ``<reports_dir>/<name>.html`` (self-contained) and ``<run_dir>/figures/*.png|pdf``.

    Parameters
    ----------
    run_dir : str or Path
        A ``bayes-disc sample`` output folder (summary.json, posterior.nc, run_info.json).
    reports_dir : str or Path
        Folder of the HTML file; relative paths resolve against the current working directory
        (default: ``reports/<name>.html``).
    builders : list of callable, optional
        Section builders (default :func:`~.builders.default_builders`).
    seed : int
        Seed of every random choice (posterior draws, noise).

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
        sections = build_sections(ctx, builders)
    name = run.summary["name"]
    out = Path(reports_dir) / f"{name}.html"
    out.parent.mkdir(parents=True, exist_ok=True)
    elapsed = time.perf_counter() - t0
    subtitle = f"Flying-disc coefficients from tracked flights (bayes-disc). Run folder: {Path(run_dir).resolve()}"
    html = render_document(f"{name}: bayes-disc report", subtitle, sections,
                           footer=f"Report built in {elapsed:.1f} s; figures in {ctx.figure_dir}.")
    out.write_text(html, encoding="utf-8")
    logger.info(f"wrote {out} ({len(sections)} sections, {len(ctx.figures_written)} figures, {elapsed:.1f} s)")
    return out
