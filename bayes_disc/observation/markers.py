"""Marker data files (docs/data-formats.md): read with validation, write, and arrange per flight.

CSV, one row per marker per sample, header ``flight,t,marker,x,y,z`` (extra columns allowed, e.g. a
per-point standard deviation ``sigma_m`` [m] or the per-point covariance ``cov_xx, cov_xy, cov_xz, cov_yy,
cov_yz, cov_zz`` [m²] written by ``bayes-disc track``; the marker noise models use them,
:mod:`bayes_disc.observation.models.noise`). World-frame positions in metres, time in seconds, increasing
within a flight. A missing observation is a missing row or NaN coordinates. Anything else is rejected
with a :class:`MarkerFileError` naming the file, the line and the problem; nothing is dropped or reordered.
"""
from __future__ import annotations

import csv
import io
import math
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .config_io import TextDecodeError, read_text

REQUIRED_COLUMNS = ("flight", "t", "marker", "x", "y", "z")
#: per-point covariance columns [m²] (upper triangle, row-major), as ``bayes-disc track`` writes them
COV_COLUMNS = ("cov_xx", "cov_xy", "cov_xz", "cov_yy", "cov_yz", "cov_zz")
#: matrix entry of each covariance column
COV_INDEX = ((0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2))
#: marker spacing above this (m) on one disc means the file is not in metres
MAX_MARKER_SPACING_M = 2.0
#: coordinates above this (m) are not a disc flight in metres
MAX_COORDINATE_M = 1000.0


class MarkerFileError(ValueError):
    """A marker file that breaks the format of docs/data-formats.md; the message names file, line and problem."""

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

    ``sigma`` (n, n_markers) holds per-point standard deviations [m] when the file gave ``sigma_m``;
    ``cov`` (n, n_markers, 3, 3) per-point covariances [m²] when it gave all of :data:`COV_COLUMNS`;
    ``line`` is the 1-based line of the flight's first row in ``source`` when read from a file.
    """

    name: str
    source: str
    times: np.ndarray
    marker_ids: tuple[str, ...]
    positions: np.ndarray
    sigma: np.ndarray | None = None
    line: int | None = None
    cov: np.ndarray | None = None

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
                                 self.positions[keep], None if self.sigma is None else self.sigma[keep], self.line,
                                 None if self.cov is None else self.cov[keep])


def _float(text: str, path, line: int, column: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise MarkerFileError(path, line, f"column {column!r}: {text!r} is not a number") from None
    if math.isinf(value):
        raise MarkerFileError(path, line, f"column {column!r}: infinite value")
    return value


def _read_text(path: Path) -> str:
    """The file's UTF-8 text (byte-order mark dropped); a folder, a binary or a non-UTF-8 file is named."""
    if path.is_dir():
        raise MarkerFileError(path, None, "is a folder, not a file (expected a marker CSV)")
    if not path.is_file():
        raise MarkerFileError(path, None, "file not found")
    try:
        return read_text(path)
    except TextDecodeError as e:
        raise MarkerFileError(path, e.line, e.problem) from None


_DECIMAL_COMMA = re.compile(r"\d,\d")


def _separator_problem(header: list[str], first_data_line: str | None) -> str | None:
    """The reason a header that lacks the required columns was split wrongly, if it was (';' or tab)."""
    if len(header) != 1:
        return None
    for sep, name in ((";", "';'"), ("\t", "tabs")):
        if sep in header[0] and all(c in header[0].split(sep) for c in REQUIRED_COLUMNS[:3]):
            if first_data_line is not None and _DECIMAL_COMMA.search(first_data_line):
                return (f"fields separated by {name} with decimal commas: export as comma-separated with "
                        "decimal points (docs/data-formats.md)")
            return f"fields separated by {name}: export as comma-separated (docs/data-formats.md)"
    return None


