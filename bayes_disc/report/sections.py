"""The report as an ordered list of sections.

A :class:`Section` is a self-contained block: an id (the HTML anchor; tests and links rely on it), a title,
a one-line reading guide, an HTML body and its figures. A *section builder* is any callable
``builder(ctx) -> Section | None`` taking the :class:`~.context.ReportContext` of a run; ``None`` leaves the
section out. :func:`.builders.default_builders` returns the standard list; a later capability adds its section by
passing ``builders=default_builders() + [my_builder]`` (or inserting it where it belongs) to
:func:`~.run.build_report`, without touching the rest of the report.

This module holds only the building blocks; it imports none of the section builders (:mod:`.content`
imports it), so the report's modules import one way: sections → content → builders → run.
"""
from __future__ import annotations

import html as _html
import math
from dataclasses import dataclass, field
from typing import Callable, Iterable, Sequence


@dataclass(frozen=True)
class ReportFigure:
    """A rendered figure: file stem, caption, PNG bytes (embedded) and the PNG/PDF files written."""

    name: str
    caption: str
    png: bytes
    png_path: str
    pdf_path: str


@dataclass
class Section:
    """One block of the report. ``html`` is trusted markup made with :func:`table`/:func:`esc`."""

    id: str
    title: str
    guide: str
    html: str = ""
    figures: list[ReportFigure] = field(default_factory=list)


SectionBuilder = Callable[["ReportContext"], "Section | None"]  # noqa: F821 (forward reference)


def esc(value) -> str:
    """HTML-escaped text of any value."""
    return _html.escape(str(value), quote=True)


def fmt(x, digits: int = 4) -> str:
    """A number with ``digits`` significant digits; '–' for None or non-finite values."""
    if x is None:
        return "–"
    try:
        xf = float(x)
    except (TypeError, ValueError):
        return esc(x)
    if not math.isfinite(xf):
        return "–"
    return f"{xf:.{digits}g}"


def table(headers: Sequence[str], rows: Iterable[Sequence], cls: str = "") -> str:
    """An HTML table. Cells are escaped unless given as ``Raw``; headers are escaped."""
    out = [f'<table class="{esc(cls)}"><thead><tr>' + "".join(f"<th>{esc(h)}</th>" for h in headers)
           + "</tr></thead><tbody>"]
    for row in rows:
        out.append("<tr>" + "".join(f"<td>{c.html if isinstance(c, Raw) else esc(c)}</td>" for c in row) + "</tr>")
    out.append("</tbody></table>")
    return "".join(out)


@dataclass(frozen=True)
class Raw:
    """Markup that :func:`table` inserts unescaped."""

    html: str
