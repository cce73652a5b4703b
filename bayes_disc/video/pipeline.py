"""``bayes-disc track TRACK.yaml``: footage (or imported points) + calibration → marker file (docs/data-formats.md).

For every reference frame f (time t = t0 + f / fps) and every camera c, the camera's frame
i = f − frame_offset_c is read, blobs are detected (full frame, or in windows around the predicted
marker pixels once the tracker has a prediction), merged and edge blobs are dropped, the markers are
labelled and triangulated (:mod:`.identity`, :mod:`.triangulation`) and the tracker is updated.
The output has one row per reference frame and marker (NaN where the marker was not labelled: gaps are
never filled) with extra columns ``reproj_rms_px``, ``n_views`` and the covariance ``cov_xx, cov_xy,
cov_xz, cov_yy, cov_yz, cov_zz`` [m²] = σ_px² (Σ JᵀJ)⁻¹ with σ_px = ``triangulation.pixel_sigma``, or
(``auto``, the default) the pooled estimate σ̂² = Σ n·rms² / Σ (2n − 3) over the flight's points.

The configuration format is documented in ``bayes_disc/video/README.md``.
"""
from __future__ import annotations

import sys
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from .calibration import (ImageConvention, UNITS, cameras_from_dlt_csv, dlt_calibrate, read_anipose_toml,
                          read_camera_yaml, read_control_points, read_image_points, refine_camera,
                          write_camera_yaml)
from .config import Section, load_yaml
from .detection import Blobs, DetectionConfig, detect_full, detect_roi
from .errors import VideoInputError
from .footage import open_source
from .identity import FrameLabels, IdentityConfig, Tracker, label_frame, layout_distinctness
from .imports import FORMATS, DEFAULT_CONVENTION, read_xypts, read_xyzpts, reprojection_check
from .triangulation import triangulate
from ..observation.markers import COV_COLUMNS, COV_INDEX



@dataclass
class CameraInput:
    """Footage of one camera: its source string and frame offset (camera frame i ↔ reference i + offset)."""

    name: str
    source: str
    frame_offset: int = 0


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
    pixel_sigma: float | None = None  # None: estimated from the reprojection residuals ("auto")
    output: Path | None = None
    calibration_report: str = ""

    @property
    def layout(self) -> np.ndarray:
        return np.array([self.markers[m] for m in self.markers], float)

    @property
    def marker_ids(self) -> list:
        return list(self.markers)


@dataclass
class TrackResult:
    """Tracks on the reference frames: frames (F,), times (F,) [s], xyz (F, M, 3) [m], rms_px (F, M),
    n_views (F, M), cov (F, M, 3, 3) [m²]; stats: counts for the report."""

    flight: str
    marker_ids: list
    frames: np.ndarray
    times: np.ndarray
    xyz: np.ndarray
    rms_px: np.ndarray
    n_views: np.ndarray
    cov: np.ndarray
    stats: dict = field(default_factory=dict)

    def table(self):
        """The result as a :class:`bayes_disc.observation.markers.MarkerTable` (frame-major rows)."""
        from ..observation.markers import MarkerTable

        F, M = self.xyz.shape[:2]
        extra = {"reproj_rms_px": self.rms_px.reshape(-1).astype(float),
                 "n_views": self.n_views.reshape(-1).astype(int)}
        for name, (i, j) in zip(COV_COLUMNS, COV_INDEX):
            extra[name] = self.cov[:, :, i, j].reshape(-1).astype(float)
        return MarkerTable(flight=np.full(F * M, self.flight, dtype=object), t=np.repeat(self.times, M),
                           marker=np.tile(np.array(self.marker_ids, dtype=object), F),
                           xyz=self.xyz.reshape(-1, 3), extra=extra)

    def write(self, path) -> None:
        from ..observation.markers import write_marker_csv

        write_marker_csv(path, self.table())

    def summary(self) -> str:
        seen = np.all(np.isfinite(self.xyz), axis=2)
        parts = [f"flight {self.flight}: {len(self.frames)} frames, {int(seen.sum())}/{seen.size} marker positions "
                 f"({100 * seen.mean():.1f} %)"]
        if seen.any():
            parts.append(f"median reprojection RMS {np.nanmedian(self.rms_px):.3f} px")
        for k, v in self.stats.items():
            parts.append(f"{k}: {v}")
        return "; ".join(parts)


