"""The logging period of a flatball-ins file, from signals independent of the flight model.

Two methods:

**Magnetometer against gyroscope.** While the disc spins, the Earth's field seen in sensor axes
turns about sensor z at minus the spin rate. After removing the centre of the (mag-x, mag-y) circle
(hard-iron offset and the tilt's constant part, fitted by least squares), the field's phase advances
between consecutive rows by −∫ω_z dt = −P · (ω_z,i−1 + ω_z,i)/2 · Δrow, with P the row period. The
sums over a window give ``P = −Σ Δφ / Σ ω̄ Δrow``. The sign is a check: a world-fixed field must turn
against the spin when the magnetometer's x–y axes turn the same way as the gyroscope's. The
uncertainty is the scatter of the estimate over ``n_windows`` consecutive sub-windows (standard
error of their mean). The magnetometer samples on its own clock (the flatball firmware: 100 Hz
continuous mode, two-sample average) so single rows step by whole magnetometer samples; the sums
are unaffected except at the window edges, which the scatter includes.

**Row times from the magnetometer.** The same phase places every row in time: between two rows of the
flatball logger the field advances by one, two or three of the magnetometer's samples, which rows equally
spaced at the mean period could not hold (at most two), so t_i = (row_i − row_0) P is wrong by up to a few
rows over a throw (unless the magnetometer's readings, not the rows, are uneven). With the step's phase
advance Δψ_i taken within ±π of −ω̄_z,i P̄ Δrow_i (P̄ the mean row period),

    Δτ_i = −Δψ_i / ω̄_z,i,    τ_0 = 0,    u_i = (row_n − row_0) τ_i / τ_n                  [rows]

(:func:`row_offsets_from_magnetometer`), and the rows are sampled at t_i = P u_i: the same mean period P,
each row where the field's phase puts it. The field's own clock (100 Hz, two-sample average) leaves a
hold of up to one of its samples on each row.

**Barometer cadence.** In the flatball firmware the pressure is read in a separate task that
sleeps 100 ms (``vTaskDelay``) after each reading, so pressure changes every ``r`` rows with
``r · P = T_baro ≥ 0.1 s`` (the task's execution time adds to the sleep). The cadence therefore
gives a *lower bound* ``P ≥ 0.1 s / r`` and, with the magnetometer's P, the baro task's true period
``T_baro = r · P``, which must be the same for every file of one logger and firmware.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .formats import InertialLog

#: steps below this multiple of the shortest tenth count as one magnetometer sample (row_offsets_from_magnetometer)
SINGLE_STEP_FACTOR = 1.5
#: sleep of the flatball firmware's barometer task between readings (s): a lower bound of its period
FLATBALL_BARO_SLEEP = 0.100


@dataclass
class PeriodEstimate:
    """Row period from the magnetometer and the gyroscope over one window.

    Attributes
    ----------
    period : float
        Row period over the whole window, s.
    sd : float
        Standard error from the scatter over sub-windows, s.
    windows : ndarray, shape (k,)
        The period of each sub-window, s.
    n_rows : int
        Logger rows spanned by the window.
    phase_sign : int
        Sign of Σ Δφ / Σ ω_z (−1 expected for a world-fixed field, see the module docstring).
    detail : dict
        Circle centre and radius (µT), relative radius scatter, total phase (rad), largest phase
        step per row (rad).
    """

    period: float
    sd: float
    windows: np.ndarray
    n_rows: int
    phase_sign: int
    detail: dict = field(default_factory=dict)


@dataclass
class BaroCadence:
    """How often the pressure reading changes.

    Attributes
    ----------
    rows_per_update : float
        Mean logger rows between pressure updates.
    sd : float
        Its standard error (from the scatter of the update rows about a constant cadence).
    n_updates : int
        Updates used.
    histogram : dict
        Interval (rows) -> count, as found.
    period_lower_bound : float
        ``FLATBALL_BARO_SLEEP / rows_per_update``, s: the row period is at least this.
    """

    rows_per_update: float
    sd: float
    n_updates: int
    histogram: dict
    period_lower_bound: float


def fit_circle(xy: np.ndarray) -> tuple[np.ndarray, float]:
    """Least-squares circle through points (algebraic fit, Kåsa).

    Parameters
    ----------
    xy : ndarray, shape (m, 2)

    Returns
    -------
    (ndarray, float)
        Centre (2,) and radius, in the units of ``xy``.
    """
    a = np.column_stack([2.0 * xy, np.ones(len(xy))])
    b = (xy ** 2).sum(axis=1)
    sol = np.linalg.lstsq(a, b, rcond=None)[0]
    centre = sol[:2]
    return centre, float(math.sqrt(sol[2] + centre @ centre))


def _phase_and_turn(log: InertialLog, a: int, b: int):
    xy = log.mag[a:b, :2]
    centre, radius = fit_circle(xy)
    z = (xy[:, 0] - centre[0]) + 1j * (xy[:, 1] - centre[1])
    dphi = np.angle(z[1:] * np.conj(z[:-1]))
    wz = log.gyro[a:b, 2]
    drow = np.diff(log.rows[a:b]).astype(float)
    turn = 0.5 * (wz[1:] + wz[:-1]) * drow          # ∫ω_z dt / P over each step (rad per unit period)
    return dphi, turn, centre, radius, np.abs(z)


def period_from_mag_gyro(log: InertialLog, start: int, end: int, n_windows: int = 6) -> PeriodEstimate:
    """Row period from the magnetometer's phase against the integrated gyro-z (module docstring).

    Parameters
    ----------
    log : InertialLog
        A recording with ``mag`` (µT) and ``gyro`` (rad/s).
    start, end : int
        Logger rows of the window (end exclusive), e.g. a throw's free flight.
    n_windows : int
        Sub-windows for the uncertainty (>= 2).

    Returns
    -------
    PeriodEstimate
    """
    if log.mag is None:
        raise ValueError(f"{log.name}: no magnetometer data")
    if n_windows < 2:
        raise ValueError("n_windows must be >= 2")
    a = int(np.searchsorted(log.rows, start))
    b = int(np.searchsorted(log.rows, end))
    if b - a < 4 * n_windows:
        raise ValueError(f"{log.name}: window {start}..{end} too short ({b - a} samples) for {n_windows} sub-windows")
    dphi, turn, centre, radius, rad = _phase_and_turn(log, a, b)
    total_turn = float(turn.sum())
    if abs(total_turn) < 2 * math.pi:
        raise ValueError(f"{log.name}: the sensor turns less than one revolution about z in {start}..{end}")
    ratio = float(dphi.sum() / total_turn)
    sign = -1 if ratio < 0 else 1
    windows = np.array([abs(dphi[k].sum() / turn[k].sum()) for k in np.array_split(np.arange(dphi.size), n_windows)])
    return PeriodEstimate(period=abs(ratio), sd=float(windows.std(ddof=1) / math.sqrt(n_windows)),
                          windows=windows, n_rows=int(log.rows[b - 1] - log.rows[a]), phase_sign=sign,
                          detail={"circle_centre_uT": centre.tolist(), "circle_radius_uT": radius,
                                  "radius_rel_scatter": float(rad.std() / radius),
                                  "total_phase_rad": float(dphi.sum()),
                                  "max_phase_step_rad": float(np.abs(dphi).max())})


def row_offsets_from_magnetometer(log: InertialLog) -> tuple[np.ndarray, dict]:
    """Every row's time from the magnetometer's phase, in units of the mean row period (module docstring).

    Parameters
    ----------
    log : InertialLog
        One throw's rows (spinning throughout), with ``mag`` [µT] and ``gyro`` [rad/s].

    Returns
    -------
    (ndarray, dict)
        u (n,) [rows]: u_0 = 0, u_{n−1} = row_{n−1} − row_0, increasing; and a summary: ``mean_period_s``
        τ_n / (row_n − row_0), ``shortest_step_s`` and ``longest_step_s`` per logger row,
        ``sample_period_s`` (the median step among those below :data:`SINGLE_STEP_FACTOR` times the shortest
        tenth: one magnetometer sample), ``rows_by_samples`` ({"1": rows, "2": …}: the steps in whole
        samples), and ``deviation_rms_rows`` and ``deviation_max_rows``, u against the equally spaced rows.

    Raises
    ------
    ValueError
        No magnetometer; fewer than 8 rows; the sensor turns less than one revolution; the field turns
        with the spin instead of against it; or a row whose phase does not advance (the line is named).
    """
    if log.mag is None:
        raise ValueError(f"{log.name}: row times from the magnetometer need a magnetometer")
    n = len(log.rows)
    if n < 8:
        raise ValueError(f"{log.name}: {n} rows are too few for row times from the magnetometer")
    dphi, turn, _, _, _ = _phase_and_turn(log, 0, n)          # turn: ω̄_z Δrow per step [rad/s × rows]
    drow = np.diff(log.rows).astype(float)
    mean_period = abs(dphi.sum() / turn.sum()) if turn.sum() != 0 else 0.0
    if mean_period * abs(turn.sum()) < 2 * math.pi:
        raise ValueError(f"{log.name}: the sensor turns less than one revolution about z")
    expected = -turn * mean_period                                # each step unwrapped around the mean period
    dphi = dphi + 2 * math.pi * np.round((expected - dphi) / (2 * math.pi))
    if np.sum(dphi) * np.sum(turn) >= 0:
        raise ValueError(f"{log.name}: the field's phase turns with the spin, not against it (magnetometer axes?)")
    step = -dphi / (turn / drow)                                    # Δτ_i [s]
    bad = np.flatnonzero(step <= 0)
    if bad.size:
        raise ValueError(f"{log.name}: the magnetometer's phase does not advance from line {log.lines[bad[0]]} "
                         f"to line {log.lines[bad[0] + 1]} ({bad.size} such step(s)); use row_times: uniform")
    tau = np.r_[0.0, np.cumsum(step)]
    rows = (log.rows - log.rows[0]).astype(float)
    u = rows[-1] * tau / tau[-1]
    per_row = step / drow
    single = per_row[per_row < SINGLE_STEP_FACTOR * np.percentile(per_row, 10)]
    sample = float(np.median(single))
    counts = np.round(per_row / sample).astype(int)
    return u, {"mean_period_s": float(tau[-1] / rows[-1]), "shortest_step_s": float(per_row.min()),
               "longest_step_s": float(per_row.max()), "sample_period_s": sample,
               "rows_by_samples": {str(c): int(np.sum(counts == c)) for c in np.unique(counts)},
               "deviation_rms_rows": float(np.sqrt(np.mean((u - rows) ** 2))),
               "deviation_max_rows": float(np.abs(u - rows).max())}


def baro_cadence(log: InertialLog, start: int | None = None, end: int | None = None) -> BaroCadence:
    """Rows between pressure updates (a pressure reading differing from the previous row's).

    An interval of about twice the median counts as two update periods (an update that happened
    to repeat the previous value). The cadence is the slope of the update rows against the update
    count, its standard error from the residuals.

    Parameters
    ----------
    log : InertialLog
        A recording with ``pressure``.
    start, end : int, optional
        Logger rows to use (end exclusive); default the whole log.

    Returns
    -------
    BaroCadence
    """
    if log.pressure is None:
        raise ValueError(f"{log.name}: no pressure data")
    a = 0 if start is None else int(np.searchsorted(log.rows, start))
    b = len(log) if end is None else int(np.searchsorted(log.rows, end))
    p, rows = log.pressure[a:b], log.rows[a:b]
    upd = rows[1:][np.diff(p) != 0.0]
    if upd.size < 5:
        raise ValueError(f"{log.name}: fewer than 5 pressure updates in the window")
    gaps = np.diff(upd)
    med = float(np.median(gaps))
    counts = np.maximum(1, np.rint(gaps / med)).astype(int)
    k = np.concatenate([[0], np.cumsum(counts)]).astype(float)
    slope, icpt = np.polyfit(k, upd.astype(float), 1)
    resid = upd - (slope * k + icpt)
    sxx = float(((k - k.mean()) ** 2).sum())
    sd = float(math.sqrt((resid ** 2).sum() / max(k.size - 2, 1) / sxx))
    values, n = np.unique(gaps, return_counts=True)
    return BaroCadence(rows_per_update=float(slope), sd=sd, n_updates=int(upd.size),
                       histogram={int(v): int(c) for v, c in zip(values, n)},
                       period_lower_bound=FLATBALL_BARO_SLEEP / float(slope))


@dataclass
class TimeBase:
    """Both period estimates of one throw and how they relate.

    Attributes
    ----------
    name : str
        Flight name.
    mag_gyro : PeriodEstimate
    baro : BaroCadence or None
    baro_task_period : float or None
        ``rows_per_update · period``: the barometer task's true period implied by the two, s.
    baro_task_period_sd : float or None
        Its standard error, s.
    consistent_with_bound : bool or None
        Whether the mag/gyro period respects the barometer's lower bound (within 2 sd).
    """

    name: str
    mag_gyro: PeriodEstimate
    baro: BaroCadence | None
    baro_task_period: float | None
    baro_task_period_sd: float | None
    consistent_with_bound: bool | None


def estimate_timebase(log: InertialLog, start: int, end: int, name: str | None = None,
                      n_windows: int = 6) -> TimeBase:
    """Row period of a throw from the magnetometer/gyro and the barometer cadence, same window.

    Parameters
    ----------
    log : InertialLog
        The recording.
    start, end : int
        Logger rows of the throw's free flight (end exclusive); both methods use these rows (the
        firmware's loop period drifts over a file, so the throw's own rows are compared).
    name : str, optional
        Flight name (default the log's).
    n_windows : int
        Sub-windows for the mag/gyro uncertainty.

    Returns
    -------
    TimeBase
    """
    est = period_from_mag_gyro(log, start, end, n_windows)
    baro = baro_cadence(log, start, end) if log.pressure is not None else None
    task = task_sd = ok = None
    if baro is not None:
        task = baro.rows_per_update * est.period
        task_sd = task * math.hypot(baro.sd / baro.rows_per_update, est.sd / est.period)
        ok = bool(est.period + 2 * est.sd >= baro.period_lower_bound)
    return TimeBase(name=log.name if name is None else name, mag_gyro=est, baro=baro, baro_task_period=task,
                    baro_task_period_sd=task_sd, consistent_with_bound=ok)
