"""Run configuration (docs/configuration.md plus bayes-disc's own keys), validated up front.

Keys beyond those of docs/configuration.md (all optional):

```yaml
sampler:                 # emcee settings
  ensembles: 4           # independent ensembles; R-hat is computed across them
  walkers: 0             # per ensemble; 0 = 2·dim + 2, at most 128 when block moves are enabled
  max_steps: 3000        # cap per ensemble
  check_every: 50        # steps between convergence checks
  min_steps: 300
  n_tau: 10              # stop when every chain is ≥ n_tau · τ long (τ: emcee's estimator) ...
  rhat: 1.01             # ... R-hat across ensembles is below this ...
  ess: 400               # ... and every coefficient's bulk ESS reaches this
  independence_fraction: 0.8   # share of the independence (ridge-aware) jumps (rest: DE moves)
  block_fraction: 0.3    # share of the flight-block moves (Gibbs sweeps over flights, shared shifts),
                         # used when the walkers are fewer than 2·dim + 2; 0 = never
  adapt_steps: 75        # warm-up: the proposals are re-fitted after 75 and 150 steps
  seed: 1
  processes: 2           # ensembles run in parallel processes
least_squares: {starts: 4, max_nfev: 200}
prior: {coefficients: potts_crowther, initial_conditions: flat}   # or a name, or {around: ...};
                                         # initial_conditions: flat | reference (.priors)
simulator: {method: vern7, step_factor: null}   # Runge–Kutta tableau and step factor (kernel defaults)
physics: {side_force: {CY: 0.0}}        # extra terms (physics.TERMS) and data explanations
                                         # (marker_geometry, time_offset); values are starting guesses
flight_options:                          # per flight, by name
  fffl10: {t_start: 0.0, t_end: 0.8,     # time window [s]
           noise: {model: ar1}}          # this flight's noise model (overrides the top-level keys given)
noise: {model: auto, per_point: auto}   # marker noise model (auto | gaussian | ar1 | robust; auto: chosen
                                         # per flight by evidence at the least squares) and per-point errors
                                         # (auto: use sigma_m / covariance columns when the file has them)
truth: truth.json                        # optional truth file (synthetic data) for reports
imu:                                     # inertial logs (instead of or besides `flights`)
  - file: data/2025-08-31-002-rb.csv
    format: flatball-ins                 # or imu-csv
    throws: [[1007, 1344]]               # optional: release and first-impact rows per throw (default: found)
    magnetometer: true                   # use the log's magnetometer (default true when the log has one)
    barometer: true                      # use the log's barometer (default false)
    row_times: magnetometer              # rows placed in time by the magnetometer's phase (default uniform)
    gyro_noise: nutation                 # transverse gyro noise: white (default), or white plus a randomly
                                         # forced nutation (Kalman filter)
credit: "where the data come from"       # shown in the report wherever the data are shown (licences)
```
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path

from ...observation.config_io import ConfigError, Section, load_yaml
from ...observation.config_blocks import read_disc_env, read_markers, read_physics
from ...observation.models.inertial import ROW_TIMES
from ...observation.models.nutation import GYRO_NOISE
from ...observation.models.noise import NOISE_MODELS, PER_POINT
from ...physics import COEFFICIENT_NAMES, LITERATURE, Disc, Environment, literature_coefficients
from ...physics.kernel import DEFAULT_METHOD, TABLEAUX
from .priors import IC_PRIOR_DEFAULT, IC_PRIORS, CoefficientPrior, prior_around

PRIORS = ("potts_crowther", "weak")
#: ``noise.model: auto``: each flight's marker noise model chosen by evidence
AUTO = "auto"
#: ``noise.model`` values of a run configuration
NOISE_CHOICES = (AUTO,) + NOISE_MODELS


@dataclass(frozen=True)
class SamplerSettings:
    ensembles: int = 4
    walkers: int = 0
    max_steps: int = 3000
    check_every: int = 50
    min_steps: int = 300
    n_tau: float = 10.0
    rhat: float = 1.01
    ess: float = 400.0
    independence_fraction: float = 0.8
    block_fraction: float = 0.3
    adapt_steps: int = 75
    seed: int = 1
    processes: int = 2


@dataclass(frozen=True)
class LeastSquaresSettings:
    starts: int = 4
    max_nfev: int = 200


@dataclass(frozen=True)
class NoiseSettings:
    """Marker noise of a flight (:mod:`bayes_disc.observation.models.noise`): the model and whether
    per-point errors (``sigma_m`` or covariance columns) are used (``auto``: when the file has them).

    ``model: auto`` (the default) leaves the choice among white, AR(1), per-point and robust noise to the
    evidence at the least squares (:mod:`bayes_disc.inference.fitting.noise_choice`); any other value is used
    as given."""

    model: str = AUTO
    per_point: str = "auto"


@dataclass(frozen=True)
class FlightOption:
    t_start: float | None = None
    t_end: float | None = None
    noise: dict = field(default_factory=dict)     # overrides of NoiseSettings' fields for this flight


@dataclass(frozen=True)
class ImuSource:
    """One inertial log of the run: file, format, optional explicit throws (logger rows, end exclusive) and
    whether its magnetometer (default) and barometer (on request) are used (when the log has them), and how
    its rows are placed in time (``row_times``: equally spaced, or by the magnetometer's phase) and what noise its
    transverse gyro has (``gyro_noise``: white, or white plus a randomly forced nutation)."""

    file: Path
    format: str
    throws: tuple[tuple[int, int], ...] | None = None
    magnetometer: bool = True
    barometer: bool = False
    row_times: str = "uniform"
    gyro_noise: str = "white"



def read_prior(path: Path, sec: Section) -> "tuple[str | CoefficientPrior, str]":
    """The ``prior`` key: the coefficients' prior and the initial conditions'.

    ``prior: potts_crowther`` (or ``weak``): a named coefficient set. As a mapping:
    ``prior: {coefficients: weak, initial_conditions: flat}``, or Gaussians around values,
    ``prior: {around: hummel2002, relative_sd: 0.1, sd: {CNr: 1e-5}}`` — ``around`` a literature key
    (``physics.LITERATURE``) or a mapping {coefficient: value} of all ten; sd = relative_sd·|value| unless
    given under ``sd`` (:func:`.priors.prior_around`). ``initial_conditions`` (:data:`.priors.IC_PRIORS`, default
    :data:`.priors.IC_PRIOR_DEFAULT`): ``reference`` adds the conditional reference prior of every flight's
    initial conditions given the coefficients, ``flat`` leaves their wide Gaussians alone (:mod:`.priors`).

    Parameters
    ----------
    path : Path
        The configuration file (for errors).
    sec : Section
        The configuration's top level.

    Returns
    -------
    coefficients : str or CoefficientPrior
        The name of a named set, or the ``around`` prior.
    initial_conditions : str
        ``reference`` or ``flat``.

    Raises
    ------
    ConfigError
        Naming ``prior`` or its sub-key.
    """
    raw = sec.raw("prior", "potts_crowther")
    if not isinstance(raw, dict):
        return sec.string("prior", "potts_crowther", choices=PRIORS), IC_PRIOR_DEFAULT
    p = sec.section("prior")
    ic = p.string("initial_conditions", IC_PRIOR_DEFAULT, choices=IC_PRIORS)
    if not p.has("around"):
        named = p.string("coefficients", "potts_crowther", choices=PRIORS)
        p.finish()
        return named, ic
    if p.has("coefficients"):
        raise ConfigError(path, p.key("coefficients"), "give either a named set (coefficients) or around, not both")
    around = p.raw("around", required=True)
    if isinstance(around, str):
        if around not in LITERATURE:
            raise ConfigError(path, p.key("around"), f"unknown coefficient set {around!r}; known: {sorted(LITERATURE)}")
        values, label = literature_coefficients(around).as_dict(), around
    else:
        v = Section(path, around, p.key("around"))
        values = {n: v.number(n, required=True) for n in COEFFICIENT_NAMES}
        v.finish()
        label = "given values"
    rel = p.number("relative_sd", 0.1, positive=True)
    w = p.section("sd")
    given = {n: w.number(n, positive=True) for n in COEFFICIENT_NAMES if w.has(n)}
    w.finish()
    p.finish()
    try:
        return prior_around(values, rel, given, label=label), ic
    except ValueError as e:
        raise ConfigError(path, "prior", str(e)) from None

IMU_FORMATS = ("flatball-ins", "imu-csv")


@dataclass(frozen=True)
class RunConfig:
    path: Path
    name: str
    files: tuple[Path, ...]
    markers: dict
    disc: Disc = Disc()
    env: Environment = Environment()
    prior: "str | CoefficientPrior" = "potts_crowther"
    ic_prior: str = IC_PRIOR_DEFAULT              # prior.initial_conditions: reference | flat (.priors)
    output: Path = Path("runs/run")
    sampler: SamplerSettings = SamplerSettings()
    least_squares: LeastSquaresSettings = LeastSquaresSettings()
    simulator_method: str = DEFAULT_METHOD
    simulator_step_factor: float | None = None
    physics: dict = field(default_factory=dict)
    flight_options: dict = field(default_factory=dict)
    truth: Path | None = None
    imu: tuple[ImuSource, ...] = ()
    credit: str = ""
    noise: NoiseSettings = NoiseSettings()

    @property
    def marker_ids(self) -> tuple[str, ...]:
        return tuple(self.markers)

    def flight_noise(self, flight: str) -> tuple[NoiseSettings, str]:
        """The noise settings of ``flight`` (top level, overridden by its ``flight_options``) and the
        configuration key that set them (for error messages)."""
        o = self.flight_options.get(flight)
        if o is None or not o.noise:
            return self.noise, "noise"
        return replace(self.noise, **o.noise), f"flight_options.{flight}.noise"

    def with_flight_noise(self, chosen: dict) -> "RunConfig":
        """This configuration with the noise of some flights set explicitly.

        Parameters
        ----------
        chosen : dict
            {flight: {"model": ..., "per_point": ...}}, e.g. the models ``noise: auto`` chose
            (:meth:`bayes_disc.inference.fitting.noise_choice.NoiseChoice.settings`).

        Returns
        -------
        RunConfig
            The same run with those flights' ``flight_options.<flight>.noise`` set (their windows kept).
        """
        options = dict(self.flight_options)
        for flight, noise in chosen.items():
            o = options.get(flight, FlightOption())
            options[flight] = replace(o, noise={**o.noise, **noise})
        return replace(self, flight_options=options)


def load_config(path, output_override=None) -> RunConfig:
    """Read and validate CONFIG.yaml.

    Parameters
    ----------
    path : str or Path
        The configuration file (docs/configuration.md plus the keys of this module's docstring); relative paths in it
        resolve against its folder.
    output_override : str or Path, optional
        Replaces the configuration's output folder.

    Returns
    -------
    RunConfig
        The validated configuration.

    Raises
    ------
    ConfigError
        For every problem, naming the file and the key.
    """
    path = Path(path)
    return config_from_mapping(load_yaml(path), path, output_override=output_override)


def config_from_mapping(data: dict, path, output_override=None) -> RunConfig:
    """Validate a configuration already read into a mapping (same keys and rules as CONFIG.yaml).

    Long: one validation pass over the top-level keys, in the order their errors are reported.

    Parameters
    ----------
    data : dict
        The configuration's top-level mapping.
    path : str or Path
        The file the mapping stands for: errors name it, relative paths resolve against its folder and
        it is recorded as the run's configuration (``RunConfig.path``).
    output_override : str or Path, optional
        Replaces the configuration's output folder.

    Returns
    -------
    RunConfig
        The validated configuration.

    Raises
    ------
    ConfigError
        For every problem, naming ``path`` and the key.
    """
    path = Path(path)
    sec = Section(path, data)
    name = sec.string("name", required=True)
    if any(c in name for c in "/\\") or name.startswith("."):
        raise ConfigError(path, "name", f"must be a plain run name, got {name!r}")
    imu = _read_imu(path, sec)
    raw_flights = sec.raw("flights", None, required=not imu)
    if raw_flights is None:
        raw_flights = []
    elif not isinstance(raw_flights, list) or not raw_flights:
        raise ConfigError(path, "flights", "must be a non-empty list of {file: ...}")
    files = []
    for i, rf in enumerate(raw_flights):
        f = Section(path, rf, f"flights[{i}]")
        file = path.parent / f.string("file", required=True)
        f.finish()
        if not file.is_file():
            raise ConfigError(path, f"flights[{i}].file", f"file not found: {file}")
        files.append(file)
    markers = read_markers(path, sec) if files or "markers" in sec.data else {}
    disc, env = read_disc_env(path, sec)
    prior, ic_prior = read_prior(path, sec)
    out = sec.string("output", None)
    output = (path.parent / out) if out else Path.cwd() / "runs" / name
    if output_override is not None:
        output = Path(output_override)
    s = sec.section("sampler")
    sampler = SamplerSettings(
        ensembles=s.number("ensembles", 4, integer=True, minimum=2),
        walkers=s.number("walkers", 0, integer=True, nonnegative=True),
        max_steps=s.number("max_steps", 3000, integer=True, minimum=10),
        check_every=s.number("check_every", 50, integer=True, minimum=5),
        min_steps=s.number("min_steps", 300, integer=True, minimum=5),
        n_tau=s.number("n_tau", 10.0, positive=True),
        rhat=s.number("rhat", 1.01, minimum=1.0),
        ess=s.number("ess", 400.0, positive=True),
        independence_fraction=s.number("independence_fraction", 0.8, minimum=0.0, maximum=1.0),
        block_fraction=s.number("block_fraction", 0.3, minimum=0.0, maximum=1.0),
        adapt_steps=s.number("adapt_steps", 75, integer=True, minimum=10),
        seed=s.number("seed", 1, integer=True, nonnegative=True),
        processes=s.number("processes", 2, integer=True, minimum=1),
    )
    s.finish()
    ls = sec.section("least_squares")
    least = LeastSquaresSettings(starts=ls.number("starts", 4, integer=True, minimum=1),
                                 max_nfev=ls.number("max_nfev", 200, integer=True, minimum=5))
    ls.finish()
    sim = sec.section("simulator")
    method = sim.string("method", DEFAULT_METHOD, choices=tuple(TABLEAUX))
    step = sim.number("step_factor", None, positive=True)
    sim.finish()
    physics = read_physics(path, sec, marker_ids=tuple(markers) if markers else None)
    fo_raw = sec.raw("flight_options", {}) or {}
    if not isinstance(fo_raw, dict):
        raise ConfigError(path, "flight_options", "must map flight names to options")
    flight_options = {}
    for fname, opts in fo_raw.items():
        o = Section(path, opts, f"flight_options.{fname}")
        fo = FlightOption(t_start=o.number("t_start", None), t_end=o.number("t_end", None),
                          noise=_read_noise(path, o.section("noise"), None))
        o.finish()
        if fo.t_start is not None and fo.t_end is not None and fo.t_end <= fo.t_start:
            raise ConfigError(path, f"flight_options.{fname}.t_end", "must be after t_start")
        flight_options[str(fname)] = fo
    credit = sec.string("credit", None) or ""
    noise = NoiseSettings(**_read_noise(path, sec.section("noise"), NoiseSettings()))
    truth = sec.string("truth", None)
    truth_path = path.parent / truth if truth else None
    if truth_path is not None and not truth_path.is_file():
        raise ConfigError(path, "truth", f"file not found: {truth_path}")
    sec.finish()
    return RunConfig(path=path, name=name, files=tuple(files), markers=markers, disc=disc, env=env, prior=prior,
                     ic_prior=ic_prior, output=output, sampler=sampler, least_squares=least, simulator_method=method,
                     simulator_step_factor=step, physics=physics, flight_options=flight_options, truth=truth_path,
                     imu=imu, credit=credit, noise=noise)


def _read_noise(path: Path, sec: Section, defaults: NoiseSettings | None) -> dict:
    """A ``noise:`` block → {field: value} (with ``defaults`` filled in; without, only the keys given)."""
    out = {}
    model = sec.string("model", None if defaults is None else defaults.model, choices=NOISE_CHOICES)
    if model is not None:
        out["model"] = model
    pp = sec.raw("per_point", None if defaults is None else defaults.per_point)
    if pp is not None:
        pp = {True: "true", False: "false"}.get(pp, pp) if isinstance(pp, bool) else pp
        if pp not in PER_POINT:
            raise ConfigError(path, sec.key("per_point"), f"must be one of {list(PER_POINT)}, got {pp!r}")
        out["per_point"] = pp
    sec.finish()
    return out


def _read_imu(path: Path, sec: Section) -> tuple[ImuSource, ...]:
    """The ``imu:`` list: file (relative to the config), format, optional throws [[start, end], ...],
    ``magnetometer`` (default true), ``barometer`` (default false), ``row_times`` (default uniform) and
    ``gyro_noise`` (default white)."""
    raw = sec.raw("imu", None)
    if raw is None:
        return ()
    if not isinstance(raw, list) or not raw:
        raise ConfigError(path, "imu", "must be a non-empty list of {file: ..., format: ...}")
    out = []
    for i, entry in enumerate(raw):
        e = Section(path, entry, f"imu[{i}]")
        file = path.parent / e.string("file", required=True)
        fmt = e.string("format", required=True, choices=IMU_FORMATS)
        throws = e.raw("throws", None)
        magnetometer = e.boolean("magnetometer", True)
        barometer = e.boolean("barometer", False)
        row_times = e.string("row_times", "uniform", choices=ROW_TIMES)
        gyro_noise = e.string("gyro_noise", "white", choices=GYRO_NOISE)
        e.finish()
        if not file.is_file():
            raise ConfigError(path, f"imu[{i}].file", f"file not found: {file}")
        if throws is not None:
            ok = isinstance(throws, list) and throws and all(
                isinstance(t, list) and len(t) == 2 and all(isinstance(v, int) for v in t) and t[1] > t[0] + 10
                for t in throws)
            if not ok:
                raise ConfigError(path, f"imu[{i}].throws", "must be a list of [release_row, end_row] integer pairs "
                                  "(end after release, at least 10 rows)")
            throws = tuple((int(a), int(b)) for a, b in throws)
        if row_times == "magnetometer" and fmt != "flatball-ins":
            raise ConfigError(path, f"imu[{i}].row_times", "magnetometer: only for logs without time column "
                              "(format flatball-ins)")
        out.append(ImuSource(file=file, format=fmt, throws=throws, magnetometer=magnetometer, barometer=barometer,
                             row_times=row_times, gyro_noise=gyro_noise))
    return tuple(out)
