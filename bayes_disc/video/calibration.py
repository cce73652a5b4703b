"""Camera calibration: the 11-parameter DLT, its decomposition to K, R, t, and camera files.

DLT (Abdel-Aziz & Karara 1971; Hartley & Zisserman §7.1). With coefficients L1..L11, a world point
(X, Y, Z) projects to

    u = (L1 X + L2 Y + L3 Z + L4) / (L9 X + L10 Y + L11 Z + 1)
    v = (L5 X + L6 Y + L7 Z + L8) / (L9 X + L10 Y + L11 Z + 1),

i.e. the projection matrix P = [[L1 L2 L3 L4], [L5 L6 L7 L8], [L9 L10 L11 1]]. :func:`dlt_calibrate`
estimates it linearly from ≥ 6 non-coplanar control points after Hartley normalisation (centroid at
the origin, mean distance √3 in space and √2 in the image) and reports per-point and leave-one-out
residuals. :func:`decompose_projection` factors P = λ K [R | t] (RQ decomposition); :func:`refine_camera`
optionally adds OpenCV lens distortion by non-linear least squares.

Image conventions: bayes-disc works in OpenCV pixels (origin top-left, first pixel centre at 0). Files
of MATLAB tools (DLTdv, easyWand) and Argus put the origin at the bottom-left; :class:`ImageConvention`
converts points and DLT coefficients (the conversion is an affine map of the image, exact for P).

Camera files read here: the bayes-disc camera YAML (:func:`read_camera_yaml`), DLT coefficient CSVs
(11 rows × cameras, as DLTdv, Argus and easyWand write them: :func:`read_dlt_csv`) and anipose
``calibration.toml`` (:func:`read_anipose_toml`). Writers exist for each (for round trips and export).
"""
from __future__ import annotations

import csv
import math
import tomllib
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
import yaml
from scipy.linalg import rq
from scipy.optimize import least_squares

from .camera import Camera
from .errors import VideoInputError

#: world units accepted in camera files, as metres per unit
UNITS = {"m": 1.0, "cm": 0.01, "mm": 0.001}


# ---------------------------------------------------------------------------------------------------
# image conventions
# ---------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class ImageConvention:
    """Pixel coordinate convention of a file.

    origin: ``top-left`` (y down, OpenCV/anipose) or ``bottom-left`` (y up: DLTdv, easyWand, Argus);
    first_pixel: coordinate of the first pixel's centre (0 in OpenCV, 1 in MATLAB tools).
    With image height H, OpenCV pixels are x_cv = x − b and y_cv = y − b (top-left) or
    y_cv = (H − 1 + b) − y (bottom-left), b = first_pixel.
    """

    origin: str = "top-left"
    first_pixel: float = 0.0

    def __post_init__(self):
        if self.origin not in ("top-left", "bottom-left"):
            raise ValueError(f"image origin must be 'top-left' or 'bottom-left', got {self.origin!r}")

    def matrix(self, height: int | None) -> np.ndarray:
        """A (3, 3) with [u_cv, v_cv, 1]ᵀ = A [u, v, 1]ᵀ."""
        b = float(self.first_pixel)
        if self.origin == "top-left":
            return np.array([[1, 0, -b], [0, 1, -b], [0, 0, 1.0]])
        if height is None or height <= 0:
            raise ValueError("a bottom-left image origin needs the image height")
        return np.array([[1, 0, -b], [0, -1, height - 1 + b], [0, 0, 1.0]])

    def to_opencv(self, uv, height: int | None) -> np.ndarray:
        A = self.matrix(height)
        uv = np.asarray(uv, float)
        return np.stack([A[0, 0] * uv[..., 0] + A[0, 2], A[1, 1] * uv[..., 1] + A[1, 2]], axis=-1)

    def from_opencv(self, uv, height: int | None) -> np.ndarray:
        A = np.linalg.inv(self.matrix(height))
        uv = np.asarray(uv, float)
        return np.stack([A[0, 0] * uv[..., 0] + A[0, 2], A[1, 1] * uv[..., 1] + A[1, 2]], axis=-1)


