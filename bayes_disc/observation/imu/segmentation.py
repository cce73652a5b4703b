"""Finding the throws in an inertial log: release, first impact, and which side is up.

Criteria (each with its value kept in :class:`Segment` so a reader can judge them):

1. **Spinning span**: rows where the angular-rate magnitude |ω| exceeds ``spin_threshold``
   (default 1000 dps, as in the flatball README) for at least ``min_rows`` consecutive rows.
2. **Release** (the end of the arm's spin-up): the first row of the span where the spin |ω_z|
   reaches ``(1 - release_fraction)`` of the span's largest |ω_z|. The hand spins the disc up within
   a few rows; once free, the spin only decays, slowly (≈ 1 dps per row in the flatball logs), so
   the peak lies at the hand-off.
3. **First impact** (end of the free flight): after ``settle_rows`` rows past release, the first row
   whose change of |ω_z| from the previous row departs from the flight's typical change by more
   than ``jump_sigma`` robust standard deviations (median absolute deviation of the row-to-row
   changes over the middle half of the flight window) and by at least ``min_jump`` rad/s. A catch
   or the ground brakes the spin abruptly; in free flight the row-to-row change is a smooth decay.
   ``end`` is that row, exclusive: the free flight is rows ``release .. end - 1``.
4. **Orientation**: the median in-flight specific force along sensor z. The aerodynamic normal
   force points up in flight; for a right-side-up disc up is −b3 and the sensor's +z points like b3
   (docs/data-formats.md), so acc-z < 0; for a disc flown upside down it is > 0.

Names follow docs/data-formats.md: ``<stem>`` for the first throw of a file, ``<stem>_2``, ``<stem>_3``… next.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .formats import G_STANDARD, InertialLog

ORIENTATIONS = ("right_side_up", "upside_down", "undetermined")


@dataclass(frozen=True)
class SegmentationSettings:
    """Thresholds of :func:`find_throws` (see the module docstring for their meaning).

    Attributes
    ----------
    spin_threshold : float
        |ω| above which a row belongs to a spinning span, rad/s (default 1000 dps).
    min_rows : int
        Shortest spinning span counted as a throw, rows.
    release_fraction : float
        Release is the first row with |ω_z| >= (1 - release_fraction) · max |ω_z| of the span.
    settle_rows : int
        Rows after release skipped before looking for the impact (the hand-off transient).
    jump_sigma : float
        Impact threshold in robust standard deviations of the in-flight row-to-row |ω_z| change.
    min_jump : float
        Smallest change of |ω_z| between two rows taken as an impact, rad/s.
    orientation_margin : float
        |median acc-z| below this (m/s²) leaves the orientation undetermined.
    """

    spin_threshold: float = math.radians(1000.0)
    min_rows: int = 30
    release_fraction: float = 0.01
    settle_rows: int = 5
    jump_sigma: float = 10.0
    min_jump: float = math.radians(5.0)
    orientation_margin: float = 0.2 * G_STANDARD

    def __post_init__(self) -> None:
        for name in ("spin_threshold", "jump_sigma", "min_jump", "orientation_margin"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v > 0):
                raise ValueError(f"segmentation.{name} must be a positive number, got {v!r}")
        if not (0 < self.release_fraction < 0.5):
            raise ValueError(f"segmentation.release_fraction must lie in (0, 0.5), got {self.release_fraction!r}")
        if self.min_rows < 3 or self.settle_rows < 0:
            raise ValueError("segmentation.min_rows must be >= 3 and settle_rows >= 0")


@dataclass
class Segment:
    """One throw in a log; rows are logger rows (``InertialLog.rows`` values).

    Attributes
    ----------
    name : str
        Flight name (``<stem>``, ``<stem>_2``, …).
    start : int
        Release row (first row of free flight).
    end : int
        First impact row (exclusive end of the free flight).
    spin_start, spin_end : int
        First row with |ω| above the spin threshold, first row after the span below it.
    orientation : str
        ``right_side_up``, ``upside_down`` or ``undetermined``.
    reason : str
        How start and end were found (criteria or ``override``).
    criteria : dict
        The numbers behind the decisions (rad/s, m/s², rows).
    """

    name: str
    start: int
    end: int
    spin_start: int
    spin_end: int
    orientation: str
    reason: str
    criteria: dict = field(default_factory=dict)

    @property
    def n_rows(self) -> int:
        """Rows of free flight, counted on the logger's step counter (end - start)."""
        return self.end - self.start


def flight_names(stem: str, n: int) -> list[str]:
    """Names (docs/data-formats.md) of the ``n`` throws of a file: ``stem``, ``stem_2``, ``stem_3``…

    Parameters
    ----------
    stem : str
        The file stem.
    n : int
        Number of throws.

    Returns
    -------
    list of str
    """
    return [stem if k == 0 else f"{stem}_{k + 1}" for k in range(n)]


