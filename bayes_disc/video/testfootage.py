"""Test footage of a known flight, made without :mod:`.render`, for checking a tracking setup.

``bayes-disc test-footage FOLDER`` writes what a three-camera recording session leaves behind — image
sequences, an 11-coefficient DLT calibration in DLTdv's convention and a plain ``track.yaml`` — together
with the truth, so that ``bayes-disc track FOLDER/track.yaml`` can be scored against it (``truth.csv``,
``truth_2d.csv``, ``truth.json``). Its imaging model differs on purpose from the renderer's, so that the
tracker is not tested only on the pictures of its own author:

- **cameras**: 3×4 DLT matrices (skew and unequal pixel scales, no lens distortion), written as
  DLTdv coefficients (origin bottom-left, first pixel 1, world in mm);
- **flight**: an analytic path x(t) = p₀ + v₀ t + ½ a t², banking and pitching slowly, spinning at
  ``spin`` rad/s with a small wobble — no simulator of this package is used; or (:class:`TabulatedFlight`)
  marker positions given densely in time, e.g. a flight ``bayes-disc synth`` simulated with known
  coefficients, so that footage of it can be tracked and sampled against that truth;
- **markers**: round Gaussian spots sampled at pixel centres (not integrated over the pixel) with a
  width σ drawn per marker and varied from frame to frame within ``sigma_px``; flux from a marker gain,
  a camera gain, the view angle onto the top face and a per-frame flicker, so that the brightness of a
  marker changes by about ×2 over a flight and between markers;
- **exposure smear**: ``smear_samples`` positions spread evenly over the exposure ``exposure_s``;
- **scene**: a pedestal, a bright static patch crossed by the flight in the first camera, and a pole
  in front of the flight in two cameras (brief occlusions, partial at their edges);
- **noise**: read noise and shot noise, rounding and clipping to 8 bits;
- **timing**: reference frame f is stamped t_f = t0 + f / fps, the middle of its exposure
  (``timestamps: mid-exposure``) or its start (``exposure-start``). Camera c's frame i is exposed at
  reference frame i + k_c + δ_c: an integer frame offset k_c (a camera started late has k_c > 0) and
  a sub-frame delay δ_c (|δ_c| ≤ ½). ``truth.csv`` holds the positions at the middle of each reference
  exposure, t_f (+ exposure/2 with ``exposure-start``).

Everything is drawn from ``numpy.random.default_rng`` seeded with ``seed``: the same spec gives the
same files.
"""
from __future__ import annotations

import csv
import json
import math
from dataclasses import dataclass, field, replace
from pathlib import Path

import cv2
import numpy as np
import yaml

DEFAULT_MARKERS = {"0": [0.100, 0.000, -0.015], "1": [-0.0308, 0.0846, -0.015], "2": [-0.0707, -0.0778, -0.015]}
TIMESTAMPS = ("mid-exposure", "exposure-start")


@dataclass(frozen=True)
class TestCamera:
    """One camera of the test footage.

    dlt: the 11 DLT coefficients L1..L11 in DLTdv pixels (origin bottom-left, first pixel centre at 1)
    and world millimetres; image_size (width, height) [px]; frame_offset k and subframe δ [frames]:
    camera frame i is exposed at reference frame i + k + δ; gain: brightness factor; patch: a bright
    static rectangle (x0, y0, x1, y1, level DN) in image pixels or None; pole: an opaque vertical bar
    (x_centre, half_width, level DN) or None.
    """

    __test__ = False  # a footage class, not a test case for pytest

    name: str
    dlt: tuple
    image_size: tuple
    frame_offset: int = 0
    subframe: float = 0.0
    gain: float = 1.0
    patch: tuple | None = None
    pole: tuple | None = None


@dataclass(frozen=True)
class TestFlight:
    """Analytic flight: centre p0 + v0 t + ½ a t² [m]; bank and pitch angles roll0 + roll_rate t and
    pitch0 + pitch_rate t [rad]; spin [rad/s] about the disc's axis; wobble amplitude [rad] at half the
    spin rate; duration [s] is set by the spec's frame count."""

    __test__ = False  # a footage class, not a test case for pytest

    position: tuple = (0.0, 0.0, 1.3)
    velocity: tuple = (13.0, 0.4, 2.2)
    acceleration: tuple = (-2.0, 0.3, -3.6)
    roll0: float = -0.10
    roll_rate: float = 0.25
    pitch0: float = 0.10
    pitch_rate: float = 0.05
    spin: float = 50.0
    wobble: float = 0.03


