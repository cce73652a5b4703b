"""Inertial log files (docs/data-formats.md): the flatball-ins logger CSVs and the ``imu-csv`` format.

Both readers return :class:`InertialLog` records in SI units and sensor axes:

- ``flatball-ins`` (one log per file, no time column): the known defects of the logger files are
  repaired and every repair is reported in ``InertialLog.repairs`` with its line number; anything
  that cannot be repaired raises :class:`ImuFileError` (file, line, problem). The logger's on-board
  AHRS columns (``roll``, ``pitch``, ``yaw``, ``q*``, ``fe-*``, ``fl-*``, ``ahrs_*``) are its own
  estimates, not measurements, and are not returned.
- ``imu-csv`` (``flight,t,gx,gy,gz,ax,ay,az``; rad/s, m/s², s): one log per flight, validated like
  the marker files (docs/data-formats.md): time increasing within a flight, NaN time rejected, line numbers in
  every error; extra numeric columns are kept in ``InertialLog.extra``.

Unit conversions: accelerations logged in g are converted with the *standard* gravity
``G_STANDARD = 9.80665 m/s²`` (the definition of the unit g that the accelerometer's sensitivity
refers to), not with the local gravity of a run's environment; angular rates in deg/s are converted
with π/180.
"""
from __future__ import annotations

import csv
import math
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

#: the unit g (m/s²) used to convert accelerometer readings in g to m/s² (standard gravity)
G_STANDARD = 9.80665
#: gyroscope full scale of the flatball logger (ISM330DHCX set to ±4000 dps), rad/s
FLATBALL_GYRO_FULL_SCALE = math.radians(4000.0)
#: accelerometer full scale of the flatball logger (±16 g), m/s²
FLATBALL_ACC_FULL_SCALE = 16.0 * G_STANDARD
#: a sample within this fraction of full scale is reported as (possibly) saturated
SATURATION_FRACTION = 0.01

#: input formats understood by :func:`read_imu`
FORMATS = ("flatball-ins", "imu-csv")

#: every column of the flatball-ins logger, in file order (gyro columns under their ``gyro-*`` name)
FLATBALL_COLUMNS = (
    "idx", "batt-v", "patm-Pa", "amb-temp-degC", "acc-x", "acc-y", "acc-z", "gyro-x", "gyro-y", "gyro-z",
    "mag-x", "mag-y", "mag-z", "roll", "pitch", "yaw", "qw", "qx", "qy", "qz",
    "fe-acc-x", "fe-acc-y", "fe-acc-z", "fl-acc-x", "fl-acc-y", "fl-acc-z",
    "ahrs_accel_err", "ahrs_accel_recovery_trig", "ahrs_mag_err", "ahrs_mag_recovery_trig", "ahrs_flgs",
)
#: the older gyro naming (file 001-rb) mapped onto the ``gyro-*`` names
FLATBALL_GYRO_ALIASES = {"gx": "gyro-x", "gy": "gyro-y", "gz": "gyro-z"}
#: the measurement columns read from a flatball-ins file
FLATBALL_MEASURED = ("idx", "patm-Pa", "acc-x", "acc-y", "acc-z", "gyro-x", "gyro-y", "gyro-z",
                     "mag-x", "mag-y", "mag-z")

IMU_CSV_COLUMNS = ("flight", "t", "gx", "gy", "gz", "ax", "ay", "az")


class ImuFileError(ValueError):
    """An inertial log that cannot be read or repaired; the message names file, line and problem."""

    def __init__(self, path, line: int | None, problem: str):
        self.path, self.line, self.problem = str(path), line, problem
        where = f"{path}:{line}" if line is not None else f"{path}"
        super().__init__(f"{where}: {problem}")