OPENCV = ImageConvention("top-left", 0.0)
#: DLTdv / easyWand (MATLAB): origin bottom-left, first pixel centre at 1
DLTDV = ImageConvention("bottom-left", 1.0)
#: Argus: origin bottom-left (DLTdv compatible), pixel coordinates from 0
ARGUS = ImageConvention("bottom-left", 0.0)


# ---------------------------------------------------------------------------------------------------
# DLT
# ---------------------------------------------------------------------------------------------------
def coefficients_to_matrix(L) -> np.ndarray:
    """11 DLT coefficients → P (3, 4) with P[2, 3] = 1."""
    L = np.asarray(L, float).ravel()
    if L.size != 11:
        raise ValueError(f"DLT: expected 11 coefficients, got {L.size}")
    return np.append(L, 1.0).reshape(3, 4)


def matrix_to_coefficients(P) -> np.ndarray:
    """P (3, 4) → 11 DLT coefficients (P scaled so that P[2, 3] = 1)."""
    P = np.asarray(P, float)
    if abs(P[2, 3]) < 1e-12 * np.abs(P).max():
        raise ValueError("DLT: P[2,3] is zero (the world origin lies in the camera's principal plane); "
                         "the 11-parameter form cannot represent this camera - move the world origin")
    return (P / P[2, 3]).ravel()[:11]


def project_dlt(L, xyz) -> np.ndarray:
    """Pixels (n, 2) of world points (n, 3) through 11 DLT coefficients."""
    P = coefficients_to_matrix(L)
    xyz = np.asarray(xyz, float)
    h = xyz @ P[:, :3].T + P[:, 3]
    return h[..., :2] / h[..., 2:3]


def _normaliser(points: np.ndarray) -> np.ndarray:
    """Hartley normalisation: translate the centroid to 0, mean distance to √dim."""
    dim = points.shape[1]
    c = points.mean(axis=0)
    d = np.linalg.norm(points - c, axis=1).mean()
    s = math.sqrt(dim) / d if d > 0 else 1.0
    T = np.eye(dim + 1)
    T[:dim, :dim] *= s
    T[:dim, dim] = -s * c
    return T


def _dlt_linear(xyz: np.ndarray, uv: np.ndarray) -> np.ndarray:
    T3, T2 = _normaliser(xyz), _normaliser(uv)
    Xh = np.hstack([xyz, np.ones((len(xyz), 1))]) @ T3.T
    uh = np.hstack([uv, np.ones((len(uv), 1))]) @ T2.T
    n = len(xyz)
    A = np.zeros((2 * n, 12))
    A[0::2, 0:4] = Xh
    A[0::2, 8:12] = -uh[:, 0:1] * Xh
    A[1::2, 4:8] = Xh
    A[1::2, 8:12] = -uh[:, 1:2] * Xh
    _, s, Vt = np.linalg.svd(A)
    if s[10] < 1e-10 * s[0]:
        raise ValueError("DLT: control points are degenerate (the linear system has rank < 11)")
    P = np.linalg.inv(T2) @ Vt[-1].reshape(3, 4) @ T3
    return P


@dataclass
class DLTCalibration:
    """Result of :func:`dlt_calibrate`.

    coefficients (11,); camera: the decomposition (K, R, t; no distortion unless refined);
    residuals (n, 2) [px]: projection − observation of each control point; rms_px: RMS of the residual
    norms; loo_px (n,): leave-one-out residual norm of each point (its projection through the DLT of the
    other points), NaN when fewer than 7 points; point_ids: names of the control points.
    """

    coefficients: np.ndarray
    camera: Camera
    residuals: np.ndarray
    rms_px: float
    loo_px: np.ndarray
    point_ids: list

    def report(self) -> str:
        lines = [f"camera {self.camera.name}: {len(self.point_ids)} control points, RMS {self.rms_px:.3f} px, "
                 f"leave-one-out RMS {math.sqrt(np.nanmean(self.loo_px ** 2)) if np.any(np.isfinite(self.loo_px)) else float('nan'):.3f} px"]
        for pid, r, l in zip(self.point_ids, self.residuals, self.loo_px):
            lines.append(f"  {pid}: residual {np.linalg.norm(r):.3f} px, leave-one-out {l:.3f} px")
        return "\n".join(lines)