@dataclass(frozen=True, eq=False)
class TabulatedFlight:
    """A flight given by its world marker positions ``xyz`` (T, M, 3) [m], in the spec's marker order, at
    ``times`` (T,) [s] on the footage's clock (the clock of the spec's ``t0`` and of ``truth.csv``; for a
    simulated flight, time from release), strictly increasing and dense enough for a cubic spline through each
    coordinate (≥ 20 samples per radian of spin: a simulation at 2400 Hz for spins up to 50 rad/s puts the
    spline within 10⁻⁹ m). Footage may only ask for times inside the table."""

    __test__ = False  # a footage class, not a test case for pytest

    times: np.ndarray
    xyz: np.ndarray

    def __post_init__(self):
        from scipy.interpolate import CubicSpline
        t, X = np.asarray(self.times, float), np.asarray(self.xyz, float)
        if t.ndim != 1 or X.shape[:1] != t.shape or X.ndim != 3 or X.shape[2] != 3:
            raise ValueError(f"a tabulated flight needs times (T,) and xyz (T, M, 3), got {t.shape} and {X.shape}")
        if t.size < 4 or np.any(np.diff(t) <= 0) or not np.all(np.isfinite(X)):
            raise ValueError("a tabulated flight needs ≥ 4 strictly increasing times and finite positions")
        object.__setattr__(self, "_spline", CubicSpline(t, X.reshape(t.size, -1), axis=0))

    def positions(self, t) -> np.ndarray:
        """World marker positions (T', M, 3) [m] at times t (T',) [s] on the footage's clock."""
        t = np.atleast_1d(np.asarray(t, float))
        lo, hi = float(self.times[0]), float(self.times[-1])
        if t.min() < lo - 1e-12 or t.max() > hi + 1e-12:
            raise ValueError(f"footage asks for the flight at {t.min():.4f}…{t.max():.4f} s, outside its table "
                             f"{lo:.4f}…{hi:.4f} s: start the footage later (t0) or make fewer frames")
        return self._spline(t).reshape(t.size, -1, 3)


#: a table this many radians of marker rotation per sample apart or more is too sparse for the spline
MAX_TABLE_TURN_RAD = 0.05


def tabulated_flight_from_markers(path, flight: str | None = None, markers=DEFAULT_MARKERS) -> TabulatedFlight:
    """A :class:`TabulatedFlight` from a marker file (docs/data-formats.md) holding one flight densely and
    without gaps, e.g. ``bayes-disc synth`` with ``sample_rate_hz: 2400``, ``noise_mm: 0``, ``dropout: 0``.

    Parameters
    ----------
    path : str or Path
        The marker file.
    flight : str, optional
        Which flight (needed when the file holds several).
    markers : dict
        {id: body position [m]} of the footage's markers; the file must hold exactly these ids.

    Returns
    -------
    TabulatedFlight
        The file's times [s] (for ``synth``, from the release) and positions (T, M, 3) [m].

    Raises
    ------
    VideoInputError
        The file cannot be read, the flight is not in it, a position is missing, or the samples are too far
        apart for the spline (more than :data:`MAX_TABLE_TURN_RAD` of marker rotation between two).
    """
    from ..observation.markers import MarkerFileError, flights_from_table, read_marker_csv
    from .errors import VideoInputError
    ids = list(markers)
    try:
        obs = flights_from_table(read_marker_csv(path, ids), ids, source=str(path))
    except (MarkerFileError, OSError) as e:
        raise VideoInputError(f"{path}: {e}") from None
    names = [f.name for f in obs]
    if flight is None and len(obs) > 1:
        raise VideoInputError(f"{path}: holds flights {names}; name the one to film")
    chosen = obs[0] if flight is None else next((f for f in obs if f.name == flight), None)
    if chosen is None:
        raise VideoInputError(f"{path}: no flight {flight!r} (it holds {names})")
    if not np.all(np.isfinite(chosen.positions)):
        raise VideoInputError(f"{path}: flight {chosen.name} has missing positions; film a flight without dropout "
                              "or noise")
    d = chosen.positions[:, 1] - chosen.positions[:, 0]
    turn = np.arccos(np.clip(np.sum(d[1:] * d[:-1], axis=1) / np.linalg.norm(d[1:], axis=1)
                             / np.linalg.norm(d[:-1], axis=1), -1.0, 1.0))
    if turn.max() > MAX_TABLE_TURN_RAD:
        raise VideoInputError(f"{path}: flight {chosen.name}'s markers turn up to {turn.max():.2f} rad between samples, "
                              f"more than {MAX_TABLE_TURN_RAD} for the spline: synthesize it at a higher sample_rate_hz")
    return TabulatedFlight(chosen.times, chosen.positions)


