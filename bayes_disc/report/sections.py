"""The report as an ordered list of sections.

A :class:`Section` is a self-contained block: an id (the HTML anchor; tests and links rely on it), a title,
a one-line reading guide (empty: none shown), an HTML body and its figures. A *section builder* is any callable
``builder(ctx) -> Section | None`` taking the :class:`~.context.ReportContext` of a run; ``None`` leaves the
section out. :func:`.builders.default_builders` returns the standard list; a later capability adds its section by
passing ``builders=default_builders() + [my_builder]`` (or inserting it where it belongs) to
:func:`~.run.build_report`, without touching the rest of the report.

This module holds only the building blocks; it imports none of the section builders (:mod:`.content`
imports it), so the report's modules import one way: sections → content → findings → builders → run.
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


#: a value smaller than this fraction of its scale is round-off of a zero (a truth of 1.8e-15 next to 50 rad/s)
ROUND_OFF = 1e-12


def fmt_scaled(x, scale: float, digits: int = 4) -> str:
    """:func:`fmt`, but "0" for a value that is round-off of zero.

    Parameters
    ----------
    x : float or None
        The value.
    scale : float
        The magnitude of the quantity it was computed with (e.g. the norm of its vector) in the same unit;
        ``|x| < ROUND_OFF·scale`` prints as "0".
    digits : int
        Significant digits otherwise.

    Returns
    -------
    str
        The formatted number ('–' for None or non-finite values).
    """
    if x is not None and math.isfinite(float(x)) and abs(float(x)) < ROUND_OFF * abs(float(scale)):
        return "0"
    return fmt(x, digits)


def fmt_percent(fraction, digits: int = 2) -> str:
    """A fraction as a percentage with ``digits`` significant digits ("0.42 %", "3.1 %", "97 %"); '–' for None.

    Parameters
    ----------
    fraction : float or None
        The fraction (1 = 100 %).
    digits : int
        Significant digits.

    Returns
    -------
    str
        Never rounds a fraction below 1 up to "100 %" (0.9996 → "99.96 %").
    """
    if fraction is None or not math.isfinite(float(fraction)):
        return "–"
    v = 100.0 * float(fraction)
    text = f"{v:.{digits}g}"
    while float(text) == 100.0 and v < 100.0 and digits < 8:   # 99.96 % is not 100 %
        digits += 1
        text = f"{v:.{digits}g}"
    if "e" in text:
        text = f"{v:.{digits + 2}f}".rstrip("0").rstrip(".")
    return f"{text} %"


def fmt_estimate(median, lo, hi, max_decimals: int = 6) -> tuple[str, str]:
    """A median and its interval with the same number of decimals, set by the interval's width (two
    significant digits of the width): ("0.1892", "0.1864 … 0.1920").

    Parameters
    ----------
    median, lo, hi : float
        The posterior median and the interval's ends.
    max_decimals : int
        Beyond this many decimals (tiny quantities) the numbers use :func:`fmt` instead.

    Returns
    -------
    tuple of str
        The median and "lo … hi".
    """
    vals = [float(v) for v in (median, lo, hi)]
    width = vals[2] - vals[1]
    if not all(math.isfinite(v) for v in vals) or width <= 0:
        return fmt(median), f"{fmt(lo)} … {fmt(hi)}"
    d = max(0, 1 - math.floor(math.log10(width)))
    if d > max_decimals:
        return fmt(median), f"{fmt(lo)} … {fmt(hi)}"
    return f"{vals[0]:.{d}f}", f"{vals[1]:.{d}f} … {vals[2]:.{d}f}"


def fmt_count(x) -> str:
    """A count-like statistic (effective sample size, steps) as a whole number ("116751", not "1.17e+05");
    '–' for None or non-finite values."""
    if x is None:
        return "–"
    try:
        xf = float(x)
    except (TypeError, ValueError):
        return esc(x)
    return f"{xf:.0f}" if math.isfinite(xf) else "–"


def ordinal(n: int) -> str:
    """1st, 2nd, 3rd, 4th, 11th, 12th, 21st …"""
    n = int(n)
    suffix = "th" if 10 <= n % 100 <= 20 else {1: "st", 2: "nd", 3: "rd"}.get(n % 10, "th")
    return f"{n}{suffix}"


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