def dlt_calibrate(xyz, uv, *, name: str = "camera", image_size=(0, 0), point_ids=None) -> DLTCalibration:
    """11-parameter DLT from ≥ 6 non-coplanar control points.

    xyz (n, 3) world positions [m]; uv (n, 2) observed pixels (OpenCV convention). Points with NaN are
    left out. Raises :class:`VideoInputError` for fewer than 6 points or coplanar points.
    """
    xyz = np.asarray(xyz, float).reshape(-1, 3)
    uv = np.asarray(uv, float).reshape(-1, 2)
    if len(xyz) != len(uv):
        raise VideoInputError(f"camera {name}: {len(xyz)} control points but {len(uv)} image points")
    ids = list(point_ids) if point_ids is not None else [str(i) for i in range(len(xyz))]
    ok = np.all(np.isfinite(xyz), axis=1) & np.all(np.isfinite(uv), axis=1)
    xyz, uv, ids = xyz[ok], uv[ok], [i for i, k in zip(ids, ok) if k]
    n = len(xyz)
    if n < 6:
        raise VideoInputError(f"camera {name}: DLT needs at least 6 control points seen by the camera, got {n}")
    s = np.linalg.svd(xyz - xyz.mean(axis=0), compute_uv=False)
    if s[2] < 1e-3 * s[0]:
        raise VideoInputError(f"camera {name}: control points are (nearly) coplanar; the 11-parameter DLT "
                              "needs points spanning three dimensions")
    try:
        P = _dlt_linear(xyz, uv)
        L = matrix_to_coefficients(P)
    except ValueError as e:
        raise VideoInputError(f"camera {name}: {e}") from None
    res = project_dlt(L, xyz) - uv
    loo = np.full(n, np.nan)
    if n >= 7:
        for i in range(n):
            keep = np.arange(n) != i
            try:
                Li = matrix_to_coefficients(_dlt_linear(xyz[keep], uv[keep]))
                loo[i] = np.linalg.norm(project_dlt(Li, xyz[i:i + 1])[0] - uv[i])
            except ValueError:
                pass
    K, R, t = decompose_projection(coefficients_to_matrix(L))
    cam = Camera(name, K, R, t, np.zeros(0), image_size)
    return DLTCalibration(L, cam, res, float(np.sqrt(np.mean(np.sum(res ** 2, axis=1)))), loo, ids)


def decompose_projection(P):
    """Factor P (3, 4) = λ K [R | t] with K upper triangular (K[2,2] = 1, fx, fy > 0) and det R = +1.

    The overall sign of P is chosen so that det(K R) > 0 (a right-handed camera in OpenCV pixels);
    for image conventions with y up, convert P to OpenCV pixels first (:class:`ImageConvention`).
    Returns K (3, 3), R (3, 3), t (3,).
    """
    P = np.asarray(P, float)
    M = P[:, :3]
    if np.linalg.det(M) < 0:
        P = -P
        M = P[:, :3]
    K, R = rq(M)
    D = np.diag(np.sign(np.diag(K)))
    K, R = K @ D, D @ R
    lam = K[2, 2]
    K = K / lam
    t = np.linalg.solve(K, P[:, 3]) / lam
    if np.linalg.det(R) < 0:  # cannot happen with det(M) > 0, kept as a guard
        raise ValueError("decomposition produced a reflection")
    return K, R, t


_DIST_NAMES = ("k1", "k2", "p1", "p2", "k3")


