"""Synthetic flights from a readable description (``bayes-disc synth SYNTH.yaml``).

Each flight is described by its launch: speed [m/s], launch angle above horizontal [deg], heading
[deg], release position [m], the disc attitude as nose-up pitch [deg] (or the angle of attack at
release, ``alpha_deg``) and roll [deg], spin r [rad/s] (> 0 clockwise from above: right-handed
backhand) and optional wobble rates p, q [rad/s]; flight time [s], per-flight marker noise [mm] and a
dropout fraction. Extra physics terms (``physics:``) make data with effects the base model lacks; a
per-flight ``gust`` (a wind that blows only during a time window of one flight) makes a disturbance
that no term of the library describes; ``marker_geometry`` and ``time_offset`` in ``physics:`` make
recordings whose markers sit elsewhere on the disc or are recorded at shifted times. ``nature:`` adds
forms of physics that no formula of the library has (:mod:`bayes_disc.physics.nature`: a ground effect
with another decay law, the wind-tunnel table's α-dependence, a power-law wind shear, a saturating side
force), to see what ``diagnose`` makes of effects that do not follow the library's formulas.
Output: a marker file (docs/data-formats.md) and a truth JSON (coefficients, terms, initial states, noise).

An ``imu:`` block adds what an inertial logger fixed in the disc records during the same flights
(:mod:`.inertial_synth`): sensor position ``offset`` [m], accelerometer filter ``lpf_tau`` [s], ``tilt``
[rad], row ``period`` [s], gyro/acc noise (axial, transverse) and biases, written as ``flatball-ins``
logger files (one per flight, named ``<flight>.csv``: no time column, still rows before release and after
the end, so the throw is found as in real logs) or one ``imu-csv`` file (the free flights only, t from
release). A flight may override the logger's per-throw values (``period``, biases, filter state at
release) under its own ``imu:`` or leave the logger out (``imu: false``). The marker times and the
logger's release are the same instant t = 0, so a run may fit both. The truth JSON records the logger
and each throw's release row.
"""
from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..physics import Coefficients, Disc, Environment, Trajectories, get_terms, literature_coefficients, simulate
from ..physics.conditions import flight_conditions
from ..physics.nature import get_nature
from ..physics.frames import (attitude_from_yaw_pitch_roll, omega_body_from_pqr,
                              quat_to_matrix)
from .registry import split_extensions
from .markers import FlightObservation, table_from_flights, write_marker_csv
from .imu.formats import InertialLog, write_flatball_ins, write_imu_csv
from .inertial_synth import LoggerSpec, recorded_throw, synthetic_log
from .synth_defects import Defects, ar1_noise, inject_outliers, point_sigmas, swap_labels


DEFAULT_MARKERS = {"0": [0.100, 0.000, -0.015], "1": [-0.0308, 0.0846, -0.015], "2": [-0.0707, -0.0778, -0.015]}


@dataclass(frozen=True)
class LaunchSpec:
    """How one synthetic flight is thrown (angles in degrees, SI otherwise)."""

    name: str
    speed: float
    launch_angle_deg: float = 0.0
    heading_deg: float = 0.0
    position: tuple = (0.0, 0.0, 1.0)
    pitch_deg: float | None = None
    alpha_deg: float | None = None
    roll_deg: float = 0.0
    spin: float = 60.0
    p: float = 0.0
    q: float = 0.0
    duration: float = 1.0
    noise_mm: float = 2.0
    dropout: float = 0.0
    gust: tuple | None = None     # (t_start, t_end, w_x, w_y, w_z): extra wind [m/s] during [t_start, t_end) s
    defects: Defects = Defects()  # data defects (off by default)

    def initial_state(self, wind=None) -> np.ndarray:
        """State (13,) at release: position, velocity, quaternion, body ω."""
        gam, psi = np.radians(self.launch_angle_deg), np.radians(self.heading_deg)
        v = self.speed * np.array([np.cos(gam) * np.cos(psi), np.cos(gam) * np.sin(psi), np.sin(gam)])
        if self.pitch_deg is not None:
            pitch = np.radians(self.pitch_deg)
        else:
            # air-relative flight-path angle + α; exact for zero roll and wind
            va = v - (0.0 if wind is None else np.asarray(wind, float))
            pitch = np.arctan2(va[2], np.hypot(va[0], va[1])) + np.radians(self.alpha_deg or 0.0)
        q = attitude_from_yaw_pitch_roll(psi, pitch, np.radians(self.roll_deg))
        w = omega_body_from_pqr((self.p, self.q, self.spin), v, q, wind)
        return np.concatenate([self.position, v, q, w])