@dataclass(frozen=True)
class TestFootageSpec:
    """Everything the footage is made from (times in s, intensities in DN, pixels in px)."""

    __test__ = False  # a footage class, not a test case for pytest

    cameras: tuple
    flight: TestFlight = TestFlight()
    markers: dict = field(default_factory=lambda: dict(DEFAULT_MARKERS))
    name: str = "test_flight"
    seed: int = 1
    fps: float = 120.0
    t0: float = 0.0
    n_frames: int = 151
    exposure_s: float = 0.001
    timestamps: str = "mid-exposure"
    smear_samples: int = 9
    sigma_px: tuple = (1.3, 2.0)
    flux_dn: float = 2300.0
    marker_gains: tuple = (0.72, 1.0, 1.35)
    flicker: float = 0.12
    pedestal_dn: float = 8.0
    read_noise_dn: float = 2.0
    electrons_per_dn: float = 6.0
    min_view_elevation_deg: float = 8.0

    def __post_init__(self):
        if self.timestamps not in TIMESTAMPS:
            raise ValueError(f"timestamps must be one of {TIMESTAMPS}, got {self.timestamps!r}")
        if len(self.cameras) < 2 or self.n_frames < 3 or self.smear_samples < 1:
            raise ValueError("test footage needs ≥ 2 cameras, ≥ 3 frames and ≥ 1 smear sample")
        if any(abs(c.subframe) > 0.5 for c in self.cameras):
            raise ValueError("a camera's subframe delay must lie in [-0.5, 0.5] frames")

    @property
    def layout(self) -> np.ndarray:
        """Body-frame marker positions (M, 3) [m]."""
        return np.array([self.markers[m] for m in self.markers], float)

    def exposure_centre(self, frame) -> np.ndarray:
        """Middle of reference frame ``frame``'s exposure [s] (a camera adds its δ / fps)."""
        shift = 0.5 * self.exposure_s if self.timestamps == "exposure-start" else 0.0
        return self.t0 + np.asarray(frame, float) / self.fps + shift


# ---------------------------------------------------------------------------------------------------
# geometry
# ---------------------------------------------------------------------------------------------------
def dlt_camera(position, target, focal_px: float, image_size, aspect: float = 1.0, skew: float = 0.0,
               principal_offset=(0.0, 0.0)) -> tuple:
    """11 DLT coefficients (DLTdv pixels, world mm) of a camera at ``position`` [m] looking at ``target``
    [m] with image up along +z; focal length [px], pixel aspect fy/fx, skew [px] and principal-point
    offset from the image centre [px]."""
    C = np.asarray(position, float)
    z = np.asarray(target, float) - C
    z /= np.linalg.norm(z)
    x = np.cross(z, [0.0, 0.0, 1.0])
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    R = np.stack([x, y, z])
    w, h = image_size
    cx, cy = (w - 1) / 2 + principal_offset[0], (h - 1) / 2 + principal_offset[1]
    K = np.array([[focal_px, skew, cx], [0.0, focal_px * aspect, cy], [0.0, 0.0, 1.0]])
    P = K @ np.hstack([R, (-R @ C)[:, None]])               # OpenCV pixels, world m
    flip = np.array([[1.0, 0.0, 1.0], [0.0, -1.0, h], [0.0, 0.0, 1.0]])  # → origin bottom-left, first pixel 1
    P = flip @ P @ np.diag([1e-3, 1e-3, 1e-3, 1.0])          # world mm
    return tuple((P / P[2, 3]).ravel()[:11])


def project(camera: TestCamera, X) -> tuple[np.ndarray, np.ndarray]:
    """Image-array pixels (..., 2) (column, row; pixel centres at integers, row 0 at the top) and depth
    sign (...) of world points X (..., 3) [m] through the camera's DLT."""
    L = np.append(np.asarray(camera.dlt, float), 1.0).reshape(3, 4)
    Xmm = np.asarray(X, float) * 1e3
    hom = Xmm @ L[:, :3].T + L[:, 3]
    u = hom[..., 0] / hom[..., 2]
    v = hom[..., 1] / hom[..., 2]
    # in front of the camera: with the image's y axis flipped (DLTdv) a right-handed camera has det(L[:, :3]) of
    # the opposite sign to its depth scale
    front = np.sign(np.linalg.det(L[:, :3])) * hom[..., 2] < 0
    return np.stack([u - 1.0, camera.image_size[1] - v], axis=-1), front


