"""Synthetic inertial logs: what a logger fixed in the disc records during a simulated flight.

Computed independently of the fitting path (:mod:`.models.inertial`): the flight is simulated on a grid
``SUBSTEPS`` times finer than the row period; the acceleration and angular acceleration come from the
readable equations of motion (:func:`bayes_disc.physics.state_derivative`, exact) instead of finite
differences; the on-chip filter τ dy/dt = x − y is integrated on that fine grid; rows are read at
t_i = i·P directly (no interpolation). Noise: Gaussian, per sensor axis group (axial z, transverse x, y).

The magnetometer follows the model of :mod:`.models.magnetometer`: a fixed world field B_w rotated into
sensor axes, averaged over the window [t_i − 2 T_m, t_i] (here by the trapezoidal rule on the fine grid,
the cumulative integral read linearly between its points; before release the disc is at its release
attitude), plus the hard-iron offset h and Gaussian noise per axis group (none by default, so that the
default logs draw the same random numbers for gyro and accelerometer as without it).

The barometer (recorded throws only) follows the model of :mod:`.models.barometer`: the outside pressure of
the height and the port's share of the dynamic pressure, followed with a first-order lag (stepped on the fine
grid), read about every 0.1 s half a row before the row that shows it, plus Gaussian noise.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..physics import Coefficients, Disc, Environment, simulate, state_derivative
from ..physics.frames import quat_to_matrix
from .imu.formats import InertialLog
from .models.inertial import low_pass, sensor_rotation
from .models.magnetometer import MAG_WINDOW
from .models.nutation import sample_nutation

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
        World magnetic field [µT] (x, y horizontal, z up: the northern hemisphere's field has z < 0).
    mag_hard_iron : (3,) tuple
        Magnetometer hard-iron offset h in sensor axes [µT].
    mag_noise : (2,) tuple
        Magnetometer noise sd (axial z, transverse x/y) [µT].
    baro_dynamic : float
        Pressure coefficient c_q of the barometer's port [–] (:mod:`.models.barometer`).
    baro_lag : float
        Time constant τ_b of the barometer's first-order lag [s] (> 0).
    baro_noise : float
        Barometer reading noise sd [Pa] (every reading differs from the previous one).
    nutation : (3,) tuple or None
        A randomly forced nutation added to the flight rows' gyro x and y (:mod:`.models.nutation`): its
        stationary RMS per axis [rad/s], decay rate λ [1/s] and turning rate κ_N [–]; zero at release.
        None: none.
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
    mag_hard_iron: tuple = (0.0, 0.0, 0.0)
    mag_noise: tuple = (0.0, 0.0)
    baro_dynamic: float = 0.0
    baro_lag: float = 0.7
    baro_noise: float = 1.0
    nutation: tuple | None = None
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
    gyro = states[rows, 10:13] @ C.T + np.asarray(spec.gyro_bias, float)
    b_body = np.einsum("njk,k->nj", np.transpose(quat_to_matrix(states[:, 6:10]), (0, 2, 1)),
                       np.asarray(spec.field_uT, float))
    mag = window_average(b_body, h, times[rows]) @ C.T + np.asarray(spec.mag_hard_iron, float)
    return gyro, acc[rows] + np.asarray(spec.acc_bias, float), mag, states[rows]


def window_average(f: np.ndarray, h: float, t: np.ndarray) -> np.ndarray:
    """Mean of f over [t − w, t] (w = :data:`~.models.magnetometer.MAG_WINDOW`), f held at f[0] before
    the grid's start.

    Parameters
    ----------
    f : (J, 3) array
        Signal on the grid j·h.
    h : float
        Grid step [s].
    t : (n,) array
        Window ends [s], on the grid's span.

    Returns
    -------
    (n, 3) array
    """
    cum = np.concatenate([np.zeros((1, 3)), np.cumsum(0.5 * (f[1:] + f[:-1]) * h, axis=0)])
    grid = np.arange(f.shape[0]) * h

    def integral(x):                       # ∫_0^x f dt, with f = f[0] for x < 0
        inside = np.column_stack([np.interp(np.maximum(x, 0.0), grid, cum[:, c]) for c in range(3)])
        return inside + np.minimum(x, 0.0)[:, None] * f[0]
    return (integral(t) - integral(t - MAG_WINDOW)) / MAG_WINDOW


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
    spin = gyro[:, 2].copy()
    gyro = gyro + rng.normal(0.0, 1.0, gyro.shape) * gs
    acc = acc + rng.normal(0.0, 1.0, acc.shape) * as_
    mag = _mag_noise(mag, spec, rng)
    gyro[:, :2] += _nutation(spin, spec, rng)
    rows = np.arange(n_rows)
    return InertialLog(name=name, source="synth", fmt="imu-csv" if timed else "flatball-ins", rows=rows,
                       lines=rows + 2, gyro=gyro, acc=acc, mag=mag, pressure=None,
                       times=rows * spec.period if timed else None, repairs=[])


#: standard sea-level pressure [Pa] around which the synthetic barometer reads
PRESSURE_PA = 101325.0
#: period [s] of the synthetic barometer task (the flatball firmware sleeps 0.1 s between readings)
BARO_TASK_PERIOD = 0.105


def _nutation(spin: np.ndarray, spec: LoggerSpec, rng: np.random.Generator) -> np.ndarray:
    """(n, 2) the randomly forced nutation of ``spec.nutation`` on n flight rows of spin ``spin`` [rad/s] (zeros
    and no draw without it)."""
    if spec.nutation is None:
        return np.zeros((spin.size, 2))
    rms, decay, kappa = spec.nutation
    return sample_nutation(spec.period * np.arange(spin.size), spin, decay, kappa, rms, rng)


def _mag_noise(mag: np.ndarray, spec: LoggerSpec, rng: np.random.Generator) -> np.ndarray:
    """mag (n, 3) [µT] plus Gaussian noise (axial, transverse sd of ``spec.mag_noise``); no draw without noise."""
    if not any(spec.mag_noise):
        return mag
    sd = np.array([spec.mag_noise[1], spec.mag_noise[1], spec.mag_noise[0]])
    return mag + rng.normal(0.0, 1.0, mag.shape) * sd


def rest_readings(quaternion: np.ndarray, spec: LoggerSpec, g: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Noise-free gyro [rad/s], accelerometer [m/s²] (filter settled) and magnetometer [µT] of a logger at
    rest with body attitude ``quaternion`` (4,) (w, x, y, z; body→world): ω = 0, f_B = Rᵀ g ẑ.

    Parameters
    ----------
    quaternion : (4,) array
        Body→world attitude of the resting disc.
    spec : LoggerSpec
        The logger (tilt, biases, world field).
    g : float
        Gravitational acceleration [m/s²].

    Returns
    -------
    gyro, acc, mag : (3,) arrays
        Sensor-axis readings [rad/s], [m/s²], [µT].
    """
    C = sensor_rotation(np.asarray(spec.tilt, float)[None])[0]
    R = quat_to_matrix(np.asarray(quaternion, float))
    gyro = np.asarray(spec.gyro_bias, float).copy()
    acc = C @ R.T @ np.array([0.0, 0.0, g]) + np.asarray(spec.acc_bias, float)
    mag = C @ R.T @ np.asarray(spec.field_uT, float) + np.asarray(spec.mag_hard_iron, float)
    return gyro, acc, mag