#: logger values a flight may override under its own ``imu:`` (per throw in the inertial model)
PER_THROW_KEYS = ("period", "gyro_bias", "acc_bias", "lpf_state")


@dataclass(frozen=True)
class ImuSynth:
    """The inertial logger of a synthetic data set and how its logs are written.

    Attributes
    ----------
    logger : LoggerSpec
        The logger (shared mount: offset, filter, tilt, noise; default per-throw values).
    format : str
        ``flatball-ins`` (one file per flight, ``<output>/<flight>.csv``) or ``imu-csv`` (one file).
    output : Path
        Folder (flatball-ins) or file (imu-csv).
    rest_before, rest_after : float
        Still time before release and after the end [s] (flatball-ins).
    first_row : int
        Step counter of every log's first row (flatball-ins).
    flights : dict
        Flight name -> LoggerSpec of that throw (flights without a logger absent).
    """

    logger: LoggerSpec
    format: str
    output: Path
    rest_before: float = 1.0
    rest_after: float = 0.3
    first_row: int = 0
    flights: dict = field(default_factory=dict)


@dataclass(frozen=True)
class SynthSpec:
    """A synthetic data set: constants, coefficients, extra physics, markers and flights."""

    name: str
    flights: tuple[LaunchSpec, ...]
    coefficients: Coefficients = field(default_factory=lambda: literature_coefficients("hummel2002"))
    disc: Disc = Disc()
    env: Environment = Environment()
    markers: dict = field(default_factory=lambda: dict(DEFAULT_MARKERS))
    physics: dict = field(default_factory=dict)  # term id -> {parameter: value}
    nature: dict = field(default_factory=dict)   # form of nature id (physics.nature) -> {parameter: value}
    sample_rate_hz: float = 120.0
    seed: int = 0
    imu: ImuSynth | None = None

    @property
    def terms(self):
        """Physics terms of the data: the ``physics`` entries that are not data explanations, then the
        forms of ``nature``."""
        return split_extensions(self.physics)[0] + get_nature(self.nature)

    def extension(self) -> np.ndarray:
        """The terms' parameter values, in :attr:`terms` order (a parameter not given: its off value)."""
        vals = []
        for term in self.terms:
            given = self.physics[term.id] if term.id in self.physics else self.nature[term.id]
            for p in term.parameters:
                vals.append(float(given.get(p.name, p.off_value)))
        return np.array(vals, float)

    def wind_at(self, position) -> np.ndarray | None:
        """Σ of the terms' wind velocities [m/s] (3,) at ``position`` (3,) [m] and t = 0; None without
        wind."""
        terms = [t for t in self.terms if t.air is not None]
        if not terms:
            return None
        ext, w, off = self.extension(), np.zeros(3), 0
        for t in self.terms:
            if t.air is not None:
                w += np.array(t.air(ext, off, 0.0, *map(float, position)))
            off += len(t.parameters)
        return w