@dataclass
class InertialLog:
    """One inertial recording in SI units, sensor axes.

    Attributes
    ----------
    name : str
        Flight name: the file stem (flatball-ins) or the ``flight`` column (imu-csv).
    source : str
        Path of the file read.
    fmt : str
        Input format, one of :data:`FORMATS`.
    rows : ndarray of int, shape (n,)
        Logger step counter (flatball-ins ``idx``; gaps kept so that t = rows·period stays right) or
        0..n-1 for imu-csv.
    lines : ndarray of int, shape (n,)
        1-based line number of each sample in the source file.
    gyro : ndarray, shape (n, 3)
        Angular rate, rad/s, sensor axes.
    acc : ndarray, shape (n, 3)
        Specific force at the sensor, m/s², sensor axes.
    mag : ndarray or None, shape (n, 3)
        Magnetic field, µT, magnetometer axes (flatball-ins only).
    pressure : ndarray or None, shape (n,)
        Barometric pressure, Pa (flatball-ins only).
    times : ndarray or None, shape (n,)
        Sample times in s (imu-csv); None when the file has no time column (flatball-ins).
    repairs : list of str
        Every repair made while reading, each naming its line(s).
    warnings : list of str
        Observations that are not repairs (possible saturation, repeated samples).
    extra : dict
        Extra numeric columns of an imu-csv file, name -> (n,) array.
    """

    name: str
    source: str
    fmt: str
    rows: np.ndarray
    lines: np.ndarray
    gyro: np.ndarray
    acc: np.ndarray
    mag: np.ndarray | None = None
    pressure: np.ndarray | None = None
    times: np.ndarray | None = None
    repairs: list = field(default_factory=list)
    warnings: list = field(default_factory=list)
    extra: dict = field(default_factory=dict)

    def __len__(self) -> int:
        return int(self.rows.size)

    def position(self, row: int) -> int:
        """Array position of logger row ``row`` (``rows`` value); KeyError if the row is absent."""
        hit = np.flatnonzero(self.rows == row)
        if hit.size != 1:
            raise KeyError(f"{self.name}: row {row} is not in the log")
        return int(hit[0])

    def select(self, start: int, end: int, name: str | None = None) -> "InertialLog":
        """Sub-log of the array positions ``start:end`` (end exclusive), optionally renamed.

        Parameters
        ----------
        start, end : int
            Array positions (not logger rows), 0 <= start < end <= len(self).
        name : str, optional
            Name of the sub-log (default: this log's name).

        Returns
        -------
        InertialLog
            The samples ``start:end`` of every channel; repairs and warnings are copied.
        """
        if not (0 <= start < end <= len(self)):
            raise ValueError(f"{self.name}: bad selection {start}:{end} of {len(self)} samples")
        s = slice(start, end)
        return InertialLog(
            name=self.name if name is None else name, source=self.source, fmt=self.fmt,
            rows=self.rows[s].copy(), lines=self.lines[s].copy(), gyro=self.gyro[s].copy(), acc=self.acc[s].copy(),
            mag=None if self.mag is None else self.mag[s].copy(),
            pressure=None if self.pressure is None else self.pressure[s].copy(),
            times=None if self.times is None else self.times[s].copy(),
            repairs=list(self.repairs), warnings=list(self.warnings),
            extra={k: v[s].copy() for k, v in self.extra.items()})


# ---------------------------------------------------------------------------------------- flatball-ins

_KNOWN_NAMES = set(FLATBALL_COLUMNS) | set(FLATBALL_GYRO_ALIASES)


def _split_glued(token: str):
    """``'fe-acc-z2428'`` -> (``'fe-acc-z'``, ``'2428'``) when a known name is followed by a number."""
    for name in sorted(_KNOWN_NAMES, key=len, reverse=True):
        if token.startswith(name):
            rest = token[len(name):]
            if re.fullmatch(r"[+-]?\d+(\.\d*)?([eE][+-]?\d+)?", rest):
                return name, rest
    return None


