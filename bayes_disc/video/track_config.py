"""Reading ``TRACK.yaml`` (format in ``bayes_disc/video/README.md``): markers, calibration, cameras and
the settings of detection, identity, triangulation, timestamps, synchronisation and checks.

Unknown keys are errors naming the key (:class:`~.config.Section`).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .calibration import (ImageConvention, UNITS, cameras_from_dlt_csv, dlt_calibrate, read_anipose_toml,
                          read_camera_yaml, read_control_points, read_image_points, refine_camera,
                          write_camera_yaml)
from .config import Section, load_yaml
from .consistency import CheckConfig
from .detection import DetectionConfig
from .errors import VideoInputError
from .identity import IdentityConfig, layout_distinctness
from .imports import FORMATS, DEFAULT_CONVENTION


@dataclass
class CameraInput:
    """Footage of one camera: its source string and frame offset (camera frame i is exposed at reference
    frame i + offset; a fraction is a sub-frame delay). ``frame_offset`` None: estimated from the footage."""

    name: str
    source: str
    frame_offset: float | None = 0


@dataclass(frozen=True)
class SyncConfig:
    """Estimation of missing frame offsets (:mod:`.sync`): offsets tried ±max_offset frames; tau_px
    truncation of the epipolar distance [px] (None: half the typical image motion of the blobs per
    frame, at least 3 px); subframe: also estimate a sub-frame delay."""

    max_offset: int = 10
    tau_px: float | None = None
    subframe: bool = True


@dataclass
class ImportSpec:
    """Points digitised with another tool (see :mod:`.imports`)."""

    fmt: str
    xypts: Path | None
    xyzpts: Path | None
    metres_per_unit: float
    convention: ImageConvention
    cameras: list
    points: dict
    first_frame: int
    max_check_rms_px: float


@dataclass
class TrackConfig:
    """A parsed TRACK.yaml (see README). ``cameras`` holds the calibrated cameras used, in order."""

    path: Path
    flight: str
    fps: float
    t0: float
    markers: dict
    cameras: dict
    inputs: list = field(default_factory=list)
    importing: ImportSpec | None = None
    frames: tuple | None = None
    detection: DetectionConfig = DetectionConfig()
    roi: bool = True
    background: str = "none"
    background_frames: int = 25
    identity: IdentityConfig = IdentityConfig()
    pixel_sigma: float | None = None  # None ("auto"): each blob's own covariance plus a camera noise
    output: Path | None = None
    calibration_report: str = ""
    timestamps: str = "mid-exposure"
    exposure_s: float = 0.0
    sync: SyncConfig = SyncConfig()
    checks: CheckConfig = CheckConfig()
    outlier_level: float = 0.999

    @property
    def time_shift(self) -> float:
        """Time from a frame's stamp t0 + f / fps to the middle of its exposure [s] (the instant a blob
        centroid shows: a smeared blob is centred on the mean position over the exposure)."""
        return 0.5 * self.exposure_s if self.timestamps == "exposure-start" else 0.0

    @property
    def layout(self) -> np.ndarray:
        return np.array([self.markers[m] for m in self.markers], float)

    @property
    def marker_ids(self) -> list:
        return list(self.markers)



def _markers(sec: Section) -> dict:
    raw = sec.raw("markers", None, required=True)
    if not isinstance(raw, dict) or len(raw) < 3:
        raise sec.error("markers", "must map at least 3 marker ids to body positions [x, y, z] (m)")
    ms = Section(sec.path, raw, "markers")
    out = {str(k): ms.vector(k, 3, required=True) for k in ms.keys()}
    ms.finish()
    layout = np.array(list(out.values()))
    d = np.linalg.norm(layout[:, None] - layout[None], axis=2)[np.triu_indices(len(layout), 1)]
    if np.min(d) < 0.005:
        raise sec.error("markers", "two markers are closer than 5 mm")
    return out


def _check_layout(sec: Section, markers: dict, ident: IdentityConfig) -> None:
    """Footage needs a layout whose side lengths identify the markers (a scalene triangle): reject one
    that some relabelling changes by less than side_sigma_m · √max(ambiguity_margin, 1) (then every
    frame would be ambiguous, see :mod:`.identity`)."""
    sep = layout_distinctness(np.array(list(markers.values()), float))
    need = ident.side_sigma_m * np.sqrt(max(ident.ambiguity_margin, 1.0))
    if np.isfinite(sep) and sep < need:
        raise sec.error("markers", f"the layout is (nearly) symmetric: relabelling the markers changes the side "
                                   f"lengths by only {1e3 * sep:.1f} mm (need ≥ {1e3 * need:.1f} mm = identity."
                                   "side_sigma_m · √ambiguity_margin), so they could never be told apart; use a "
                                   "scalene layout")


def _convention(sec: Section, default: ImageConvention) -> ImageConvention:
    origin = sec.string("origin", default.origin, choices=("top-left", "bottom-left"))
    first = sec.number("first_pixel", default.first_pixel)
    return ImageConvention(origin, first)


def _image_sizes(sec: Section, key: str, names: list) -> dict:
    v = sec.raw(key, None)
    if v is None:
        raise sec.error(key, "is required ([width, height] for all cameras, or a mapping camera → [width, height])")
    if isinstance(v, dict):
        s = Section(sec.path, v, sec.key(key))
        out = {n: tuple(s.vector(n, 2, required=True, integer=True)) for n in names}
        s.finish()
        return out
    size = Section(sec.path, {key: v}, sec.prefix).vector(key, 2, integer=True)
    return {n: tuple(size) for n in names}


def load_calibration(sec: Section) -> tuple[dict, str]:
    """Cameras from a ``calibration`` section; returns ({name: Camera}, report text)."""
    fmt = sec.string("format", "bayes-disc", choices=("bayes-disc", "dlt-csv", "anipose", "control-points"))
    report = ""
    if fmt == "bayes-disc":
        cams = read_camera_yaml(sec.path_of("file", required=True))
    elif fmt == "anipose":
        cams = read_anipose_toml(sec.path_of("file", required=True), UNITS[sec.string("units", "m", choices=tuple(UNITS))])
    elif fmt == "dlt-csv":
        path = sec.path_of("file", required=True)
        names = sec.raw("cameras", None, required=True)
        if not isinstance(names, list) or not all(isinstance(n, str) and n for n in names):
            raise sec.error("cameras", "must be a list of camera names, one per column of the DLT file")
        sizes = _image_sizes(sec, "image_size", names)
        conv = _convention(sec, ImageConvention("bottom-left", 1.0))
        cams = cameras_from_dlt_csv(path, names, sizes, conv, UNITS[sec.string("units", "m", choices=tuple(UNITS))])
    else:  # control points
        ids, xyz = read_control_points(sec.path_of("points", required=True))
        ip = sec.section("image_points", required=True)
        names = ip.keys()
        if not names:
            raise sec.error("image_points", "no cameras given")
        files = {n: ip.path_of(n, required=True) for n in names}
        ip.finish()
        sizes = _image_sizes(sec, "image_size", names)
        conv = _convention(sec, ImageConvention("top-left", 0.0))
        dist_terms = sec.raw("distortion", [])
        if not isinstance(dist_terms, list):
            raise sec.error("distortion", "must be a list of distortion terms, e.g. [k1, k2]")
        cams, lines = {}, []
        for n in names:
            pts = read_image_points(files[n])
            unknown = [p for p in pts if p not in ids]
            if unknown:
                raise VideoInputError(f"{files[n]}: point {unknown[0]!r} is not in the control-point file")
            uv = np.array([conv.to_opencv(pts[p], sizes[n][1]) if p in pts else [np.nan, np.nan] for p in ids])
            cal = dlt_calibrate(xyz, uv, name=n, image_size=sizes[n], point_ids=ids)
            cam = cal.camera
            lines.append(cal.report())
            if dist_terms:
                cam = refine_camera(cam, xyz, uv, [str(d) for d in dist_terms])
                res = cam.project(xyz) - uv
                ok = np.all(np.isfinite(res), axis=1)
                lines.append(f"  refined with distortion {dist_terms}: RMS {np.sqrt(np.mean(np.sum(res[ok] ** 2, 1))):.3f} px")
            cams[n] = cam
        report = "\n".join(lines)
        out = sec.string("write", None)
        if out is not None:
            write_camera_yaml(sec.folder / out, cams)
    sec.finish()
    return cams, report


def parse_track_config(path) -> TrackConfig:
    """Read and check a TRACK.yaml (unknown keys are errors naming the key).

    Long: one validation pass over the file's keys, in the order their errors are reported."""
    path = Path(path)
    sec = Section(path, load_yaml(path))
    flight = sec.string("flight", path.stem)
    fps = sec.number("fps", required=True, positive=True)
    t0 = sec.number("t0", 0.0)
    markers = _markers(sec)
    frames = sec.vector("frames", 2, integer=True)
    if frames is not None and frames[1] < frames[0]:
        raise sec.error("frames", f"end {frames[1]} is before start {frames[0]}")
    cams, report = load_calibration(sec.section("calibration", required=True))
    if sec.has("cameras") and sec.has("import"):
        raise sec.error("import", "give either 'cameras' (footage) or 'import' (digitised points), not both")
    inputs, importing = [], None
    if sec.has("import"):
        importing = _parse_import(sec.section("import"), cams)
        used = {n: cams[n] for n in importing.cameras}
    else:
        cs = sec.section("cameras", required=True)
        for name in cs.keys():
            name = str(name)
            c = cs.section(name)
            if name not in cams:
                raise cs.error(name, f"camera {name!r} is not in the calibration (it has: {', '.join(cams)})")
            inputs.append(CameraInput(name, c.string("source", required=True), c.number("frame_offset", None)))
            c.finish()
        if len(inputs) < 2:
            raise sec.error("cameras", "at least two cameras are needed to triangulate")
        used = {i.name: cams[i.name] for i in inputs}
    ds = sec.section("detection")
    det = _detection(ds, path)
    roi = ds.boolean("roi", True)
    background = ds.string("background", "none", choices=("none", "median"))
    bg_frames = ds.number("background_frames", 25, integer=True, minimum=3)
    ds.finish()
    ids = sec.section("identity")
    ts = sec.section("triangulation")
    try:
        ident = IdentityConfig(
            reprojection_px=ids.number("reprojection_px", 2.0, positive=True),
            reprojection_sigma_px=ids.number("reprojection_sigma_px", 0.5, positive=True),
            side_sigma_m=ids.number("side_sigma_m", 0.003, positive=True),
            prediction_sigma_m=ids.number("prediction_sigma_m", 0.01, positive=True),
            cv_sigma_m=ids.number("cv_sigma_m", 0.03, positive=True),
            gate_sigma=ids.number("gate_sigma", 5.0, positive=True),
            miss_cost=ids.number("miss_cost", 25.0, positive=True),
            view_bonus=ids.number("view_bonus", 1.0, nonnegative=True),
            missing_view_cost=ids.number("missing_view_cost", 4.0, nonnegative=True),
            ambiguity_margin=ids.number("ambiguity_margin", 9.0, nonnegative=True),
            swap_distance_m=ids.number("swap_distance_m", 0.02, positive=True),
            max_gap_frames=ids.number("max_gap_frames", 5, integer=True, minimum=1),
            max_pose_gap=ids.number("max_pose_gap", 2, integer=True, minimum=1),
            min_views=ts.number("min_views", 2, integer=True, minimum=2))
    except ValueError as e:
        if isinstance(e, VideoInputError):
            raise
        raise VideoInputError(f"{path}: key 'identity': {e}") from None
    if importing is None:
        _check_layout(sec, markers, ident)
    ps = ts.raw("pixel_sigma", "auto")
    if ps == "auto":
        pixel_sigma = None
    else:
        pixel_sigma = ts.number("pixel_sigma", positive=True)
    outlier_level = ts.number("outlier_level", 0.999, positive=True, maximum=0.999999)
    ids.finish()
    ts.finish()
    timestamps, exposure = _timestamps(sec.section("timestamps"))
    sync = _sync(sec.section("sync"))
    checks = _checks(sec.section("checks"))
    out = sec.string("output", f"{flight}_tracks.csv")
    sec.finish()
    return TrackConfig(path, flight, fps, t0, markers, used, inputs, importing, tuple(frames) if frames else None,
                       det, roi, background, bg_frames, ident, pixel_sigma, path.parent / out, report, timestamps,
                       exposure, sync, checks, outlier_level)


