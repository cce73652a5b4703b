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
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from ..physics import (COEFFICIENT_NAMES, LITERATURE, Coefficients, Disc, Environment, Trajectories, get_terms,
                       literature_coefficients, simulate)
from ..physics.conditions import flight_conditions
from ..physics.nature import get_nature
from ..physics.frames import (attitude_from_yaw_pitch_roll, omega_body_from_pqr,
                              quat_to_matrix)
from .config_blocks import read_disc_env, read_markers, read_nature, read_physics  # noqa: F401 (moved; imported back)
from .config_io import ConfigError, Section, load_yaml
from .registry import split_extensions
from .markers import FlightObservation, table_from_flights, write_marker_csv
from .imu.formats import InertialLog, write_flatball_ins, write_imu_csv
from .inertial_synth import LoggerSpec, recorded_throw, synthetic_log

#: kinds of data defect (``defects:`` keys)
DEFECT_KINDS = ("outliers", "swaps", "ar1", "sigma_m")


@dataclass(frozen=True)
class Defects:
    """Data defects of one synthetic flight (module docstring); the defaults are off.

    Attributes
    ----------
    outlier_fraction : float
        Fraction of the observed points made gross outliers.
    outlier_size_m : tuple of float
        (low, high) displacement of an outlier [m]; the size is uniform in it, the direction uniform on
        the sphere.
    swap_frames : int
        Number of frames (sample times) in which two markers' labels are exchanged.
    swap_fraction : float
        Fraction of the frames with a swap (added to ``swap_frames``: ``round(fraction · n_frames)``).
    ar1_rho : float
        AR(1) coefficient ρ of the marker noise between consecutive samples (0: white noise).
    sigma_fraction : float
        Fraction of the flight's samples with ``sigma_factor`` × the noise.
    sigma_factor : float
        Noise multiplier k of those samples.
    sigma_where : str
        ``segment`` (one contiguous block of samples, all markers) or ``random`` (random points).
    """

    outlier_fraction: float = 0.0
    outlier_size_m: tuple = (0.02, 0.06)
    swap_frames: int = 0
    swap_fraction: float = 0.0
    ar1_rho: float = 0.0
    sigma_fraction: float = 0.0
    sigma_factor: float = 1.0
    sigma_where: str = "segment"
    per_point_sigma: bool = False   # write a sigma_m column (set when any sigma_m block is given)

    @property
    def any(self) -> bool:
        """Whether the flight has any defect (or a sigma_m column)."""
        return (self.outlier_fraction > 0 or self.swap_frames > 0 or self.swap_fraction > 0 or self.ar1_rho != 0
                or self.per_point_sigma)


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
        ext, w, off = self.extension()[:, None], np.zeros(3), 0
        for t in self.terms:
            if t.air is not None:
                w += np.array(t.air(ext, off, 0, 0.0, *map(float, position)))
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


# ------------------------------------------------------------------------------------------- defects
def ar1_noise(z: np.ndarray, rho: float) -> np.ndarray:
    """Unit-variance AR(1) noise along the first axis from white standard normals.

    e_0 = z_0, e_t = ρ e_{t−1} + √(1−ρ²) z_t: stationary from the first sample, Var e_t = 1,
    Corr(e_t, e_{t+k}) = ρ^k.

    Parameters
    ----------
    z : ndarray, shape (n, ...)
        White N(0, 1) draws; axis 0 is time (one sample interval per step).
    rho : float
        AR(1) coefficient, |ρ| < 1 (0 returns ``z`` itself).

    Returns
    -------
    ndarray, shape of ``z``
    """
    if rho == 0.0:
        return z
    e = np.empty_like(z)
    e[0] = z[0]
    c = np.sqrt(1.0 - rho * rho)
    for t in range(1, z.shape[0]):
        e[t] = rho * e[t - 1] + c * z[t]
    return e


def point_sigmas(n: int, n_markers: int, sigma: float, d: Defects, rng: np.random.Generator):
    """Every point's noise sd: ``sigma`` [m], times ``d.sigma_factor`` on a fraction of the samples.

    Parameters
    ----------
    n, n_markers : int
        Samples and markers of the flight.
    sigma : float
        The flight's noise sd [m].
    d : Defects
        ``sigma_fraction`` of the samples (``segment``: one contiguous block of all markers, at a uniformly
        random place; ``random``: random points) get ``sigma_factor`` × ``sigma``.
    rng : numpy.random.Generator

    Returns
    -------
    sig : ndarray, shape (n, n_markers)
        Point sds [m].
    truth : dict
        fraction, factor, where, and the points with the larger noise (``t_range_s`` index range for a
        segment, ``n_points``).
    """
    sig = np.full((n, n_markers), sigma)
    truth = {"fraction": d.sigma_fraction, "factor": d.sigma_factor, "where": d.sigma_where}
    if d.sigma_fraction <= 0.0:
        truth["n_points"] = 0
        return sig, truth
    if d.sigma_where == "segment":
        m = int(round(d.sigma_fraction * n))
        start = int(rng.integers(0, n - m + 1))
        sig[start:start + m] *= d.sigma_factor
        truth["samples"] = [start, start + m]
        truth["n_points"] = m * n_markers
    else:
        hit = rng.random((n, n_markers)) < d.sigma_fraction
        sig[hit] *= d.sigma_factor
        truth["n_points"] = int(hit.sum())
    return sig, truth


