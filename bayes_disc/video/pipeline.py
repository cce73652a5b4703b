"""``bayes-disc track TRACK.yaml``: footage (or imported points) + calibration → marker file (docs/data-formats.md).

Footage is tracked in stages:

1. **synchronisation** — cameras without a ``frame_offset`` get one estimated from the footage
   (:mod:`.sync`; every frame is detected in full first);
2. **labelling** — frame by frame: detection, labelling on the rigid layout, tracking (:mod:`.labelling`);
3. **second pass** — sub-frame delays estimated (for cameras whose offset was estimated) and applied,
   views holding two markers' light or disagreeing with the others left out, each camera's pixel noise
   calibrated against the residuals, points triangulated again (:mod:`.refine`);
4. **checks** — every point against the rigid layout and its neighbours in time; inconsistent points
   are inflated or left out (:mod:`.consistency`).

The output has one row per reference frame and marker (NaN where the marker was not labelled: gaps are
never filled), stamped t = t0 + f / fps at the middle of the exposure (+ exposure_s / 2 when the frame
stamps mark the exposure's start, ``timestamps.convention: exposure-start``), with extra columns
``reproj_rms_px``, ``n_views``, the covariance ``cov_xx, cov_xy, cov_xz, cov_yy, cov_yz, cov_zz`` [m²]
and ``flag`` (``ok`` or the reasons a point was inflated or left out). With ``triangulation.pixel_sigma:
auto`` (the default) the covariance is (Σ_c J_cᵀ W_c J_c)⁻¹ with W_c⁻¹ = the blob's own centroid
covariance + σ_c² I (σ_c: the camera noise of :mod:`.refine`); with a number σ it is σ² (Σ_c J_cᵀ J_c)⁻¹.
Beside the CSV, ``<output stem>.json`` holds the frame offsets used (given or estimated), the
timestamp convention, the camera noise and the counts of the run.

The configuration format is documented in ``bayes_disc/video/README.md``.
"""
from __future__ import annotations

import json
import sys
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from .consistency import check_points
from .errors import VideoInputError
from .footage import open_source
from .imports import read_xypts, read_xyzpts, reprojection_check
from .labelling import FramePass, backgrounds_of, detect_all, label_frames
from .refine import CameraNoise, Views, refine, shifted, shot_noise, triangulate_views
from .sync import SyncResult, coarse_subframe, estimate_frame_offsets, estimate_subframe, typical_motion
from .track_config import CameraInput, TrackConfig, parse_track_config  # noqa: F401  (the configuration API)
from .triangulation import triangulate
from ..observation.markers import COV_COLUMNS, COV_INDEX


@dataclass
class TrackResult:
    """Tracks on the reference frames: frames (F,), times (F,) [s], xyz (F, M, 3) [m], rms_px (F, M),
    n_views (F, M), cov (F, M, 3, 3) [m²]; stats: counts for the report; flags (F, M): ``ok`` or the
    reasons a point was inflated or left out (None for imported points); meta: what the run used (frame
    offsets, timestamp convention, camera noise), written beside the CSV."""

    flight: str
    marker_ids: list
    frames: np.ndarray
    times: np.ndarray
    xyz: np.ndarray
    rms_px: np.ndarray
    n_views: np.ndarray
    cov: np.ndarray
    stats: dict = field(default_factory=dict)
    flags: np.ndarray | None = None
    meta: dict = field(default_factory=dict)

    def table(self):
        """The result as a :class:`bayes_disc.observation.markers.MarkerTable` (frame-major rows)."""
        from ..observation.markers import MarkerTable

        F, M = self.xyz.shape[:2]
        extra = {"reproj_rms_px": self.rms_px.reshape(-1).astype(float),
                 "n_views": self.n_views.reshape(-1).astype(int)}
        for name, (i, j) in zip(COV_COLUMNS, COV_INDEX):
            extra[name] = self.cov[:, :, i, j].reshape(-1).astype(float)
        if self.flags is not None:
            extra["flag"] = np.array([str(x) for x in self.flags.reshape(-1)], dtype=object)
        return MarkerTable(flight=np.full(F * M, self.flight, dtype=object), t=np.repeat(self.times, M),
                           marker=np.tile(np.array(self.marker_ids, dtype=object), F),
                           xyz=self.xyz.reshape(-1, 3), extra=extra)

    def write(self, path) -> None:
        """Write the marker file and, when there is metadata, ``<stem>.json`` beside it."""
        from ..observation.markers import write_marker_csv

        write_marker_csv(path, self.table())
        if self.meta:
            Path(path).with_suffix(".json").write_text(json.dumps({**self.meta, "stats": _jsonable(self.stats)},
                                                                  indent=2, ensure_ascii=False))

    def summary(self) -> str:
        seen = np.all(np.isfinite(self.xyz), axis=2)
        parts = [f"flight {self.flight}: {len(self.frames)} frames, {int(seen.sum())}/{seen.size} marker positions "
                 f"({100 * seen.mean():.1f} %)"]
        if seen.any():
            parts.append(f"median reprojection RMS {np.nanmedian(self.rms_px):.3f} px")
        for k, v in self.stats.items():
            parts.append(f"{k}: {v}")
        return "; ".join(parts)


