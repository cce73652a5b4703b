"""Inertial recordings of a run: throws found in the logs, their time base, and data-derived starts.

For every ``imu:`` source of the configuration the log is read (repairs reported), its throws found
(release to first impact; explicit rows when the configuration gives them), each throw's row period
estimated from the magnetometer against the gyro (:mod:`bayes_disc.observation.imu.timebase`; used only
to start the fit and to cross-check the period the flight model estimates), and the throw classified:
a disc flown upside down (a hammer) is outside the right-side-up flight model and is reported as
``out_of_model``, never fitted.

Start of an inertial throw: body rates ω_0 from the gyro at release, the disc level, and the air velocity
in body axes u = V (cos α cos ψ, cos α sin ψ, sin α) chosen on a grid of speeds V, angles of attack α and
directions ψ in the disc plane (the "spin phase" of the airflow relative to the logger's axes, which the
data determine but no simple formula gives) by the smallest noise-weighted misfit of the flight simulated
with the wind-tunnel coefficients.
"""
from __future__ import annotations

import logging
from dataclasses import dataclass, field

import numpy as np

from ...observation.imu import (estimate_timebase, find_throws, landing_log, read_imu, row_offsets_from_magnetometer,
                                throw_logs)
from ...observation.imu.formats import ImuFileError, InertialLog
from ...observation.models.inertial import InertialMeasurements
from ...observation.models.magnetometer import MAG_OWN_PARAMETERS
from ...physics import literature_coefficients

log = logging.getLogger(__name__)

#: nominal row period [s] when a log has no magnetometer to estimate it from (firmware loop 100 Hz)
NOMINAL_PERIOD = 0.010
#: time after a throw's impact whose barometer readings are used (the sensor's relaxation on the ground) [s]
LANDING_SPAN = 1.5
#: noise scales [rad/s, m/s²] weighting gyro against accelerometer misfit in the start search
START_WEIGHTS = np.array([0.1, 0.1, 0.1, 1.0, 1.0, 1.0])


@dataclass
class InertialThrow:
    """One throw of an inertial log: the free-flight sub-log, where it came from and whether it is fitted."""

    log: InertialLog
    source: str
    status: str                      # ok | out_of_model
    reason: str
    segment: dict = field(default_factory=dict)
    period_mag_gyro: float | None = None
    period_mag_gyro_sd: float | None = None
    repairs: list = field(default_factory=list)
    magnetometer: bool = True        # the source allows its magnetometer to be used (when the log has one)
    barometer: bool = False          # the source asks for its barometer to be used (when the log has one)
    landing: InertialLog | None = None   # rows right after the impact (the barometer's relaxation)
    row_times: str = "uniform"       # rows equally spaced in time, or placed by the magnetometer's phase
    row_time_summary: dict | None = None   # with row_times "magnetometer": how far the rows lie from equally spaced
    gyro_noise: str = "white"        # transverse gyro noise: white, or with a randomly forced nutation

    @property
    def name(self) -> str:
        return self.log.name

    def to_dict(self) -> dict:
        return {"source": self.source, "status": self.status, "reason": self.reason, "segment": self.segment,
                "rows": int(len(self.log.rows)), "period_mag_gyro_s": self.period_mag_gyro,
                "period_mag_gyro_sd_s": self.period_mag_gyro_sd, "row_times": self.row_times,
                "row_time_summary": self.row_time_summary, "gyro_noise": self.gyro_noise, "repairs": self.repairs}