def swap_labels(pos: np.ndarray, sig: np.ndarray | None, d: Defects, rng: np.random.Generator) -> list:
    """Exchange two observed markers' labels in randomly chosen frames (in place).

    Parameters
    ----------
    pos : ndarray, shape (n, n_markers, 3)
        Recorded positions [m], NaN where missing; modified.
    sig : ndarray, shape (n, n_markers), or None
        Point sds [m], exchanged with the positions; modified.
    d : Defects
        ``swap_frames`` + round(``swap_fraction`` · n) frames, among those with ≥ 2 observed markers.
    rng : numpy.random.Generator

    Returns
    -------
    list of (frame, marker a, marker b)
        Indices of every swapped frame and its two markers, in time order.
    """
    observed = np.all(np.isfinite(pos), axis=-1)
    eligible = np.flatnonzero(observed.sum(axis=1) >= 2)
    want = d.swap_frames + int(round(d.swap_fraction * pos.shape[0]))
    if want > eligible.size:
        raise ValueError(f"{want} label swaps asked for but only {eligible.size} frames have two markers")
    out = []
    for i in np.sort(rng.choice(eligible, size=want, replace=False)):
        a, b = np.sort(rng.choice(np.flatnonzero(observed[i]), size=2, replace=False))
        pos[i, [a, b]] = pos[i, [b, a]]
        if sig is not None:
            sig[i, [a, b]] = sig[i, [b, a]]
        out.append((int(i), int(a), int(b)))
    return out