def _simulate_flight(spec: SynthSpec, f: LaunchSpec, y0: np.ndarray, times: np.ndarray, mb: np.ndarray, terms,
                     ext: np.ndarray):
    """One flight's trajectory from its release at t = 0 to ``times`` (≥ 0); with a gust, three segments
    (before, during with the gust's wind added, after), each started from the previous one's final state."""
    def run(y, ts, t0, gust=None):
        tt, ee = terms, ext
        if gust is not None:
            wind_ids = [t.id for t in terms]
            if "wind" in wind_ids:
                j = sum(len(t.parameters) for t in terms[: wind_ids.index("wind")])
                ee = ext.copy()
                ee[j: j + 3] += gust
            else:
                (wind,) = get_terms(["wind"])
                shape = [p.off_value for p in wind.parameters[3:]]          # no shear: the gust is uniform
                tt, ee = terms + (wind,), np.r_[ext, gust, shape]
        tr = simulate(y, spec.coefficients.as_array(), ts, t0=t0, disc=spec.disc, env=spec.env, marker_body=mb,
                      terms=tt, extension=ee if ee.size else None)
        if not tr.ok[0]:
            raise ValueError(f"synthetic flight {f.name!r}: simulation failed ({tr.failure_reasons()[0]})")
        return tr
    if f.gust is None:
        return run(y0, times, 0.0)
    g0, g1 = float(f.gust[0]), float(f.gust[1])
    w = np.asarray(f.gust[2:5], float)
    cuts = [0.0, g0, g1, np.inf]
    states, markers, y, t_start = [], [], y0, 0.0
    for i in range(3):
        sel = (times >= cuts[i]) & (times < cuts[i + 1])
        end = min(cuts[i + 1], times[-1])
        ts = np.r_[times[sel], end]
        tr = run(y, ts, t_start, w if i == 1 else None)
        states.append(tr.states[0, :-1])
        markers.append(tr.markers[0, :-1])
        y, t_start = tr.states[0, -1], end
    return Trajectories(times=times, states=np.concatenate(states)[None], markers=np.concatenate(markers)[None],
                        status=np.zeros(1, int))


def _recorded_markers(spec: SynthSpec, f: LaunchSpec, y0, times, mb, terms, ext, markers) -> np.ndarray:
    """Markers as recorded, with the data explanations of ``spec.physics`` applied exactly: marker j sits
    at b_j + Δ_j (``marker_geometry``) and is recorded at t + δ_j (``time_offset``; all δ shifted by a
    common amount so that no marker is recorded before the release, which the fit absorbs)."""
    ids = tuple(spec.markers)
    geo, tim = spec.physics.get("marker_geometry"), spec.physics.get("time_offset")
    if not geo and not tim:
        return markers
    delta = np.zeros_like(mb)
    if geo:
        for j, m in enumerate(ids):
            delta[j] = [geo.get(f"marker_{a}_{m}", 0.0) for a in ("b1", "b2", "b3")]
    dt = np.array([0.0] + [(tim or {}).get(f"dt_{m}", 0.0) for m in ids[1:]])
    dt -= min(0.0, dt.min())
    out = np.empty_like(markers)
    for j in range(len(ids)):
        tr = _simulate_flight(spec, f, y0, times + dt[j], (mb[j] + delta[j])[None], terms, ext)
        out[:, j] = tr.markers[0, :, 0]
    return out


@dataclass
class SynthResult:
    """Synthetic data: marker flights, the truth, and the inertial logs (when the spec has a logger).

    Attributes
    ----------
    flights : list of FlightObservation
        Marker recordings (t = 0 at release).
    truth : dict
        Everything the data were made from (the truth JSON).
    imu_logs : list of InertialLog
        One per flight with a logger: the whole recording (flatball-ins, still parts included) or the free
        flight (imu-csv).
    imu : ImuSynth or None
        The logger description (format, output).
    """

    flights: list[FlightObservation]
    truth: dict
    imu_logs: list[InertialLog] = field(default_factory=list)
    imu: ImuSynth | None = None


def _spec_dict(spec: LoggerSpec) -> dict:
    return {"offset_m": list(spec.offset), "lpf_tau_s": spec.lpf_tau, "tilt_rad": list(spec.tilt),
            "period_s": spec.period, "gyro_noise_rad_s": {"axial": spec.gyro_noise[0], "transverse": spec.gyro_noise[1]},
            "acc_noise_m_s2": {"axial": spec.acc_noise[0], "transverse": spec.acc_noise[1]},
            "gyro_bias_rad_s": list(spec.gyro_bias), "acc_bias_m_s2": list(spec.acc_bias),
            "field_uT": list(spec.field_uT), "baro_dynamic": spec.baro_dynamic, "baro_lag_s": spec.baro_lag,
            "baro_noise_pa": spec.baro_noise,
            "nutation": None if spec.nutation is None else dict(zip(("rms_rad_s", "decay_per_s", "kappa"), spec.nutation))}