@dataclass
class RecordedThrow:
    """A synthetic logger recording of one throw with still parts before release and after the end.

    Attributes
    ----------
    log : InertialLog
        The whole recording (``rows`` the logger's step counter, ``times`` None: a flatball-ins log).
    clean : InertialLog
        The same rows without sensor noise.
    release_row : int
        Logger row of the release (first row of free flight, t = 0).
    end_row : int
        First row after the free flight (exclusive end; the disc is at rest from there).
    lpf_state : (3,) array
        The accelerometer filter state at release [m/s²] (sensor axes, without bias).
    """

    log: InertialLog
    clean: InertialLog
    release_row: int
    end_row: int
    lpf_state: np.ndarray


def _barometer(heights: np.ndarray, speeds: np.ndarray, spec: LoggerSpec, rng: np.random.Generator,
               env: Environment) -> np.ndarray:
    """Pressure [Pa] per row, as the flatball firmware's barometer task records it (:mod:`.models.barometer`).

    The outside pressure p_e = p_std − ρ g z + c_q ½ ρ |v|² (p_std = :data:`PRESSURE_PA`) is taken linear
    between rows on a grid ``SUBSTEPS`` times finer (the dynamic part only between rows in flight, so that
    it starts at the release row and stops at the last row in flight), and the sensor follows it with the
    first-order lag τ_b, stepped exactly for the mean of each fine step's end values (settled at the first
    row's p_e: the disc rests before release). A reading is taken every ⌈T/P⌉ rows
    (T = :data:`BARO_TASK_PERIOD`), half a row before the first row that shows it (read linearly on the fine
    grid), and held until the next, with Gaussian noise of sd ``spec.baro_noise``.

    Parameters
    ----------
    heights, speeds : (n,) arrays
        Height [m] and speed [m/s] of the disc at each row (speed 0: at rest, > 0: in flight).
    spec : LoggerSpec
        The logger (port coefficient, lag, noise).
    rng : numpy.random.Generator
        Noise source.
    env : Environment
        Air density [kg/m³] and gravitational acceleration [m/s²].

    Returns
    -------
    (n,) array
    """
    rows = np.arange(heights.size)
    fine_t = np.arange((heights.size - 1) * SUBSTEPS + 1) / SUBSTEPS                  # in rows
    flying = speeds > 0
    both = flying[np.floor(fine_t).astype(int)] & flying[np.ceil(fine_t).astype(int)]
    dynamic = np.where(both, np.interp(fine_t, rows, speeds ** 2), 0.0)
    height = np.interp(fine_t, rows, heights)
    fine = PRESSURE_PA - env.rho * env.g * height + spec.baro_dynamic * 0.5 * env.rho * dynamic
    decay = np.exp(-spec.period / SUBSTEPS / spec.baro_lag)
    sensor = np.empty_like(fine)
    sensor[0] = fine[0]
    for j in range(1, fine.size):
        sensor[j] = decay * sensor[j - 1] + (1.0 - decay) * 0.5 * (fine[j - 1] + fine[j])
    every = int(np.ceil(BARO_TASK_PERIOD / spec.period))
    reads = np.arange(0, heights.size, every)
    value = np.interp(np.maximum(reads - 0.5, 0.0), fine_t, sensor) + rng.normal(0.0, spec.baro_noise, reads.size)
    return np.repeat(value, every)[: heights.size]