def _timestamps(sec: Section) -> tuple[str, float]:
    """``timestamps: {convention, exposure_s}``: what t0 + f / fps marks (the middle or the start of the
    exposure) and the exposure time [s] (required for ``exposure-start``)."""
    conv = sec.string("convention", "mid-exposure", choices=("mid-exposure", "exposure-start"))
    exposure = sec.number("exposure_s", 0.0, nonnegative=True)
    if conv == "exposure-start" and not exposure > 0:
        raise sec.error("exposure_s", "is required (and positive) with convention exposure-start: the rows are "
                                      "stamped at the middle of the exposure, t0 + f / fps + exposure_s / 2")
    sec.finish()
    return conv, exposure


def _sync(sec: Section) -> SyncConfig:
    out = SyncConfig(max_offset=sec.number("max_offset", 10, integer=True, minimum=1),
                     tau_px=_auto_number(sec, "tau_px"), subframe=sec.boolean("subframe", True))
    sec.finish()
    return out


def _auto_number(sec: Section, key: str):
    """A positive number, or ``auto`` (None)."""
    if sec.raw(key, "auto") == "auto":
        return None
    return sec.number(key, positive=True)


def _checks(sec: Section) -> CheckConfig:
    out = CheckConfig(action=sec.string("action", "inflate", choices=("inflate", "drop")),
                      layout_sigma_m=sec.number("layout_sigma_m", 0.001, nonnegative=True),
                      z_max=sec.number("z_max", 4.0, positive=True),
                      level=sec.number("level", 1e-4, positive=True, maximum=0.5),
                      enabled=sec.boolean("enabled", True))
    sec.finish()
    return out


