"""Reports of a ``bayes-disc sample`` run: corner plots, diagnostics and one self-contained HTML file.

``build_report(run_dir)`` writes ``reports/<name>.html`` and ``<run_dir>/figures/*.png|pdf``. The report
is a list of :class:`Section` objects made by section builders (:func:`default_builders`); later
capabilities add theirs to that list.
"""
from .errors import ReportInputError
from .run import build_report, build_sections
from .builders import DEFAULT_SECTION_IDS, default_builders
from .sections import ReportFigure, Section

__all__ = ["ReportInputError", "build_report", "build_sections", "DEFAULT_SECTION_IDS", "ReportFigure", "Section",
           "default_builders"]