def camera_centre(camera: TestCamera) -> np.ndarray:
    """Projection centre [m] of a DLT camera (null vector of P)."""
    L = np.append(np.asarray(camera.dlt, float), 1.0).reshape(3, 4)
    return -np.linalg.solve(L[:, :3], L[:, 3]) * 1e-3


def _rot(axis: int, a) -> np.ndarray:
    a = np.asarray(a, float)
    c, s = np.cos(a), np.sin(a)
    R = np.zeros(a.shape + (3, 3))
    i, j = [k for k in range(3) if k != axis]
    R[..., axis, axis] = 1.0
    R[..., i, i] = c
    R[..., j, j] = c
    R[..., i, j] = -s
    R[..., j, i] = s
    return R


def pose(flight: TestFlight, t) -> tuple[np.ndarray, np.ndarray]:
    """Disc centre (T, 3) [m] and body→world rotation (T, 3, 3) at times t (T,) [s] (t from release).
    The body z axis points down out of the bottom face (markers sit at body z < 0, on the top)."""
    t = np.atleast_1d(np.asarray(t, float))
    c = (np.asarray(flight.position) + np.outer(t, flight.velocity) + 0.5 * np.outer(t * t, flight.acceleration))
    roll = flight.roll0 + flight.roll_rate * t + flight.wobble * np.sin(0.5 * flight.spin * t)
    pitch = flight.pitch0 + flight.pitch_rate * t + flight.wobble * np.cos(0.5 * flight.spin * t)
    heading = math.atan2(flight.velocity[1], flight.velocity[0])
    flat = np.diag([1.0, -1.0, -1.0])                     # right side up: body z down
    R = _rot(2, np.full_like(t, heading)) @ _rot(1, -pitch) @ _rot(0, roll) @ flat @ _rot(2, flight.spin * t)
    return c, R


def marker_positions(spec: TestFootageSpec, t) -> tuple[np.ndarray, np.ndarray]:
    """World marker positions (T, M, 3) [m] and top-face normals (T, 3) at times t (T,) [s]."""
    if isinstance(spec.flight, TabulatedFlight):
        X = spec.flight.positions(t)
        return X, top_normals(X, spec.layout)
    c, R = pose(spec.flight, np.asarray(t, float) - spec.t0)
    X = np.einsum("tij,mj->tmi", R, spec.layout) + c[:, None, :]
    return X, -R[:, :, 2]


def top_normals(X: np.ndarray, layout: np.ndarray) -> np.ndarray:
    """Unit normals (T, 3) of the top face (body −z) from the first three markers' world positions X
    (T, M, 3) and their body positions ``layout`` (M, 3): a rotation keeps the sense of a cross product."""
    n = np.cross(X[:, 1] - X[:, 0], X[:, 2] - X[:, 0])
    sense = np.sign(np.cross(layout[1] - layout[0], layout[2] - layout[0]) @ [0.0, 0.0, -1.0])
    if sense == 0:
        raise ValueError("the first three markers are collinear or their plane contains the disc's axis")
    return sense * n / np.linalg.norm(n, axis=1, keepdims=True)


# ---------------------------------------------------------------------------------------------------
# truth and frames
# ---------------------------------------------------------------------------------------------------
def _band_fraction(u, sigma, pole) -> np.ndarray:
    """Fraction of a Gaussian spot's flux (centre column u, width σ, broadcast) behind a pole's band of
    pixel columns (centres within x_centre ± half_width, each covering ±½ px)."""
    if pole is None:
        return np.zeros(np.broadcast(u, sigma).shape)
    xc, hw = pole[0], pole[1]
    a = math.ceil(xc - hw) - 0.5
    b = math.floor(xc + hw) + 0.5
    from scipy.special import ndtr
    return ndtr((b - u) / sigma) - ndtr((a - u) / sigma)


