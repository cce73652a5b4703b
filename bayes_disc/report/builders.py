"""The standard list of section builders, in report order (see :mod:`.sections` for the protocol)."""
from __future__ import annotations

from . import content, findings
from .answer import answer_section
from .inertial import inertial_section
from .sections import SectionBuilder


def default_builders() -> list[SectionBuilder]:
    """The standard sections, in report order.

    Returns
    -------
    list of callable
        A new list on every call (callers may extend it); each item maps a
        :class:`~.context.ReportContext` to a :class:`~.sections.Section` or None.
    """
    return [answer_section, content.coefficient_table, content.corner_section, content.convergence_section,
            content.residual_section, findings.flagged_section, content.flight_section, inertial_section,
            content.force_curve_section, findings.identifiability_section, findings.missing_physics_section,
            content.appendix_section]


#: section ids of :func:`default_builders`, in order
DEFAULT_SECTION_IDS = ("answer", "coefficients", "corner", "convergence", "residuals", "flagged", "flights",
                       "inertial", "force-curves", "identifiability", "missing-physics", "appendix")
