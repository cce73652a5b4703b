"""Synthetic multi-camera footage of a simulated flight, with ground truth (``bayes-disc render``).

The flight is simulated with :func:`bayes_disc.physics.simulate` (the model of docs/conventions.md). Each camera is a
pinhole with OpenCV distortion (:mod:`.camera`). A marker of diameter d at depth Z images as a
pixel-integrated Gaussian of standard deviation

    σ = sqrt(psf_sigma_px² + (f d / (4 Z))²)       [px]   (a uniform disc of radius r has σ = r/2)

and flux F = gain · peak · 2πσ² [DN] (``peak``: the brightness of a still, centred blob), integrated
exactly over each pixel with the error function. Motion blur averages ``blur_samples`` positions spread
evenly over the exposure, which is centred on the frame time t_f = t0 + f / fps. Then: background level,
Gaussian read noise (σ_n DN, optionally shot noise of a sensor with ``shot_noise_gain`` e⁻/DN),
rounding and clipping to the bit depth (saturation). A marker is hidden when the camera sees the disc's
top face at an elevation below ``min_view_elevation_deg`` (occlusion of the top face: markers sit on the
top surface, whose outward normal is −b3) or when it is behind the camera. The flight's initial state
holds at the start of frame 0's exposure (t0 − exposure/2). Frames are dropped at random
with probability ``drop_rate`` (not written for image sequences; black frames in videos).

``noise_region: windows`` adds noise only around the markers (the rest of the frame is the flat
background): much faster and much smaller files, with the same statistics where the detector looks.

Camera ``frame_offset`` k: the camera's frame i is exposed at reference frame i + k.
"""
from __future__ import annotations

import csv
import json
import math
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

from ..physics import COEFFICIENT_NAMES, LITERATURE, literature_coefficients, simulate
from ..physics.frames import attitude_from_yaw_pitch_roll, quat_to_matrix
from .calibration import write_camera_yaml
from .camera import Camera, look_at
from .config import Section, load_yaml
from .errors import VideoInputError
from .footage import ArrayFrames
from .psf import pixel_integrated_gaussian

DEFAULT_MARKERS = {"0": [0.100, 0.000, -0.015], "1": [-0.0308, 0.0846, -0.015], "2": [-0.0707, -0.0778, -0.015]}


@dataclass(frozen=True)
class FlightSpec:
    """Initial state and coefficients of the simulated throw (SI; quaternion body→world (w, x, y, z),
    body-frame angular velocity [rad/s])."""

    name: str = "synthetic"
    position: tuple = (0.0, 0.0, 1.2)
    velocity: tuple = (13.0, 0.0, 1.5)
    quaternion: tuple = (0.0, 1.0, 0.0, 0.0)
    omega_body: tuple = (0.0, 0.0, 55.0)
    coefficients: tuple = tuple(literature_coefficients("hummel2002").as_array())
    duration: float = 1.2

    def initial_state(self) -> np.ndarray:
        q = np.asarray(self.quaternion, float)
        q = q / np.linalg.norm(q)
        return np.concatenate([self.position, self.velocity, q, self.omega_body]).astype(float)


@dataclass(frozen=True)
class RenderCamera:
    """A synthetic camera: the calibrated model and its frame offset and brightness gain."""

    camera: Camera
    frame_offset: int = 0
    gain: float = 1.0


@dataclass(frozen=True)
class ImagingSpec:
    """Imaging model (see module docstring). Intensities in DN, times in s."""

    bit_depth: int = 8
    background: float = 6.0
    peak: float = 200.0
    psf_sigma_px: float = 0.7
    marker_diameter: float = 0.02
    exposure_s: float = 0.0005
    blur_samples: int = 5
    noise_sigma: float = 1.5
    shot_noise_gain: float = 0.0
    noise_region: str = "full"
    drop_rate: float = 0.0
    occlusion: bool = True
    min_view_elevation_deg: float = 5.0

    def __post_init__(self):
        if self.bit_depth not in (8, 16):
            raise ValueError("imaging.bit_depth must be 8 or 16")
        if self.noise_region not in ("full", "windows"):
            raise ValueError("imaging.noise_region must be 'full' or 'windows'")
        if self.blur_samples < 1:
            raise ValueError("imaging.blur_samples must be ≥ 1")
        if not 0 <= self.drop_rate < 1:
            raise ValueError("imaging.drop_rate must be in [0, 1)")

    @property
    def max_dn(self) -> int:
        return 2 ** self.bit_depth - 1