#: the words of every "coordinates look like millimetres" rejection (files and in-memory tables)
MILLIMETRE_HINT = "looks like millimetres; marker files are in metres (docs/data-formats.md)"


def _parse_row(row: list[str], line: int, header: list[str], idx: dict, known, path):
    """Reference validation of one data row (docs/data-formats.md): (flight, t, marker, [x, y, z]) or
    MarkerFileError."""
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
        raise MarkerFileError(path, line, f"coordinate {max(abs(v) for v in xyz):g} m: {MILLIMETRE_HINT}")
    return flight, t, marker, xyz


def _first_bad_row(rows, lines, header, idx, known, path) -> None:
    """Raise the error of the first row (file order) that breaks the format of docs/data-formats.md, checked one
    by one."""
    for row, line in zip(rows, lines):
        _parse_row(row, line, header, idx, known, path)
    raise AssertionError("a row was flagged as invalid but passes the row-by-row check")


def _columns_fast(rows, header, idx, known):
    """Columns of well-formed rows, vectorised; None if any row breaks a rule (then :func:`_first_bad_row`
    finds and names it). Returns (flight (n,), t (n,), marker (n,), xyz (n, 3))."""
    n_fields = len(header)
    if any(len(r) != n_fields for r in rows):
        return None
    cols = list(zip(*rows))
    flight = [f.strip() for f in cols[idx["flight"]]]
    marker = [m.strip() for m in cols[idx["marker"]]]
    if not all(flight):
        return None
    if known is not None and not set(marker) <= set(known):
        return None
    try:
        t = np.fromiter(map(float, cols[idx["t"]]), float, len(rows))
        xyz = np.stack([np.fromiter(map(float, cols[idx[c]]), float, len(rows)) for c in ("x", "y", "z")], axis=1)
    except ValueError:
        return None
    nan = np.isnan(xyz)
    with np.errstate(invalid="ignore"):
        big = np.nanmax(np.abs(np.where(nan, 0.0, xyz)), axis=1) > MAX_COORDINATE_M
    if (not np.all(np.isfinite(t)) or np.isinf(xyz).any() or (nan.any(axis=1) & ~nan.all(axis=1)).any()
            or big.any()):
        return None
    return np.array(flight, dtype=object), t, np.array(marker, dtype=object), xyz


def _extra_value(text: str):
    text = text.strip()
    try:
        return float(text) if text else math.nan
    except ValueError:
        return text


def read_marker_csv(path, marker_ids=None) -> MarkerTable:
    """Read and validate a marker file (docs/data-formats.md).

    Parameters
    ----------
    path : str or Path
        The CSV file (UTF-8; a byte-order mark and CRLF line ends are accepted).
    marker_ids : sequence of str, optional
        The known marker ids (config ``markers`` keys); a row with any other id is rejected.

    Returns
    -------
    MarkerTable
        The rows in file order, with their 1-based line numbers.

    Raises
    ------
    MarkerFileError
        Naming the file, the line and the problem (the first problem in file order). Time linear in rows.
    """
    path = Path(path)
    text = _read_text(path)
    known = None if marker_ids is None else [str(m) for m in marker_ids]
    reader = csv.reader(io.StringIO(text, newline=""))
    try:
        header = next(reader)
    except StopIteration:
        raise MarkerFileError(path, 1, "empty file: header 'flight,t,marker,x,y,z' required") from None
    header = [h.strip() for h in header]
    missing = [c for c in REQUIRED_COLUMNS if c not in header]
    if missing:
        after = text.split("\n", 2)
        why = _separator_problem(header, after[1] if len(after) > 1 else None)
        raise MarkerFileError(path, 1, why or f"header lacks column(s) {missing}; required: "
                              f"{','.join(REQUIRED_COLUMNS)}")
    if len(set(header)) != len(header):
        raise MarkerFileError(path, 1, "header repeats a column name")
    idx = {c: header.index(c) for c in header}
    extras = [c for c in header if c not in REQUIRED_COLUMNS]
    rows, lines = [], []
    add_row, add_line = rows.append, lines.append
    for row in reader:
        if row and (row[0].strip() or any(c.strip() for c in row)):  # blank lines are skipped
            add_row(row)
            add_line(reader.line_num)
    if not rows:
        raise MarkerFileError(path, None, "no data rows")
    cols = _columns_fast(rows, header, idx, known)
    if cols is None:
        _first_bad_row(rows, lines, header, idx, known, path)
    flight, t, marker, xyz = cols
    extra = {c: np.array([_extra_value(r[idx[c]]) for r in rows]) for c in extras}
    table = MarkerTable(flight=flight, t=t, marker=marker, xyz=xyz, extra=extra, lines=np.array(lines))
    validate_table(table, path)
    return table


