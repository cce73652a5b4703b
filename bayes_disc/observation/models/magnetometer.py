"""The magnetometer of an inertial logger: the Earth's field seen through the simulated attitude.

A logger fixed in the disc reads, in its sensor axes s (the tilt C of :mod:`.inertial`, shared with the
gyroscope and accelerometer),

    m_s(t_i) = C ⟨Rᵀ⟩_i B_w + h                                                             [µT]
    B_w = (H cos ψ, H sin ψ, −Z)                  (world axes: x, y horizontal, z up)
    ⟨Rᵀ⟩_i B_w = (1/w) ∫_{t_i − w}^{t_i} R(t)ᵀ B_w dt,   w = 2 T_m

with R(t) the simulated body→world rotation, H the horizontal strength of the Earth's field and Z its
downward vertical component [µT] (Z > 0 in the northern hemisphere; the dip is atan(Z/H)), ψ the
heading of the field's horizontal part in the simulation's world frame [rad], h the hard-iron offset
[µT] (the logger's own field, fixed in sensor axes) and t_i = (row_i − row_0) P the row's time on the
throw's clock: the same row period P as the gyroscope and accelerometer.

Why a window: the magnetometer samples on its own clock (flatball firmware: 100 Hz continuous mode,
T_m = 10 ms, each output the average of two conversions), and a row reads the latest output, taken
u ∈ [0, T_m) before the row. The two conversions sit at t_i − u and t_i − u − T_m; with the hold
phase u spread uniformly over the rows (the row and magnetometer clocks are not locked), their
expected value is the boxcar mean over [t_i − 2 T_m, t_i] above — a delay of T_m and an averaging that
shortens the rotating (transverse) field by sinc(ω T_m) (≈ 0.96 at 50 rad/s). The mean is computed by
four-point Gauss–Legendre quadrature of the simulated body-axis field (cubic interpolation on the
simulation grid); window nodes before release are read at the release attitude, and the first rows
whose nominal window reaches before release are not used (the hand's spin-up is not simulated).

Not modelled: the hold phase of each row (the sawtooth u_i, which depends on the two clocks' exact
ratio): its scatter about the mean enters the noise, mostly in the transverse axes (the field turns by
ω T_m ≈ 0.5 rad per magnetometer sample); soft-iron distortion and scale errors of the magnetometer
(a sphere, not an ellipsoid); fields of the disc's surroundings (the field is uniform and constant
over a throw); the magnetometer's own axis misalignment relative to the gyroscope (one tilt C for all).

Parameters — shared by the run's throws (one logger, one field): ``mag_field_horizontal`` H [µT],
prior N(20, 20²); ``mag_field_down`` Z [µT], prior N(40, 40²); ``mag_hard_iron_x…z`` h [µT], prior
N(0, 100²). Per throw: ``mag_heading`` ψ [rad], prior N(0, 10²) (flat over a turn: the simulated
heading of an inertial-only throw is arbitrary, so each throw has its own). Noise: two groups per
throw, axial (sensor z) and transverse (x, y), each σ integrated out (Jeffreys prior) as the
observation-model contract does.
"""
from __future__ import annotations

import numpy as np

from ...physics import TermParameter
from ...physics.frames import quat_to_matrix

#: the magnetometer's sample period T_m [s] (continuous mode, 100 Hz)
MAG_SAMPLE_PERIOD = 0.010
#: conversions averaged per output
MAG_AVERAGED = 2
#: width w of the averaging window [s]
MAG_WINDOW = MAG_AVERAGED * MAG_SAMPLE_PERIOD
#: Gauss–Legendre nodes on [0, 1] and weights of the window mean
_GL_X, _GL_W = np.polynomial.legendre.leggauss(4)
GL_NODES = 0.5 * (_GL_X + 1.0)
GL_WEIGHTS = 0.5 * _GL_W

MAG_SHARED_PARAMETERS = (
    TermParameter("mag_field_horizontal", "µT", "horizontal strength H of the Earth's field", 20.0, 20.0),
    TermParameter("mag_field_down", "µT", "downward vertical component Z of the Earth's field", 40.0, 40.0),
    TermParameter("mag_hard_iron_x", "µT", "magnetometer hard-iron offset along sensor x", 0.0, 100.0),
    TermParameter("mag_hard_iron_y", "µT", "magnetometer hard-iron offset along sensor y", 0.0, 100.0),
    TermParameter("mag_hard_iron_z", "µT", "magnetometer hard-iron offset along sensor z", 0.0, 100.0),
)
MAG_OWN_PARAMETERS = (
    TermParameter("mag_heading", "rad", "heading ψ of the field's horizontal part in the world frame", 0.0, 10.0),
)
MAG_GROUPS = ("mag_axial", "mag_transverse")
MAG_SERIES = ("mag_x", "mag_y", "mag_z")
#: nominal noise scales [µT] (axial, transverse): first least-squares weights
MAG_NOMINAL_NOISE = (1.0, 3.0)


def field_world(horizontal: np.ndarray, down: np.ndarray, heading: np.ndarray) -> np.ndarray:
    """The Earth's field in world axes (x, y horizontal, z up).

    Parameters
    ----------
    horizontal, down, heading : (B,) arrays
        H [µT], Z [µT] (positive downward), ψ [rad].

    Returns
    -------
    (B, 3) array
        B_w = (H cos ψ, H sin ψ, −Z) [µT].
    """
    return np.stack([horizontal * np.cos(heading), horizontal * np.sin(heading), -down], axis=1)


def body_field(states: np.ndarray, b_world: np.ndarray) -> np.ndarray:
    """The world field in body axes along simulated states.

    Parameters
    ----------
    states : (B, J, 13) array
        Simulated states (quaternion body→world in columns 6:10).
    b_world : (B, 3) array
        World field [µT].

    Returns
    -------
    (B, J, 3) array
        R(t_j)ᵀ B_w [µT].
    """
    R = quat_to_matrix(states[..., 6:10])                         # (B, J, 3, 3), normalised inside
    return np.einsum("bjki,bk->bji", R, b_world)


def window_mean(f: np.ndarray, h: float, t: np.ndarray, interpolate) -> np.ndarray:
    """The mean of a signal over the window [t − w, t] (w = :data:`MAG_WINDOW`) by Gauss–Legendre
    quadrature; nodes before the grid's start are read at the start.

    Parameters
    ----------
    f : (B, J, 3) array
        Signal on the grid j·h.
    h : float
        Grid step [s].
    t : (B, n) array
        Window ends [s].
    interpolate : callable
        ``interpolate(f, h, times)`` → (B, n, 3) (the inertial model's cubic interpolation).

    Returns
    -------
    (B, n, 3) array
    """
    out = np.zeros(t.shape + (f.shape[2],))
    for x, wgt in zip(GL_NODES, GL_WEIGHTS):
        out += wgt * interpolate(f, h, np.ascontiguousarray(np.maximum(t - (1.0 - x) * MAG_WINDOW, 0.0)))
    return out