@dataclass(frozen=True)
class RenderSpec:
    """Everything needed to render: flight, markers (id → body position, m), cameras, imaging, frame
    rate [Hz], time of reference frame 0 [s] and the random seed."""

    flight: FlightSpec
    cameras: tuple
    markers: dict = field(default_factory=lambda: dict(DEFAULT_MARKERS))
    imaging: ImagingSpec = ImagingSpec()
    fps: float = 120.0
    t0: float = 0.0
    seed: int = 0

    @property
    def n_frames(self) -> int:
        return int(math.floor(self.flight.duration * self.fps + 1e-9)) + 1

    @property
    def marker_ids(self) -> list:
        return list(self.markers)

    @property
    def layout(self) -> np.ndarray:
        return np.array([self.markers[m] for m in self.markers], float)


class Renderer:
    """Renders frames on demand and holds the ground truth.

    Truth arrays (reference frames f = 0..F−1, markers m, cameras c): ``times`` (F,) [s];
    ``xyz`` (F, M, 3) [m] at the frame times; ``uv`` (C, F, M, 2) [px]: the mean projected position
    over the exposure (the expected blob centroid); ``visible`` (C, F, M): in front, in the image and
    not occluded; ``recorded`` (C, F): the camera has a frame there (frame offsets); ``dropped`` (C, F);
    ``sigma_px`` (C, F, M). A marker appears in camera c's footage where ``seen`` (C, F, M) is true.
    """

    def __init__(self, spec: RenderSpec):
        self.spec = spec
        im = spec.imaging
        F, S = spec.n_frames, im.blur_samples
        self.times = spec.t0 + np.arange(F) / spec.fps
        offs = (np.arange(S) + 0.5) / S - 0.5 if S > 1 else np.zeros(1)
        sub_t = (self.times[:, None] + offs[None, :] * im.exposure_s).ravel()
        all_t = np.concatenate([self.times, sub_t])
        order = np.argsort(all_t, kind="stable")
        t_sorted = all_t[order]
        # the initial state holds at the start of frame 0's exposure
        tr = simulate(spec.flight.initial_state(), np.asarray(spec.flight.coefficients, float), t_sorted,
                      t0=float(t_sorted[0]), marker_body=spec.layout)
        if not tr.ok[0]:
            raise VideoInputError(f"render: flight simulation failed ({tr.failure_reasons()[0]})")
        inv = np.empty_like(order)
        inv[order] = np.arange(len(order))
        markers = tr.markers[0][inv]
        states = tr.states[0][inv]
        self.xyz = markers[:F]                              # (F, M, 3)
        self.states = states[:F]
        sub = markers[F:].reshape(F, S, -1, 3)              # (F, S, M, 3)
        top = -quat_to_matrix(states[:F, 6:10])[:, :, 2]    # (F, 3) outward normal of the top face
        C, M = len(spec.cameras), len(spec.markers)
        self.uv_sub = np.full((C, F, S, M, 2), np.nan)
        self.uv = np.full((C, F, M, 2), np.nan)
        self.visible = np.zeros((C, F, M), bool)
        self.sigma_px = np.full((C, F, M), np.nan)
        self.dropped = np.zeros((C, F), bool)
        self.recorded = np.zeros((C, F), bool)   # the camera has a frame at this reference frame
        sin_min = math.sin(math.radians(im.min_view_elevation_deg))
        for c, rc in enumerate(spec.cameras):
            cam = rc.camera
            p = cam.project(sub)                            # (F, S, M, 2)
            self.uv_sub[c] = p
            self.uv[c] = p.mean(axis=1)
            z = cam.depth(self.xyz)                         # (F, M)
            f = cam.K[0, 0]
            with np.errstate(invalid="ignore", divide="ignore"):
                self.sigma_px[c] = np.sqrt(im.psf_sigma_px ** 2 + (f * im.marker_diameter / (4 * z)) ** 2)
            vis = (z > 0) & np.all(np.isfinite(p), axis=(1, 3)) & np.all(cam.in_image(p, margin=0.0), axis=1)
            if im.occlusion:
                view = cam.center[None, None, :] - self.xyz
                elev = np.einsum("fmk,fk->fm", view, top) / np.linalg.norm(view, axis=2)
                vis &= elev > sin_min
            self.visible[c] = vis
            rng = np.random.default_rng([spec.seed, 7, c])
            self.dropped[c] = rng.random(F) < im.drop_rate
            first, last = self.frame_range(c)
            self.recorded[c, first + rc.frame_offset:last + rc.frame_offset + 1] = True

    @property
    def seen(self) -> np.ndarray:
        """(C, F, M): the marker is rendered in camera c's frame (visible, recorded, not dropped)."""
        return self.visible & (self.recorded & ~self.dropped)[:, :, None]

    # -- frames ------------------------------------------------------------------------------------------
    def frame_range(self, c: int) -> tuple[int, int]:
        """Camera frame indices i (first, last) that show the flight (reference frames 0..F−1)."""
        k = self.spec.cameras[c].frame_offset
        return max(0, -k), self.spec.n_frames - 1 - k

    def render(self, c: int, i: int) -> np.ndarray | None:
        """Camera c's frame i (None if dropped or outside the flight)."""
        spec, im = self.spec, self.spec.imaging
        rc = spec.cameras[c]
        f = i + rc.frame_offset
        first, last = self.frame_range(c)
        if i < first or i > last or self.dropped[c, f]:
            return None
        w, h = rc.camera.image_size
        dtype = np.uint8 if im.bit_depth == 8 else np.uint16
        rng = np.random.default_rng([spec.seed, 11, c, f])
        vis = np.flatnonzero(self.visible[c, f])
        if im.noise_region == "full":
            canvas = np.full((h, w), im.background, np.float32)
            x0 = y0 = 0
            x1, y1 = w, h
        else:
            if len(vis) == 0:
                return np.full((h, w), int(round(min(im.background, im.max_dn))), dtype)
            pts = self.uv_sub[c, f][:, vis].reshape(-1, 2)
            r = int(math.ceil(5 * np.nanmax(self.sigma_px[c, f, vis]))) + 8
            x0, y0 = max(int(np.floor(pts[:, 0].min())) - r, 0), max(int(np.floor(pts[:, 1].min())) - r, 0)
            x1, y1 = min(int(np.ceil(pts[:, 0].max())) + r + 1, w), min(int(np.ceil(pts[:, 1].max())) + r + 1, h)
            canvas = np.full((y1 - y0, x1 - x0), im.background, np.float32)
        for m in vis:
            sig = self.sigma_px[c, f, m]
            p = self.uv_sub[c, f, :, m]                     # (S, 2)
            r = int(math.ceil(5 * sig)) + 1
            bx0 = max(int(np.floor(p[:, 0].min())) - r, x0)
            by0 = max(int(np.floor(p[:, 1].min())) - r, y0)
            bx1 = min(int(np.ceil(p[:, 0].max())) + r + 1, x1)
            by1 = min(int(np.ceil(p[:, 1].max())) + r + 1, y1)
            if bx1 <= bx0 or by1 <= by0:
                continue
            ex, ey = pixel_integrated_gaussian(p[:, 0], p[:, 1], np.full(len(p), sig), bx0, bx1, by0, by1)
            flux = rc.gain * im.peak * 2 * math.pi * sig * sig
            canvas[by0 - y0:by1 - y0, bx0 - x0:bx1 - x0] += (flux / len(p)) * (ey.T @ ex).astype(np.float32)
        if im.noise_sigma > 0 or im.shot_noise_gain > 0:
            var = np.full(canvas.shape, im.noise_sigma ** 2, np.float32)
            if im.shot_noise_gain > 0:
                var += np.maximum(canvas - im.background, 0) / im.shot_noise_gain
            canvas += np.sqrt(var) * rng.standard_normal(canvas.shape, dtype=np.float32)
        np.clip(np.rint(canvas, out=canvas), 0, im.max_dn, out=canvas)
        if im.noise_region == "full":
            return canvas.astype(dtype)
        out = np.full((h, w), int(round(min(im.background, im.max_dn))), dtype)
        out[y0:y1, x0:x1] = canvas.astype(dtype)
        return out

    def source(self, c: int) -> ArrayFrames:
        """Camera c's footage as a frame source (rendered on demand)."""
        first, last = self.frame_range(c)
        return ArrayFrames(lambda i, c=c: self.render(c, i), first, last, f"rendered camera {self.camera_names[c]}")

    @property
    def camera_names(self) -> list:
        return [rc.camera.name for rc in self.spec.cameras]

    @property
    def cameras(self) -> list:
        return [rc.camera for rc in self.spec.cameras]

    # -- output ------------------------------------------------------------------------------------------
    def write_truth(self, path) -> None:
        """Marker file (docs/data-formats.md) of the true positions (every frame and marker) with ``n_cameras``: the
        number of cameras that rendered the marker in that frame (recorded, not dropped, visible)."""
        spec = self.spec
        n_cam = self.seen.sum(axis=0)
        Path(path).parent.mkdir(parents=True, exist_ok=True)
        with open(path, "w", newline="") as fh:
            w = csv.writer(fh, lineterminator="\n")
            w.writerow(["flight", "t", "marker", "x", "y", "z", "n_cameras"])
            for f in range(spec.n_frames):
                for m, mid in enumerate(spec.marker_ids):
                    x, y, z = self.xyz[f, m]
                    w.writerow([spec.flight.name, f"{self.times[f]:.9g}", mid, f"{x:.9f}", f"{y:.9f}", f"{z:.9f}",
                                int(n_cam[f, m])])

    def write_truth_2d(self, path) -> None:
        """Per camera, frame and marker: expected centroid (OpenCV px), visibility and dropped flag."""
        spec = self.spec
        Path(path).parent.mkdir(parents=True, exist_ok=True)
        with open(path, "w", newline="") as fh:
            w = csv.writer(fh, lineterminator="\n")
            w.writerow(["camera", "camera_frame", "frame", "t", "marker", "u", "v", "visible", "recorded", "dropped"])
            for c, rc in enumerate(spec.cameras):
                for f in range(spec.n_frames):
                    for m, mid in enumerate(spec.marker_ids):
                        u, v = self.uv[c, f, m]
                        w.writerow([rc.camera.name, f - rc.frame_offset, f, f"{self.times[f]:.9g}", mid,
                                    f"{u:.6f}", f"{v:.6f}", int(self.visible[c, f, m]), int(self.recorded[c, f]),
                                    int(self.dropped[c, f])])

    def write_footage(self, folder, fmt: str = "png", progress: bool = True) -> dict:
        """Write every camera's frames: ``folder/<camera>/<camera>_%06d.png`` (dropped frames are
        missing files) or ``folder/<camera>.avi`` (lossless FFV1; dropped frames are black).
        Returns {camera: source string relative to ``folder``}."""
        from tqdm import tqdm

        folder = Path(folder)
        folder.mkdir(parents=True, exist_ok=True)
        sources = {}
        total = sum(self.frame_range(c)[1] - self.frame_range(c)[0] + 1 for c in range(len(self.spec.cameras)))
        bar = tqdm(total=total, desc="render", unit="frame", disable=not progress)
        for c, name in enumerate(self.camera_names):
            first, last = self.frame_range(c)
            w, h = self.spec.cameras[c].camera.image_size
            if fmt == "png":
                d = folder / name
                d.mkdir(parents=True, exist_ok=True)
                for old in d.glob(f"{name}_*.png"):
                    old.unlink()
                for i in range(first, last + 1):
                    img = self.render(c, i)
                    if img is not None:
                        cv2.imwrite(str(d / f"{name}_{i:06d}.png"), img)
                    bar.update(1)
                sources[name] = f"{name}/{name}_%06d.png"
            elif fmt == "avi":
                if self.spec.imaging.bit_depth != 8:
                    raise VideoInputError("render: video output needs bit_depth 8 (use png for 16-bit)")
                path = folder / f"{name}.avi"
                wr = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"FFV1"), float(self.spec.fps), (w, h), False)
                if not wr.isOpened():
                    raise VideoInputError(f"render: OpenCV cannot write {path} (FFV1)")
                black = np.zeros((h, w), np.uint8)
                for i in range(0, last + 1):  # a video starts at camera frame 0
                    img = self.render(c, i) if i >= first else None
                    wr.write(black if img is None else img)
                    bar.update(1 if i >= first else 0)
                wr.release()
                sources[name] = f"{name}.avi"
            else:
                raise VideoInputError(f"render: unknown footage format {fmt!r} (png or avi)")
        bar.close()
        return sources