def _detection(ds: Section, path: Path) -> DetectionConfig:
    """The detection settings of a ``detection`` section (``roi`` and ``background`` are read by the caller)."""
    try:
        return DetectionConfig(
            threshold=ds.number("threshold", 30.0, positive=True), min_area=ds.number("min_area", 2, integer=True, minimum=1),
            max_area=ds.number("max_area", 5000, integer=True, minimum=1), pad=ds.number("pad", 3, integer=True, minimum=1),
            mask_dilation=ds.number("mask_dilation", 2, integer=True, nonnegative=True),
            noise_floor_sigma=ds.number("noise_floor_sigma", 2.0, nonnegative=True),
            saturation=ds.number("saturation", None, positive=True),
            max_elongation=ds.number("max_elongation", 2.0, minimum=1.0),
            merge_flux_ratio=ds.number("merge_flux_ratio", None, minimum=1.0),
            merge_area_ratio=ds.number("merge_area_ratio", None, minimum=1.0),
            gain=ds.number("gain", None, positive=True),
            expected_area=ds.number("expected_area", None, positive=True),
            roi_radius=ds.number("roi_radius", 16, integer=True, minimum=2), tile=ds.number("tile", 8, integer=True, minimum=2),
            deblend=ds.boolean("deblend", True))
    except ValueError as e:
        if isinstance(e, VideoInputError):
            raise
        raise VideoInputError(f"{path}: key 'detection': {e}") from None