class TestFootage:
    """Truth and frames of a :class:`TestFootageSpec`.

    Truth arrays (reference frames f = 0..F−1, cameras c, markers m): ``times`` (F,) middle of each
    reference exposure [s]; ``xyz`` (F, M, 3) [m] there; ``uv`` (C, F, M, 2) mean image position over
    the camera's own exposure (image-array pixels, OpenCV convention); ``sigma_px``, ``flux`` (C, F, M)
    spot width [px] and flux [DN·px²]; ``unoccluded`` (C, F, M) fraction of the flux not behind a pole;
    ``visible`` (C, F, M): in front, top face towards the camera, inside the image; ``recorded`` (C, F):
    the camera has a frame there; ``seen`` (C, F, M): visible, recorded, ≥ 95 % unoccluded and ≥ 3σ + 1 px
    from the image border — the positions a tracker can be asked to find.
    """

    __test__ = False  # a footage class, not a test case for pytest

    def __init__(self, spec: TestFootageSpec):
        self.spec = spec
        F, M, C, S = spec.n_frames, len(spec.markers), len(spec.cameras), spec.smear_samples
        rng = np.random.default_rng([spec.seed, 1])
        self.times = spec.exposure_centre(np.arange(F))
        self.xyz = marker_positions(spec, self.times)[0]
        shape = (C, F, M)
        self.uv_sub = np.full((C, F, S, M, 2), np.nan)
        self.uv, self.sigma_px, self.flux = np.full(shape + (2,), np.nan), np.zeros(shape), np.zeros(shape)
        self.unoccluded, self.visible = np.ones(shape), np.zeros(shape, bool)
        self.recorded = np.zeros((C, F), bool)
        lo, hi = spec.sigma_px
        base = rng.uniform(lo + 0.1 * (hi - lo), hi - 0.1 * (hi - lo), (C, M))
        phase = rng.uniform(0, 2 * np.pi, (C, M))
        gains = np.resize(np.asarray(spec.marker_gains, float), M) * rng.uniform(0.95, 1.05, M)
        offs = (np.arange(S) + 0.5) / S - 0.5 if S > 1 else np.zeros(1)
        f = np.arange(F)
        for c, cam in enumerate(spec.cameras):
            tc = self.times + cam.subframe / spec.fps                       # this camera's exposure centres
            Xs, normals = marker_positions(spec, (tc[:, None] + offs[None, :] * spec.exposure_s).ravel())
            Xs = Xs.reshape(F, S, M, 3)
            p, front = project(cam, Xs)
            self.uv_sub[c] = p
            self.uv[c] = p.mean(axis=1)
            Xc, nc = marker_positions(spec, tc)
            view = camera_centre(cam)[None, None, :] - Xc
            sin_elev = np.einsum("fmk,fk->fm", view, nc) / np.linalg.norm(view, axis=2)
            sig = base[c] + 0.15 * np.sin(2 * np.pi * f[:, None] / 37.0 + phase[c]) + rng.normal(0, 0.05, (F, M))
            self.sigma_px[c] = np.clip(sig, lo, hi)
            flick = 1 + spec.flicker * np.sin(2 * np.pi * 0.173 * f + 2.0 * c)[:, None] + rng.normal(0, 0.03, (F, M))
            self.flux[c] = (spec.flux_dn * cam.gain * gains[None, :] * (0.3 + 0.7 * np.clip(sin_elev, 0, 1)) * flick)
            w, h = cam.image_size
            inside = np.all((p[..., 0] > -0.5) & (p[..., 0] < w - 0.5) & (p[..., 1] > -0.5) & (p[..., 1] < h - 0.5), axis=1)
            self.visible[c] = np.all(front, axis=1) & inside & (sin_elev > math.sin(math.radians(spec.min_view_elevation_deg)))
            hidden = _band_fraction(p[..., 0], self.sigma_px[c][:, None, :], cam.pole).mean(axis=1)
            self.unoccluded[c] = 1.0 - hidden
            first, last = self.frame_range(c)
            self.recorded[c, first + cam.frame_offset:last + cam.frame_offset + 1] = True

    @property
    def camera_names(self) -> list:
        return [c.name for c in self.spec.cameras]

    @property
    def seen(self) -> np.ndarray:
        """(C, F, M): the positions a tracker can be asked to find (see the class docstring)."""
        m = 3 * self.sigma_px + 1
        ok = np.zeros_like(self.visible)
        for c, cam in enumerate(self.spec.cameras):
            w, h = cam.image_size
            u, v = self.uv[c, ..., 0], self.uv[c, ..., 1]
            with np.errstate(invalid="ignore"):
                ok[c] = (u >= m[c]) & (u <= w - 1 - m[c]) & (v >= m[c]) & (v <= h - 1 - m[c])
        return self.visible & ok & (self.unoccluded >= 0.95) & self.recorded[:, :, None]

    def frame_range(self, c: int) -> tuple[int, int]:
        """Camera c's first and last frame index (its frames cover reference frames 0..F−1)."""
        k = self.spec.cameras[c].frame_offset
        return max(0, -k), self.spec.n_frames - 1 - k

    def scene(self, c: int) -> np.ndarray:
        """Camera c's static scene (height, width) [DN]: pedestal and bright patch, without noise."""
        cam, spec = self.spec.cameras[c], self.spec
        w, h = cam.image_size
        img = np.full((h, w), spec.pedestal_dn, np.float32)
        if cam.patch is not None:
            x0, y0, x1, y1, level = cam.patch
            xs, ys = np.arange(w, dtype=np.float32), np.arange(h, dtype=np.float32)
            soft = lambda q, a, b: np.clip((q - a) / 4.0, 0, 1) * np.clip((b - q) / 4.0, 0, 1)  # noqa: E731
            img += float(level) * np.outer(soft(ys, y0, y1), soft(xs, x0, x1)).astype(np.float32)
        return img

    def render(self, c: int, i: int) -> np.ndarray | None:
        """Camera c's frame i (uint8, height × width), or None outside its recording."""
        spec, cam = self.spec, self.spec.cameras[c]
        first, last = self.frame_range(c)
        if i < first or i > last:
            return None
        f = i + cam.frame_offset
        img = self.scene(c)
        h, w = img.shape
        for m in np.flatnonzero(self.visible[c, f]):
            self._add_spot(img, self.uv_sub[c, f, :, m], self.sigma_px[c, f, m], self.flux[c, f, m])
        if cam.pole is not None:
            xc, hw, level = cam.pole
            img[:, max(math.ceil(xc - hw), 0):min(math.floor(xc + hw) + 1, w)] = level
        rng = np.random.default_rng([spec.seed, 2, c, i])
        var = spec.read_noise_dn ** 2 + np.maximum(img, 0) / spec.electrons_per_dn
        img += np.sqrt(var) * rng.standard_normal(img.shape, dtype=np.float32)
        return np.clip(np.rint(img), 0, 255).astype(np.uint8)

    @staticmethod
    def _add_spot(img: np.ndarray, path: np.ndarray, sigma: float, flux: float) -> None:
        """Add a smeared Gaussian spot: ``path`` (S, 2) positions over the exposure, width σ [px], flux."""
        h, w = img.shape
        r = int(math.ceil(5 * sigma))
        x0, x1 = max(int(np.floor(path[:, 0].min())) - r, 0), min(int(np.ceil(path[:, 0].max())) + r + 1, w)
        y0, y1 = max(int(np.floor(path[:, 1].min())) - r, 0), min(int(np.ceil(path[:, 1].max())) + r + 1, h)
        if x1 <= x0 or y1 <= y0:
            return
        xs, ys = np.arange(x0, x1, dtype=float), np.arange(y0, y1, dtype=float)
        ex = np.exp(-0.5 * ((xs[None, :] - path[:, :1]) / sigma) ** 2)      # (S, nx)
        ey = np.exp(-0.5 * ((ys[None, :] - path[:, 1:]) / sigma) ** 2)      # (S, ny)
        amp = flux / (2 * np.pi * sigma * sigma * len(path))
        img[y0:y1, x0:x1] += (amp * ey.T @ ex).astype(np.float32)

    def source(self, c: int):
        """Camera c's frames as a frame source of :mod:`.footage` (rendered on demand)."""
        from .footage import ArrayFrames

        first, last = self.frame_range(c)
        return ArrayFrames(lambda i, c=c: self.render(c, i), first, last, f"test camera {self.camera_names[c]}")