# ---------------------------------------------------------------------------------------------------
# configuration
# ---------------------------------------------------------------------------------------------------
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
            inputs.append(CameraInput(name, c.string("source", required=True), c.number("frame_offset", 0, integer=True)))
            c.finish()
        if len(inputs) < 2:
            raise sec.error("cameras", "at least two cameras are needed to triangulate")
        used = {i.name: cams[i.name] for i in inputs}
    ds = sec.section("detection")
    try:
        det = DetectionConfig(
            threshold=ds.number("threshold", 30.0, positive=True), min_area=ds.number("min_area", 2, integer=True, minimum=1),
            max_area=ds.number("max_area", 5000, integer=True, minimum=1), pad=ds.number("pad", 3, integer=True, minimum=1),
            mask_dilation=ds.number("mask_dilation", 2, integer=True, nonnegative=True),
            noise_floor_sigma=ds.number("noise_floor_sigma", 2.0, nonnegative=True),
            saturation=ds.number("saturation", None, positive=True),
            max_elongation=ds.number("max_elongation", 2.0, minimum=1.0),
            merge_flux_ratio=ds.number("merge_flux_ratio", 1.6, minimum=1.0),
            merge_area_ratio=ds.number("merge_area_ratio", 2.0, minimum=1.0),
            expected_area=ds.number("expected_area", None, positive=True),
            roi_radius=ds.number("roi_radius", 16, integer=True, minimum=2), tile=ds.number("tile", 8, integer=True, minimum=2),
            deblend=ds.boolean("deblend", True))
    except ValueError as e:
        if isinstance(e, VideoInputError):
            raise
        raise VideoInputError(f"{path}: key 'detection': {e}") from None
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
    ids.finish()
    ts.finish()
    out = sec.string("output", f"{flight}_tracks.csv")
    sec.finish()
    return TrackConfig(path, flight, fps, t0, markers, used, inputs, importing, tuple(frames) if frames else None,
                       det, roi, background, bg_frames, ident, pixel_sigma, path.parent / out, report)


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


# ---------------------------------------------------------------------------------------------------
# running
# ---------------------------------------------------------------------------------------------------
def _median_background(src, first: int, last: int, n: int):
    idx = np.unique(np.linspace(first, last, n).round().astype(int))
    frames = [f for f in (src.get(i) for i in idx) if f is not None]
    if len(frames) < 3:
        return None
    return np.median(np.stack(frames), axis=0).astype(np.float32)


def estimate_pixel_sigma(rms_px: np.ndarray, n_views: np.ndarray) -> tuple[float, int]:
    """Pooled centroid standard deviation [px] from reprojection residuals: σ̂² = Σ n·rms² / Σ (2n − 3)
    over points triangulated from n ≥ 2 views (each has 2n residuals and 3 fitted coordinates).
    Returns (σ̂, degrees of freedom); σ̂ is NaN without degrees of freedom."""
    ok = np.isfinite(rms_px) & (n_views >= 2)
    dof = int(np.sum(2 * n_views[ok] - 3))
    if dof == 0:
        return float("nan"), 0
    return float(np.sqrt(np.sum(n_views[ok] * rms_px[ok] ** 2) / dof)), dof


def _calibrate_covariance(result: "TrackResult", cfg: "TrackConfig") -> None:
    """Scale the covariances from the internal σ (identity.pixel_sigma) to the configured or estimated σ."""
    used = cfg.identity.pixel_sigma
    est, dof = estimate_pixel_sigma(result.rms_px, result.n_views)
    result.stats["pixel sigma estimated from residuals (px)"] = round(est, 4) if np.isfinite(est) else "n/a"
    result.stats["residual degrees of freedom"] = dof
    if cfg.pixel_sigma is not None:
        target = cfg.pixel_sigma
    elif dof >= 10 and est > 0:
        target = est
    else:
        target = used
        result.stats["pixel sigma"] = f"too few residual degrees of freedom ({dof}); covariance uses {used} px"
    result.cov *= (target / used) ** 2
    result.stats["pixel sigma used for the covariance (px)"] = round(float(target), 4)