def _parse_import(sec: Section, cams: dict) -> ImportSpec:
    fmt = sec.string("format", required=True, choices=FORMATS)
    xy = sec.path_of("xypts")
    xyz = sec.path_of("xyzpts")
    if xy is None and xyz is None:
        raise sec.error("xypts", "give xypts (2-D points), xyzpts (3-D points) or both")
    names = sec.raw("cameras", None)
    if names is None:
        names = list(cams)
    if not isinstance(names, list) or not all(isinstance(n, str) for n in names):
        raise sec.error("cameras", "must be a list of calibration camera names (camera 1, 2, ... of the file)")
    for n in names:
        if n not in cams:
            raise sec.error("cameras", f"camera {n!r} is not in the calibration (it has: {', '.join(cams)})")
    pts = sec.raw("points", None, required=True)
    if not isinstance(pts, dict) or not pts:
        raise sec.error("points", "must map the file's point names to marker ids, e.g. {pt1: '0'}")
    spec = ImportSpec(fmt, xy, xyz, UNITS[sec.string("units", "m", choices=tuple(UNITS))],
                      _convention(sec, DEFAULT_CONVENTION[fmt]), list(names), {str(k): str(v) for k, v in pts.items()},
                      sec.number("first_frame", 0, integer=True), sec.number("max_check_rms_px", 3.0, positive=True))
    sec.finish()
    return spec


