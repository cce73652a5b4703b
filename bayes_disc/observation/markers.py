"""Marker data files (SPEC §4): read with validation, write, and arrange per flight.

CSV, one row per marker per sample, header ``flight,t,marker,x,y,z`` (extra columns allowed, e.g. a
per-point standard deviation ``sigma_m``). World-frame positions in metres, time in seconds, increasing
within a flight. A missing observation is a missing row or NaN coordinates. Anything else is rejected
with a :class:`MarkerFileError` naming the file, the line and the problem; nothing is dropped or reordered.
"""
from __future__ import annotations

import csv
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

REQUIRED_COLUMNS = ("flight", "t", "marker", "x", "y", "z")
#: marker spacing above this (m) on one disc means the file is not in metres
MAX_MARKER_SPACING_M = 2.0
#: coordinates above this (m) are not a disc flight in metres
MAX_COORDINATE_M = 1000.0


class MarkerFileError(ValueError):
    """A marker file that breaks SPEC §4; the message names file, line and problem."""

    def __init__(self, path, line: int | None, problem: str):
        self.path, self.line, self.problem = str(path), line, problem
        where = f"{path}:{line}" if line is not None else f"{path}"
        super().__init__(f"{where}: {problem}")


@dataclass
class MarkerTable:
    """Rows of a marker file in file order. ``extra`` holds any additional numeric columns."""

    flight: np.ndarray
    t: np.ndarray
    marker: np.ndarray
    xyz: np.ndarray
    extra: dict = field(default_factory=dict)
    lines: np.ndarray | None = None  # 1-based line numbers in the source file, when read from one

    def __len__(self) -> int:
        return len(self.t)

    @property
    def flights(self) -> list[str]:
        """Flight names in order of first appearance."""
        return list(dict.fromkeys(self.flight.tolist()))


@dataclass
class FlightObservation:
    """One flight on its sample grid: times (n,), positions (n, n_markers, 3) with NaN where missing.

    ``sigma`` (n, n_markers) holds per-point standard deviations [m] when the file gave ``sigma_m``.
    """

    name: str
    source: str
    times: np.ndarray
    marker_ids: tuple[str, ...]
    positions: np.ndarray
    sigma: np.ndarray | None = None

    @property
    def observed(self) -> np.ndarray:
        """(n, n_markers) True where the marker was seen."""
        return np.all(np.isfinite(self.positions), axis=-1)

    @property
    def n_points(self) -> int:
        return int(self.observed.sum())

    def window(self, t_start: float | None = None, t_end: float | None = None) -> "FlightObservation":
        keep = np.ones(self.times.size, bool)
        if t_start is not None:
            keep &= self.times >= t_start
        if t_end is not None:
            keep &= self.times <= t_end
        return FlightObservation(self.name, self.source, self.times[keep], self.marker_ids,
                                 self.positions[keep], None if self.sigma is None else self.sigma[keep])