def refine_camera(camera: Camera, xyz, uv, distortion=("k1", "k2"), fix_skew: bool = True) -> Camera:
    """Non-linear least-squares refinement of a camera on control points, adding OpenCV distortion.

    Parameters: fx, fy, cx, cy, rotation vector, t, the named ``distortion`` terms (subset of k1, k2,
    p1, p2, k3) and, unless ``fix_skew`` (then the skew is set to 0, as for any modern sensor; the linear
    DLT's skew absorbs distortion), the skew. Minimises the pixel reprojection error.
    """
    xyz = np.asarray(xyz, float)
    uv = np.asarray(uv, float)
    ok = np.all(np.isfinite(xyz), axis=1) & np.all(np.isfinite(uv), axis=1)
    xyz, uv = xyz[ok], uv[ok]
    for d in distortion:
        if d not in _DIST_NAMES:
            raise VideoInputError(f"camera {camera.name}: unknown distortion term {d!r} (known: {_DIST_NAMES})")
    n_par = 4 + (0 if fix_skew else 1) + 6 + len(distortion)
    if 2 * len(xyz) < n_par + 2:
        raise VideoInputError(f"camera {camera.name}: {len(xyz)} control points are too few to refine "
                              f"{n_par} parameters")
    K = camera.K
    rvec = cv2.Rodrigues(camera.R)[0].ravel()
    d0 = np.zeros(5)
    d0[:min(5, camera.dist.size)] = camera.dist[:5]
    idx = [_DIST_NAMES.index(d) for d in distortion]
    x0 = np.concatenate([[K[0, 0], K[1, 1], K[0, 2], K[1, 2]], [] if fix_skew else [K[0, 1]], rvec, camera.t,
                         d0[idx]])

    def build(x):
        fx, fy, cx, cy = x[:4]
        j = 4
        skew = 0.0
        if not fix_skew:
            skew = x[4]
            j = 5
        R = cv2.Rodrigues(x[j:j + 3])[0]
        t = x[j + 3:j + 6]
        d = d0.copy()
        d[idx] = x[j + 6:]
        return Camera(camera.name, np.array([[fx, skew, cx], [0, fy, cy], [0, 0, 1]]), R, t, d, camera.image_size)

    def fun(x):
        try:
            return (build(x).project(xyz) - uv).ravel()
        except ValueError:
            return np.full(uv.size, 1e6)

    sol = least_squares(fun, x0, method="lm", x_scale="jac")
    return build(sol.x)


# ---------------------------------------------------------------------------------------------------
# conversions between conventions and units
# ---------------------------------------------------------------------------------------------------
def camera_from_dlt(L, name: str, image_size=(0, 0), convention: ImageConvention = OPENCV,
                    metres_per_unit: float = 1.0) -> Camera:
    """Camera from 11 DLT coefficients given in ``convention`` pixels and world units of
    ``metres_per_unit`` m (e.g. 0.001 for mm)."""
    P = coefficients_to_matrix(L)
    A = convention.matrix(image_size[1] if image_size else None)
    P = A @ P @ np.diag([1 / metres_per_unit] * 3 + [1.0])
    K, R, t = decompose_projection(P)
    return Camera(name, K, R, t, np.zeros(0), image_size)


def dlt_from_camera(camera: Camera, convention: ImageConvention = OPENCV, metres_per_unit: float = 1.0) -> np.ndarray:
    """11 DLT coefficients of a camera's pinhole part in ``convention`` pixels and file world units."""
    A = np.linalg.inv(convention.matrix(camera.height))
    P = A @ camera.P @ np.diag([metres_per_unit] * 3 + [1.0])
    return matrix_to_coefficients(P)


# ---------------------------------------------------------------------------------------------------
# files
# ---------------------------------------------------------------------------------------------------
def _units(value, where: str) -> float:
    if value not in UNITS:
        raise VideoInputError(f"{where}: units must be one of {list(UNITS)}, got {value!r}")
    return UNITS[value]


def read_camera_yaml(path) -> dict[str, Camera]:
    """Read a bayes-disc camera file.

    ``units`` (m, cm or mm; default m) applies to every ``t``. Per camera: ``image_size`` [w, h] px,
    ``K`` 3×3, either ``R`` 3×3 (world→camera) or ``rvec`` (Rodrigues, rad), ``t`` (3), optional ``dist``
    (OpenCV order).
    """
    from .config import Section, load_yaml

    sec = Section(path, load_yaml(path))
    scale = _units(sec.string("units", "m"), f"{path}: key 'units'")
    cams_sec = sec.section("cameras", required=True)
    cameras = {}
    for name in cams_sec.keys():
        c = cams_sec.section(name)
        size = c.vector("image_size", 2, required=True, integer=True)
        K = c.matrix("K", 3, 3, required=True)
        if c.has("R") and c.has("rvec"):
            raise c.error("rvec", "give either R or rvec, not both")
        if c.has("rvec"):
            R = cv2.Rodrigues(np.array(c.vector("rvec", 3), float))[0]
        else:
            R = c.matrix("R", 3, 3, required=True)
        t = np.array(c.vector("t", 3, required=True)) * scale
        dist = c.vector("dist", None, [])
        c.finish()
        try:
            cameras[str(name)] = Camera(str(name), K, R, t, dist, tuple(size))
        except ValueError as e:
            raise VideoInputError(f"{path}: key 'cameras.{name}': {e}") from None
    sec.finish()
    if not cameras:
        raise VideoInputError(f"{path}: key 'cameras': no cameras defined")
    return cameras