def _jsonable(x):
    if isinstance(x, dict):
        return {str(k): _jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_jsonable(v) for v in x]
    if isinstance(x, (np.integer,)):
        return int(x)
    if isinstance(x, (np.floating,)):
        return float(x)
    return x


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


def _open_sources(cfg: TrackConfig, sources: dict | None) -> list:
    out = []
    for inp in cfg.inputs:
        out.append(sources[inp.name] if sources is not None and inp.name in sources
                   else open_source(inp.source, cfg.path.parent))
    return out


def _synchronise(cfg: TrackConfig, cams: list, names: list, usable) -> SyncResult:
    """Frame offsets: the given ones (a fraction is a sub-frame delay) and, from ``usable`` (per camera
    {camera frame: usable centroids}), the others estimated (:mod:`.sync`), with a first guess of their
    sub-frame delays."""
    given = {i.name: i.frame_offset for i in cfg.inputs if i.frame_offset is not None}
    whole = {n: int(round(v)) for n, v in given.items()}
    if all(i.frame_offset is not None for i in cfg.inputs):
        sync = SyncResult(offsets=dict(whole), source={n: "config" for n in whole})
    else:
        tau = cfg.sync.tau_px if cfg.sync.tau_px is not None else max(3.0, 0.5 * typical_motion(usable))
        try:
            sync = estimate_frame_offsets(cams, names, usable, whole, cfg.sync.max_offset, tau)
        except ValueError as e:
            raise VideoInputError(f"{cfg.path}: {e}") from None
        free = [c for c, n in enumerate(names) if sync.source[n] == "estimated"]
        if cfg.sync.subframe and free:
            guess = coarse_subframe(cams, names, usable, sync.offsets, free, 1.5)
            sync.subframe.update({names[c]: guess[c] for c in free})
    for n, v in given.items():
        sync.subframe[n] = float(v) - whole[n]
    return sync


def track_footage(cfg: TrackConfig, sources: dict | None = None, progress: bool = True) -> TrackResult:
    """Synchronise, detect, label, refine and check over the reference frames (module docstring).

    sources: optional {camera name: frame source} overriding the config's ``source`` strings (tests).
    """
    names = [i.name for i in cfg.inputs]
    cams = [cfg.cameras[n] for n in names]
    srcs = _open_sources(cfg, sources)
    try:
        backgrounds = backgrounds_of(cfg, srcs)
        # detect every frame first when offsets are to be estimated or a camera has a sub-frame delay
        estimate = any(i.frame_offset is None or i.frame_offset != round(i.frame_offset) for i in cfg.inputs)
        cached = detect_all(cfg, cams, srcs, backgrounds, progress) if estimate else None
        usable = None if cached is None else [{i: b.uv[b.usable] for i, b in d.items()} for d in cached]
        sync = _synchronise(cfg, cams, names, usable)
        offsets = [sync.offsets[n] for n in names]
        start = [sync.subframe.get(n, 0.0) for n in names]
        fp = label_frames(cfg, cams, srcs, offsets, backgrounds, cached, progress,
                          start if any(start) else None)
        delays = _subframe_delays(cfg, cams, names, _views_for_covariance(cfg, fp.views), sync)
        if any(abs(delays[c] - start[c]) >= 0.02 for c in range(len(cams))):
            # label again with the delayed cameras' blobs moved to the reference instants
            fp = label_frames(cfg, cams, srcs, offsets, backgrounds, cached, progress,
                              [delays[c] for c in range(len(cams))])
    finally:
        for s in srcs:
            s.close()
    return _second_pass(cfg, cams, names, fp, sync, delays)


def _views_for_covariance(cfg: TrackConfig, views: Views) -> Views:
    """The views with a fixed ``pixel_sigma`` in place of the blobs' own covariances, when one is given."""
    if cfg.pixel_sigma is None:
        return views
    views = views.copy()
    views.cov[views.seen] = cfg.pixel_sigma ** 2 * np.eye(2)
    views.cov_shot[:] = 0.0
    return views