# ---------------------------------------------------------------------------------------------------
# ready-made rigs
# ---------------------------------------------------------------------------------------------------
def standard_test_spec(size: str = "full", seed: int = 1, frame_offsets=(0, 0, 2), subframes=(0.0, 0.0, 0.0),
                       **changes) -> TestFootageSpec:
    """Three cameras around a throw: two on either side of the flight line, one behind and above the
    thrower; a bright patch behind the flight in the first camera, a pole in front of it in the first two.

    size ``full``: 1280×1024 px, 151 frames at 120 Hz (1.25 s, ≈ 15 m); ``small``: 640×512 px, 48 frames
    (0.39 s, ≈ 5 m) seen from closer. frame_offsets, subframes: k_c, δ_c per camera (the third camera
    starts two frames late by default). Keyword arguments replace fields of :class:`TestFootageSpec`
    (``flight``, ``n_frames``, ``t0``, …; the patch and poles are placed on the flight given).
    """
    if size == "full":
        n, wh, scale, focal = 151, (1280, 1024), 1.0, (1000.0, 970.0, 860.0)
    elif size == "small":
        n, wh, scale, focal = 48, (640, 512), 0.42, (560.0, 540.0, 400.0)
    else:
        raise ValueError(f"size must be 'full' or 'small', got {size!r}")
    mid = 7.5 * scale
    rig = [("camA", [mid, -10.0 * scale, 8.0 * scale + 1.3], [mid, 0.0, 1.4], 1.0, 0.4, (4.0, -6.0)),
           ("camB", [mid - 0.5, 9.5 * scale, 8.5 * scale + 1.3], [mid, 0.0, 1.4], 1.01, 0.0, (-5.0, 3.0)),
           ("camC", [mid - 2.5 * scale, -5.0 * scale, 12.0 * scale + 1.3], [mid + 1.5 * scale, 0.0, 1.3], 0.995, -0.3, (2.0, 5.0))]
    cams = tuple(TestCamera(name, dlt_camera(pos, tgt, f, wh, aspect, skew, pp), wh, int(k), float(d), gain)
                 for (name, pos, tgt, aspect, skew, pp), f, k, d, gain in
                 zip(rig, focal, frame_offsets, subframes, (1.0, 0.9, 1.15)))
    spec = TestFootageSpec(cameras=cams, seed=seed, **{"n_frames": n, **changes})
    return _with_scenery(spec)