def _flatball_header(path, lines: list[str], repairs: list[str]):
    """Parse (and repair) the header; returns (column names, index of the first data line)."""
    if not lines or not lines[0].strip():
        raise ImuFileError(path, 1, "empty file: flatball-ins header required")
    raw = lines[0].split(",")
    names = [c.strip() for c in raw]
    first_data = 1
    glued_at = next((k for k, c in enumerate(names) if c not in _KNOWN_NAMES), None)
    if glued_at is not None:
        split = _split_glued(names[glued_at])
        if split is None:
            raise ImuFileError(path, 1, f"unknown column {names[glued_at]!r} in the header")
        names = names[:glued_at] + [split[0]]
        glued_fields = len(raw) - glued_at
        repairs.append(f"line 1: header cut after {split[0]!r} with a data row glued to it (idx {split[1]}, "
                       f"{glued_fields} fields); the glued row was dropped")
        if len(lines) < 2 or not lines[1].startswith(","):
            raise ImuFileError(path, 2, "header is cut and its continuation (a line starting with ',') is missing")
        cont = [c.strip() for c in lines[1].split(",")[1:]]
        unknown = [c for c in cont if c not in _KNOWN_NAMES]
        if unknown:
            raise ImuFileError(path, 2, f"header continuation holds unknown column(s) {unknown}")
        names += cont
        first_data = 2
        repairs.append(f"line 2: rest of the header ({len(cont)} columns, from {cont[0]!r}) joined to line 1")
    spaced = [c for c in (lines[0].split(",") + (lines[1].split(",")[1:] if first_data == 2 else []))
              if c != c.strip() and c.strip()]
    if spaced:
        repairs.append(f"line 1: stray spaces stripped from column name(s) {', '.join(repr(c) for c in spaced)}")
    aliases = [c for c in names if c in FLATBALL_GYRO_ALIASES]
    if aliases:
        repairs.append(f"line 1: gyro columns named {', '.join(aliases)}; read as "
                       f"{', '.join(FLATBALL_GYRO_ALIASES[c] for c in aliases)}")
        names = [FLATBALL_GYRO_ALIASES.get(c, c) for c in names]
    if len(set(names)) != len(names):
        raise ImuFileError(path, 1, "header repeats a column name")
    missing = [c for c in FLATBALL_MEASURED if c not in names]
    if missing:
        raise ImuFileError(path, 1, f"header lacks measurement column(s) {missing}")
    return names, first_data