def spinning_spans(omega_norm: np.ndarray, threshold: float, min_rows: int) -> list[tuple[int, int]]:
    """Runs of consecutive samples with ``omega_norm > threshold``, at least ``min_rows`` long.

    Parameters
    ----------
    omega_norm : ndarray, shape (n,)
        |ω| per sample, rad/s.
    threshold : float
        rad/s.
    min_rows : int
        Shortest run kept.

    Returns
    -------
    list of (int, int)
        Array positions (first, one past last) of each run.
    """
    above = np.concatenate([[False], omega_norm > threshold, [False]])
    edges = np.flatnonzero(np.diff(above.astype(np.int8)))
    return [(int(a), int(b)) for a, b in zip(edges[::2], edges[1::2]) if b - a >= min_rows]


def release_position(spin: np.ndarray, first: int, last: int, fraction: float) -> int:
    """First position in ``first:last`` with ``spin >= (1 - fraction) · max(spin[first:last])``.

    Parameters
    ----------
    spin : ndarray, shape (n,)
        |ω_z| per sample, rad/s.
    first, last : int
        The spinning span (array positions, last exclusive).
    fraction : float
        Relative tolerance below the peak.

    Returns
    -------
    int
        Array position of release.
    """
    seg = spin[first:last]
    return first + int(np.argmax(seg >= (1.0 - fraction) * seg.max()))