def write_camera_yaml(path, cameras) -> None:
    """Write cameras (dict or list) as a bayes-disc camera file (units m)."""
    cams = cameras.values() if isinstance(cameras, dict) else cameras
    data = {"units": "m", "cameras": {}}
    for c in cams:
        data["cameras"][c.name] = {
            "image_size": [int(c.width), int(c.height)],
            "K": [[float(x) for x in row] for row in c.K],
            "R": [[float(x) for x in row] for row in c.R],
            "t": [float(x) for x in c.t],
            "dist": [float(x) for x in c.dist],
        }
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    Path(path).write_text("# bayes-disc camera file: x_cam = R x_world + t (OpenCV; pixels from the top-left)\n"
                          + yaml.safe_dump(data, sort_keys=False, default_flow_style=None))


def read_dlt_csv(path) -> np.ndarray:
    """DLT coefficient file: 11 rows, one column per camera (comma, tab or space separated; an optional
    non-numeric header line is skipped). Returns (n_cameras, 11)."""
    path = Path(path)
    if not path.is_file():
        raise VideoInputError(f"{path}: file not found")
    rows = []
    for lineno, line in enumerate(path.read_text().splitlines(), start=1):
        text = line.strip()
        if not text:
            continue
        fields = [f for f in (text.replace(",", " ").replace(";", " ").split()) if f]
        try:
            rows.append([float(f) for f in fields])
        except ValueError:
            if not rows:
                continue  # header
            raise VideoInputError(f"{path}:{lineno}: not a number in {text!r}") from None
    if len(rows) != 11:
        raise VideoInputError(f"{path}: a DLT coefficient file has 11 rows (one column per camera), found {len(rows)}")
    widths = {len(r) for r in rows}
    if len(widths) != 1:
        raise VideoInputError(f"{path}: rows have different numbers of columns {sorted(widths)}")
    A = np.array(rows, float)
    if not np.all(np.isfinite(A)):
        raise VideoInputError(f"{path}: coefficients must be finite")
    return A.T


def write_dlt_csv(path, cameras, convention: ImageConvention = DLTDV, metres_per_unit: float = 1.0) -> None:
    """Write cameras' DLT coefficients, 11 rows × cameras, in ``convention`` pixels and file units."""
    cols = [dlt_from_camera(c, convention, metres_per_unit) for c in cameras]
    A = np.array(cols).T
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh, lineterminator="\n")
        for row in A:
            w.writerow([repr(float(x)) for x in row])


def cameras_from_dlt_csv(path, names, image_sizes, convention: ImageConvention = DLTDV,
                         metres_per_unit: float = 1.0) -> dict[str, Camera]:
    """Cameras from a DLT coefficient CSV; ``names`` label the columns in order, ``image_sizes`` maps
    each name to (width, height) (the height is needed to flip a bottom-left origin)."""
    L = read_dlt_csv(path)
    names = list(names)
    if len(names) != L.shape[0]:
        raise VideoInputError(f"{path}: {L.shape[0]} camera column(s) but {len(names)} camera name(s) given")
    out = {}
    for name, coef in zip(names, L):
        try:
            out[name] = camera_from_dlt(coef, name, tuple(image_sizes[name]), convention, metres_per_unit)
        except ValueError as e:
            raise VideoInputError(f"{path}: camera {name}: {e}") from None
    return out