def _with_scenery(spec: TestFootageSpec) -> TestFootageSpec:
    """Place the bright patch (first camera, behind the middle of the flight) and the poles (first camera
    at 30 % of the flight, second at 70 %) where the flight's image passes."""
    F = spec.n_frames
    cams = list(spec.cameras)
    centre = lambda cam, frac: project(cam, marker_positions(spec, spec.exposure_centre(frac * (F - 1)))[0][0].mean(0))[0]  # noqa: E731
    a = cams[0]
    u, v = centre(a, 0.5)
    w = a.image_size[0]
    cams[0] = replace(a, patch=(u - 0.08 * w, v - 0.05 * w, u + 0.08 * w, v + 0.02 * w, 70.0),
                      pole=(float(centre(a, 0.3)[0]), 0.006 * w, 30.0))
    b = cams[1]
    cams[1] = replace(b, pole=(float(centre(b, 0.7)[0]), 0.005 * b.image_size[0], 24.0))
    return replace(spec, cameras=tuple(cams))


# ---------------------------------------------------------------------------------------------------
# files
# ---------------------------------------------------------------------------------------------------
def track_config(spec: TestFootageSpec, sources: dict, calibration: str = "cameras_dlt.csv") -> dict:
    """A plain TRACK.yaml (as a mapping) for the footage: DLT calibration, sources, median background, no
    frame offsets (the tracker estimates them) and the timestamp convention of the footage."""
    return {"flight": spec.name, "fps": spec.fps, "t0": spec.t0,
            "markers": {k: [float(x) for x in v] for k, v in spec.markers.items()},
            "calibration": {"format": "dlt-csv", "file": calibration, "cameras": [c.name for c in spec.cameras],
                            "image_size": {c.name: list(c.image_size) for c in spec.cameras},
                            "origin": "bottom-left", "first_pixel": 1, "units": "mm"},
            "cameras": {name: {"source": src} for name, src in sources.items()},
            "timestamps": {"convention": spec.timestamps, "exposure_s": spec.exposure_s},
            "detection": {"background": "median"},
            "output": "tracks.csv"}