def _float(text: str, path, line: int, column: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise MarkerFileError(path, line, f"column {column!r}: {text!r} is not a number") from None
    if math.isinf(value):
        raise MarkerFileError(path, line, f"column {column!r}: infinite value")
    return value


def read_marker_csv(path, marker_ids=None) -> MarkerTable:
    """Read and validate a SPEC §4 marker file.

    marker_ids: the known marker ids (config ``markers`` keys); a row with any other id is rejected.
    """
    path = Path(path)
    if not path.is_file():
        raise MarkerFileError(path, None, "file not found")
    known = None if marker_ids is None else [str(m) for m in marker_ids]
    rows_f, rows_t, rows_m, rows_xyz, rows_line = [], [], [], [], []
    extra_cols: dict[str, list] = {}
    with path.open(newline="") as fh:
        reader = csv.reader(fh)
        try:
            header = next(reader)
        except StopIteration:
            raise MarkerFileError(path, 1, "empty file: header 'flight,t,marker,x,y,z' required") from None
        header = [h.strip() for h in header]
        missing = [c for c in REQUIRED_COLUMNS if c not in header]
        if missing:
            raise MarkerFileError(path, 1, f"header lacks column(s) {missing}; required: {','.join(REQUIRED_COLUMNS)}")
        if len(set(header)) != len(header):
            raise MarkerFileError(path, 1, "header repeats a column name")
        idx = {c: header.index(c) for c in header}
        extras = [c for c in header if c not in REQUIRED_COLUMNS]
        for c in extras:
            extra_cols[c] = []
        for row in reader:
            line = reader.line_num
            if not row or all(not c.strip() for c in row):
                continue
            if len(row) != len(header):
                raise MarkerFileError(path, line, f"{len(row)} fields, header has {len(header)}")
            flight = row[idx["flight"]].strip()
            if not flight:
                raise MarkerFileError(path, line, "empty flight name")
            t = _float(row[idx["t"]], path, line, "t")
            if math.isnan(t):
                raise MarkerFileError(path, line, "time is NaN")
            marker = row[idx["marker"]].strip()
            if known is not None and marker not in known:
                raise MarkerFileError(path, line, f"unknown marker {marker!r} (known: {', '.join(known)})")
            xyz = [_float(row[idx[c]], path, line, c) for c in ("x", "y", "z")]
            nan = [math.isnan(v) for v in xyz]
            if any(nan) and not all(nan):
                raise MarkerFileError(path, line, "some but not all coordinates are NaN")
            if not any(nan) and max(abs(v) for v in xyz) > MAX_COORDINATE_M:
                raise MarkerFileError(path, line, f"coordinate {max(abs(v) for v in xyz):g} m: looks like "
                                      "millimetres; marker files are in metres (docs/data-formats.md)")
            for c in extras:
                text = row[idx[c]].strip()
                try:
                    extra_cols[c].append(float(text) if text else math.nan)
                except ValueError:
                    extra_cols[c].append(text)
            rows_f.append(flight)
            rows_t.append(t)
            rows_m.append(marker)
            rows_xyz.append(xyz)
            rows_line.append(line)
    if not rows_t:
        raise MarkerFileError(path, None, "no data rows")
    table = MarkerTable(flight=np.array(rows_f, dtype=object), t=np.array(rows_t, float),
                        marker=np.array(rows_m, dtype=object), xyz=np.array(rows_xyz, float),
                        extra={c: np.array(v) for c, v in extra_cols.items()}, lines=np.array(rows_line))
    validate_table(table, path)
    return table


def validate_table(table: MarkerTable, path="<table>") -> None:
    """Checks that need whole flights: time order, duplicates, marker count, units by marker spacing."""
    lines = table.lines if table.lines is not None else np.arange(len(table)) + 2
    for name in table.flights:
        rows = np.flatnonzero(table.flight == name)
        t = table.t[rows]
        drop = np.flatnonzero(np.diff(t) < 0)
        if drop.size:
            r = rows[drop[0] + 1]
            raise MarkerFileError(path, int(lines[r]), f"flight {name!r}: time {table.t[r]:g} s goes back "
                                  f"from {table.t[rows[drop[0]]]:g} s (time must increase within a flight)")
        seen = {}
        for r in rows:
            key = (table.t[r], table.marker[r])
            if key in seen:
                raise MarkerFileError(path, int(lines[r]), f"flight {name!r}: marker {table.marker[r]!r} at "
                                      f"t = {table.t[r]:g} s repeats line {seen[key]}")
            seen[key] = int(lines[r])
        finite = np.all(np.isfinite(table.xyz[rows]), axis=1)
        ids = set(table.marker[rows][finite].tolist())
        if len(ids) < 3:
            raise MarkerFileError(path, int(lines[rows[0]]), f"flight {name!r}: only {len(ids)} marker(s) "
                                  "observed; at least 3 are needed to fix the disc's attitude")
        spacing = _median_spacing(table.t[rows], table.marker[rows], table.xyz[rows])
        if spacing is not None and spacing > MAX_MARKER_SPACING_M:
            raise MarkerFileError(path, int(lines[rows[0]]), f"flight {name!r}: markers are {spacing:.3g} apart "
                                  "(median): looks like millimetres; marker files are in metres (docs/data-formats.md)")


def _median_spacing(t, marker, xyz) -> float | None:
    order = np.argsort(t, kind="stable")
    t, marker, xyz = t[order], marker[order], xyz[order]
    starts = np.flatnonzero(np.r_[True, np.diff(t) > 0])
    ends = np.r_[starts[1:], t.size]
    d = []
    for s, e in zip(starts, ends):
        p = xyz[s:e][np.all(np.isfinite(xyz[s:e]), axis=1)]
        if len(p) >= 2:
            d.append(np.linalg.norm(p[0] - p[1]))
        if len(d) >= 200:
            break
    return float(np.median(d)) if d else None


def write_marker_csv(path, table: MarkerTable, precision: int = 9) -> None:
    """Write a SPEC §4 file (extra columns after the required ones, in ``table.extra`` order)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    extras = list(table.extra)
    with path.open("w", newline="") as fh:
        w = csv.writer(fh, lineterminator="\n")
        w.writerow(list(REQUIRED_COLUMNS) + extras)
        for i in range(len(table)):
            xyz = ["nan" if not np.isfinite(v) else f"{v:.{precision}f}" for v in table.xyz[i]]
            ex = []
            for c in extras:
                v = table.extra[c][i]
                ex.append(f"{v:.6g}" if isinstance(v, (float, np.floating)) else str(v))
            w.writerow([table.flight[i], f"{table.t[i]:.9g}", table.marker[i], *xyz, *ex])


def table_from_flights(flights: list[FlightObservation], drop_missing: bool = True) -> MarkerTable:
    """Flat rows (sample-major, markers in layout order) of per-flight observations."""
    f, t, m, xyz, sig = [], [], [], [], []
    any_sigma = any(o.sigma is not None for o in flights)
    for obs in flights:
        for i, ti in enumerate(obs.times):
            for k, mid in enumerate(obs.marker_ids):
                p = obs.positions[i, k]
                if drop_missing and not np.all(np.isfinite(p)):
                    continue
                f.append(obs.name)
                t.append(ti)
                m.append(mid)
                xyz.append(p)
                if any_sigma:
                    sig.append(np.nan if obs.sigma is None else obs.sigma[i, k])
    extra = {"sigma_m": np.array(sig, float)} if any_sigma else {}
    return MarkerTable(np.array(f, dtype=object), np.array(t, float), np.array(m, dtype=object),
                       np.array(xyz, float).reshape(-1, 3), extra)


def flights_from_table(table: MarkerTable, marker_ids, source: str = "") -> list[FlightObservation]:
    """Per-flight arrays on each flight's sample grid (the distinct times of its rows)."""
    marker_ids = tuple(str(m) for m in marker_ids)
    col = {m: k for k, m in enumerate(marker_ids)}
    sigma_col = table.extra.get("sigma_m")
    out = []
    for name in table.flights:
        rows = np.flatnonzero(table.flight == name)
        times = np.unique(table.t[rows])
        pos = np.full((times.size, len(marker_ids), 3), np.nan)
        sig = np.full((times.size, len(marker_ids)), np.nan) if sigma_col is not None else None
        ti = np.searchsorted(times, table.t[rows])
        for r, i in zip(rows, ti):
            k = col[str(table.marker[r])]
            pos[i, k] = table.xyz[r]
            if sig is not None:
                sig[i, k] = float(sigma_col[r])
        out.append(FlightObservation(name=name, source=source, times=times, marker_ids=marker_ids,
                                     positions=pos, sigma=sig))
    return out


def load_flights(path, marker_ids) -> list[FlightObservation]:
    """Read, validate and arrange a marker file."""
    table = read_marker_csv(path, marker_ids)
    return flights_from_table(table, marker_ids, source=str(path))