def load_run_throws(cfg) -> list[InertialThrow]:
    """Every throw of the configuration's ``imu:`` sources (fitted ones and out-of-model ones).

    Parameters
    ----------
    cfg : RunConfig

    Returns
    -------
    list of InertialThrow
    """
    out = []
    for src in cfg.imu:
        for rec in read_imu(src.file, src.format):
            for r in rec.repairs:
                log.info("%s: repaired: %s", src.file.name, r)
            if rec.times is not None:          # imu-csv: each flight is a free flight from its first row
                out.append(InertialThrow(rec, str(src.file), "ok", "timed log: whole flight", repairs=rec.repairs,
                                         magnetometer=src.magnetometer, barometer=src.barometer,
                                         gyro_noise=src.gyro_noise))
                continue
            segments = find_throws(rec, override=list(src.throws) if src.throws else None)
            if not segments:
                raise ImuFileError(src.file, None, "no throw found (|gyro| never exceeds the spin threshold); "
                                   "give the rows with imu[..].throws")
            starts = [s.start for s in segments[1:]] + [None]
            for seg, sub, nxt in zip(segments, throw_logs(rec, segments), starts):
                status, reason, tb = "ok", seg.reason, None
                if rec.mag is not None:
                    try:
                        tb = estimate_timebase(rec, seg.start + 5, seg.end, name=seg.name)
                    except ValueError as e:     # e.g. a throw too short for the barometer cadence
                        reason += f"; no independent row-period estimate ({e})"
                        log.warning("%s: no independent row-period estimate: %s", seg.name, e)
                if seg.orientation == "upside_down":
                    status = "out_of_model"
                    reason = ("flown upside down (accelerometer z shows the lift along +b3): the flight model is "
                              "for a right-side-up disc; not fitted")
                info = {"start_row": int(seg.start), "end_row": int(seg.end), "orientation": seg.orientation,
                        "reason": seg.reason}
                period = None if tb is None else float(tb.mag_gyro.period)
                placed = None
                if src.row_times == "magnetometer" and status == "ok":
                    try:
                        placed = row_offsets_from_magnetometer(sub)[1]
                    except ValueError as e:
                        raise ImuFileError(src.file, None, f"row_times: magnetometer: {e}") from e
                landing = landing_log(rec, seg, int(LANDING_SPAN / (period or NOMINAL_PERIOD)), nxt)
                out.append(InertialThrow(sub, str(src.file), status, reason, info, period,
                                         None if tb is None else float(tb.mag_gyro.sd), list(rec.repairs),
                                         magnetometer=src.magnetometer, barometer=src.barometer, landing=landing,
                                         row_times=src.row_times, row_time_summary=placed,
                                         gyro_noise=src.gyro_noise))
    names = [t.name for t in out]
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise ImuFileError(out[0].source, None, f"throw name(s) {dup} appear in more than one log")
    return out


def inertial_model(throw: InertialThrow, env) -> InertialMeasurements:
    """The observation model of a throw (nominal period: the magnetometer/gyro estimate, else 10 ms); its
    magnetometer is used when the log carries one and the source does not switch it off, its barometer when
    the log carries one and the source asks for it (with the rows after the impact when the throw has them),
    its rows placed in time as the source says (``row_times``), its transverse gyro noise as the source says
    (``gyro_noise``).

    Parameters
    ----------
    throw : InertialThrow
    env : Environment
        The run's air density [kg/m³] and gravitational acceleration [m/s²].

    Returns
    -------
    InertialMeasurements
    """
    barometer = throw.barometer and throw.log.pressure is not None
    landing = throw.landing if barometer and throw.landing is not None and throw.landing.pressure is not None else None
    return InertialMeasurements(throw.log, env.g, period=throw.period_mag_gyro or NOMINAL_PERIOD,
                                magnetometer=throw.magnetometer and throw.log.mag is not None,
                                barometer=barometer, rho=env.rho, landing=landing, row_times=throw.row_times,
                                gyro_noise=throw.gyro_noise)


def magnetometer_shared_start(models) -> dict:
    """Starting values {name: value} of the field and hard iron from the throws' magnetometers: the hard
    iron's x, y at the mean centre of the circles the field draws in the sensor's x–y plane, H at their
    median radius, Z at its prior centre and the hard iron's z at the mean axial reading minus Z (Z and
    h_z are told apart only by the disc's tilts, which the fit resolves).

    Parameters
    ----------
    models : iterable of InertialMeasurements
        The run's inertial models (those without the magnetometer are skipped).

    Returns
    -------
    dict
        Empty when no model uses its magnetometer.
    """
    from ...observation.imu.timebase import fit_circle
    from ...observation.models.magnetometer import MAG_SHARED_PARAMETERS
    centres, radii, axial = [], [], []
    for m in models:
        if isinstance(m, InertialMeasurements) and m.magnetometer:
            c, r = fit_circle(m.log.mag[:, :2])
            centres.append(c)
            radii.append(r)
            axial.append(float(np.mean(m.log.mag[:, 2])))
    if not centres:
        return {}
    down = MAG_SHARED_PARAMETERS[1].off_value
    cx, cy = np.mean(centres, axis=0)
    return {"mag_field_horizontal": float(np.median(radii)), "mag_field_down": down, "mag_hard_iron_x": float(cx),
            "mag_hard_iron_y": float(cy), "mag_hard_iron_z": float(np.mean(axial)) - down}