def track_footage(cfg: TrackConfig, sources: dict | None = None, progress: bool = True) -> TrackResult:
    """Run detection, identity and triangulation over the reference frames.

    sources: optional {camera name: frame source} overriding the config's ``source`` strings (tests).
    """
    from tqdm import tqdm

    names = [i.name for i in cfg.inputs]
    cams = [cfg.cameras[n] for n in names]
    offsets = [i.frame_offset for i in cfg.inputs]
    srcs = []
    for inp in cfg.inputs:
        if sources is not None and inp.name in sources:
            srcs.append(sources[inp.name])
        else:
            srcs.append(open_source(inp.source, cfg.path.parent))
    try:
        if cfg.frames is not None:
            f0, f1 = cfg.frames
        else:
            ranges = [(s.frame_range()[0] + k, s.frame_range()[1] + k) for s, k in zip(srcs, offsets)]
            f0, f1 = min(r[0] for r in ranges), max(r[1] for r in ranges)
        backgrounds = [None] * len(srcs)
        if cfg.background == "median":
            for c, s in enumerate(srcs):
                a, b = s.frame_range()
                backgrounds[c] = _median_background(s, a, b, cfg.background_frames)
        frames = np.arange(f0, f1 + 1)
        F, M, C = len(frames), len(cfg.markers), len(cams)
        xyz = np.full((F, M, 3), np.nan)
        rms = np.full((F, M), np.nan)
        nv = np.zeros((F, M), int)
        cov = np.full((F, M, 3, 3), np.nan)
        layout = cfg.layout
        tracker = Tracker(layout, cfg.identity)
        n_missing = [0] * C
        n_roi = n_full = n_blobs = n_unusable = n_ambiguous = 0
        r = cfg.detection.roi_radius
        for k, f in enumerate(tqdm(frames, desc=f"track {cfg.flight}", unit="frame", disable=not progress)):
            pred, psig = tracker.predict(int(f))
            blob_uv = []
            for c, (cam, src) in enumerate(zip(cams, srcs)):
                img = src.get(int(f - offsets[c]))
                if img is None:
                    n_missing[c] += 1
                    blob_uv.append(np.zeros((0, 2)))
                    continue
                if img.shape[:2] != (cam.height, cam.width):
                    raise VideoInputError(f"camera {cam.name}: frame {int(f - offsets[c])} is "
                                          f"{img.shape[1]}×{img.shape[0]} px but the calibration says "
                                          f"{cam.width}×{cam.height}")
                if cfg.roi and pred is not None:
                    ctr = cam.project(pred[np.all(np.isfinite(pred), axis=1)])
                    ctr = ctr[np.all(np.isfinite(ctr), axis=1) & cam.in_image(ctr, margin=-r)]
                    blobs = detect_roi(img, ctr, cfg.detection, backgrounds[c]) if len(ctr) else Blobs()
                    n_roi += 1
                else:
                    blobs = detect_full(img, cfg.detection, backgrounds[c])
                    n_full += 1
                n_blobs += len(blobs)
                n_unusable += int((~blobs.usable).sum())
                blob_uv.append(blobs.uv[blobs.usable])
            lab: FrameLabels = label_frame(cams, blob_uv, layout, cfg.identity, pred, psig)
            tracker.update(int(f), lab.xyz)
            xyz[k], rms[k], nv[k], cov[k] = lab.xyz, lab.rms_px, lab.n_views, lab.cov
            n_ambiguous += int(lab.ambiguous.sum())
    finally:
        for s in srcs:
            s.close()
    stats = {"frames missing per camera": dict(zip(names, n_missing)), "ROI detections": n_roi,
             "full-frame detections": n_full, "blobs": n_blobs, "merged/edge blobs dropped": n_unusable,
             "ambiguous labels left NaN": n_ambiguous}
    result = TrackResult(cfg.flight, cfg.marker_ids, frames, cfg.t0 + frames / cfg.fps, xyz, rms, nv, cov, stats)
    _calibrate_covariance(result, cfg)
    return result


