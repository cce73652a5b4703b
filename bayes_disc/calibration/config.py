"""The calibration campaign description ``CAL.yaml`` (``bayes-disc calibrate``), validated up front.

```yaml
name: four_flights_white  # campaign name
replicates: 100            # N synthetic data sets
seed: 16                   # replicate i draws everything from numpy's default_rng([seed, i])
template: synth.yaml       # SYNTH.yaml (relative to this file) or an inline mapping of its keys:
                           # flights (launch), noise_mm, dropout, defects, markers, sample_rate_hz …
truth:                     # where the replicates' coefficients come from
  draw: prior              # prior: the run's coefficient prior (exact SBC; run.prior may be an ``around``
                           # prior, e.g. {around: hummel2002, relative_sd: 0.1}); around: N(values, sd²)
  values: hummel2002       # (around) a literature set or {name: value}; default hummel2002
  relative_sd: 0.1         # (around) sd = relative_sd·|value| …
  sd: {CL0: 0.02}          # (around) … or given per coefficient (wins)
  max_redraws: 20          # a truth whose flights fail to simulate is drawn again (counted)
launch_jitter: {speed: 1.0, alpha_deg: 2.0}   # optional: each flight's launch value + U(−h, h) per replicate
run:                       # the run configuration's keys (docs/configuration.md), passed through as given:
  prior: potts_crowther    # prior, sampler, least_squares, simulator, physics, flight_options, the
  sampler: {max_steps: 2000}   # likelihood options … (not name, flights, markers, output, truth, imu);
                           # sampler.processes is 1 (a replicate runs in one Dask worker process)
draws: 99                  # L thinned posterior draws per replicate (ranks 0…L)
bins: null                 # rank-histogram bins (a divisor of L + 1; default: ≤ 20 with ≥ 5 per bin)
output: out                # relative to this file; default runs/<name> in the working directory
```
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..inference.model.config import config_from_mapping
from ..observation.config_io import ConfigError, Section, load_yaml
from ..observation.synth import SynthSpec
from ..observation.synth_config import load_synth_spec, synth_spec_from_mapping
from ..physics import COEFFICIENT_NAMES, LITERATURE, literature_coefficients

#: run-configuration keys a campaign sets itself (from the template and the replicate)
RESERVED_RUN_KEYS = ("name", "flights", "markers", "output", "truth", "imu")
#: launch values that ``launch_jitter`` may vary (LaunchSpec fields)
JITTER_KEYS = ("speed", "launch_angle_deg", "heading_deg", "pitch_deg", "alpha_deg", "roll_deg", "spin", "p", "q")
TRUTH_DRAWS = ("prior", "around")


@dataclass(frozen=True)
class TruthSpec:
    """How a replicate's coefficients are drawn.

    Attributes
    ----------
    draw : str
        ``prior``: θ̃_k ~ N(m_k, s_k²) of the run's coefficient prior (exact SBC); ``around``:
        θ̃_k ~ N(values_k, sd_k²) independently (a coverage check near those values, SBC only approximately).
    values, sd : dict
        Centre and sd per coefficient (for ``prior``: the prior's).
    max_redraws : int
        Truths whose flights fail to simulate are drawn again at most this often.
    """

    draw: str
    values: dict
    sd: dict
    max_redraws: int = 20


@dataclass(frozen=True)
class CalConfig:
    """A validated calibration campaign (module docstring).

    Attributes
    ----------
    path : Path
        CAL.yaml (or the file an in-memory description stands for).
    name : str
    replicates : int
        N.
    seed : int
    template : SynthSpec
        The synthetic data set every replicate varies (coefficients and seed replaced, launch jittered).
    truth : TruthSpec
    launch_jitter : dict
        Launch field → half-width h of the uniform jitter (field units).
    run : dict
        The run configuration's keys, passed through to every replicate's run (``sampler.processes`` 1).
    draws : int
        L.
    bins : int or None
    output : Path
    """

    path: Path
    name: str
    replicates: int
    seed: int
    template: SynthSpec
    truth: TruthSpec
    launch_jitter: dict = field(default_factory=dict)
    run: dict = field(default_factory=dict)
    draws: int = 99
    bins: int | None = None
    output: Path = Path("runs/calibration")

    @property
    def names(self) -> list[str]:
        """The coefficients whose calibration is measured (names as in docs/conventions.md)."""
        return list(COEFFICIENT_NAMES)

    def key(self) -> dict:
        """Everything a finished replicate depends on (not N, output): a resumed campaign must match it."""
        return {"seed": self.seed, "template": repr(self.template), "truth": repr(self.truth),
                "launch_jitter": self.launch_jitter, "run": self.run, "draws": self.draws}

    def earlier_keys(self) -> list[dict]:
        """The key as campaigns recorded it before the template gained the fields of
        :data:`LATER_TEMPLATE_FIELDS`, when they hold the value that leaves a replicate unchanged (such a
        campaign resumes: its replicates are the same)."""
        text = repr(self.template)
        for name, neutral in LATER_TEMPLATE_FIELDS.items():
            if getattr(self.template, name) == neutral:
                text = text.replace(f", {name}={neutral!r}", "")
        return [] if text == repr(self.template) else [{**self.key(), "template": text}]


#: synth-template fields added after campaigns were first recorded, with their neutral value
LATER_TEMPLATE_FIELDS = {"nature": {}}


def _template(path: Path, sec: Section) -> SynthSpec:
    raw = sec.raw("template", required=True)
    if isinstance(raw, str):
        file = path.parent / raw
        if not file.is_file():
            raise ConfigError(path, "template", f"file not found: {file}")
        return load_synth_spec(file)[0]
    if not isinstance(raw, dict):
        raise ConfigError(path, "template", "must be a SYNTH.yaml file name or a mapping of its keys")
    data = {"name": "template", **raw}
    try:
        return synth_spec_from_mapping(data, path)[0]
    except ConfigError as e:
        raise ConfigError(path, f"template.{e.key}" if e.key else "template", e.problem) from None


def _truth(path: Path, sec: Section, prior) -> TruthSpec:
    from ..inference.model.priors import coefficient_prior
    t = sec.section("truth")
    draw = t.string("draw", "prior", choices=TRUTH_DRAWS)
    redraws = t.number("max_redraws", 20, integer=True, nonnegative=True)
    if draw == "prior":
        cp = coefficient_prior(prior)
        t.finish()
        return TruthSpec(draw, dict(cp.mean), dict(cp.sd), redraws)
    raw = t.raw("values", "hummel2002")
    if isinstance(raw, str):
        if raw not in LITERATURE:
            raise ConfigError(path, t.key("values"), f"unknown set {raw!r}; known: {sorted(LITERATURE)}")
        values = literature_coefficients(raw).as_dict()
    else:
        v = Section(path, raw, t.key("values"))
        base = literature_coefficients("hummel2002").as_dict()
        values = {n: v.number(n, base[n]) for n in COEFFICIENT_NAMES}
        v.finish()
    rel = t.number("relative_sd", 0.1, nonnegative=True)
    s = t.section("sd")
    sd = {n: s.number(n, rel * abs(values[n]), nonnegative=True) for n in COEFFICIENT_NAMES}
    s.finish()
    t.finish()
    return TruthSpec(draw, values, sd, redraws)


def _run_mapping(path: Path, sec: Section) -> tuple[dict, object]:
    """The ``run:`` block, checked by the run configuration's own validation (errors named ``run.<key>``),
    and the run's coefficient prior as that validation reads it (a name or an ``around`` prior)."""
    run = sec.raw("run", {}) or {}
    if not isinstance(run, dict):
        raise ConfigError(path, "run", "must be a mapping of run-configuration keys")
    for k in RESERVED_RUN_KEYS:
        if k in run:
            raise ConfigError(path, f"run.{k}", "set by the campaign (template and replicate), not in run")
    sampler = run.get("sampler") or {}
    if not isinstance(sampler, dict):
        raise ConfigError(path, "run.sampler", "must be a mapping")
    if sampler.get("processes", 1) != 1:
        raise ConfigError(path, "run.sampler.processes", "must be 1: each replicate runs in one Dask worker "
                          "process (the campaign's parallelism is its workers)")
    run = {**run, "sampler": {**sampler, "processes": 1}}
    probe = {**run, "name": "probe", "flights": [{"file": path.name}],
             "markers": {"0": [0.1, 0.0, 0.0], "1": [0.0, 0.1, 0.0], "2": [-0.1, 0.0, 0.0]}}
    try:
        probed = config_from_mapping(probe, path, output_override=path.parent)
    except ConfigError as e:
        raise ConfigError(path, f"run.{e.key}" if e.key else "run", e.problem) from None
    return run, probed.prior


def load_cal_config(path, output_override=None) -> CalConfig:
    """Read and validate CAL.yaml.

    Parameters
    ----------
    path : str or Path
        The campaign file (keys: module docstring, docs/calibration.md).
    output_override : str or Path, optional
        Replaces its output folder.

    Returns
    -------
    CalConfig

    Raises
    ------
    ConfigError
        For every problem, naming the file and the key.
    """
    path = Path(path)
    return cal_config_from_mapping(load_yaml(path), path, output_override)


def cal_config_from_mapping(data: dict, path, output_override=None) -> CalConfig:
    """:func:`load_cal_config` of a mapping already read (``path``: the file it stands for)."""
    path = Path(path)
    sec = Section(path, data)
    name = sec.string("name", required=True)
    if any(c in name for c in "/\\") or name.startswith("."):
        raise ConfigError(path, "name", f"must be a plain campaign name, got {name!r}")
    n = sec.number("replicates", required=True, integer=True, minimum=1)
    seed = sec.number("seed", 0, integer=True, nonnegative=True)
    template = _template(path, sec)
    run, prior = _run_mapping(path, sec)
    truth = _truth(path, sec, prior)
    j = sec.section("launch_jitter")
    jitter = {}
    for k in list(j.data):
        if k not in JITTER_KEYS:
            raise ConfigError(path, j.key(str(k)), f"unknown launch value; known: {list(JITTER_KEYS)}")
        jitter[k] = j.number(k, nonnegative=True)
    j.finish()
    draws = sec.number("draws", 99, integer=True, minimum=9)
    bins = sec.number("bins", None, integer=True, minimum=2)
    if bins is not None and (draws + 1) % bins:
        raise ConfigError(path, "bins", f"must divide draws + 1 = {draws + 1}")
    out = sec.string("output", None)
    output = (path.parent / out) if out else Path.cwd() / "runs" / name
    if output_override is not None:
        output = Path(output_override)
    sec.finish()
    return CalConfig(path=path, name=name, replicates=n, seed=seed, template=template, truth=truth,
                     launch_jitter=jitter, run=run, draws=draws, bins=bins, output=output)


def replicate_rng(cal: CalConfig, index: int) -> np.random.Generator:
    """The random stream of replicate ``index``: ``default_rng([seed, index])`` (independent of N)."""
    return np.random.default_rng([cal.seed, index])