def _inertial_logs(spec: SynthSpec, rng: np.random.Generator, states0: dict) -> tuple[list, dict]:
    """The logs of every flight with a logger and their truth entries."""
    imu, terms, ext = spec.imu, spec.terms, spec.extension()
    logs, per = [], {}
    for f in spec.flights:
        lspec = imu.flights.get(f.name)
        if lspec is None:
            continue
        if f.gust is not None:
            raise ValueError(f"synthetic flight {f.name!r}: a gust cannot be recorded by the inertial logger "
                             "(the logger synthesizer simulates one flight without segments)")
        kw = dict(disc=spec.disc, env=spec.env, terms=terms, extension=ext if ext.size else None)
        entry = {"period_s": lspec.period, "gyro_bias_rad_s": list(lspec.gyro_bias),
                 "acc_bias_m_s2": list(lspec.acc_bias)}
        if imu.format == "flatball-ins":
            rec = recorded_throw(f.name, states0[f.name], spec.coefficients, f.duration, lspec, rng,
                                 imu.rest_before, imu.rest_after, imu.first_row, **kw)
            logs.append(rec.log)
            entry.update({"file": f"{imu.output.name}/{f.name}.csv", "release_row": rec.release_row,
                          "end_row": rec.end_row, "rows_in_flight": rec.end_row - rec.release_row,
                          "lpf_state_m_s2": rec.lpf_state.tolist()})
        else:
            log = synthetic_log(f.name, states0[f.name], spec.coefficients, f.duration, lspec, rng, timed=True, **kw)
            logs.append(log)
            entry.update({"file": imu.output.name, "release_row": 0, "end_row": int(len(log)),
                          "rows_in_flight": int(len(log))})
        per[f.name] = entry
    truth = {"format": imu.format, "logger": _spec_dict(imu.logger), "rest_before_s": imu.rest_before,
             "rest_after_s": imu.rest_after, "first_row": imu.first_row, "throws": per,
             "note": "file relative to the truth file's folder when output is beside it; release_row: logger "
                     "row of release (t = 0, the first marker sample); end_row: first row after the free flight"}
    return logs, truth


