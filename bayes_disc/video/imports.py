"""Point files of other digitising tools: DLTdv and Argus 2-D (``xypts``) and 3-D (``xyzpts``) CSVs.

Layouts (one row per frame, the first row is frame 1 of the digitised sequence; NaN or empty = missing):

==========  =====================================  ==============================
tool        2-D header (point p, camera c)          3-D header
==========  =====================================  ==============================
DLTdv       ``pt1_cam1_X, pt1_cam1_Y, pt1_cam2_X…``  ``pt1_X, pt1_Y, pt1_Z, …``
Argus       ``track_cam_1_x, track_cam_1_y, …``      ``track_x, track_y, track_z, …``
==========  =====================================  ==============================

Both tools write 2-D coordinates with the image origin at the bottom-left (y up); DLTdv, a MATLAB
tool, counts the first pixel as 1, Argus as 0 (see :class:`~.calibration.ImageConvention`); both are
settable. Readers return OpenCV pixels (origin top-left, first pixel 0), which needs each camera's image
height. :func:`reprojection_check` compares imported 3-D points with imported 2-D points through the
calibration: a wrong origin, pixel base, units or camera order shows up as a large RMS.
"""
from __future__ import annotations

import csv
import math
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .calibration import ARGUS, DLTDV, ImageConvention
from .errors import VideoInputError

FORMATS = ("dltdv", "argus")
_XY_RX = {"dltdv": re.compile(r"^(.+)_cam(\d+)_([XY])$"), "argus": re.compile(r"^(.+)_cam_(\d+)_([xy])$")}
_XYZ_RX = {"dltdv": re.compile(r"^(.+)_([XYZ])$"), "argus": re.compile(r"^(.+)_([xyz])$")}
DEFAULT_CONVENTION = {"dltdv": DLTDV, "argus": ARGUS}


@dataclass
class Points2D:
    """uv (F, P, C, 2) in OpenCV pixels (NaN = missing); names: the file's point names (P); n_cameras C."""

    uv: np.ndarray
    names: list

    @property
    def n_cameras(self) -> int:
        return self.uv.shape[2]


@dataclass
class Points3D:
    """xyz (F, P, 3) [m] (NaN = missing); names (P)."""

    xyz: np.ndarray
    names: list


def _read_table(path) -> tuple[list, np.ndarray]:
    path = Path(path)
    if not path.is_file():
        raise VideoInputError(f"{path}: file not found")
    with path.open(newline="") as fh:
        text = fh.read()
    delim = "\t" if text.count("\t") > text.count(",") else ","
    reader = csv.reader(text.splitlines(), delimiter=delim)
    header = [h.strip() for h in next(reader, [])]
    if not header or not any(header):
        raise VideoInputError(f"{path}:1: empty file, a header line is required")
    rows = []
    for lineno, row in enumerate(reader, start=2):
        if not row or all(not c.strip() for c in row):
            continue
        if len(row) != len(header):
            raise VideoInputError(f"{path}:{lineno}: {len(row)} fields, header has {len(header)}")
        vals = []
        for col, c in zip(header, row):
            c = c.strip()
            if c == "" or c.lower() == "nan":
                vals.append(math.nan)
                continue
            try:
                vals.append(float(c))
            except ValueError:
                raise VideoInputError(f"{path}:{lineno}: column {col!r}: {c!r} is not a number") from None
        rows.append(vals)
    return header, np.array(rows, float).reshape(-1, len(header))


def detect_format(path) -> str:
    """``dltdv`` or ``argus`` from a 2-D or 3-D file's header."""
    header, _ = _read_table(path)
    if all(_XY_RX["argus"].match(h) for h in header):
        return "argus"
    if all(_XY_RX["dltdv"].match(h) for h in header):
        return "dltdv"
    if all(re.match(r"^.+_[xyz]$", h) for h in header):
        return "argus"
    if all(re.match(r"^.+_[XYZ]$", h) for h in header):
        return "dltdv"
    raise VideoInputError(f"{path}:1: header is neither DLTdv (pt1_cam1_X…, pt1_X…) nor Argus (…_cam_1_x, …_x)")