# ---------------------------------------------------------------------------------------------------
# configuration
# ---------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class RenderOutput:
    folder: Path
    footage_format: str = "png"
    calibration: str = "cameras.yaml"
    truth: str = "truth.csv"
    truth_2d: str = "truth_2d.csv"


def _coefficients(sec: Section, name: str):
    v = sec.raw(name, "hummel2002")
    if isinstance(v, str):
        if v not in LITERATURE:
            raise sec.error(name, f"unknown coefficient set {v!r} (known: {sorted(LITERATURE)})")
        return tuple(literature_coefficients(v).as_array())
    if isinstance(v, dict):
        sub = Section(sec.path, v, sec.key(name))
        vals = tuple(sub.number(n, required=True) for n in COEFFICIENT_NAMES)
        sub.finish()
        return vals
    raise sec.error(name, "must be a literature set name or a mapping of the ten coefficients")


def parse_render_config(path, output_dir=None) -> tuple[RenderSpec, RenderOutput]:
    """Read a render YAML (format in ``bayes_disc/video/README.md``)."""
    path = Path(path)
    sec = Section(path, load_yaml(path))
    seed = sec.number("seed", 0, integer=True, nonnegative=True)
    fps = sec.number("fps", 120.0, positive=True)
    t0 = sec.number("t0", 0.0)
    fs = sec.section("flight", required=True)
    if fs.has("quaternion") and fs.has("attitude_deg"):
        raise fs.error("attitude_deg", "give either quaternion or attitude_deg, not both")
    if fs.has("attitude_deg"):
        a = fs.section("attitude_deg")
        q = attitude_from_yaw_pitch_roll(math.radians(a.number("yaw", 0.0)), math.radians(a.number("pitch", 0.0)),
                                         math.radians(a.number("roll", 0.0)))
        a.finish()
    else:
        q = fs.vector("quaternion", 4, [0.0, 1.0, 0.0, 0.0])
        if np.linalg.norm(q) == 0:
            raise fs.error("quaternion", "must not be zero")
    flight = FlightSpec(name=fs.string("name", path.stem), position=tuple(fs.vector("position", 3, [0, 0, 1.2])),
                        velocity=tuple(fs.vector("velocity", 3, [13.0, 0.0, 1.5])), quaternion=tuple(q),
                        omega_body=tuple(fs.vector("omega_body", 3, [0.0, 0.0, 55.0])),
                        coefficients=_coefficients(fs, "coefficients"),
                        duration=fs.number("duration", 1.2, positive=True))
    fs.finish()
    markers = _markers(sec)
    ims = sec.section("imaging")
    try:
        imaging = ImagingSpec(
            bit_depth=ims.number("bit_depth", 8, integer=True), background=ims.number("background", 6.0, nonnegative=True),
            peak=ims.number("peak", 200.0, positive=True), psf_sigma_px=ims.number("psf_sigma_px", 0.7, positive=True),
            marker_diameter=ims.number("marker_diameter", 0.02, nonnegative=True),
            exposure_s=ims.number("exposure_s", 0.0005, nonnegative=True),
            blur_samples=ims.number("blur_samples", 5, integer=True, minimum=1),
            noise_sigma=ims.number("noise_sigma", 1.5, nonnegative=True),
            shot_noise_gain=ims.number("shot_noise_gain", 0.0, nonnegative=True),
            noise_region=ims.string("noise_region", "full", choices=("full", "windows")),
            drop_rate=ims.number("drop_rate", 0.0, nonnegative=True, maximum=0.99),
            occlusion=ims.boolean("occlusion", True),
            min_view_elevation_deg=ims.number("min_view_elevation_deg", 5.0, minimum=0, maximum=89))
    except ValueError as e:
        if isinstance(e, VideoInputError):
            raise
        raise VideoInputError(f"{path}: key 'imaging': {e}") from None
    ims.finish()
    cs = sec.section("cameras", required=True)
    cams = []
    for name in cs.keys():
        c = cs.section(name)
        try:
            cam = look_at(str(name), c.vector("position", 3, required=True), c.vector("look_at", 3, required=True),
                          c.number("focal_px", required=True, positive=True),
                          c.vector("image_size", 2, [1280, 1024], integer=True), up=c.vector("up", 3, [0, 0, 1]),
                          principal_point=c.vector("principal_point", 2), dist=c.vector("dist", None, []))
        except ValueError as e:
            if isinstance(e, VideoInputError):
                raise
            raise VideoInputError(f"{path}: key 'cameras.{name}': {e}") from None
        cams.append(RenderCamera(cam, c.number("frame_offset", 0, integer=True), c.number("gain", 1.0, positive=True)))
        c.finish()
    if not cams:
        raise sec.error("cameras", "no cameras defined")
    os_ = sec.section("output")
    folder_key = Path(os_.string("folder", "."))
    if output_dir is not None:
        folder = Path(output_dir)
    else:
        folder = folder_key if folder_key.is_absolute() else path.parent / folder_key
    out = RenderOutput(folder, os_.string("footage", "png", choices=("png", "avi")),
                       os_.string("calibration", "cameras.yaml"), os_.string("truth", "truth.csv"),
                       os_.string("truth_2d", "truth_2d.csv"))
    os_.finish()
    sec.finish()
    return RenderSpec(flight, tuple(cams), markers, imaging, fps, t0, seed), out