def impact_position(spin: np.ndarray, release: int, last: int, s: SegmentationSettings) -> tuple[int, dict]:
    """First abrupt change of the spin after release (see the module docstring, criterion 3).

    Parameters
    ----------
    spin : ndarray, shape (n,)
        |ω_z| per sample, rad/s.
    release : int
        Array position of release.
    last : int
        One past the spinning span (array position); the search also covers this sample.
    s : SegmentationSettings

    Returns
    -------
    (int, dict)
        Array position of the first impact (exclusive end of the free flight) and the criteria
        values: typical in-flight change, robust scale, threshold, the change found (rad/s per row).
    """
    first = release + s.settle_rows + 1
    last = min(last + 1, spin.size)
    if last - first < 8:
        raise ValueError(f"spinning span too short after release ({last - first} rows) to find an impact")
    d = np.diff(spin)[first - 1:last - 1]          # d[k] = spin[first + k] - spin[first + k - 1]
    n = d.size
    mid = d[n // 4: max(3 * n // 4, n // 4 + 3)]
    centre = float(np.median(mid))
    scale = float(1.4826 * np.median(np.abs(mid - centre)))
    threshold = max(s.jump_sigma * scale, s.min_jump)
    bad = np.flatnonzero(np.abs(d - centre) > threshold)
    pos = first + int(bad[0]) if bad.size else last
    crit = {"typical_spin_change_per_row": centre, "spin_change_scale": scale, "impact_threshold": threshold,
            "impact_spin_change": float(d[bad[0]]) if bad.size else float("nan"),
            "impact_found": bool(bad.size)}
    return pos, crit


def orientation_of(acc_z: np.ndarray, margin: float) -> tuple[str, dict]:
    """Classify a throw as right side up / upside down from the in-flight specific force along z.

    Parameters
    ----------
    acc_z : ndarray, shape (m,)
        Specific force along sensor z during free flight, m/s².
    margin : float
        |median| below this leaves the orientation ``undetermined``, m/s².

    Returns
    -------
    (str, dict)
        The orientation and its evidence (median in m/s² and in g, fraction of rows with acc-z > 0).
    """
    med = float(np.median(acc_z))
    evidence = {"acc_z_median": med, "acc_z_median_g": med / G_STANDARD,
                "acc_z_fraction_positive": float(np.mean(acc_z > 0))}
    if abs(med) < margin:
        return "undetermined", evidence
    return ("upside_down" if med > 0 else "right_side_up"), evidence


def _segment_at(log: InertialLog, name: str, release: int, end: int, span: tuple[int, int], reason: str,
                criteria: dict, s: SegmentationSettings) -> Segment:
    fly = slice(release, end)
    orient, evidence = orientation_of(log.acc[fly, 2], s.orientation_margin)
    criteria = dict(criteria)
    criteria.update(evidence)
    wz = log.gyro[fly, 2]
    criteria.update({"spin_at_release": float(log.gyro[release, 2]), "spin_at_end": float(log.gyro[end - 1, 2]),
                     "spin_median": float(np.median(wz)),
                     "acc_norm_peak_row": int(log.rows[span[0] + int(np.argmax(
                         np.linalg.norm(log.acc[span[0]:min(release + s.settle_rows, len(log))], axis=1)))]),
                     "missing_rows_in_flight": int(log.rows[end - 1] - log.rows[release] + 1 - (end - release))})
    spin_end = int(log.rows[span[1]]) if span[1] < len(log) else int(log.rows[-1]) + 1
    return Segment(name=name, start=int(log.rows[release]),
                   end=int(log.rows[end]) if end < len(log) else int(log.rows[-1]) + 1,
                   spin_start=int(log.rows[span[0]]), spin_end=spin_end, orientation=orient, reason=reason,
                   criteria=criteria)


def find_throws(log: InertialLog, settings: SegmentationSettings | None = None,
                override: list[tuple[int, int]] | None = None) -> list[Segment]:
    """Find every throw in a log: release, first impact, orientation.

    Parameters
    ----------
    log : InertialLog
        The recording (gyro rad/s, acc m/s²).
    settings : SegmentationSettings, optional
        Thresholds (defaults as documented there).
    override : list of (int, int), optional
        Explicit (start, end) logger rows per throw (end exclusive) replacing the automatic release
        and impact; orientation is still measured. Each row must be present in the log (``end`` may
        also be one past the last row); an absent row raises KeyError.

    Returns
    -------
    list of Segment
        In time order, named ``<name>``, ``<name>_2``, …; empty when nothing spins above threshold.
    """
    s = SegmentationSettings() if settings is None else settings
    omega = np.linalg.norm(log.gyro, axis=1)
    spin = np.abs(log.gyro[:, 2])
    names_needed = len(override) if override is not None else None
    if override is not None:
        names = flight_names(log.name, names_needed)
        out = []
        for name, (start, end) in zip(names, override):
            if not start < end:
                raise ValueError(f"{log.name}: override start {start} must be before end {end}")
            a = log.position(start)
            b = len(log) if end == int(log.rows[-1]) + 1 else log.position(end)
            if b - a < 3:
                raise ValueError(f"{log.name}: override {start}..{end} holds fewer than 3 samples")
            out.append(_segment_at(log, name, a, b, (a, b), "override: explicit start and end rows",
                                   {"override": (int(start), int(end))}, s))
        return out
    spans = spinning_spans(omega, s.spin_threshold, s.min_rows)
    names = flight_names(log.name, len(spans))
    out = []
    for name, (first, last) in zip(names, spans):
        rel = release_position(spin, first, last, s.release_fraction)
        end, crit = impact_position(spin, rel, last, s)
        crit = {"spin_peak": float(spin[first:last].max()), **crit}
        reason = (f"release: first row with |ω_z| >= {1 - s.release_fraction:.0%} of the span's peak "
                  f"{math.degrees(crit['spin_peak']):.0f} dps; end: ")
        reason += (f"first |ω_z| change of {math.degrees(crit['impact_spin_change']):.1f} dps/row, beyond "
                   f"{math.degrees(crit['impact_threshold']):.1f} dps/row from the in-flight "
                   f"{math.degrees(crit['typical_spin_change_per_row']):.2f} dps/row"
                   if crit["impact_found"] else "no impact found: the spinning span's end")
        out.append(_segment_at(log, name, rel, end, (first, last), reason, crit, s))
    return out


def throw_logs(log: InertialLog, segments: list[Segment]) -> list[InertialLog]:
    """Cut a log into one sub-log per throw (free flight only), named like the segments.

    Parameters
    ----------
    log : InertialLog
    segments : list of Segment

    Returns
    -------
    list of InertialLog
        Rows ``segment.start .. segment.end - 1`` of ``log``.
    """
    out = []
    for seg in segments:
        a = log.position(seg.start)
        b = int(np.searchsorted(log.rows, seg.end))
        out.append(log.select(a, b, name=seg.name))
    return out


def landing_log(log: InertialLog, segment: Segment, rows: int, next_start: int | None = None) -> InertialLog | None:
    """The rows right after a throw's free flight (the disc on the ground), for the barometer's relaxation.

    Parameters
    ----------
    log : InertialLog
    segment : Segment
    rows : int
        How many logger rows after the flight's end to take at most.
    next_start : int, optional
        Release row of the log's next throw: the landing rows stop before it.

    Returns
    -------
    InertialLog or None
        Rows ``segment.end .. segment.end + rows - 1`` present in ``log`` (before ``next_start``), named like
        the segment; None when there are none.
    """
    stop = segment.end + rows if next_start is None else min(segment.end + rows, next_start)
    a, b = int(np.searchsorted(log.rows, segment.end)), int(np.searchsorted(log.rows, stop))
    return log.select(a, b, name=segment.name) if b > a else None