def _number(text: str, path, line: int, column: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise ImuFileError(path, line, f"column {column!r}: {text!r} is not a number") from None
    if not math.isfinite(value):
        raise ImuFileError(path, line, f"column {column!r}: {text!r} is not a finite number")
    return value


def read_flatball_ins(path) -> InertialLog:
    """Read one flatball-ins logger CSV, repairing and reporting its known defects.

    Long: one pass over the file's lines, whose repairs (header, stray spaces, short rows) are reported in
    line order.

    Repairs (each reported in ``repairs`` with its line): a header cut by a glued data row (the
    glued row is dropped, the header continuation on the next line joined), stray spaces in column
    names, the ``gx, gy, gz`` gyro naming, rows with the wrong number of fields (dropped), rows
    repeating the previous ``idx`` with identical content (dropped), missing ``idx`` values (the gap
    is kept in ``rows``). Not repairable (raise :class:`ImuFileError`): an unknown header, a
    repeated ``idx`` with different content, ``idx`` going backwards, a non-numeric or non-finite
    measurement, no data rows.

    Parameters
    ----------
    path : str or Path
        The CSV file.

    Returns
    -------
    InertialLog
        ``name`` = file stem, ``times`` None, gyro rad/s, acc m/s² (g × :data:`G_STANDARD`), mag µT,
        pressure Pa; ``warnings`` lists samples within 1 % of the gyro or accelerometer full scale
        and samples whose every sensor channel repeats the previous row.
    """
    path = Path(path)
    if not path.is_file():
        raise ImuFileError(path, None, "file not found")
    text = path.read_text()
    lines = text.split("\n")
    if lines and lines[-1] == "":
        lines = lines[:-1]
    lines = [ln[:-1] if ln.endswith("\r") else ln for ln in lines]
    repairs: list[str] = []
    names, first = _flatball_header(path, lines, repairs)
    col = {c: k for k, c in enumerate(names)}
    data: list[list[float]] = []
    line_no: list[int] = []
    raw_rows: list[list[str]] = []
    for k in range(first, len(lines)):
        ln = k + 1
        if not lines[k].strip():
            repairs.append(f"line {ln}: empty line skipped")
            continue
        fields = next(csv.reader([lines[k]]))
        if len(fields) != len(names):
            repairs.append(f"line {ln}: {len(fields)} fields, header has {len(names)}; row dropped "
                           f"(starts {lines[k][:24]!r})")
            continue
        idx_text = fields[col["idx"]].strip()
        if not re.fullmatch(r"\d+", idx_text):
            raise ImuFileError(path, ln, f"idx {idx_text!r} is not a non-negative integer")
        values = [float(idx_text)] + [_number(fields[col[c]].strip(), path, ln, c) for c in FLATBALL_MEASURED[1:]]
        stripped = [f.strip() for f in fields]
        if data:
            prev = int(data[-1][0])
            cur = int(values[0])
            if cur == prev:
                if stripped == raw_rows[-1]:
                    repairs.append(f"line {ln}: duplicate of line {line_no[-1]} (idx {cur}); dropped")
                    continue
                raise ImuFileError(path, ln, f"idx {cur} repeats line {line_no[-1]} with different content")
            if cur < prev:
                raise ImuFileError(path, ln, f"idx {cur} goes backwards (previous idx {prev} on line {line_no[-1]})")
            if cur > prev + 1:
                gap = (f"idx {prev + 1}" if cur == prev + 2 else f"idx {prev + 1}..{cur - 1}")
                repairs.append(f"line {ln}: {gap} missing (between lines {line_no[-1]} and {ln}); gap kept in rows")
        data.append(values)
        line_no.append(ln)
        raw_rows.append(stripped)
    if not data:
        raise ImuFileError(path, None, "no data rows")
    arr = np.asarray(data, float)
    pick = {c: arr[:, k] for k, c in enumerate(FLATBALL_MEASURED)}
    gyro = np.radians(np.column_stack([pick["gyro-x"], pick["gyro-y"], pick["gyro-z"]]))
    acc = G_STANDARD * np.column_stack([pick["acc-x"], pick["acc-y"], pick["acc-z"]])
    mag = np.column_stack([pick["mag-x"], pick["mag-y"], pick["mag-z"]])
    log = InertialLog(name=path.stem, source=str(path), fmt="flatball-ins", rows=pick["idx"].astype(np.int64),
                      lines=np.asarray(line_no, np.int64), gyro=gyro, acc=acc, mag=mag,
                      pressure=pick["patm-Pa"].copy(), times=None, repairs=repairs)
    log.warnings.extend(saturation_warnings(log, FLATBALL_GYRO_FULL_SCALE, FLATBALL_ACC_FULL_SCALE))
    log.warnings.extend(repeated_sample_warnings(log))
    return log


#: AHRS and housekeeping columns written by :func:`write_flatball_ins` (estimates of the logger, not measured)
FLATBALL_WRITTEN_CONSTANTS = {"batt-v": 4.05, "amb-temp-degC": 25.0}


def write_flatball_ins(path, log: InertialLog) -> Path:
    """Write a log as a flatball-ins logger CSV (every logger column, header as the logger writes it).

    Measured columns from the log: ``idx`` = ``rows``, ``acc-*`` in g (÷ :data:`G_STANDARD`), ``gyro-*``
    in deg/s, ``mag-*`` in µT, ``patm-Pa``; values with 17 significant digits, so that reading the file
    back gives the log's numbers. ``batt-v`` and ``amb-temp-degC`` are constants
    (:data:`FLATBALL_WRITTEN_CONSTANTS`); the on-board AHRS columns (``roll`` … ``ahrs_flgs``), which the
    reader ignores, are written as 0.

    Parameters
    ----------
    path : str or Path
        Output file (overwritten).
    log : InertialLog
        With ``mag`` (n, 3) [µT] and ``pressure`` (n,) [Pa]; ``rows`` strictly increasing, non-negative.

    Returns
    -------
    Path
        The written file.
    """
    if log.mag is None or log.pressure is None:
        raise ValueError(f"write_flatball_ins: log {log.name!r} needs magnetometer and pressure readings")
    rows = np.asarray(log.rows)
    if rows.size == 0 or rows[0] < 0 or np.any(np.diff(rows) <= 0):
        raise ValueError(f"write_flatball_ins: log {log.name!r}: rows must be non-negative and increasing")
    measured = {"patm-Pa": log.pressure, "acc-x": log.acc[:, 0] / G_STANDARD, "acc-y": log.acc[:, 1] / G_STANDARD,
                "acc-z": log.acc[:, 2] / G_STANDARD, "gyro-x": np.degrees(log.gyro[:, 0]),
                "gyro-y": np.degrees(log.gyro[:, 1]), "gyro-z": np.degrees(log.gyro[:, 2]),
                "mag-x": log.mag[:, 0], "mag-y": log.mag[:, 1], "mag-z": log.mag[:, 2]}
    for name, v in measured.items():
        if not np.all(np.isfinite(v)):
            raise ValueError(f"write_flatball_ins: log {log.name!r}: column {name!r} holds non-finite values")
    path = Path(path)
    with path.open("w", newline="") as fh:
        w = csv.writer(fh, lineterminator="\n")
        w.writerow(FLATBALL_COLUMNS)
        for k in range(rows.size):
            out = []
            for c in FLATBALL_COLUMNS:
                if c == "idx":
                    out.append(str(int(rows[k])))
                elif c in measured:
                    out.append(repr(float(measured[c][k])))
                else:
                    out.append(repr(float(FLATBALL_WRITTEN_CONSTANTS.get(c, 0.0))))
            w.writerow(out)
    return path


def _row_list(rows: np.ndarray, lines: np.ndarray, limit: int = 12) -> str:
    shown = ", ".join(f"{r} (line {ln})" for r, ln in zip(rows[:limit], lines[:limit]))
    return shown + (f", … {rows.size - limit} more" if rows.size > limit else "")


def saturation_warnings(log: InertialLog, gyro_full_scale: float, acc_full_scale: float,
                        fraction: float = SATURATION_FRACTION) -> list[str]:
    """Report samples within ``fraction`` of a sensor's full scale.

    Parameters
    ----------
    log : InertialLog
        The recording.
    gyro_full_scale : float
        Gyroscope full scale, rad/s.
    acc_full_scale : float
        Accelerometer full scale, m/s².
    fraction : float
        Relative margin below full scale that counts as (possibly) saturated.

    Returns
    -------
    list of str
        One message per sensor with such samples (none when all samples are clear), naming rows and
        lines, and one message per sensor stating the largest magnitude otherwise.
    """
    out = []
    for label, values, fs, unit, conv in (("gyro", log.gyro, gyro_full_scale, "dps", math.degrees(1.0)),
                                          ("acc", log.acc, acc_full_scale, "g", 1.0 / G_STANDARD)):
        peak = np.abs(values).max(axis=1)
        hit = np.flatnonzero(peak >= (1.0 - fraction) * fs)
        if hit.size:
            out.append(f"{label}: {hit.size} sample(s) within {fraction:.0%} of full scale "
                       f"±{fs * conv:g} {unit} (possibly saturated): rows {_row_list(log.rows[hit], log.lines[hit])}")
        else:
            out.append(f"{label}: no sample within {fraction:.0%} of full scale ±{fs * conv:g} {unit} "
                       f"(largest {peak.max() * conv:.1f} {unit})")
    return out


def repeated_sample_warnings(log: InertialLog) -> list[str]:
    """Report rows whose gyro, acc and mag readings all equal the previous row's (a stale sample).

    Parameters
    ----------
    log : InertialLog
        A recording with a magnetometer (the averaged magnetometer never repeats by chance).

    Returns
    -------
    list of str
        At most one message naming the rows and lines (empty when there are none).
    """
    if log.mag is None or len(log) < 2:
        return []
    same = np.all(np.diff(np.hstack([log.gyro, log.acc, log.mag]), axis=0) == 0.0, axis=1)
    hit = np.flatnonzero(same) + 1
    if not hit.size:
        return []
    return [f"{hit.size} row(s) repeat every gyro, acc and mag value of the previous row (stale sample, kept): "
            f"rows {_row_list(log.rows[hit], log.lines[hit])}"]


# --------------------------------------------------------------------------------------------- imu-csv

def read_imu_csv(path) -> list[InertialLog]:
    """Read and validate an ``imu-csv`` file (docs/data-formats.md); one :class:`InertialLog` per flight.

    Long: one validation pass over the rows, in the order their errors are reported.

    Header ``flight,t,gx,gy,gz,ax,ay,az`` required (extra columns allowed, kept in ``extra`` when
    numeric). Rejected with :class:`ImuFileError` naming file and line: a wrong field count, an empty
    flight name, a non-numeric or NaN/infinite time, time not increasing within a flight, a
    non-numeric or infinite rate or force, a triplet partly NaN (a whole NaN triplet is a missing
    reading and is kept as NaN). Nothing is dropped or reordered.

    Parameters
    ----------
    path : str or Path
        The CSV file.

    Returns
    -------
    list of InertialLog
        In order of first appearance of each flight; ``times`` in s, gyro rad/s, acc m/s²,
        ``rows`` = 0..n-1, ``mag`` and ``pressure`` None.
    """
    path = Path(path)
    if not path.is_file():
        raise ImuFileError(path, None, "file not found")
    per: dict[str, dict] = {}
    with path.open(newline="") as fh:
        reader = csv.reader(fh)
        try:
            header = [h.strip() for h in next(reader)]
        except StopIteration:
            raise ImuFileError(path, 1, f"empty file: header {','.join(IMU_CSV_COLUMNS)} required") from None
        missing = [c for c in IMU_CSV_COLUMNS if c not in header]
        if missing:
            raise ImuFileError(path, 1, f"header lacks column(s) {missing}; required: {','.join(IMU_CSV_COLUMNS)}")
        if len(set(header)) != len(header):
            raise ImuFileError(path, 1, "header repeats a column name")
        col = {c: header.index(c) for c in header}
        extras = [c for c in header if c not in IMU_CSV_COLUMNS]
        for row in reader:
            ln = reader.line_num
            if not row or all(not c.strip() for c in row):
                continue
            if len(row) != len(header):
                raise ImuFileError(path, ln, f"{len(row)} fields, header has {len(header)}")
            flight = row[col["flight"]].strip()
            if not flight:
                raise ImuFileError(path, ln, "empty flight name")
            try:
                t = float(row[col["t"]])
            except ValueError:
                raise ImuFileError(path, ln, f"column 't': {row[col['t']]!r} is not a number") from None
            if not math.isfinite(t):
                raise ImuFileError(path, ln, "time is NaN" if math.isnan(t) else "time is infinite")
            rec = per.setdefault(flight, {"t": [], "g": [], "a": [], "line": [], "extra": {c: [] for c in extras}})
            if rec["t"] and not t > rec["t"][-1]:
                raise ImuFileError(path, ln, f"time {t!r} s does not increase in flight {flight!r} "
                                   f"(previous {rec['t'][-1]!r} s on line {rec['line'][-1]})")
            triplets = []
            for names in (("gx", "gy", "gz"), ("ax", "ay", "az")):
                vals = []
                for c in names:
                    try:
                        v = float(row[col[c]])
                    except ValueError:
                        raise ImuFileError(path, ln, f"column {c!r}: {row[col[c]]!r} is not a number") from None
                    if math.isinf(v):
                        raise ImuFileError(path, ln, f"column {c!r}: infinite value")
                    vals.append(v)
                nan = [math.isnan(v) for v in vals]
                if any(nan) and not all(nan):
                    raise ImuFileError(path, ln, f"some but not all of {','.join(names)} are NaN")
                triplets.append(vals)
            rec["t"].append(t)
            rec["g"].append(triplets[0])
            rec["a"].append(triplets[1])
            rec["line"].append(ln)
            for c in extras:
                text = row[col[c]].strip()
                try:
                    rec["extra"][c].append(float(text) if text else math.nan)
                except ValueError:
                    rec["extra"][c].append(text)
    if not per:
        raise ImuFileError(path, None, "no data rows")
    logs = []
    for flight, rec in per.items():
        n = len(rec["t"])
        extra = {}
        for c, vals in rec["extra"].items():
            if all(isinstance(v, float) for v in vals):
                extra[c] = np.asarray(vals, float)
        logs.append(InertialLog(name=flight, source=str(path), fmt="imu-csv", rows=np.arange(n, dtype=np.int64),
                                lines=np.asarray(rec["line"], np.int64), gyro=np.asarray(rec["g"], float),
                                acc=np.asarray(rec["a"], float), times=np.asarray(rec["t"], float), extra=extra))
    return logs


def write_imu_csv(path, logs) -> Path:
    """Write logs with ``times`` as an ``imu-csv`` file (docs/data-formats.md), exactly (17 significant digits).

    Parameters
    ----------
    path : str or Path
        Output file (overwritten).
    logs : sequence of InertialLog
        Each with ``times`` (n,) s, distinct names; ``extra`` columns are written when every log has
        the same extra names.

    Returns
    -------
    Path
        The written file.
    """
    logs = list(logs)
    if not logs:
        raise ValueError("write_imu_csv: no logs")
    names = [lg.name for lg in logs]
    if len(set(names)) != len(names):
        raise ValueError(f"write_imu_csv: repeated flight names {names}")
    extra_names = list(logs[0].extra)
    for lg in logs:
        if lg.times is None:
            raise ValueError(f"write_imu_csv: log {lg.name!r} has no times")
        if list(lg.extra) != extra_names:
            raise ValueError(f"write_imu_csv: log {lg.name!r} has extra columns {list(lg.extra)}, "
                             f"first log has {extra_names}")
        if "," in lg.name or not lg.name.strip():
            raise ValueError(f"write_imu_csv: flight name {lg.name!r} cannot be written")
    path = Path(path)
    with path.open("w", newline="") as fh:
        w = csv.writer(fh, lineterminator="\n")
        w.writerow(list(IMU_CSV_COLUMNS) + extra_names)
        for lg in logs:
            for k in range(len(lg)):
                vals = [lg.times[k], *lg.gyro[k], *lg.acc[k], *(lg.extra[c][k] for c in extra_names)]
                w.writerow([lg.name] + [repr(float(v)) for v in vals])
    return path


def read_imu(path, fmt: str) -> list[InertialLog]:
    """Read an inertial file in the named format (``imu: [{file, format}]``, docs/configuration.md).

    Parameters
    ----------
    path : str or Path
        The file.
    fmt : str
        ``"flatball-ins"`` or ``"imu-csv"``; any other name is an error.

    Returns
    -------
    list of InertialLog
        One log per file (flatball-ins, whole recording; throws are found by
        :func:`bayes_disc.observation.imu.segmentation.find_throws`) or one per flight (imu-csv).
    """
    if fmt == "flatball-ins":
        return [read_flatball_ins(path)]
    if fmt == "imu-csv":
        return read_imu_csv(path)
    raise ValueError(f"unknown IMU format {fmt!r}; known: {', '.join(FORMATS)}")