def recorded_throw(name: str, initial_state: np.ndarray, coefficients: Coefficients, duration: float,
                   spec: LoggerSpec, rng: np.random.Generator, rest_before: float = 1.0, rest_after: float = 0.3,
                   first_row: int = 0, disc: Disc = Disc(), env: Environment = Environment(), terms=(),
                   extension=None) -> RecordedThrow:
    """A flatball-ins-like recording: the disc still for ``rest_before`` [s], the throw from release for
    ``duration`` [s] (:func:`logger_readings`), then still again for ``rest_after`` [s].

    The throwing motion itself (the hand's spin-up) is not simulated: the rows jump from rest to the
    release state. Before release the disc rests at its release attitude with the filter settled; after
    the end it rests at its final attitude, the filter relaxing from its last in-flight value towards the
    resting one as e^(−t/τ) (the landing is not simulated either). Gyro and accelerometer noise as
    :func:`synthetic_log` on every row; the barometer reads the pressure of the height (and the port's
    share of the dynamic pressure) every ⌈0.105 s / P⌉ rows, as the flatball firmware's barometer task
    does (:func:`_barometer`).

    Parameters
    ----------
    name : str
        Flight name of the log.
    initial_state : (13,) array
        State at release.
    coefficients : Coefficients
        Aerodynamic coefficients.
    duration : float
        Free flight [s]; ``int(duration / P) + 1`` rows.
    spec : LoggerSpec
        The logger.
    rng : numpy.random.Generator
        Noise source.
    rest_before, rest_after : float
        Still time before release and after the end [s].
    first_row : int
        Step counter of the first row (≥ 0).
    disc, env, terms, extension
        As for :func:`bayes_disc.physics.simulate`.

    Returns
    -------
    RecordedThrow
    """
    if first_row < 0 or rest_before < 0 or rest_after < 0:
        raise ValueError("recorded_throw: first_row, rest_before and rest_after must not be negative")
    n_fly = int(duration / spec.period) + 1
    n_pre = int(round(rest_before / spec.period))
    n_post = int(round(rest_after / spec.period))
    gyro_f, acc_f, mag_f, states = logger_readings(initial_state, coefficients, n_fly, spec, disc, env, terms,
                                                   extension)
    g0, a0, m0 = rest_readings(states[0, 6:10], spec, env.g)
    g1, a1, m1 = rest_readings(states[-1, 6:10], spec, env.g)
    decay = np.exp(-spec.period * np.arange(1, n_post + 1) / spec.lpf_tau)[:, None]
    acc_post = a1 + (acc_f[-1] - a1) * decay
    gyro = np.vstack([np.tile(g0, (n_pre, 1)), gyro_f, np.tile(g1, (n_post, 1))])
    acc = np.vstack([np.tile(a0, (n_pre, 1)), acc_f, acc_post])
    mag = np.vstack([np.tile(m0, (n_pre, 1)), mag_f, np.tile(m1, (n_post, 1))])
    heights = np.r_[np.full(n_pre, states[0, 2]), states[:, 2], np.full(n_post, states[-1, 2])]
    speeds = np.r_[np.zeros(n_pre), np.linalg.norm(states[:, 3:6], axis=1), np.zeros(n_post)]
    gs = np.array([spec.gyro_noise[1], spec.gyro_noise[1], spec.gyro_noise[0]])
    as_ = np.array([spec.acc_noise[1], spec.acc_noise[1], spec.acc_noise[0]])
    noisy_gyro = gyro + rng.normal(0.0, 1.0, gyro.shape) * gs
    noisy_acc = acc + rng.normal(0.0, 1.0, acc.shape) * as_
    pressure = _barometer(heights, speeds, spec, rng, env)
    noisy_mag = _mag_noise(mag, spec, rng)
    noisy_gyro[n_pre: n_pre + n_fly, :2] += _nutation(gyro_f[:, 2], spec, rng)
    rows = first_row + np.arange(gyro.shape[0])

    def make(gy, ac, mg):
        return InertialLog(name=name, source="synth", fmt="flatball-ins", rows=rows.copy(), lines=rows - first_row + 2,
                           gyro=gy, acc=ac, mag=mg.copy(), pressure=pressure.copy(), times=None, repairs=[])
    return RecordedThrow(log=make(noisy_gyro, noisy_acc, noisy_mag), clean=make(gyro, acc, mag),
                         release_row=int(first_row + n_pre),
                         end_row=int(first_row + n_pre + n_fly),
                         lpf_state=acc_f[0] - np.asarray(spec.acc_bias, float))