def read_xypts(path, fmt: str, heights, convention: ImageConvention | None = None) -> Points2D:
    """Read a 2-D point file of ``fmt`` (``dltdv``/``argus``) into OpenCV pixels; heights: image height
    [px] of camera 1, 2, ... (needed for a bottom-left origin)."""
    if fmt not in FORMATS:
        raise VideoInputError(f"{path}: unknown point-file format {fmt!r} (known: {FORMATS})")
    conv = convention or DEFAULT_CONVENTION[fmt]
    header, data = _read_table(path)
    rx = _XY_RX[fmt]
    names, cams, where = [], set(), {}
    for j, h in enumerate(header):
        m = rx.match(h)
        if not m:
            raise VideoInputError(f"{path}:1: column {h!r} does not match the {fmt} 2-D layout "
                                  f"({'pt1_cam1_X' if fmt == 'dltdv' else 'name_cam_1_x'})")
        name, cam, axis = m.group(1), int(m.group(2)), m.group(3).lower()
        if name not in names:
            names.append(name)
        cams.add(cam)
        if (name, cam, axis) in where:
            raise VideoInputError(f"{path}:1: column {h!r} repeats")
        where[(name, cam, axis)] = j
    C = max(cams)
    if sorted(cams) != list(range(1, C + 1)):
        raise VideoInputError(f"{path}:1: camera numbers {sorted(cams)} are not 1..{C}")
    heights = list(heights) if heights is not None else [None] * C
    if len(heights) < C:
        raise VideoInputError(f"{path}: the file has {C} cameras but only {len(heights)} are configured")
    uv = np.full((len(data), len(names), C, 2), np.nan)
    for p, name in enumerate(names):
        for c in range(C):
            jx, jy = where.get((name, c + 1, "x")), where.get((name, c + 1, "y"))
            if jx is None or jy is None:
                raise VideoInputError(f"{path}:1: point {name!r} camera {c + 1} lacks its x or y column")
            try:
                uv[:, p, c] = conv.to_opencv(np.stack([data[:, jx], data[:, jy]], axis=1), heights[c])
            except ValueError as e:
                raise VideoInputError(f"{path}: camera {c + 1}: {e}") from None
    return Points2D(uv, names)


def read_xyzpts(path, fmt: str, metres_per_unit: float = 1.0) -> Points3D:
    """Read a 3-D point file of ``fmt``; coordinates are converted to metres."""
    if fmt not in FORMATS:
        raise VideoInputError(f"{path}: unknown point-file format {fmt!r} (known: {FORMATS})")
    header, data = _read_table(path)
    rx = _XYZ_RX[fmt]
    names, where = [], {}
    for j, h in enumerate(header):
        m = rx.match(h)
        if not m or _XY_RX[fmt].match(h):
            raise VideoInputError(f"{path}:1: column {h!r} does not match the {fmt} 3-D layout "
                                  f"({'pt1_X' if fmt == 'dltdv' else 'name_x'})")
        name, axis = m.group(1), m.group(2).lower()
        if name not in names:
            names.append(name)
        where[(name, axis)] = j
    xyz = np.full((len(data), len(names), 3), np.nan)
    for p, name in enumerate(names):
        for k, a in enumerate("xyz"):
            j = where.get((name, a))
            if j is None:
                raise VideoInputError(f"{path}:1: point {name!r} lacks its {a} column")
            xyz[:, p, k] = data[:, j] * metres_per_unit
    return Points3D(xyz, names)


def write_xypts(path, points: Points2D, fmt: str, heights, convention: ImageConvention | None = None) -> None:
    """Write a 2-D point file in ``fmt`` layout (from OpenCV pixels)."""
    conv = convention or DEFAULT_CONVENTION[fmt]
    C = points.n_cameras
    header, cols = [], []
    for p, name in enumerate(points.names):
        for c in range(C):
            xy = conv.from_opencv(points.uv[:, p, c], heights[c])
            if fmt == "dltdv":
                header += [f"{name}_cam{c + 1}_X", f"{name}_cam{c + 1}_Y"]
            else:
                header += [f"{name}_cam_{c + 1}_x", f"{name}_cam_{c + 1}_y"]
            cols += [xy[:, 0], xy[:, 1]]
    _write(path, header, np.stack(cols, axis=1))


def write_xyzpts(path, points: Points3D, fmt: str, metres_per_unit: float = 1.0) -> None:
    """Write a 3-D point file in ``fmt`` layout (file units = metres / metres_per_unit)."""
    header, cols = [], []
    for p, name in enumerate(points.names):
        for k, a in enumerate("XYZ" if fmt == "dltdv" else "xyz"):
            header.append(f"{name}_{a}")
            cols.append(points.xyz[:, p, k] / metres_per_unit)
    _write(path, header, np.stack(cols, axis=1))


def _write(path, header, data) -> None:
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh, lineterminator="\n")
        w.writerow(header)
        for row in data:
            w.writerow(["NaN" if not np.isfinite(v) else repr(float(v)) for v in row])


def reprojection_check(cameras, xyz: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """RMS [px] per camera of the distance between imported 2-D points uv (F, P, C, 2) and the projection
    of imported 3-D points xyz (F, P, 3); NaN for a camera with no common point."""
    out = np.full(len(cameras), np.nan)
    for c, cam in enumerate(cameras):
        p = cam.project(xyz)
        d2 = np.sum((p - uv[:, :, c]) ** 2, axis=-1)
        ok = np.isfinite(d2)
        if ok.any():
            out[c] = float(np.sqrt(d2[ok].mean()))
    return out