def inject_outliers(pos: np.ndarray, d: Defects, rng: np.random.Generator) -> list:
    """Displace a fraction of the observed points by a gross error (in place).

    Each chosen point moves by s·u, s ~ U(``outlier_size_m``) [m], u uniform on the unit sphere.

    Parameters
    ----------
    pos : ndarray, shape (n, n_markers, 3)
        Recorded positions [m], NaN where missing; modified.
    d : Defects
        ``outlier_fraction`` of the observed points (rounded) become outliers.
    rng : numpy.random.Generator

    Returns
    -------
    list of (frame, marker, offset)
        Index of each outlier's frame and marker and its displacement [m] (list of 3), in time order.
    """
    obs = np.argwhere(np.all(np.isfinite(pos), axis=-1))
    m = int(round(d.outlier_fraction * len(obs)))
    if m == 0:
        return []
    chosen = obs[np.sort(rng.choice(len(obs), size=m, replace=False))]
    u = rng.normal(size=(m, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    size = rng.uniform(d.outlier_size_m[0], d.outlier_size_m[1], size=m)
    out = []
    for (i, k), uj, sj in zip(chosen, u, size):
        off = uj * sj
        pos[i, k] += off
        out.append((int(i), int(k), off.tolist()))
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
            "field_uT": list(spec.field_uT)}


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


# ------------------------------------------------------------------------------------------------------
def _coefficients(path, sec: Section) -> Coefficients:
    raw = sec.raw("coefficients", "hummel2002")
    if isinstance(raw, str):
        if raw not in LITERATURE:
            raise ConfigError(path, "coefficients", f"unknown set {raw!r}; known: {sorted(LITERATURE)}")
        return literature_coefficients(raw)
    base = literature_coefficients("hummel2002").as_dict()
    c = Section(path, raw, "coefficients")
    for n in COEFFICIENT_NAMES:
        base[n] = c.number(n, base[n])
    c.finish()
    return Coefficients.from_mapping(base)


def _gust(path, f: Section) -> tuple | None:
    g = f.section("gust")
    if not g.data:
        return None
    t0 = g.number("t_start", required=True, nonnegative=True)
    t1 = g.number("t_end", required=True, positive=True)
    w = g.vector("wind", 3, required=True)
    g.finish()
    if t1 <= t0:
        raise ConfigError(path, g.key("t_end"), "must be after t_start")
    return (t0, t1, *w)


def _pair(path, sec: Section, name: str, default) -> tuple:
    v = sec.vector(name, 2, list(default))
    if min(v) < 0:
        raise ConfigError(path, sec.key(name), f"noise sds must not be negative, got {v}")
    return tuple(v)


def _logger_values(path, sec: Section, base: LoggerSpec, keys) -> LoggerSpec:
    """LoggerSpec ``base`` with the ``keys`` given in ``sec`` replaced."""
    vals = {}
    readers = {
        "offset": lambda: tuple(sec.vector("offset", 3, list(base.offset))),
        "lpf_tau": lambda: sec.number("lpf_tau", base.lpf_tau, positive=True),
        "tilt": lambda: tuple(sec.vector("tilt", 2, list(base.tilt))),
        "period": lambda: sec.number("period", base.period, positive=True, maximum=1.0),
        "gyro_noise": lambda: _pair(path, sec, "gyro_noise", base.gyro_noise),
        "acc_noise": lambda: _pair(path, sec, "acc_noise", base.acc_noise),
        "gyro_bias": lambda: tuple(sec.vector("gyro_bias", 3, list(base.gyro_bias))),
        "acc_bias": lambda: tuple(sec.vector("acc_bias", 3, list(base.acc_bias))),
        "lpf_state": lambda: (None if sec.raw("lpf_state", None) is None
                              else tuple(sec.vector("lpf_state", 3))),
        "field_uT": lambda: tuple(sec.vector("field_uT", 3, list(base.field_uT))),
    }
    for k in keys:
        vals[k] = readers[k]()
    return replace(base, **vals)


def _read_imu_block(path, sec: Section, name: str, raw_flights: list) -> ImuSynth | None:
    """The ``imu:`` block (logger, format, output) and each flight's own ``imu:`` (overrides or false)."""
    if not sec.has("imu"):
        return None
    s = sec.section("imu")
    logger = _logger_values(path, s, LoggerSpec(), ("offset", "lpf_tau", "tilt", "period", "gyro_noise",
                                                   "acc_noise", "gyro_bias", "acc_bias", "lpf_state", "field_uT"))
    fmt = s.string("format", "flatball-ins", choices=("flatball-ins", "imu-csv"))
    default_out = f"{name}_imu" if fmt == "flatball-ins" else f"{name}_imu.csv"
    output = path.parent / s.string("output", default_out)
    rest_before = s.number("rest_before", 1.0, nonnegative=True)
    rest_after = s.number("rest_after", 0.3, nonnegative=True)
    first_row = s.number("first_row", 0, integer=True, nonnegative=True)
    s.finish()
    flights = {}
    for i, rf in enumerate(raw_flights):
        fname = rf.get("name", f"flight{i + 1}") if isinstance(rf, dict) else None
        own = rf.get("imu", {}) if isinstance(rf, dict) else {}
        if own is False:
            continue
        f = Section(path, own, f"flights[{i}].imu")
        flights[fname] = _logger_values(path, f, logger, PER_THROW_KEYS)
        f.finish()
    return ImuSynth(logger=logger, format=fmt, output=output, rest_before=rest_before, rest_after=rest_after,
                    first_row=first_row, flights=flights)


def _read_defects(path, sec: Section) -> dict:
    """The kinds given in a ``defects:`` block, as :class:`Defects` field values (``sec``: the block)."""
    vals = {}
    unknown = [k for k in sec.data if k not in DEFECT_KINDS]
    if unknown:
        raise ConfigError(path, sec.key(str(unknown[0])), f"unknown defect; known: {list(DEFECT_KINDS)}")
    if sec.has("outliers"):
        o = sec.section("outliers")
        size = o.vector("size_m", 2, [0.02, 0.06])
        if not 0 < size[0] <= size[1]:
            raise ConfigError(path, o.key("size_m"), f"must be [low, high] with 0 < low ≤ high (m), got {size}")
        vals.update(outlier_fraction=o.number("fraction", required=True, minimum=0.0, maximum=0.5),
                    outlier_size_m=tuple(size))
        o.finish()
    if sec.has("swaps"):
        w = sec.section("swaps")
        vals.update(swap_frames=w.number("frames", 0, integer=True, nonnegative=True),
                    swap_fraction=w.number("fraction", 0.0, minimum=0.0, maximum=0.5))
        w.finish()
    if sec.has("ar1"):
        a = sec.section("ar1")
        rho = a.number("rho", required=True)
        if not -1.0 < rho < 1.0:
            raise ConfigError(path, a.key("rho"), f"must be in (−1, 1), got {rho!r}")
        vals["ar1_rho"] = rho
        a.finish()
    if sec.has("sigma_m"):
        g = sec.section("sigma_m")
        vals.update(sigma_fraction=g.number("fraction", 0.0, minimum=0.0, maximum=1.0),
                    sigma_factor=g.number("factor", 1.0, positive=True),
                    sigma_where=g.string("where", "segment", choices=("segment", "random")),
                    per_point_sigma=True)
        g.finish()
    for k in DEFECT_KINDS:
        sec.used.add(k)
    return vals


def load_synth_spec(path) -> tuple[SynthSpec, Path, Path]:
    """Read SYNTH.yaml; returns the spec and the marker/truth output paths (relative to the file)."""
    path = Path(path)
    return synth_spec_from_mapping(load_yaml(path), path)


def synth_spec_from_mapping(data: dict, path) -> tuple[SynthSpec, Path, Path]:
    """A synthetic data set from a SYNTH.yaml mapping already read.

    Parameters
    ----------
    data : dict
        The mapping (keys as SYNTH.yaml: docs/configuration.md).
    path : str or Path
        The file it stands for: named in errors; relative output paths resolve against its folder.

    Returns
    -------
    spec : SynthSpec
    markers_path, truth_path : Path
        Where ``write_synth`` puts the marker file and the truth JSON.

    Raises
    ------
    ConfigError
        For a bad or unknown key, naming it.
    """
    path = Path(path)
    sec = Section(path, data)
    name = sec.string("name", required=True)
    seed = sec.number("seed", 0, integer=True, nonnegative=True)
    rate = sec.number("sample_rate_hz", 120.0, positive=True)
    coef = _coefficients(path, sec)
    disc, env = read_disc_env(path, sec)
    markers = read_markers(path, sec, DEFAULT_MARKERS)
    physics = read_physics(path, sec, marker_ids=tuple(markers))
    nature = read_nature(path, sec)
    out = sec.section("output")
    markers_path = path.parent / out.string("markers", f"{name}_markers.csv")
    truth_path = path.parent / out.string("truth", f"{name}_truth.json")
    out.finish()
    raw_flights = sec.raw("flights", required=True)
    if not isinstance(raw_flights, list) or not raw_flights:
        raise ConfigError(path, "flights", "must be a non-empty list")
    imu = _read_imu_block(path, sec, name, raw_flights)
    common_defects = _read_defects(path, sec.section("defects"))
    flights = []
    for i, rf in enumerate(raw_flights):
        f = Section(path, rf, f"flights[{i}]")
        if imu is not None:
            f.raw("imu")                                   # read above, with the logger
        elif f.has("imu"):
            raise ConfigError(path, f.key("imu"), "a flight's imu needs the top-level imu block (the logger)")
        pitch = f.number("pitch_deg", None, minimum=-90, maximum=90)
        alpha = f.number("alpha_deg", None, minimum=-90, maximum=90)
        if pitch is not None and alpha is not None:
            raise ConfigError(path, f.key("alpha_deg"), "give pitch_deg or alpha_deg, not both")
        flights.append(LaunchSpec(
            name=f.string("name", f"flight{i + 1}"),
            speed=f.number("speed", required=True, positive=True),
            launch_angle_deg=f.number("launch_angle_deg", 0.0, minimum=-90, maximum=90),
            heading_deg=f.number("heading_deg", 0.0),
            position=tuple(f.vector("position", 3, [0.0, 0.0, 1.0])),
            pitch_deg=pitch, alpha_deg=alpha if pitch is None else None,
            roll_deg=f.number("roll_deg", 0.0, minimum=-90, maximum=90),
            spin=f.number("spin", 60.0), p=f.number("p", 0.0), q=f.number("q", 0.0),
            duration=f.number("duration", 1.0, positive=True),
            noise_mm=f.number("noise_mm", 2.0, nonnegative=True),
            dropout=f.number("dropout", 0.0, minimum=0.0, maximum=0.9),
            gust=_gust(path, f),
            defects=Defects(**{**common_defects, **_read_defects(path, f.section("defects"))}),
        ))
        f.finish()
    names = [f.name for f in flights]
    if len(set(names)) != len(names):
        raise ConfigError(path, "flights", f"flight names repeat: {names}")
    if imu is not None:
        for i, f in enumerate(flights):
            if f.gust is not None and f.name in imu.flights:
                raise ConfigError(path, f"flights[{i}].gust", "a gust cannot be recorded by the inertial logger "
                                  "(give this flight `imu: false`)")
    sec.finish()
    spec = SynthSpec(name=name, flights=tuple(flights), coefficients=coef, disc=disc, env=env, markers=markers,
                     physics=physics, nature=nature, sample_rate_hz=rate, seed=seed, imu=imu)
    return spec, markers_path, truth_path