def heading_start(problem, k: int, n: int = 72) -> float:
    """The field heading ψ [rad] of inertial flight k that best fits its magnetometer along the flight
    simulated from the problem's start vector (a grid of ``n`` headings over a turn); NaN without one."""
    from dataclasses import replace
    theta = problem.start_vector()[None]
    for j, c in enumerate(problem.channels[k]):
        if not (isinstance(c, InertialMeasurements) and c.magnetometer):
            continue
        tr = problem._run(theta, k, want_states=True, times=c.times)
        if not tr.ok[0]:
            return float("nan")
        cols = problem.channel_columns(k)[j]
        extra = np.repeat(theta[:, cols], n, axis=0)
        psi = 2 * np.pi * np.arange(n) / n
        extra[:, len(c.shared_parameters) + c.parameters.index(MAG_OWN_PARAMETERS[0])] = psi
        pred = c.predict(replace(tr, states=np.repeat(tr.states, n, axis=0)), extra)
        cost = np.nanmean((pred[:, c._seen[:, 6]][..., 6:9] - c.measured[c._seen[:, 6], 6:9][None]) ** 2,
                          axis=(1, 2))
        return float(psi[int(np.nanargmin(cost))])
    return float("nan")


def level_start(throw: InertialThrow, speed: float = 12.0, alpha: float = 0.1, phase: float = 0.0) -> np.ndarray:
    """A (13,) start state: release height 1 m, level right-side-up disc, body rates from the gyro at
    release, air velocity V (cos α cos ψ, cos α sin ψ, sin α) in body axes."""
    from ...physics.frames import matrix_to_quat
    from .problem import INERTIAL_RELEASE_HEIGHT, R_LEVEL
    u = speed * np.array([np.cos(alpha) * np.cos(phase), np.cos(alpha) * np.sin(phase), np.sin(alpha)])
    return np.r_[0.0, 0.0, INERTIAL_RELEASE_HEIGHT, R_LEVEL @ u, matrix_to_quat(R_LEVEL), throw.log.gyro[0]]


def own_start(model: InertialMeasurements, throw: InertialThrow) -> np.ndarray:
    """Starting values of a throw's own parameters: the period from the magnetometer/gyro, the filter
    state from the first accelerometer row, biases 0."""
    vals = {p.name: p.off_value for p in model.parameters}
    if "imu_period" in vals:
        vals["imu_period"] = model.period
    for a, v in zip("xyz", throw.log.acc[0]):
        vals[f"lpf_state_{a}"] = float(v)
    return np.array([vals[p.name] for p in model.parameters])


def search_starts(problem, k: int, speeds=(9.0, 13.0, 17.0), alphas=(0.0, 0.15, 0.35), phases=8) -> np.ndarray:
    """The (13,) start state of inertial flight k with the smallest weighted misfit over the grid of the
    module docstring (coefficients: Potts & Crowther; other parameters at the problem's start)."""
    if problem.layout.flight_ic[k].kind != "inertial":
        raise ValueError(f"flight {problem.flights[k].name!r} has markers: its start comes from them")
    base = problem.start_vector()
    base[: problem.n_coef] = literature_coefficients("potts_crowther").as_array()
    grid = [(v, a, 2 * np.pi * j / phases) for v in speeds for a in alphas for j in range(phases)]
    thetas = np.repeat(base[None], len(grid), axis=0)
    w0 = problem.start_states[k][10:13]
    for i, (v, a, ph) in enumerate(grid):
        u = v * np.array([np.cos(a) * np.cos(ph), np.cos(a) * np.sin(ph), np.sin(a)])
        thetas[i, problem.ic_slice(k)] = np.r_[0.0, 0.0, u, w0]
    preds, ok = problem.channel_predictions(thetas, k)
    cost = np.zeros(len(grid))
    for c, p in preds:
        if isinstance(c, InertialMeasurements):
            r = (p[..., :6] - c.measured[None, :, :6]) / START_WEIGHTS
            cost += np.nanmean(r ** 2, axis=(1, 2))
    cost[~ok | ~np.isfinite(cost)] = np.inf
    best = int(np.argmin(cost))
    v, a, ph = grid[best]
    log.info("%s: start V %.0f m/s, α %.0f°, airflow direction %.0f° in the disc plane (weighted misfit %.3g)",
             problem.flights[k].name, v, np.degrees(a), np.degrees(ph), cost[best])
    u = v * np.array([np.cos(a) * np.cos(ph), np.cos(a) * np.sin(ph), np.sin(a)])
    return problem.ic_to_state(np.r_[0.0, 0.0, u, w0], k)[0]