def track_import(cfg: TrackConfig) -> TrackResult:
    """Marker tracks from DLTdv/Argus point files.

    With 2-D points the markers are triangulated with the calibration (giving reprojection RMS, views
    and covariance); 3-D points given as well are only used to check the import by reprojection. With
    3-D points alone they are taken as they are (converted to metres).
    """
    spec = cfg.importing
    cams = [cfg.cameras[n] for n in spec.cameras]
    heights = [c.height for c in cams]
    p2 = read_xypts(spec.xypts, spec.fmt, heights, spec.convention) if spec.xypts else None
    p3 = read_xyzpts(spec.xyzpts, spec.fmt, spec.metres_per_unit) if spec.xyzpts else None
    for p in (p2, p3):
        if p is None:
            continue
        path = spec.xypts if p is p2 else spec.xyzpts
        missing = [n for n in spec.points if n not in p.names]
        if missing:
            raise VideoInputError(f"{path}: point {missing[0]!r} (import.points) is not in the file "
                                  f"(it has: {', '.join(p.names)})")
        for mid in spec.points.values():
            if mid not in cfg.markers:
                raise VideoInputError(f"{cfg.path}: key 'import.points': marker {mid!r} is not in 'markers'")
    if p2 is not None and p2.n_cameras != len(cams):
        raise VideoInputError(f"{spec.xypts}: {p2.n_cameras} cameras in the file but import.cameras lists {len(cams)}")
    stats = {}
    order = list(spec.points)  # file point names in output order of their markers
    F = len(p2.uv) if p2 is not None else len(p3.xyz)
    M = len(cfg.markers)
    xyz = np.full((F, M, 3), np.nan)
    rms = np.full((F, M), np.nan)
    nv = np.zeros((F, M), int)
    cov = np.full((F, M, 3, 3), np.nan)
    col = {mid: j for j, mid in enumerate(cfg.markers)}
    if p2 is not None:
        uv = np.stack([p2.uv[:, p2.names.index(n)] for n in order], axis=1)  # (F, P, C, 2)
        tri = triangulate(cams, uv.reshape(-1, len(cams), 2), pixel_sigma=cfg.identity.pixel_sigma,
                          min_views=cfg.identity.min_views)
        P = len(order)
        if p3 is not None:
            X3 = np.stack([p3.xyz[:, p3.names.index(n)] for n in order], axis=1)
            if len(X3) != F:
                raise VideoInputError(f"{spec.xyzpts}: {len(X3)} rows but {spec.xypts} has {F}")
            check = reprojection_check(cams, X3, uv)
            stats["reprojection check RMS px"] = {n: round(float(v), 3) for n, v in zip(spec.cameras, check)}
            bad = [(n, v) for n, v in zip(spec.cameras, check) if np.isfinite(v) and v > spec.max_check_rms_px]
            if bad:
                raise VideoInputError(
                    f"{spec.xyzpts}: 3-D points reproject {bad[0][1]:.1f} px from the 2-D points in camera "
                    f"{bad[0][0]} (limit {spec.max_check_rms_px} px): check origin/first_pixel, units and camera order")
        for p, name in enumerate(order):
            j = col[spec.points[name]]
            sl = slice(p, None, P)
            xyz[:, j] = tri.xyz[sl]
            rms[:, j] = tri.rms_px[sl]
            nv[:, j] = tri.n_views[sl]
            cov[:, j] = tri.cov[sl]
    else:
        for name in order:
            j = col[spec.points[name]]
            xyz[:, j] = p3.xyz[:, p3.names.index(name)]
    frames = spec.first_frame + np.arange(F)
    result = TrackResult(cfg.flight, cfg.marker_ids, frames, cfg.t0 + frames / cfg.fps, xyz, rms, nv, cov, stats)
    if p2 is not None:
        _calibrate_covariance(result, cfg)
    return result


def run_track(path, output=None, progress: bool = True, sources: dict | None = None) -> TrackResult:
    """Parse TRACK.yaml, track, write the marker file (``output`` overrides the config's)."""
    cfg = parse_track_config(path)
    if output is not None:
        cfg = replace(cfg, output=Path(output))
    if cfg.calibration_report and progress:
        print(cfg.calibration_report, file=sys.stderr)
    result = track_import(cfg) if cfg.importing is not None else track_footage(cfg, sources, progress)
    result.write(cfg.output)
    return result