def synthesize(spec: SynthSpec) -> SynthResult:
    """Simulate every flight, add marker noise, drop a random fraction of points and add the defects.

    Parameters
    ----------
    spec : SynthSpec
        The data set.

    Returns
    -------
    SynthResult
        Flights (with per-point ``sigma`` [m] when any flight has a ``sigma_m`` defect) and the truth.

    Long: the random draws happen in one fixed order (simulation, noise, dropout, defects per flight), which
    fixes every data set a seed makes.
    """
    rng = np.random.default_rng(spec.seed)
    ids = tuple(spec.markers)
    mb = np.array([spec.markers[i] for i in ids], float)
    terms, ext = spec.terms, spec.extension()
    flights, truth_flights, states0 = [], {}, {}
    write_sigma = any(f.defects.per_point_sigma for f in spec.flights)
    for index, f in enumerate(spec.flights):
        times = np.arange(int(round(f.duration * spec.sample_rate_hz)) + 1) / spec.sample_rate_hz
        y0 = f.initial_state(spec.wind_at(f.position))
        states0[f.name] = y0
        tr = _simulate_flight(spec, f, y0, times, mb, terms, ext)
        states = tr.states[0]
        recorded = _recorded_markers(spec, f, y0, times, mb, terms, ext, tr.markers[0])
        sigma = f.noise_mm / 1000.0
        d = f.defects
        drng = np.random.default_rng([spec.seed, 2, index])     # the defects' own stream
        sig_pt, sigma_truth = None, None
        if d.ar1_rho == 0.0 and not d.per_point_sigma:
            pos = recorded + rng.normal(0.0, sigma, recorded.shape)
        else:
            # the same standard normals as white noise (so the dropout below is unchanged), made AR(1) and
            # scaled by every point's sd
            z = ar1_noise(rng.normal(0.0, 1.0, recorded.shape), d.ar1_rho)
            sig_pt, sigma_truth = point_sigmas(times.size, len(ids), sigma, d, drng)
            pos = recorded + sig_pt[..., None] * z
        drop = rng.random(pos.shape[:2]) < f.dropout
        pos[drop] = np.nan
        if sig_pt is None and write_sigma:
            sig_pt = np.full(pos.shape[:2], sigma)
        defects_truth = None
        if d.any:
            swaps = swap_labels(pos, sig_pt, d, drng)
            outliers = inject_outliers(pos, d, drng)
            defects_truth = {
                "outliers": {"fraction": d.outlier_fraction, "size_m": list(d.outlier_size_m),
                             "points": [{"t": float(times[i]), "marker": ids[k], "offset_m": off}
                                        for i, k, off in outliers]},
                "swaps": {"frames": [{"t": float(times[i]), "markers": [ids[a], ids[b]]} for i, a, b in swaps]},
                "ar1_rho": d.ar1_rho,
                "sigma_m": sigma_truth,
            }
        flights.append(FlightObservation(name=f.name, source="synth", times=times, marker_ids=ids, positions=pos,
                                         sigma=sig_pt))
        alpha = flight_conditions(states, times, terms, ext if ext.size else None).alpha[0]
        omega_w = np.einsum("nij,nj->ni", quat_to_matrix(states[:, 6:10]), states[:, 10:13])
        truth_flights[f.name] = {
            "initial_state": {"t": 0.0, "position_m": y0[:3].tolist(), "velocity_m_s": y0[3:6].tolist(),
                              "quaternion_wxyz_body_to_world": y0[6:10].tolist(),
                              "omega_body_rad_s": y0[10:13].tolist()},
            "launch": {k: v for k, v in f.__dict__.items() if k not in ("name", "defects")},
            "noise_m": sigma,
            "dropout": f.dropout,
            "n_dropped": int(drop.sum()),
            "alpha_range_deg": [float(np.degrees(alpha.min())), float(np.degrees(alpha.max()))],
            "speed_range_m_s": [float(np.linalg.norm(states[:, 3:6], axis=1).min()),
                                float(np.linalg.norm(states[:, 3:6], axis=1).max())],
            "spin_range_rad_s": [float(np.abs(omega_w[:, 2]).min()), float(np.abs(omega_w[:, 2]).max())],
            "range_m": float(np.linalg.norm(states[-1, :2] - states[0, :2])),
        }
        if defects_truth is not None:
            truth_flights[f.name]["defects"] = defects_truth
    truth = {
        "name": spec.name, "seed": spec.seed, "sample_rate_hz": spec.sample_rate_hz,
        "coefficients": spec.coefficients.as_dict(), "physics": spec.physics,
        **({"nature": spec.nature} if spec.nature else {}),
        "disc": spec.disc.__dict__, "environment": spec.env.__dict__, "markers": spec.markers,
        "flights": truth_flights,
    }
    logs = []
    if spec.imu is not None:
        # a separate stream, so that adding a logger leaves the marker noise of the same seed unchanged
        logs, truth["imu"] = _inertial_logs(spec, np.random.default_rng([spec.seed, 1]), states0)
    return SynthResult(flights=flights, truth=truth, imu_logs=logs, imu=spec.imu)


def write_synth(result: SynthResult, markers_path, truth_path) -> None:
    """Write the marker file, the truth JSON and (with a logger) the inertial logs.

    Parameters
    ----------
    result : SynthResult
        From :func:`synthesize`.
    markers_path, truth_path : str or Path
        Marker CSV (docs/data-formats.md) and truth JSON; the inertial logs go where ``result.imu.output`` says
        (flatball-ins: ``<output>/<flight>.csv``, one per flight; imu-csv: one file).
    """
    write_marker_csv(markers_path, table_from_flights(result.flights))
    Path(truth_path).parent.mkdir(parents=True, exist_ok=True)
    Path(truth_path).write_text(json.dumps(result.truth, indent=2))
    if result.imu is None or not result.imu_logs:
        return
    out = Path(result.imu.output)
    if result.imu.format == "flatball-ins":
        out.mkdir(parents=True, exist_ok=True)
        for log in result.imu_logs:
            write_flatball_ins(out / f"{log.name}.csv", log)
    else:
        out.parent.mkdir(parents=True, exist_ok=True)
        write_imu_csv(out, result.imu_logs)