def write_truth(footage: TestFootage, folder: Path) -> None:
    """``truth.csv`` (marker file with ``n_cameras``: cameras that see the marker whole), ``truth_2d.csv``
    (per camera, frame and marker: OpenCV pixel position, width, flux, unoccluded fraction, flags)."""
    spec, seen = footage.spec, footage.seen
    n_cam = seen.sum(axis=0)
    with open(folder / "truth.csv", "w", newline="") as fh:
        w = csv.writer(fh, lineterminator="\n")
        w.writerow(["flight", "t", "marker", "x", "y", "z", "n_cameras"])
        for f in range(spec.n_frames):
            for m, mid in enumerate(spec.markers):
                w.writerow([spec.name, f"{footage.times[f]:.9g}", mid, *(f"{x:.9f}" for x in footage.xyz[f, m]),
                            int(n_cam[f, m])])
    with open(folder / "truth_2d.csv", "w", newline="") as fh:
        w = csv.writer(fh, lineterminator="\n")
        w.writerow(["camera", "camera_frame", "frame", "marker", "u", "v", "sigma_px", "flux", "unoccluded",
                    "visible", "recorded", "seen"])
        for c, cam in enumerate(spec.cameras):
            for f in range(spec.n_frames):
                for m, mid in enumerate(spec.markers):
                    u, v = footage.uv[c, f, m]
                    w.writerow([cam.name, f - cam.frame_offset, f, mid, f"{u:.5f}", f"{v:.5f}",
                                f"{footage.sigma_px[c, f, m]:.4f}", f"{footage.flux[c, f, m]:.1f}",
                                f"{footage.unoccluded[c, f, m]:.4f}", int(footage.visible[c, f, m]),
                                int(footage.recorded[c, f]), int(seen[c, f, m])])


def write_test_footage(spec: TestFootageSpec, folder, progress: bool = True) -> dict:
    """Write the footage (``footage/<camera>/<camera>_%05d.png``, each camera numbering its own frames
    from 0), ``cameras_dlt.csv``, ``track.yaml``, ``truth.csv``, ``truth_2d.csv`` and ``truth.json`` into
    ``folder``. Returns the contents of ``truth.json``."""
    from tqdm import tqdm

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    footage = TestFootage(spec)
    sources = {}
    total = sum(footage.frame_range(c)[1] - footage.frame_range(c)[0] + 1 for c in range(len(spec.cameras)))
    with tqdm(total=total, desc="test footage", unit="frame", disable=not progress) as bar:
        for c, cam in enumerate(spec.cameras):
            d = folder / "footage" / cam.name
            d.mkdir(parents=True, exist_ok=True)
            for old in d.glob(f"{cam.name}_*.png"):
                old.unlink()
            first, last = footage.frame_range(c)
            for i in range(first, last + 1):
                cv2.imwrite(str(d / f"{cam.name}_{i - first:05d}.png"), footage.render(c, i))
                bar.update(1)
            sources[cam.name] = f"footage/{cam.name}/{cam.name}_%05d.png"
    with open(folder / "cameras_dlt.csv", "w", newline="") as fh:
        w = csv.writer(fh, lineterminator="\n")
        w.writerow([c.name for c in spec.cameras])
        for row in np.array([c.dlt for c in spec.cameras]).T:
            w.writerow([repr(float(x)) for x in row])
    (folder / "track.yaml").write_text("# plain tracking configuration of the test footage: bayes-disc track track.yaml\n"
                                       + yaml.safe_dump(track_config(spec, sources), sort_keys=False, default_flow_style=None))
    write_truth(footage, folder)
    info = truth_info(footage)
    (folder / "truth.json").write_text(json.dumps(info, indent=2))
    return info


def truth_info(footage: TestFootage) -> dict:
    """Summary of the footage: timing, per-camera offsets and files, ranges of width and brightness."""
    spec = footage.spec
    cams = {}
    for c, cam in enumerate(spec.cameras):
        first, _ = footage.frame_range(c)
        vis = footage.visible[c]
        cams[cam.name] = {"frame_offset": cam.frame_offset + first, "subframe": cam.subframe,
                          "frames": int(footage.recorded[c].sum()),
                          "brightness_ratio": round(float(footage.flux[c][vis].max() / footage.flux[c][vis].min()), 3),
                          "occluded_positions": int(np.sum(vis & (footage.unoccluded[c] < 0.95)))}
    return {"flight": spec.name, "seed": spec.seed, "fps": spec.fps, "t0": spec.t0, "n_frames": spec.n_frames,
            "exposure_s": spec.exposure_s, "timestamps": spec.timestamps, "sigma_px": list(spec.sigma_px),
            "truth_time": "middle of each reference frame's exposure",
            "frame_offset_meaning": "file frame n of a camera is exposed at reference frame n + frame_offset + subframe",
            "positions_seen_by_two_cameras": int(np.sum(footage.seen.sum(axis=0) >= 2)), "cameras": cams}
