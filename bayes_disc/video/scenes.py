"""Ready-made synthetic scenes for tests, benchmarks and examples.

:func:`standard_spec` is the rig of ``runs/video_demo/render.yaml``: a 15 m backhand (release at
(0, 0, 1.2) m, 13 m/s forward and 1.5 m/s up, 5° nose-up, spin 55 rad/s, Hummel 2002 coefficients) seen
by three 1280×1024 cameras at 120 Hz — two on masts either side of the flight line, one behind and
above the thrower — with lens distortion, frame offsets and one brighter camera whose near markers
saturate.
"""
from __future__ import annotations

import math
from dataclasses import replace

from ..physics import literature_coefficients
from ..physics.frames import attitude_from_yaw_pitch_roll
from .camera import look_at
from .render import DEFAULT_MARKERS, FlightSpec, ImagingSpec, RenderCamera, RenderSpec


def standard_rig(image_size=(1280, 1024)) -> tuple:
    """The three cameras of the demo (see module docstring)."""
    return (
        RenderCamera(look_at("cam1", [7.5, -12.0, 7.0], [7.5, -0.7, 1.5], 950, image_size,
                             dist=[-0.12, 0.05, 0.0005, -0.0003, -0.01])),
        RenderCamera(look_at("cam2", [7.5, 11.0, 8.0], [7.5, -0.7, 1.5], 950, image_size,
                             dist=[-0.10, 0.03, 0.0, 0.0, 0.0]), frame_offset=3),
        RenderCamera(look_at("cam3", [-4.0, -3.0, 6.0], [8.0, -0.7, 1.5], 1000, image_size,
                             dist=[0.04, 0.0, 0.0, 0.0, 0.0]), frame_offset=-2, gain=1.6),
    )


def standard_flight(duration: float = 1.58, name: str = "video_demo") -> FlightSpec:
    """The demo throw (≈ 15 m downrange after 1.58 s)."""
    q = attitude_from_yaw_pitch_roll(0.0, math.radians(5.0), 0.0)
    return FlightSpec(name=name, position=(0.0, 0.0, 1.2), velocity=(13.0, 0.0, 1.5), quaternion=tuple(q),
                      omega_body=(0.0, 0.0, 55.0),
                      coefficients=tuple(literature_coefficients("hummel2002").as_array()), duration=duration)


def standard_spec(seed: int = 2024, duration: float = 1.58, **imaging) -> RenderSpec:
    """RenderSpec of the demo; keyword arguments override :class:`ImagingSpec` fields (defaults as in
    the demo: peak 180 DN, noise 1.5 DN in windows around the markers, 1 % dropped frames)."""
    base = ImagingSpec(bit_depth=8, background=6.0, peak=180.0, psf_sigma_px=0.7, marker_diameter=0.02,
                       exposure_s=0.0005, blur_samples=5, noise_sigma=1.5, noise_region="windows", drop_rate=0.01,
                       occlusion=True, min_view_elevation_deg=5.0)
    return RenderSpec(flight=standard_flight(duration), cameras=standard_rig(), markers=dict(DEFAULT_MARKERS),
                      imaging=replace(base, **imaging), fps=120.0, t0=0.0, seed=seed)
