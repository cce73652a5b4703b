"""Inertial (IMU) recordings of one throw: gyroscope, low-pass-filtered accelerometer and, optionally,
magnetometer.

A logger fixed in the disc measures, in its sensor axes s (tilted from the body axes B by the small
rotation C = exp(−[ε]×), ε = (ε1, ε2, 0) [rad]; sensor +z along b3):

    gyro:  ω_s(t) = C ω_B(t) + b_g                                                      [rad/s]
    acc:   f_B(t) = Rᵀ (dv/dt + g ẑ) + dω_B/dt × r_s + ω_B × (ω_B × r_s)                 [m/s²]
           τ dy/dt = C f_B(t) − y,   y(0) = y_0                                           (on-chip LPF)
           a_s(t) = y(t) + b_a

with v the centre-of-mass velocity (world), R the body→world rotation, r_s the sensor position in B
relative to the centre of mass [m], τ the accelerometer filter's time constant [s], y_0 the filter state at
release (the hand was still accelerating the disc), b_g, b_a biases. The specific force f_B is what the
aerodynamic (and any extra-term) force does per unit mass plus the rotational terms at r_s; in flight the
centripetal term dominates (≈ 6 g at r = 55 rad/s, |r_s| = 2 cm).

A log without time column (``flatball-ins``) is sampled at t_i = (row_i − row_0) P with the row period P
[s] unknown (``imu_period_<flight>``), or, with ``row_times="magnetometer"``, at t_i = P u_i with u_i
[rows] the row's place in time from the magnetometer's phase (between two rows the field advances by one,
two or three magnetometer samples; :func:`..imu.timebase.row_offsets_from_magnetometer`); an
``imu-csv`` log gives t_i. The simulation runs on a fixed fine grid (four points per nominal row); dv/dt
and dω_B/dt come from fourth-order finite differences of the simulated states (exact for any extra physics
term), the filter is integrated exactly for inputs linear between grid points, and the outputs are
interpolated (cubic Lagrange) at each parameter vector's own sample times.

Noise: four groups per throw, each with its own scale (Jeffreys prior, integrated out): gyro axial (z),
gyro transverse (x, y), acc axial (z), acc transverse (x, y) — the axial gyro noise of these loggers is an
order of magnitude below the transverse one.

Parameters — shared by the run's throws (one logger, one mount): ``imu_offset_x, imu_offset_y,
imu_offset_z`` (r_s, m), ``imu_lpf_tau`` (s), ``imu_tilt_1, imu_tilt_2`` (ε, rad); per throw:
``imu_period`` (s, logs without time column), ``gyro_bias_x…z`` (rad/s), ``acc_bias_x…z`` (m/s²),
``lpf_state_x…z`` (y_0, m/s²).

Magnetometer (``magnetometer=True``; :mod:`.magnetometer` for its equations, parameters and what it
does not model): three more channels m_s(t_i) = C ⟨Rᵀ⟩_i B_w + h on the same samples t_i. They are
channels of this unit rather than a unit of their own so that the throw's clock is one parameter in one
place: the row period P that places the gyro and accelerometer rows in time places the magnetometer's
rows too, and the field's turning against the simulated attitude fixes P independently of the spin-down
and wobble. The magnetometer adds its shared parameters (field strength, hard iron) after the mount's,
the per-throw field heading after the filter state, and two noise groups (``mag_axial``,
``mag_transverse``, µT) after the four above; without it the unit is exactly the gyro/accelerometer one.

Barometer (``barometer=True``; :mod:`.barometer` for its equations, parameters and what it does not
model): one more channel, the readings of a sensor that follows the outside pressure
p_0 − ρ g (z(t) − z(0)) + c_q ½ ρ |v(t)|² with a first-order lag τ_b, on the rows that carry a new reading,
on the same clock; with ``landing`` (the rows after the flight) also their readings, as the sensor relaxes
on the ground. It measures the height of the flight, and with it the climb and the lift that the
gyroscope and accelerometer leave loose. It adds its shared port coefficient and lag last among the
shared parameters, the throw's p_0 and s_0 last among its own, one noise group (``baro``, Pa) last, and
the landing rows after the flight's rows (NaN in every other channel).

Residual series (diagnostics): measured − predicted gyro and accelerometer along the sensor axes
(``gyro_x…z`` [rad/s], ``acc_x…z`` [m/s²]), each scaled by its noise group's σ (unit standard error 1),
at the samples t_i of the parameter vector; the covariates (α, air speed, spin, height) are interpolated
from the simulation grid onto t_i. No projection on flight frames: the filter acts in sensor axes, so a
rotated, filtered specific force has no clean flight-frame component.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numba as nb
import numpy as np

from ...physics import TermParameter
from ...physics.frames import quat_from_rotvec, quat_to_matrix
from ..imu.formats import InertialLog
from ..imu.timebase import row_offsets_from_magnetometer
from .base import ObservationModel, ResidualSeries
from .barometer import (BARO_GROUPS, BARO_NOMINAL_NOISE, BARO_SERIES, BARO_SHARED_PARAMETERS, outside_pressure,
                        own_parameters, reading_rows, relax)
from .magnetometer import (MAG_GROUPS, MAG_NOMINAL_NOISE, MAG_OWN_PARAMETERS, MAG_SERIES, MAG_SHARED_PARAMETERS,
                           MAG_WINDOW, body_field, field_world, window_mean)
from .nutation import GYRO_NOISE, NUTATION_SHARED_PARAMETERS, nutation_filter

#: how the rows of a log without time column are placed in time: equally spaced, or by the magnetometer's phase
ROW_TIMES = ("uniform", "magnetometer")
#: fine simulation points per nominal row period
OVERSAMPLE = 4
#: longest row period [s] a parameter vector may take, as a multiple of the nominal one (grid length)
PERIOD_SPAN = 1.35

SHARED_PARAMETERS = (
    TermParameter("imu_offset_x", "m", "sensor position r_s along b1 (from the centre of mass)", 0.0, 0.05),
    TermParameter("imu_offset_y", "m", "sensor position r_s along b2", 0.0, 0.05),
    TermParameter("imu_offset_z", "m", "sensor position r_s along b3", 0.0, 0.02),
    TermParameter("imu_lpf_tau", "s", "accelerometer low-pass filter time constant τ", 0.1, 0.1),
    TermParameter("imu_tilt_1", "rad", "sensor tilt from the body axes about b1", 0.0, 0.05),
    TermParameter("imu_tilt_2", "rad", "sensor tilt from the body axes about b2", 0.0, 0.05),
)
GROUPS = ("gyro_axial", "gyro_transverse", "acc_axial", "acc_transverse")
#: the residual series (sensor axes), their noise groups and units
SERIES = ("gyro_x", "gyro_y", "gyro_z", "acc_x", "acc_y", "acc_z")
SERIES_GROUPS = (1, 1, 0, 3, 3, 2)
SERIES_UNITS = ("rad/s",) * 3 + ("m/s²",) * 3
#: noise groups of the magnetometer's series (mag_x, mag_y, mag_z) when it is used
MAG_SERIES_GROUPS = (5, 5, 4)


@nb.njit(cache=True)
def low_pass(x, y0, tau, h):
    """First-order filter τ dy/dt = x − y on a uniform grid, exact for x linear between points.

    Parameters
    ----------
    x : (B, J, K) array
        Filter input on the grid [unit], K channels.
    y0 : (B, K) array
        State at the first grid point.
    tau : (B,) array
        Time constants [s] (> 0).
    h : float
        Grid step [s].

    Returns
    -------
    (B, J, K) array
        Filter output y_j = α y_{j−1} + (1 − α) x_{j−1} + (x_j − x_{j−1})(1 − τ(1 − α)/h), α = e^{−h/τ}.
    """
    B, J, _ = x.shape
    out = np.empty_like(x)
    for b in range(B):
        a = np.exp(-h / tau[b])
        k = 1.0 - tau[b] * (1.0 - a) / h
        for c in range(x.shape[2]):
            y = y0[b, c]
            out[b, 0, c] = y
            for j in range(1, J):
                y = a * y + (1.0 - a) * x[b, j - 1, c] + (x[b, j, c] - x[b, j - 1, c]) * k
                out[b, j, c] = y
    return out


@nb.njit(cache=True)
def fd_derivative(f, h):
    """Fourth-order finite-difference derivative along axis 1 of f (B, J, k) on a uniform grid h [s]
    (one-sided fourth-order stencils at both ends; J ≥ 5)."""
    B, J, K = f.shape
    d = np.empty_like(f)
    s = 1.0 / (12.0 * h)
    for b in range(B):
        for c in range(K):
            for j in range(2, J - 2):
                d[b, j, c] = (f[b, j - 2, c] - 8 * f[b, j - 1, c] + 8 * f[b, j + 1, c] - f[b, j + 2, c]) * s
            d[b, 0, c] = (-25 * f[b, 0, c] + 48 * f[b, 1, c] - 36 * f[b, 2, c] + 16 * f[b, 3, c] - 3 * f[b, 4, c]) * s
            d[b, 1, c] = (-3 * f[b, 0, c] - 10 * f[b, 1, c] + 18 * f[b, 2, c] - 6 * f[b, 3, c] + f[b, 4, c]) * s
            d[b, J - 1, c] = (25 * f[b, J - 1, c] - 48 * f[b, J - 2, c] + 36 * f[b, J - 3, c]
                              - 16 * f[b, J - 4, c] + 3 * f[b, J - 5, c]) * s
            d[b, J - 2, c] = (3 * f[b, J - 1, c] + 10 * f[b, J - 2, c] - 18 * f[b, J - 3, c]
                              + 6 * f[b, J - 4, c] - f[b, J - 5, c]) * s
    return d


@nb.njit(cache=True)
def interpolate(f, h, t):
    """Cubic Lagrange interpolation of f (B, J, k) on the grid j·h at times t (B, n) [s] → (B, n, k);
    NaN where t lies outside the grid."""
    B, J, K = f.shape
    n = t.shape[1]
    out = np.empty((B, n, K))
    for b in range(B):
        for i in range(n):
            u = t[b, i] / h
            if not (u >= 0.0 and u <= J - 1):
                out[b, i, :] = np.nan
                continue
            j = min(max(int(np.floor(u)) - 1, 0), J - 4)
            s = u - j
            w0 = -(s - 1) * (s - 2) * (s - 3) / 6
            w1 = s * (s - 2) * (s - 3) / 2
            w2 = -s * (s - 1) * (s - 3) / 2
            w3 = s * (s - 1) * (s - 2) / 6
            for c in range(K):
                out[b, i, c] = w0 * f[b, j, c] + w1 * f[b, j + 1, c] + w2 * f[b, j + 2, c] + w3 * f[b, j + 3, c]
    return out


def sensor_rotation(tilt: np.ndarray) -> np.ndarray:
    """C (B, 3, 3) mapping body to sensor components for tilts ε (B, 2) [rad] (sensor z ≈ b3)."""
    rv = np.concatenate([tilt, np.zeros((tilt.shape[0], 1))], axis=1)
    return np.transpose(quat_to_matrix(quat_from_rotvec(rv)), (0, 2, 1))


@nb.njit(cache=True)
def sensor_signals(states, h, g, r_s, C):
    """Gyro and unfiltered specific force in sensor axes (module docstring) along simulated states.

    Parameters
    ----------
    states : (B, J, 13) array
        States on a uniform grid of step h [s].
    h : float
        Grid step [s].
    g : float
        Gravitational acceleration [m/s²].
    r_s : (B, 3) array
        Sensor position in body axes [m].
    C : (B, 3, 3) array
        Body → sensor rotation.

    Returns
    -------
    (B, J, 6) array
        ω_s = C ω_B [rad/s] and C f_B [m/s²], f_B = Rᵀ(dv/dt + g ẑ) + ω̇_B × r_s + ω_B × (ω_B × r_s).
    """
    B, J, _ = states.shape
    a = fd_derivative(states[:, :, 3:6].copy(), h)
    wd = fd_derivative(states[:, :, 10:13].copy(), h)
    out = np.empty((B, J, 6))
    for b in range(B):
        rx, ry, rz = r_s[b, 0], r_s[b, 1], r_s[b, 2]
        for j in range(J):
            qw, qx, qy, qz = states[b, j, 6], states[b, j, 7], states[b, j, 8], states[b, j, 9]
            nq = 1.0 / np.sqrt(qw * qw + qx * qx + qy * qy + qz * qz)
            qw, qx, qy, qz = qw * nq, qx * nq, qy * nq, qz * nq
            # R (body → world); f_cm = Rᵀ (a + g ẑ)
            r00 = 1 - 2 * (qy * qy + qz * qz)
            r01 = 2 * (qx * qy - qz * qw)
            r02 = 2 * (qx * qz + qy * qw)
            r10 = 2 * (qx * qy + qz * qw)
            r11 = 1 - 2 * (qx * qx + qz * qz)
            r12 = 2 * (qy * qz - qx * qw)
            r20 = 2 * (qx * qz - qy * qw)
            r21 = 2 * (qy * qz + qx * qw)
            r22 = 1 - 2 * (qx * qx + qy * qy)
            ax, ay, az = a[b, j, 0], a[b, j, 1], a[b, j, 2] + g
            fx = r00 * ax + r10 * ay + r20 * az
            fy = r01 * ax + r11 * ay + r21 * az
            fz = r02 * ax + r12 * ay + r22 * az
            wx, wy, wz = states[b, j, 10], states[b, j, 11], states[b, j, 12]
            dx, dy, dz = wd[b, j, 0], wd[b, j, 1], wd[b, j, 2]
            # ω̇ × r
            fx += dy * rz - dz * ry
            fy += dz * rx - dx * rz
            fz += dx * ry - dy * rx
            # ω × (ω × r)
            cx, cy, cz = wy * rz - wz * ry, wz * rx - wx * rz, wx * ry - wy * rx
            fx += wy * cz - wz * cy
            fy += wz * cx - wx * cz
            fz += wx * cy - wy * cx
            for i in range(3):
                out[b, j, i] = C[b, i, 0] * wx + C[b, i, 1] * wy + C[b, i, 2] * wz
                out[b, j, 3 + i] = C[b, i, 0] * fx + C[b, i, 1] * fy + C[b, i, 2] * fz
    return out


@dataclass(eq=False)
class InertialMeasurements(ObservationModel):
    """Gyroscope, filtered accelerometer and (optionally) magnetometer of one throw (module docstring).

    Parameters
    ----------
    log : InertialLog
        The throw's free flight (first row = release), gyro rad/s, acc m/s², mag µT, sensor axes.
    g : float
        Gravitational acceleration [m/s²].
    period : float
        Nominal row period [s] (sets the simulation grid; the row period itself is a parameter for logs
        without time column).
    magnetometer : bool
        Also predict the log's magnetometer (``log.mag`` required) on the same clock.
    barometer : bool
        Also predict the log's barometer readings (``log.pressure`` required) on the same clock.
    rho : float, optional
        Air density [kg/m³] (required with the barometer).
    landing : InertialLog, optional
        The recording's rows right after the flight (the disc on the ground), for the barometer only: their
        readings follow the sensor's relaxation to the landing height's pressure (:mod:`.barometer`).
    row_times : str
        One of :data:`ROW_TIMES`: rows equally spaced in time (``uniform``), or placed by the magnetometer's
        phase (``magnetometer``, logs without time column that carry a magnetometer; the magnetometer need
        not be predicted). The landing rows follow the flight's last row equally spaced.
    gyro_noise : str
        One of :data:`.nutation.GYRO_NOISE`: the transverse gyro's noise white (``white``), or white plus a
        randomly forced nutation (``nutation``, :mod:`.nutation`: its three parameters are shared by the
        logger's throws and the residuals are whitened by its Kalman filter).
    """

    id = "imu"
    title = "Inertial logger: gyroscope, low-pass-filtered accelerometer, magnetometer and barometer"
    equations = ("ω_s = C ω_B + b_g;  τ dy/dt = C[Rᵀ(dv/dt + g ẑ) + ω̇_B × r_s + ω_B × (ω_B × r_s)] − y, "
                 "a_s = y + b_a;  m_s = C ⟨Rᵀ⟩ B_w + h (window 2 T_m);  "
                 "τ_b dp_s/dt = p_0 − ρ g (z − z_0) + c_q ½ρ|v|² − p_s;  t_i = (row_i − row_0) P "
                 "or P u_i (u_i from the magnetometer's phase)")

    log: InertialLog
    g: float
    period: float
    magnetometer: bool = False
    barometer: bool = False
    rho: float | None = None
    landing: InertialLog | None = None
    row_times: str = "uniform"
    gyro_noise: str = "white"
    _obs: np.ndarray = field(init=False, repr=False)

    def __post_init__(self):
        if self.magnetometer and self.log.mag is None:
            raise ValueError(f"{self.log.name}: the magnetometer is asked for but the log has none")
        if self.barometer and (self.log.pressure is None or not np.isfinite(self.log.pressure).any()):
            raise ValueError(f"{self.log.name}: the barometer is asked for but the log has no pressure readings")
        if self.barometer and not (self.rho is not None and self.rho > 0):
            raise ValueError(f"{self.log.name}: the barometer needs the air density rho > 0, got {self.rho!r}")
        self.flight = self.log.name
        self.timed = self.log.times is not None
        if self.landing is not None and (self.timed or not self.barometer):
            raise ValueError(f"{self.log.name}: landing rows are used by the barometer of a log without time column "
                             "only")
        if self.row_times not in ROW_TIMES:
            raise ValueError(f"{self.log.name}: row_times must be one of {ROW_TIMES}, got {self.row_times!r}")
        if self.row_times == "magnetometer" and self.log.times is not None:
            raise ValueError(f"{self.log.name}: the log has a time column; row times from the magnetometer are for "
                             "logs without one")
        if self.gyro_noise not in GYRO_NOISE:
            raise ValueError(f"{self.log.name}: gyro_noise must be one of {GYRO_NOISE}, got {self.gyro_noise!r}")
        rows = np.asarray(self.log.rows, float)
        self.n_flight = rows.size
        after = [] if self.landing is None else np.asarray(self.landing.rows, float)
        self.row_offsets = np.r_[rows, after] - rows[0]           # (n,) rows since release, landing rows last
        self.time_offsets = self.row_offsets.copy()               # (n,) t_i / P [rows]
        self.row_time_summary = None
        if self.row_times == "magnetometer":
            u, self.row_time_summary = row_offsets_from_magnetometer(self.log)
            self.time_offsets[: self.n_flight] = u
        self.h = self.period / OVERSAMPLE
        if self.timed:
            self.sample_times = np.asarray(self.log.times, float) - float(self.log.times[0])
            span = self.sample_times[-1]
        else:
            span = self.time_offsets[self.n_flight - 1] * self.period * PERIOD_SPAN
        n_grid = max(int(np.ceil(span / self.h)) + 3, 6)
        self.times = np.arange(n_grid) * self.h                   # simulation grid [s] from release
        data = self.measured
        self._seen = np.isfinite(data)
        if self.magnetometer:     # rows whose nominal window reaches before release: the hand's spin-up
            nominal = self.sample_times if self.timed else self.time_offsets * self.period
            self._seen[nominal < MAG_WINDOW, 6:9] = False
        self._obs = data[self._seen]
        channel = np.broadcast_to(np.arange(data.shape[1]), data.shape)[self._seen]
        self._groups = np.array(self.series_groups)[channel].astype(np.intp)
        # positions of the flight rows' gyro x and y in the residual vector, for the nutation's filter
        position = (np.cumsum(self._seen.ravel()) - 1).reshape(self._seen.shape)
        if not self._seen[: self.n_flight, :2].all():
            raise ValueError(f"{self.log.name}: a flight row has no gyro x or y reading")
        self._gyro_xy = position[: self.n_flight, :2]

    # -- channels ------------------------------------------------------------------------------------
    @property
    def measured(self) -> np.ndarray:
        """(n, 6) gyro [rad/s] and accelerometer [m/s²], then the magnetometer [µT] (3 columns) and the
        barometer [Pa] (1 column, NaN on rows without a new reading) when they are used; the landing rows
        last, with the barometer only."""
        parts = [self.log.gyro, self.log.acc] + ([self.log.mag] if self.magnetometer else [])
        flight = np.concatenate(parts, axis=1)
        if not self.barometer:
            return flight
        p = np.r_[self.log.pressure, [] if self.landing is None else self.landing.pressure]
        baro = np.full(p.size, np.nan)
        new = reading_rows(p)
        baro[new] = p[new]
        flight = np.concatenate([flight, np.full((p.size - self.n_flight, flight.shape[1]), np.nan)])
        return np.concatenate([flight, baro[:, None]], axis=1)

    @property
    def series_names(self) -> tuple[str, ...]:
        """Names of the predicted channels, in the order of :meth:`predict`'s last axis."""
        return SERIES + (MAG_SERIES if self.magnetometer else ()) + (BARO_SERIES if self.barometer else ())

    @property
    def series_groups(self) -> tuple[int, ...]:
        """Noise group of each channel of :attr:`series_names`."""
        out = SERIES_GROUPS + (MAG_SERIES_GROUPS if self.magnetometer else ())
        return out + ((len(self.group_names) - 1,) if self.barometer else ())

    @property
    def group_names(self) -> tuple[str, ...]:
        """The model's noise groups, in order."""
        return GROUPS + (MAG_GROUPS if self.magnetometer else ()) + (BARO_GROUPS if self.barometer else ())

    # -- contract ------------------------------------------------------------------------------------
    @property
    def shared_parameters(self) -> tuple[TermParameter, ...]:
        return (SHARED_PARAMETERS + (MAG_SHARED_PARAMETERS if self.magnetometer else ())
                + (NUTATION_SHARED_PARAMETERS if self.gyro_noise == "nutation" else ())
                + (BARO_SHARED_PARAMETERS if self.barometer else ()))

    @property
    def parameters(self) -> tuple[TermParameter, ...]:
        own = [] if self.timed else [TermParameter("imu_period", "s", "logger row period P",
                                                   0.010, 0.003)]
        own += [TermParameter(f"gyro_bias_{a}", "rad/s", f"gyro bias along sensor {a}", 0.0, 0.05) for a in "xyz"]
        own += [TermParameter(f"acc_bias_{a}", "m/s²", f"accelerometer bias along sensor {a}", 0.0, 0.5)
                for a in "xyz"]
        own += [TermParameter(f"lpf_state_{a}", "m/s²", f"accelerometer filter state at release along {a}",
                              0.0, 50.0) for a in "xyz"]
        own += MAG_OWN_PARAMETERS if self.magnetometer else ()
        if not self.barometer:
            return tuple(own)
        return tuple(own) + own_parameters(self.log.pressure[np.isfinite(self.log.pressure)][0])

    @property
    def noise_names(self) -> tuple[str, ...]:
        return tuple(f"sigma_{g}_{self.flight}" for g in self.group_names)

    @property
    def group_index(self) -> np.ndarray:
        return self._groups

    @property
    def noise_units(self) -> tuple[str, ...]:
        return (("rad/s", "rad/s", "m/s²", "m/s²") + (("µT", "µT") if self.magnetometer else ())
                + (("Pa",) if self.barometer else ()))

    @property
    def nominal_noise(self) -> np.ndarray:
        # rad/s (axial, transverse), m/s² (axial, transverse), µT (axial, transverse)
        return np.array([0.02, 0.2, 0.3, 0.3] + (list(MAG_NOMINAL_NOISE) if self.magnetometer else [])
                        + (list(BARO_NOMINAL_NOISE) if self.barometer else []))

    def sample_times_for(self, period: np.ndarray) -> np.ndarray:
        """(B, n) sample times [s] since release for row periods (B,) (ignored for timed logs); landing rows
        last."""
        if self.timed:
            return np.broadcast_to(self.sample_times, (period.shape[0], self.sample_times.size))
        return period[:, None] * self.time_offsets[None, :]

    def split(self, extra: np.ndarray) -> dict:
        """Named parameter arrays (B, …) from the model's extra values (shared, then own); with the
        magnetometer also ``field`` (B, 3) [µT] in world axes and ``hard_iron`` (B, 3) [µT]; with the
        barometer ``baro_dynamic`` (B,) [–], ``baro_lag`` (B,) [s], ``baro_reference`` and ``baro_state``
        (B,) [Pa]; with the randomly forced nutation ``nutation`` (B, 3): λ [1/s], κ_N [–], a [–]."""
        ns = len(self.shared_parameters)
        s = extra[:, :ns]
        own = extra[:, ns:]
        j = 0 if self.timed else 1
        out = {"r_s": s[:, 0:3], "tau": s[:, 3], "tilt": s[:, 4:6],
               "period": own[:, 0] if not self.timed else np.full(extra.shape[0], np.nan),
               "b_g": own[:, j:j + 3], "b_a": own[:, j + 3:j + 6], "y0": own[:, j + 6:j + 9]}
        if self.magnetometer:
            out["field"] = field_world(s[:, 6], s[:, 7], own[:, j + 9])
            out["hard_iron"] = s[:, 8:11]
        if self.gyro_noise == "nutation":
            at = len(SHARED_PARAMETERS) + (len(MAG_SHARED_PARAMETERS) if self.magnetometer else 0)
            out["nutation"] = s[:, at: at + len(NUTATION_SHARED_PARAMETERS)]
        if self.barometer:
            out["baro_dynamic"], out["baro_lag"] = s[:, ns - 2], s[:, ns - 1]
            out["baro_reference"], out["baro_state"] = own[:, -2], own[:, -1]
        return out

    def reading_times(self, t: np.ndarray) -> np.ndarray:
        """(B, n) times [s] of the barometer readings shown on rows sampled at ``t`` (B, n): half a row
        before each row (:mod:`.barometer`); the first row's at its own time."""
        prev = np.concatenate([t[:, :1], t[:, :-1]], axis=1)
        return 0.5 * (t + prev)

    def predict(self, trajectories, extra: np.ndarray | None) -> np.ndarray:
        """(B, n, c) predicted gyro [rad/s] and accelerometer [m/s²] at the log's samples, then the
        magnetometer [µT] and the barometer [Pa] when used (:attr:`series_names`); NaN for a parameter
        vector whose samples fall beyond the simulated grid or whose τ is not positive."""
        p = self.split(extra)
        states = np.ascontiguousarray(trajectories.states)
        C = sensor_rotation(p["tilt"])
        x = sensor_signals(states, self.h, self.g, np.ascontiguousarray(p["r_s"]), np.ascontiguousarray(C))
        tau = np.where(p["tau"] > 0, p["tau"], np.nan)
        x[..., 3:] = low_pass(np.ascontiguousarray(x[..., 3:]), np.ascontiguousarray(p["y0"]),
                              np.nan_to_num(tau, nan=1.0), self.h)
        t_all = np.ascontiguousarray(self.sample_times_for(p["period"]))
        t = np.ascontiguousarray(t_all[:, : self.n_flight])
        out = interpolate(x, self.h, t)
        out[..., :3] += p["b_g"][:, None, :]
        out[..., 3:] += p["b_a"][:, None, :]
        if self.magnetometer:
            mean = window_mean(body_field(states, p["field"]), self.h, t, interpolate)    # ⟨Rᵀ⟩ B_w
            mag = np.einsum("bij,bnj->bni", C, mean) + p["hard_iron"][:, None, :]
            mag[np.isnan(out[..., 0])] = np.nan                 # samples beyond the grid
            out = np.concatenate([out, mag], axis=2)
        if self.barometer:
            out = np.concatenate([out, np.full((out.shape[0], t_all.shape[1] - self.n_flight, out.shape[2]), np.nan)],
                                 axis=1)
            baro = self.barometer_readings(states, p, t_all)
            baro[:, : self.n_flight][np.isnan(out[:, : self.n_flight, 0])] = np.nan     # samples beyond the grid
            out = np.concatenate([out, baro[..., None]], axis=2)
        out[~np.isfinite(tau)] = np.nan
        return out

    def barometer_readings(self, states: np.ndarray, p: dict, t: np.ndarray) -> np.ndarray:
        """(B, n) predicted barometer readings [Pa] on every row sampled at ``t`` (B, n) [s] (:mod:`.barometer`):
        the lagged outside pressure, integrated on the simulation grid, read half a row before each row; after
        the flight's last row T the analytic relaxation to the pressure of the height at T (the disc on the
        ground). NaN where the lag is not positive.

        Parameters
        ----------
        states : (B, J, 13) array
            Simulated states on the grid.
        p : dict
            :meth:`split` of the parameters.
        t : (B, n) array
            Row times since release [s], landing rows last.
        """
        lag = np.where(p["baro_lag"] > 0, p["baro_lag"], np.nan)
        climb = states[..., 2] - states[:, :1, 2]
        outside = outside_pressure(climb, np.linalg.norm(states[..., 3:6], axis=2), p["baro_reference"],
                                   p["baro_dynamic"], self.rho, self.g)
        sensor = low_pass(np.ascontiguousarray(outside[..., None]), np.ascontiguousarray(p["baro_state"][:, None]),
                          np.nan_to_num(lag, nan=1.0), self.h)
        read = self.reading_times(t)
        out = interpolate(sensor, self.h, np.ascontiguousarray(read))[..., 0]
        if self.landing is not None:
            impact = t[:, self.n_flight - 1]                              # (B,) T: the last row in flight
            at = interpolate(np.ascontiguousarray(np.stack([sensor[..., 0], climb], axis=2)), self.h,
                             np.ascontiguousarray(impact[:, None]))[:, 0]
            held = outside_pressure(at[:, 1:2], np.zeros((t.shape[0], 1)), p["baro_reference"], p["baro_dynamic"],
                                    self.rho, self.g)[:, 0]
            after = read >= impact[:, None]
            out = np.where(after, relax(at[:, 0], held, np.maximum(read - impact[:, None], 0.0), lag), out)
        out[~np.isfinite(lag)] = np.nan
        return out

    def residuals(self, prediction: np.ndarray) -> np.ndarray:
        return prediction[:, self._seen] - self._obs[None]

    # -- noise: white, or with the randomly forced nutation in the transverse gyro (:mod:`.nutation`) ------
    def _nutation(self, residuals: np.ndarray, extra: np.ndarray):
        """The nutation filter's whitened gyro x, y (B, n_flight) each and its log-diagonal (B, n_flight)."""
        p = self.split(extra)
        t = self.sample_times_for(p["period"])[:, : self.n_flight]
        dt = np.ascontiguousarray(np.diff(t, axis=1, prepend=t[:, :1]))
        rx = np.ascontiguousarray(residuals[:, self._gyro_xy[:, 0]])
        ry = np.ascontiguousarray(residuals[:, self._gyro_xy[:, 1]])
        nut = p["nutation"]
        return nutation_filter(rx, ry, dt, np.ascontiguousarray(self.log.gyro[:, 2], dtype=float),
                               np.ascontiguousarray(nut[:, 0]), np.ascontiguousarray(nut[:, 1]),
                               np.ascontiguousarray(nut[:, 2]))

    def whiten(self, residuals: np.ndarray, extra: np.ndarray | None) -> np.ndarray:
        """White noise: the residuals; with the randomly forced nutation, the transverse gyro's replaced by the
        Kalman filter's scaled innovations (:func:`.nutation.nutation_filter`)."""
        if self.gyro_noise == "white":
            return residuals
        ex, ey, _ = self._nutation(residuals, extra)
        e = residuals.copy()
        e[:, self._gyro_xy[:, 0]] = ex
        e[:, self._gyro_xy[:, 1]] = ey
        return e

    def _nutation_log_diagonal(self, extra: np.ndarray) -> np.ndarray:
        """(B, n_flight) the filter's −½ ln S̃_k per row (independent of the residuals)."""
        return self._nutation(np.zeros((extra.shape[0], self._obs.size)), extra)[2]

    def log_diagonal(self, extra: np.ndarray | None) -> np.ndarray | None:
        if self.gyro_noise == "white":
            return None
        ld = self._nutation_log_diagonal(extra)
        out = np.zeros((extra.shape[0], self._obs.size))
        out[:, self._gyro_xy[:, 0]] = ld
        out[:, self._gyro_xy[:, 1]] = ld
        return out

    def log_det(self, extra: np.ndarray | None) -> np.ndarray | None:
        if self.gyro_noise == "white":
            return None
        ld = self._nutation_log_diagonal(extra)
        out = np.zeros((extra.shape[0], len(self.group_names)))
        out[:, GROUPS.index("gyro_transverse")] = 2.0 * np.sum(ld, axis=1)
        return out

    def residual_series(self, trajectories, extra, prediction, conditions, reference=None) -> ResidualSeries:
        """Gyro, accelerometer (and magnetometer) residuals along the sensor axes at the samples (module
        docstring); contract: :meth:`.base.ObservationModel.residual_series`."""
        p = self.split(extra)
        t = self.sample_times_for(p["period"])[0]
        ref = self.measured if reference is None else reference[0]
        diff = ref - prediction[0]
        if reference is None:
            diff = np.where(self._seen, diff, np.nan)
        st = trajectories.states[0]
        grid = np.asarray(self.times, float)
        cov = {"alpha": np.interp(t, grid, conditions.alpha[0]), "speed": np.interp(t, grid, conditions.speed[0]),
               "spin": np.interp(t, grid, st[:, 12]), "height": np.interp(t, grid, st[:, 2]), "time": t.copy()}
        names = self.series_names
        units = SERIES_UNITS + (("µT",) * 3 if self.magnetometer else ()) + (("Pa",) if self.barometer else ())
        channels = (("gyro", "rad/s"), ("gyro", "rad/s"), ("acc", "m/s²"), ("acc", "m/s²"))
        channels += (("mag", "µT"), ("mag", "µT")) if self.magnetometer else ()
        channels += (("baro", "Pa"),) if self.barometer else ()
        return ResidualSeries(times=t.copy(), series={n: diff[:, j] for j, n in enumerate(names)},
                              unit_se={n: np.ones(t.size) for n in names},
                              groups=dict(zip(names, self.series_groups)), units=dict(zip(names, units)),
                              covariates=cov, primary=names, group_channels=channels)
