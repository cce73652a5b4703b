"""The ``bayes-disc synth`` configuration file (SYNTH.yaml) read into a :class:`.synth.SynthSpec`: launches,
coefficients, gusts, inertial loggers and defects.
"""
from __future__ import annotations

from dataclasses import replace
from pathlib import Path

from ..physics import COEFFICIENT_NAMES, LITERATURE, Coefficients, literature_coefficients
from .config_blocks import read_disc_env, read_markers, read_nature, read_physics
from .config_io import ConfigError, Section, load_yaml
from .inertial_synth import LoggerSpec
from .synth import DEFAULT_MARKERS, ImuSynth, LaunchSpec, PER_THROW_KEYS, SynthSpec
from .synth_defects import DEFECT_KINDS, Defects


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


def _nutation(path, sec: Section, default) -> tuple | None:
    """``nutation: [rms, decay, kappa]`` (rad/s ≥ 0, 1/s > 0, –) or absent (``default``)."""
    if sec.raw("nutation", None) is None:
        return default
    rms, decay, kappa = sec.vector("nutation", 3)
    if rms < 0 or decay <= 0:
        raise ConfigError(path, sec.key("nutation"), f"[rms ≥ 0, decay > 0, kappa], got {[rms, decay, kappa]}")
    return (rms, decay, kappa)


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
        "baro_dynamic": lambda: sec.number("baro_dynamic", base.baro_dynamic),
        "baro_lag": lambda: sec.number("baro_lag", base.baro_lag, positive=True),
        "baro_noise": lambda: sec.number("baro_noise", base.baro_noise, nonnegative=True),
        "nutation": lambda: _nutation(path, sec, base.nutation),
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
                                                   "acc_noise", "gyro_bias", "acc_bias", "lpf_state", "field_uT",
                                                   "baro_dynamic", "baro_lag", "baro_noise", "nutation"))
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