def group_rows(flight: np.ndarray) -> list[tuple[str, np.ndarray]]:
    """Rows of each flight, flights in order of first appearance, rows in file order; linear in rows.

    Parameters
    ----------
    flight : ndarray (n,) of str
        Flight name of every row.

    Returns
    -------
    list of (name, rows)
        ``rows``: int array of the row indices of that flight.
    """
    codes: dict[str, int] = {}
    inverse = np.fromiter((codes.setdefault(f, len(codes)) for f in flight.tolist()), np.int64, len(flight))
    order = np.argsort(inverse, kind="stable")
    bounds = np.searchsorted(inverse[order], np.arange(len(codes) + 1))
    return [(name, order[bounds[k]:bounds[k + 1]]) for name, k in codes.items()]


def validate_table(table: MarkerTable, path="<table>") -> None:
    """Checks that need whole flights: time order, duplicates, marker count, units by marker spacing.

    Linear in the number of rows, whatever the number of flights; raises :class:`MarkerFileError` naming
    the line of the first problem (flights in order of first appearance)."""
    lines = table.lines if table.lines is not None else np.arange(len(table)) + 2
    codes: dict[str, int] = {}
    marker_code = np.fromiter((codes.setdefault(m, len(codes)) for m in table.marker.tolist()), np.int64,
                              len(table))
    for name, rows in group_rows(table.flight):
        _validate_flight(table, name, rows, lines, marker_code, path)


def _validate_flight(table: MarkerTable, name: str, rows: np.ndarray, lines: np.ndarray, marker_code: np.ndarray,
                     path) -> None:
    t = table.t[rows]
    drop = np.flatnonzero(np.diff(t) < 0)
    if drop.size:
        r = rows[drop[0] + 1]
        raise MarkerFileError(path, int(lines[r]), f"flight {name!r}: time {table.t[r]:g} s goes back "
                              f"from {table.t[rows[drop[0]]]:g} s (time must increase within a flight)")
    markers = table.marker[rows]
    # time is non-decreasing here, so a repeated (t, marker) pair shares a run of equal times
    key = np.cumsum(np.r_[True, np.diff(t) > 0]) * (int(marker_code.max()) + 1) + marker_code[rows]
    if np.unique(key).size < key.size:
        seen = {}
        for r, m in zip(rows.tolist(), markers.tolist()):
            pair = (table.t[r], m)
            if pair in seen:
                raise MarkerFileError(path, int(lines[r]), f"flight {name!r}: marker {m!r} at "
                                      f"t = {table.t[r]:g} s repeats line {seen[pair]}")
            seen[pair] = int(lines[r])
    finite = np.all(np.isfinite(table.xyz[rows]), axis=1)
    ids = set(markers[finite].tolist())
    if len(ids) < 3:
        raise MarkerFileError(path, int(lines[rows[0]]), f"flight {name!r}: only {len(ids)} marker(s) "
                              "observed; at least 3 are needed to fix the disc's attitude")
    spacing = _median_spacing(t, markers, table.xyz[rows])
    if spacing is not None and spacing > MAX_MARKER_SPACING_M:
        raise MarkerFileError(path, int(lines[rows[0]]), f"flight {name!r}: markers are {spacing:.3g} apart "
                              f"(median): {MILLIMETRE_HINT}")