def read_anipose_toml(path, metres_per_unit: float = 1.0) -> dict[str, Camera]:
    """Cameras of an anipose/aniposelib ``calibration.toml`` (OpenCV model; translation in the
    calibration board's units, converted with ``metres_per_unit``)."""
    path = Path(path)
    if not path.is_file():
        raise VideoInputError(f"{path}: file not found")
    try:
        data = tomllib.loads(path.read_text())
    except tomllib.TOMLDecodeError as e:
        raise VideoInputError(f"{path}: not valid TOML ({e})") from None
    cams = {}
    for key, sec in data.items():
        if key == "metadata" or not isinstance(sec, dict):
            continue
        where = f"{path}: [{key}]"
        for field_name in ("name", "size", "matrix", "rotation", "translation"):
            if field_name not in sec:
                raise VideoInputError(f"{where}: key '{field_name}' is missing")
        if sec.get("fisheye", False):
            raise VideoInputError(f"{where}: fisheye cameras are not supported")
        unknown = set(sec) - {"name", "size", "matrix", "distortions", "rotation", "translation", "fisheye"}
        if unknown:
            raise VideoInputError(f"{where}: key '{sorted(unknown)[0]}': unknown key")
        try:
            R = cv2.Rodrigues(np.asarray(sec["rotation"], float).reshape(3, 1))[0]
            cam = Camera(str(sec["name"]), np.asarray(sec["matrix"], float), R,
                         np.asarray(sec["translation"], float).ravel() * metres_per_unit,
                         np.asarray(sec.get("distortions", []), float).ravel(),
                         tuple(int(s) for s in sec["size"]))
        except (ValueError, TypeError) as e:
            raise VideoInputError(f"{where}: {e}") from None
        if cam.name in cams:
            raise VideoInputError(f"{where}: camera name {cam.name!r} repeats")
        cams[cam.name] = cam
    if not cams:
        raise VideoInputError(f"{path}: no [cam_*] sections")
    return cams


def write_anipose_toml(path, cameras, metres_per_unit: float = 1.0) -> None:
    """Write cameras as an anipose ``calibration.toml`` (translation in file units)."""
    def arr(a):
        return "[ " + ", ".join(repr(float(x)) for x in np.ravel(a)) + ",]"

    lines = []
    for i, c in enumerate(cameras.values() if isinstance(cameras, dict) else cameras):
        rvec = cv2.Rodrigues(c.R)[0].ravel()
        lines += [f"[cam_{i}]", f'name = "{c.name}"', f"size = [ {int(c.width)}, {int(c.height)},]",
                  "matrix = [ " + ", ".join(arr(r) for r in c.K) + ",]",
                  f"distortions = {arr(c.dist if c.dist.size else np.zeros(5))}",
                  f"rotation = {arr(rvec)}", f"translation = {arr(c.t / metres_per_unit)}", ""]
    lines += ["[metadata]", "adjusted = false", "error = 0.0", ""]
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    Path(path).write_text("\n".join(lines))


def read_control_points(path) -> tuple[list, np.ndarray]:
    """Control-point file: CSV with header ``point,x,y,z`` (m). Returns ids and (n, 3)."""
    ids, xyz = [], []
    for lineno, row in _csv_rows(path, ("point", "x", "y", "z")):
        ids.append(row["point"])
        xyz.append([_num(row[c], path, lineno, c) for c in ("x", "y", "z")])
    return ids, np.array(xyz, float).reshape(-1, 3)


def read_image_points(path) -> dict[str, np.ndarray]:
    """Image-point file: CSV with header ``point,u,v`` (px). Returns {point id: (u, v)}."""
    out = {}
    for lineno, row in _csv_rows(path, ("point", "u", "v")):
        if row["point"] in out:
            raise VideoInputError(f"{path}:{lineno}: point {row['point']!r} repeats")
        out[row["point"]] = np.array([_num(row[c], path, lineno, c) for c in ("u", "v")])
    return out


def _num(text, path, lineno, col) -> float:
    try:
        return float(text)
    except ValueError:
        raise VideoInputError(f"{path}:{lineno}: column {col!r}: {text!r} is not a number") from None


def _csv_rows(path, required):
    path = Path(path)
    if not path.is_file():
        raise VideoInputError(f"{path}: file not found")
    with path.open(newline="") as fh:
        reader = csv.reader(fh)
        header = [h.strip() for h in next(reader, [])]
        missing = [c for c in required if c not in header]
        if missing:
            raise VideoInputError(f"{path}:1: header lacks column(s) {missing}; required: {','.join(required)}")
        for row in reader:
            if not row or all(not c.strip() for c in row):
                continue
            if len(row) != len(header):
                raise VideoInputError(f"{path}:{reader.line_num}: {len(row)} fields, header has {len(header)}")
            yield reader.line_num, {h: c.strip() for h, c in zip(header, row)}
