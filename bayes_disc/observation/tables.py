"""Marker data given in memory (a pandas DataFrame or a mapping of arrays) instead of a marker file
(docs/data-formats.md).

The columns are those of a marker file — ``flight, t, marker, x, y, z`` (extra numeric columns allowed,
e.g. ``sigma_m``) — one row per marker per sample, world-frame positions in metres, time in seconds. The
rows pass the checks :func:`.markers.read_marker_csv` applies to a file's lines (unknown marker, NaN or
infinite time, partly NaN coordinates, millimetre-looking magnitudes) and then the same whole-flight checks
(:func:`.markers.validate_table`); an error is a :class:`~.markers.MarkerFileError` naming the source and
the row (its position, counted from 0). Nothing is dropped or reordered.
"""
from __future__ import annotations

import math

import numpy as np

from .markers import (MAX_COORDINATE_M, MILLIMETRE_HINT, REQUIRED_COLUMNS, FlightObservation, MarkerFileError, MarkerTable,
                      flights_from_table, validate_table)


def _column_names(columns) -> list[str]:
    """Column names of a DataFrame (iterating it yields its labels) or keys of a mapping."""
    if not hasattr(columns, "__getitem__") or isinstance(columns, (str, bytes, np.ndarray)):
        raise TypeError("marker data must be a pandas DataFrame or a mapping of column name → 1-D array, "
                        f"got {type(columns).__name__}")
    return [str(c) for c in columns]


def _as_1d(columns, name: str, source: str) -> np.ndarray:
    values = columns[name]
    values = values.to_numpy() if hasattr(values, "to_numpy") else np.asarray(values)
    if values.ndim != 1:
        raise MarkerFileError(source, None, f"column {name!r} must be one-dimensional, got shape {values.shape}")
    return values


def _numbers(values: np.ndarray, name: str, source: str) -> np.ndarray:
    try:
        out = values.astype(float)
    except (TypeError, ValueError):
        bad = next(i for i, v in enumerate(values) if not _is_number(v))
        raise MarkerFileError(source, bad, f"column {name!r}: {values[bad]!r} is not a number") from None
    inf = np.flatnonzero(np.isinf(out))
    if inf.size:
        raise MarkerFileError(source, int(inf[0]), f"column {name!r}: infinite value")
    return out


def _is_number(v) -> bool:
    try:
        float(v)
    except (TypeError, ValueError):
        return False
    return True


def _labels(values: np.ndarray) -> np.ndarray:
    """Flight names / marker ids as stripped strings (integers such as marker 0 become '0')."""
    return np.array([str(v).strip() if not (isinstance(v, float) and math.isnan(v)) else "" for v in values],
                    dtype=object)


def marker_table_from_columns(columns, marker_ids=None, source: str = "<table>") -> MarkerTable:
    """Validate in-memory marker rows and return them as a :class:`~.markers.MarkerTable`.

    Parameters
    ----------
    columns : pandas.DataFrame or mapping of str to array_like
        Columns ``flight`` (names), ``t`` [s], ``marker`` (ids), ``x``, ``y``, ``z`` [m], each of shape
        (n_rows,); extra columns (e.g. ``sigma_m`` [m]) are kept.
    marker_ids : sequence of str, optional
        The known marker ids (the configuration's ``markers`` keys); a row with any other id is rejected.
    source : str
        How errors name the data (e.g. ``"flights[0].data"``).

    Returns
    -------
    MarkerTable
        The rows in the given order; ``lines`` holds the row positions (counted from 0).

    Raises
    ------
    MarkerFileError
        For any row or flight that a marker file (docs/data-formats.md) would be rejected for; the message names
        ``source`` and the row.
    TypeError
        If ``columns`` is neither a DataFrame nor a mapping.
    """
    names = _column_names(columns)
    missing = [c for c in REQUIRED_COLUMNS if c not in names]
    if missing:
        raise MarkerFileError(source, None, f"lacks column(s) {missing}; required: {','.join(REQUIRED_COLUMNS)}")
    if len(set(names)) != len(names):
        raise MarkerFileError(source, None, "repeats a column name")
    raw = {c: _as_1d(columns, c, source) for c in names}
    n = {c: v.size for c, v in raw.items()}
    if len(set(n.values())) != 1:
        raise MarkerFileError(source, None, f"columns differ in length: {n}")
    if not raw["t"].size:
        raise MarkerFileError(source, None, "no data rows")
    flight = _labels(raw["flight"])
    empty = np.flatnonzero(flight == "")
    if empty.size:
        raise MarkerFileError(source, int(empty[0]), "empty flight name")
    t = _numbers(raw["t"], "t", source)
    nan_t = np.flatnonzero(np.isnan(t))
    if nan_t.size:
        raise MarkerFileError(source, int(nan_t[0]), "time is NaN")
    marker = _labels(raw["marker"])
    if marker_ids is not None:
        known = [str(m) for m in marker_ids]
        unknown = np.flatnonzero(~np.isin(marker.astype(str), known))
        if unknown.size:
            r = int(unknown[0])
            raise MarkerFileError(source, r, f"unknown marker {marker[r]!r} (known: {', '.join(known)})")
    xyz = np.column_stack([_numbers(raw[c], c, source) for c in ("x", "y", "z")])
    nan = np.isnan(xyz)
    partial = np.flatnonzero(nan.any(axis=1) & ~nan.all(axis=1))
    if partial.size:
        raise MarkerFileError(source, int(partial[0]), "some but not all coordinates are NaN")
    big = np.flatnonzero(~nan.any(axis=1) & (np.abs(np.where(nan, 0.0, xyz)).max(axis=1) > MAX_COORDINATE_M))
    if big.size:
        r = int(big[0])
        raise MarkerFileError(source, r, f"coordinate {np.abs(xyz[r]).max():g} m: {MILLIMETRE_HINT}")
    extra = {}
    for c in names:
        if c in REQUIRED_COLUMNS:
            continue
        v = raw[c]
        extra[c] = v.astype(float) if all(_is_number(x) for x in v) else v.astype(object)
    table = MarkerTable(flight=flight, t=t, marker=marker, xyz=xyz, extra=extra, lines=np.arange(t.size))
    validate_table(table, source)
    return table


def flights_from_columns(columns, marker_ids, source: str = "<table>") -> list[FlightObservation]:
    """Validated in-memory marker rows arranged per flight, as :func:`.markers.load_flights` does for a file.

    Parameters
    ----------
    columns : pandas.DataFrame or mapping of str to array_like
        As for :func:`marker_table_from_columns`.
    marker_ids : sequence of str
        The configuration's marker ids (the column order of the positions).
    source : str
        How errors and the observations' ``source`` name the data.

    Returns
    -------
    list of FlightObservation
        One per flight in order of first appearance: times (n,) [s], positions (n, n_markers, 3) [m] with
        NaN where missing, ``sigma`` (n, n_markers) [m] when a ``sigma_m`` column was given.
    """
    table = marker_table_from_columns(columns, marker_ids, source)
    return flights_from_table(table, marker_ids, source=source)