def _median_spacing(t, marker, xyz, max_samples: int = 200) -> float | None:
    """Median distance [file units] between the first two markers seen at each of the first ``max_samples``
    sample times that have two; None if no sample time has two."""
    order = np.argsort(t, kind="stable")
    t, xyz = t[order], xyz[order]
    group = np.cumsum(np.r_[True, np.diff(t) > 0])
    fin = np.flatnonzero(np.all(np.isfinite(xyz), axis=1))
    g = group[fin]
    first = np.flatnonzero(np.r_[True, np.diff(g) > 0])
    has_second = first + 1 < fin.size
    has_second[has_second] = g[first[has_second] + 1] == g[first[has_second]]
    a, b = fin[first[has_second]][:max_samples], fin[first[has_second] + 1][:max_samples]
    if a.size == 0:
        return None
    return float(np.median(np.linalg.norm(xyz[a] - xyz[b], axis=1)))


def write_marker_csv(path, table: MarkerTable, precision: int = 9) -> None:
    """Write a marker file (docs/data-formats.md) (extra columns after the required ones, in ``table.extra`` order)."""
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
    """Per-flight arrays on each flight's sample grid (the distinct times of its rows); linear in rows.

    Parameters
    ----------
    table : MarkerTable
        Validated rows (every marker id among ``marker_ids``).
    marker_ids : sequence of str
        Marker order of the ``positions`` axis.
    source : str
        File name recorded in each flight (for messages).

    Returns
    -------
    list of FlightObservation
        Flights in order of first appearance; ``line`` is the line of the flight's first row.
    """
    marker_ids = tuple(str(m) for m in marker_ids)
    col = {m: k for k, m in enumerate(marker_ids)}
    unknown = sorted(set(table.marker.tolist()) - set(col))
    if unknown:
        raise KeyError(f"marker id(s) {unknown} not among {list(marker_ids)}")
    k_all = np.fromiter((col[str(m)] for m in table.marker.tolist()), np.int64, len(table))
    sigma_col = table.extra.get("sigma_m")
    have_cov = [c for c in COV_COLUMNS if c in table.extra]
    if have_cov and len(have_cov) < len(COV_COLUMNS):
        raise MarkerFileError(source or "<table>", 1, f"covariance column(s) {sorted(set(COV_COLUMNS) - set(have_cov))} "
                              f"missing (given: {have_cov}; all of {', '.join(COV_COLUMNS)} or none)")
    out = []
    for name, rows in group_rows(table.flight):
        times = np.unique(table.t[rows])
        ti = np.searchsorted(times, table.t[rows])
        pos = np.full((times.size, len(marker_ids), 3), np.nan)
        pos[ti, k_all[rows]] = table.xyz[rows]
        sig = None
        if sigma_col is not None:
            sig = np.full((times.size, len(marker_ids)), np.nan)
            sig[ti, k_all[rows]] = np.asarray(sigma_col[rows], float)
        cov = None
        if have_cov:
            cov = np.full((times.size, len(marker_ids), 3, 3), np.nan)
            for c, (i, j) in zip(COV_COLUMNS, COV_INDEX):
                v = np.asarray(table.extra[c][rows], float)
                cov[ti, k_all[rows], i, j] = v
                cov[ti, k_all[rows], j, i] = v
        line = None if table.lines is None else int(table.lines[rows[0]])
        out.append(FlightObservation(name=name, source=source, times=times, marker_ids=marker_ids,
                                     positions=pos, sigma=sig, line=line, cov=cov))
    return out


def load_flights(path, marker_ids) -> list[FlightObservation]:
    """Read, validate and arrange a marker file."""
    table = read_marker_csv(path, marker_ids)
    return flights_from_table(table, marker_ids, source=str(path))