def _markers(sec: Section) -> dict:
    raw = sec.raw("markers", DEFAULT_MARKERS)
    if not isinstance(raw, dict) or len(raw) < 3:
        raise sec.error("markers", "must map at least 3 marker ids to body positions [x, y, z] (m)")
    ms = Section(sec.path, raw, sec.key("markers"))
    out = {str(k): ms.vector(k, 3, required=True) for k in ms.keys()}
    ms.finish()
    return out


def run_render(path, output_dir=None, progress: bool = True) -> dict:
    """Render a config to disk: footage, camera file, truth files and ``render_info.json``."""
    spec, out = parse_render_config(path, output_dir)
    r = Renderer(spec)
    sources = r.write_footage(out.folder / "footage", out.footage_format, progress)
    write_camera_yaml(out.folder / out.calibration, r.cameras)
    r.write_truth(out.folder / out.truth)
    r.write_truth_2d(out.folder / out.truth_2d)
    info = {"flight": spec.flight.name, "fps": spec.fps, "t0": spec.t0, "n_frames": spec.n_frames, "seed": spec.seed,
            "cameras": {name: {"source": "footage/" + src, "frame_offset": rc.frame_offset,
                               "dropped_frames": int(r.dropped[c].sum()),
                               "visible_marker_frames": int(r.visible[c].sum())}
                        for c, (name, src, rc) in enumerate(zip(r.camera_names, sources.values(), spec.cameras))},
            "markers": spec.markers}
    (out.folder / "render_info.json").write_text(json.dumps(info, indent=2))
    return info
