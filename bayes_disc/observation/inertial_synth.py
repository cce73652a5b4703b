"""Synthetic inertial logs: what a logger fixed in the disc records during a simulated flight.

Computed independently of the fitting path (:mod:`.models.inertial`): the flight is simulated on a grid
``SUBSTEPS`` times finer than the row period; the acceleration and angular acceleration come from the
readable equations of motion (:func:`bayes_disc.physics.state_derivative`, exact) instead of finite
differences; the on-chip filter τ dy/dt = x − y is integrated on that fine grid; rows are read at
t_i = i·P directly (no interpolation). Noise: Gaussian, per sensor axis group (axial z, transverse x, y).
A magnetometer reading of a fixed world field rotated into sensor axes is written too, so the time base
can be cross-checked on synthetic logs as on real ones.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..physics import Coefficients, Disc, Environment, simulate, state_derivative
from ..physics.frames import quat_to_matrix
from .imu.formats import InertialLog
from .models.inertial import low_pass, sensor_rotation

#: fine-grid points per row period
SUBSTEPS = 16


@dataclass(frozen=True)
class LoggerSpec:
    """An inertial logger in the disc and its defects.

    Attributes
    ----------
    offset : (3,) tuple
        Sensor position r_s in body axes from the centre of mass [m].
    lpf_tau : float
        Accelerometer filter time constant τ [s].
    tilt : (2,) tuple
        Sensor tilt ε about b1, b2 [rad].
    period : float
        Row period P [s].
    gyro_noise, acc_noise : (2,) tuple
        Noise sd (axial z, transverse x/y) [rad/s], [m/s²].
    gyro_bias, acc_bias : (3,) tuple
        Biases [rad/s], [m/s²].
    lpf_state : (3,) tuple or None
        Filter state at release [m/s²]; None: the filter input at release (settled filter).
    field_uT : (3,) tuple
        World magnetic field [µT].
    """

    offset: tuple = (0.02, 0.0, -0.01)
    lpf_tau: float = 0.15
    tilt: tuple = (0.0, 0.0)
    period: float = 0.0122
    gyro_noise: tuple = (0.005, 0.05)
    acc_noise: tuple = (0.05, 0.05)
    gyro_bias: tuple = (0.0, 0.0, 0.0)
    acc_bias: tuple = (0.0, 0.0, 0.0)
    lpf_state: tuple | None = None
    field_uT: tuple = (20.0, 0.0, -40.0)
    truth: dict = field(default_factory=dict, compare=False)


def logger_readings(initial_state: np.ndarray, coefficients: Coefficients, n_rows: int, spec: LoggerSpec,
                    disc: Disc = Disc(), env: Environment = Environment(), terms=(), extension=None):
    """Noise-free gyro [rad/s], accelerometer [m/s²] and magnetometer [µT] rows of one throw.

    Parameters
    ----------
    initial_state : (13,) array
        State at release (t = 0, row 0).
    coefficients : Coefficients
        Aerodynamic coefficients.
    n_rows : int
        Rows to record.
    spec : LoggerSpec
        The logger.
    disc, env, terms, extension
        As for :func:`bayes_disc.physics.simulate`.

    Returns
    -------
    gyro, acc, mag : (n_rows, 3) arrays
    states : (n_rows, 13) array
        The states at the rows.
    """
    h = spec.period / SUBSTEPS
    times = np.arange((n_rows - 1) * SUBSTEPS + 1) * h
    tr = simulate(initial_state[None], coefficients.as_array()[None], times, t0=0.0, disc=disc, env=env,
                  terms=terms, extension=extension, want_states=True)
    if not tr.ok[0]:
        raise ValueError(f"synthetic inertial throw: simulation failed ({tr.failure_reasons()[0]})")
    states = tr.states[0]
    r_s = np.asarray(spec.offset, float)
    f_body = np.empty((times.size, 3))
    for j, (t, y) in enumerate(zip(times, states)):
        dy = state_derivative(t, y, coefficients, disc, env, terms, extension)
        R = quat_to_matrix(y[6:10])
        w, w_dot = y[10:13], dy[10:13]
        f_body[j] = R.T @ (dy[3:6] + np.array([0.0, 0.0, env.g])) + np.cross(w_dot, r_s) \
            + np.cross(w, np.cross(w, r_s))
    C = sensor_rotation(np.asarray(spec.tilt, float)[None])[0]
    f_s = f_body @ C.T
    y0 = f_s[0] if spec.lpf_state is None else np.asarray(spec.lpf_state, float)
    acc = low_pass(f_s[None].copy(), y0[None].copy(), np.array([spec.lpf_tau]), h)[0]
    rows = np.arange(n_rows) * SUBSTEPS
    R_rows = quat_to_matrix(states[rows, 6:10])
    gyro = states[rows, 10:13] @ C.T + np.asarray(spec.gyro_bias, float)
    mag = np.einsum("ij,njk,k->ni", C, np.transpose(R_rows, (0, 2, 1)), np.asarray(spec.field_uT, float))
    return gyro, acc[rows] + np.asarray(spec.acc_bias, float), mag, states[rows]


def synthetic_log(name: str, initial_state: np.ndarray, coefficients: Coefficients, duration: float,
                  spec: LoggerSpec, rng: np.random.Generator, disc: Disc = Disc(), env: Environment = Environment(),
                  terms=(), extension=None, timed: bool = False) -> InertialLog:
    """A noisy :class:`InertialLog` of one throw from release (row 0) for ``duration`` [s].

    ``timed``: give sample times (as an ``imu-csv`` file would); otherwise only row numbers (as the
    ``flatball-ins`` logger), the row period then being an unknown of the fit.
    """
    n_rows = int(duration / spec.period) + 1
    gyro, acc, mag, _ = logger_readings(initial_state, coefficients, n_rows, spec, disc, env, terms, extension)
    gs = np.array([spec.gyro_noise[1], spec.gyro_noise[1], spec.gyro_noise[0]])
    as_ = np.array([spec.acc_noise[1], spec.acc_noise[1], spec.acc_noise[0]])
    gyro = gyro + rng.normal(0.0, 1.0, gyro.shape) * gs
    acc = acc + rng.normal(0.0, 1.0, acc.shape) * as_
    rows = np.arange(n_rows)
    return InertialLog(name=name, source="synth", fmt="imu-csv" if timed else "flatball-ins", rows=rows,
                       lines=rows + 2, gyro=gyro, acc=acc, mag=mag, pressure=None,
                       times=rows * spec.period if timed else None, repairs=[])