def _subframe_delays(cfg: TrackConfig, cams: list, names: list, views: Views, sync: SyncResult) -> dict:
    """Sub-frame delays {camera index: δ}: given fractions, and estimates for the cameras whose offset
    was estimated (robust χ² with a 0.3 px floor per view, :func:`.sync.estimate_subframe`)."""
    delays = {c: sync.subframe.get(n, 0.0) for c, n in enumerate(names)}
    free = [c for c, n in enumerate(names) if sync.source.get(n) == "estimated"]
    if not (free and cfg.sync.subframe):
        return delays
    floor = CameraNoise(np.full(len(cams), 0.3), np.zeros(len(cams)))

    def loss(d: dict) -> float:
        tri = triangulate_views(cams, shifted(views, d), floor, cfg.identity.min_views)
        q = tri.chi2[np.isfinite(tri.chi2)]
        return float(np.sum(np.log1p(q / 10.0)))

    est, se = estimate_subframe(loss, free, delays)
    for c in free:
        sync.subframe[names[c]] = float(est[c])
        sync.subframe_se[names[c]] = float(se[c])
        sync.messages.append(f"camera {names[c]}: sub-frame delay {est[c]:+.3f} ± {se[c]:.3f} frames estimated")
    return est


def _second_pass(cfg: TrackConfig, cams: list, names: list, fp: FramePass, sync: SyncResult,
                 delays: dict) -> TrackResult:
    """Sub-frame shift, view refinement, checks; the result with flags and metadata."""
    F, M = fp.views.uv.shape[:2]
    views = shifted(_views_for_covariance(cfg, fp.views), {c: d for c, d in delays.items() if d}, names)
    auto = cfg.pixel_sigma is None
    alpha = shot_noise(fp.shot_stats) if auto and cfg.detection.gain is None else np.zeros(len(cams))
    ref = refine(cams, views, names, CameraNoise(np.zeros(len(cams)), alpha), calibrate=auto,
                 min_views=cfg.identity.min_views, level=cfg.outlier_level)
    tri = ref.tri
    xyz, cov = tri.xyz.reshape(F, M, 3), tri.cov.reshape(F, M, 3, 3)
    checks = check_points(xyz, cov, cfg.layout, cfg.checks)
    flags = _flags(fp, ref.views, xyz, checks, cfg.checks.action)
    if cfg.checks.action == "drop":
        out = checks.flag != ""
        xyz, cov = xyz.copy(), cov.copy()
        xyz[out], cov[out] = np.nan, np.nan
    else:
        cov = cov + checks.inflation
    nv = np.where(np.all(np.isfinite(xyz), axis=2), tri.n_views.reshape(F, M), 0)
    rms = np.where(nv > 0, tri.rms_px.reshape(F, M), np.nan)
    stats = dict(fp.stats)
    stats["views left out"] = ref.dropped
    stats["points flagged by the checks"] = int(np.sum(checks.flag != ""))
    stats["camera pixel noise added (px)"] = {n: round(float(v), 4) for n, v in zip(names, ref.noise.sigma)}
    if cfg.pixel_sigma is None and cfg.detection.gain is None:
        stats["gain measured on the blobs (e-/DN)"] = {n: (round(float(1 / a), 2) if a > 1e-9 else "no shot noise seen")
                                                       for n, a in zip(names, ref.noise.alpha)}
    stats["frame offsets"] = {n: round(sync.total(n), 4) for n in names}
    if sync.messages:
        stats["synchronisation"] = " | ".join(sync.messages)
    meta = {"flight": cfg.flight, "fps": cfg.fps, "t0": cfg.t0,
            "timestamps": {"convention": cfg.timestamps, "exposure_s": cfg.exposure_s,
                           "row_time": "middle of the exposure of the reference frame: t0 + f / fps"
                                       + (" + exposure_s / 2" if cfg.timestamps == "exposure-start" else "")},
            "cameras": {n: {**sync.as_dict()[n], "pixel_noise_px": round(float(s), 4),
                            "shot_noise_per_gain": round(float(a), 5)}
                        for n, s, a in zip(names, ref.noise.sigma, ref.noise.alpha)},
            "pixel_sigma": "auto" if cfg.pixel_sigma is None else cfg.pixel_sigma,
            "checks": {"action": cfg.checks.action, "prediction_sigma_m": checks.prediction_sigma}}
    times = cfg.t0 + fp.frames / cfg.fps + cfg.time_shift
    return TrackResult(cfg.flight, cfg.marker_ids, fp.frames, times, xyz, rms, nv, cov, stats, flags, meta)


def _flags(fp: FramePass, views: Views, xyz: np.ndarray, checks, action: str) -> np.ndarray:
    """Per point: ``ok``, or the reasons (views left out, check results) joined by '; '."""
    F, M = xyz.shape[:2]
    out = np.empty((F, M), object)
    verb = "left out" if action == "drop" else "covariance inflated"
    for f, m in np.ndindex(F, M):
        parts = list(views.notes[f, m])
        if checks.flag[f, m]:
            parts.append(f"{verb}: {checks.flag[f, m]}")
        if not np.all(np.isfinite(xyz[f, m])):
            if fp.ambiguous[f, m]:
                parts.append("identity ambiguous")
            elif not parts:
                parts.append("not labelled")
            elif not checks.flag[f, m]:
                parts.append("fewer than two views left")
        out[f, m] = "; ".join(parts) if parts else "ok"
    return out


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
