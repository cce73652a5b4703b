"""Python API for notebooks and scripts: ``import bayes_disc as bd``.

``bd.sample(config)``, ``bd.identifiability(config)`` and ``bd.diagnose(config)`` run the same jobs as the
command line and return result objects; ``bd.load(run_dir)`` reads a sampled run back from disk. A
``config`` is a CONFIG.yaml path, a :class:`~.inference.config.RunConfig`, or a dict with the keys of
CONFIG.yaml (SPEC §5) whose flights may be given in memory::

    {"name": "demo", "markers": {...}, "flights": [{"data": dataframe}], ...}

where ``dataframe`` is a pandas DataFrame (or a mapping of column name → 1-D array) with the columns of a
marker file, ``flight, t, marker, x, y, z`` (SPEC §4; extra columns such as ``sigma_m`` allowed). In-memory
rows are validated exactly like a file's (:mod:`.observation.tables`); they are then written, with the
configuration, to ``<output>/input/`` (``flights_<i>.csv``, ``config.yaml``) so that the run folder is
self-contained: its report, ``bd.load`` and the command line work on it later. Progress is logged (module
loggers under ``bayes_disc``; ``logging.basicConfig(level=logging.INFO)`` shows it).
"""
from __future__ import annotations

import json
import logging
import os
import shutil
import tempfile
import warnings
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from functools import cached_property
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:                                  # imported lazily at run time: `import bayes_disc` stays light
    from .inference.model.config import RunConfig

logger = logging.getLogger(__name__)

#: columns of :attr:`SampleResult.summary` (the SPEC §6 record of every parameter), in order
SUMMARY_COLUMNS = ("mean", "sd", "q05", "q50", "q95", "r_hat", "ess_bulk")
#: folder of ``<name>.html`` when :meth:`SampleResult.report` is given no path (as the command line)
DEFAULT_REPORTS_DIR = Path("reports")
#: sub-folder of a run's output that holds the configuration and data given as a dict / in memory
INPUT_DIR = "input"


# ------------------------------------------------------------------------------------------- results
def _read_json(path: Path, what: str) -> dict:
    if not path.is_file():
        raise FileNotFoundError(f"{path.parent}: no {path.name} (not the output folder of {what})")
    return json.loads(path.read_text())


def _build_report(run_dir: Path, path, seed: int, processes: int) -> Path:
    """The HTML report of ``run_dir`` at ``path`` (a ``.html`` file or a folder for ``<name>.html``), drawn in
    ``processes`` worker processes."""
    from .report import build_report
    if path is None:
        return build_report(run_dir, reports_dir=DEFAULT_REPORTS_DIR, seed=seed, processes=processes)
    target = Path(path)
    if target.suffix.lower() != ".html":
        return build_report(run_dir, reports_dir=target, seed=seed, processes=processes)
    target.parent.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(dir=target.parent) as tmp:
        built = build_report(run_dir, reports_dir=Path(tmp), seed=seed, processes=processes)
        built.replace(target)
    return target


@dataclass
class SampleResult:
    """A sampled run: the posterior of the coefficients, noise scales and initial conditions.

    Attributes
    ----------
    output : Path
        The run folder (summary.json, posterior.nc, run_info.json, least-squares files, chains).
    raw : dict
        The content of ``summary.json`` (SPEC §6).
    """

    output: Path
    raw: dict = field(repr=False)

    @classmethod
    def from_dir(cls, run_dir) -> "SampleResult":
        """Read a sampled run folder.

        Parameters
        ----------
        run_dir : str or Path
            Output folder of ``sample`` (holds summary.json and posterior.nc).

        Returns
        -------
        SampleResult

        Raises
        ------
        FileNotFoundError
            If the folder holds no summary.json or no posterior.nc.
        """
        run_dir = Path(run_dir)
        raw = _read_json(run_dir / "summary.json", "`bayes-disc sample`")
        if not (run_dir / "posterior.nc").is_file():
            raise FileNotFoundError(f"{run_dir}: no posterior.nc (not the output folder of `bayes-disc sample`)")
        return cls(output=run_dir, raw=raw)

    @property
    def name(self) -> str:
        """The run name."""
        return self.raw["name"]

    @property
    def coefficients(self) -> list[str]:
        """Names of the estimated coefficients: the ten of SPEC §2, then extra terms' parameters."""
        return list(self.raw["coefficients"])

    @property
    def convergence(self) -> dict:
        """Sampler convergence: ``converged``, ``reason``, steps, burn-in, τ [steps], R-hat max, ESS min."""
        return self.raw["convergence"]

    @property
    def converged(self) -> bool:
        """Whether every convergence criterion was met before the step cap."""
        return bool(self.raw["convergence"]["converged"])

    @property
    def summary(self):
        """Posterior summary table.

        Returns
        -------
        pandas.DataFrame
            One row per parameter (index ``parameter``: coefficients, ``sigma_<flight>`` [m], initial
            conditions [SI]), columns :data:`SUMMARY_COLUMNS`: mean, sd, 5/50/95 % quantiles, R-hat, bulk ESS.
        """
        import pandas as pd
        params = self.raw["parameters"]
        frame = pd.DataFrame([[params[n][c] for c in SUMMARY_COLUMNS] for n in params], index=list(params),
                             columns=list(SUMMARY_COLUMNS), dtype=float)
        frame.index.name = "parameter"
        return frame

    @cached_property
    def idata(self):
        """The posterior as ArviZ InferenceData (``posterior.nc``; groups posterior, sample_stats, prior,
        observed_data), read once and fully into memory."""
        import arviz as az
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            with az.rc_context({"data.load": "eager"}):
                return az.from_netcdf(str(self.output / "posterior.nc"))

    def report(self, path=None, *, seed: int | None = None) -> Path:
        """Build the self-contained HTML report of this run (figures also in ``<output>/figures``).

        Parameters
        ----------
        path : str or Path, optional
            A ``.html`` file, or a folder for ``<name>.html``; default ``reports/<name>.html`` in the
            working directory (as the command line).
        seed : int, optional
            Seed of the report's random draws; default the run's sampler seed (as the command line).
            The figures are drawn in the run's ``processes`` worker processes.

        Returns
        -------
        Path
            The HTML file written.
        """
        seed = self.raw["sampler_settings"]["seed"] if seed is None else seed
        return _build_report(self.output, path, int(seed), int(self.raw["sampler_settings"]["processes"]))


@dataclass
class IdentifiabilityResult:
    """Which coefficients the flights determine, and the throw that would help most.

    Attributes
    ----------
    output : Path
        The run folder holding ``identifiability.json``.
    raw : dict
        The content of ``identifiability.json``.
    """

    output: Path
    raw: dict = field(repr=False)

    @classmethod
    def from_dir(cls, run_dir) -> "IdentifiabilityResult":
        """Read ``<run_dir>/identifiability.json``.

        Parameters
        ----------
        run_dir : str or Path
            Output folder of ``identifiability``.

        Returns
        -------
        IdentifiabilityResult
        """
        run_dir = Path(run_dir)
        return cls(output=run_dir, raw=_read_json(run_dir / "identifiability.json", "`bayes-disc identifiability`"))

    @property
    def verdicts(self) -> dict[str, str]:
        """``{coefficient: "identified" | "weak" | "unidentified"}``."""
        return {n: v["verdict"] for n, v in self.raw["coefficients"].items()}

    @property
    def recommendation(self) -> str | None:
        """The next throw in words (None when the design step was skipped)."""
        design = self.raw.get("design")
        return None if design is None else design["recommendation"]

    @property
    def summary(self):
        """Verdict table.

        Returns
        -------
        pandas.DataFrame
            One row per coefficient (index ``coefficient``) with ``verdict``, ``reason`` and the numbers
            behind them (least-squares ``sd``, ``prior_sd``, ``contraction`` …, as in the file).
        """
        import pandas as pd
        coefs = self.raw["coefficients"]
        frame = pd.DataFrame.from_dict({n: {k: v for k, v in rec.items() if not isinstance(v, (dict, list))}
                                        for n, rec in coefs.items()}, orient="index")
        frame.index.name = "coefficient"
        return frame

    def report(self, path=None, *, seed: int | None = None) -> Path:
        """The HTML report of the sampled run in the same folder (it includes the identifiability section).

        Parameters
        ----------
        path : str or Path, optional
            As for :meth:`SampleResult.report`.
        seed : int, optional
            As for :meth:`SampleResult.report`.

        Returns
        -------
        Path
            The HTML file written.

        Raises
        ------
        FileNotFoundError
            If the folder holds no sampled run (run :func:`sample` first).
        """
        return SampleResult.from_dir(self.output).report(path, seed=seed)


@dataclass
class DiagnosisResult:
    """The missing-physics diagnosis: accepted effects, RMS before/after, the refit.

    Attributes
    ----------
    output : Path
        The run folder holding ``diagnosis.json``.
    raw : dict
        The content of ``diagnosis.json`` (SPEC §6 keys and the details of
        :mod:`.diagnostics.diagnosis`).
    """

    output: Path
    raw: dict = field(repr=False)

    @classmethod
    def from_dir(cls, run_dir) -> "DiagnosisResult":
        """Read ``<run_dir>/diagnosis.json``.

        Parameters
        ----------
        run_dir : str or Path
            Output folder of ``diagnose``.

        Returns
        -------
        DiagnosisResult
        """
        run_dir = Path(run_dir)
        return cls(output=run_dir, raw=_read_json(run_dir / "diagnosis.json", "`bayes-disc diagnose`"))

    @property
    def verdict(self) -> str:
        """``"adequate"`` or ``"missing_physics"``."""
        return self.raw["verdict"]

    @property
    def effects(self) -> list[dict]:
        """Accepted effects ranked best first: ``{id, evidence (ΔBIC), estimate, where, ...}``."""
        return self.raw["effects"]

    @property
    def words(self) -> str:
        """The diagnosis in words."""
        return self.raw["words"]

    @property
    def learned(self) -> dict | None:
        """The learned correction (``learned_discrepancy`` of ``diagnosis.json``: selected columns, ΔBIC,
        whiteness, the flight variable and family it names, its curve), or None when the base model left
        white residuals."""
        return self.raw.get("learned_discrepancy")

    @property
    def summary(self):
        """Every candidate term tried.

        Returns
        -------
        pandas.DataFrame
            One row per candidate and round: ``round``, ``id``, ``evidence`` (ΔBIC), ``status``.
        """
        import pandas as pd
        rows = [{k: c[k] for k in ("round", "id", "evidence", "status")} for c in self.raw["candidates"]]
        return pd.DataFrame(rows, columns=["round", "id", "evidence", "status"])

    @property
    def rms_mm(self):
        """RMS residual per flight before and after the accepted terms.

        Returns
        -------
        pandas.DataFrame
            Index ``flight``, columns ``before`` and ``after`` [mm].
        """
        import pandas as pd
        frame = pd.DataFrame({"before": self.raw["rms_before_mm"], "after": self.raw["rms_after_mm"]})
        frame.index.name = "flight"
        return frame

    @property
    def refit(self) -> SampleResult | None:
        """The resampled run with the accepted terms (None when nothing was resampled)."""
        run = self.raw["settings"]["refit_run"]
        return None if run is None else SampleResult.from_dir(run)

    def report(self, path=None, *, seed: int | None = None) -> Path:
        """The HTML report of the sampled run in the same folder (it includes the diagnosis).

        Parameters
        ----------
        path : str or Path, optional
            As for :meth:`SampleResult.report`.
        seed : int, optional
            As for :meth:`SampleResult.report`.

        Returns
        -------
        Path
            The HTML file written.

        Raises
        ------
        FileNotFoundError
            If the folder holds no sampled run (run :func:`sample` first).
        """
        return SampleResult.from_dir(self.output).report(path, seed=seed)


# ----------------------------------------------------------------------------------- configurations
def _plain(x):
    """YAML-safe copy: numpy arrays and scalars to Python, paths to strings, mappings with string keys."""
    import numpy as np
    if isinstance(x, Mapping):
        return {str(k): _plain(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_plain(v) for v in x]
    if isinstance(x, np.ndarray):
        return _plain(x.tolist())
    if isinstance(x, np.generic):
        return x.item()
    if isinstance(x, os.PathLike):
        return str(x)
    return x


def _is_table(x) -> bool:
    """A DataFrame, or a mapping of columns with a ``flight`` column (in-memory marker rows)."""
    return (hasattr(x, "columns") and hasattr(x, "to_numpy")) or (isinstance(x, Mapping) and "flight" in x)


def _config_from_dict(config: Mapping, output, base_dir) -> RunConfig:
    from .inference.model.config import config_from_mapping, load_config
    from .observation.config_io import ConfigError
    from .observation.markers import write_marker_csv
    from .observation.tables import marker_table_from_columns
    import yaml

    base = Path.cwd() if base_dir is None else Path(base_dir).resolve()
    label = base / "<config dict>"               # names the dict in errors; relative paths resolve in `base`
    data = dict(config)
    flights = data.get("flights")
    if _is_table(flights):
        flights = [{"data": flights}]
    tables = {}
    if isinstance(flights, list):
        markers = data.get("markers")
        marker_ids = [str(k) for k in markers] if isinstance(markers, Mapping) else None
        for i, entry in enumerate(flights):
            if isinstance(entry, Mapping) and "data" in entry:
                other = sorted(set(entry) - {"data"})
                if other:
                    raise ConfigError(label, f"flights[{i}].{other[0]}", "unknown key (an entry has either "
                                      "'file' or 'data')")
                tables[i] = marker_table_from_columns(entry["data"], marker_ids, source=f"flights[{i}].data")
    with tempfile.TemporaryDirectory() as tmp:
        staged = {i: Path(tmp) / f"flights_{i}.csv" for i in tables}
        for i, table in tables.items():
            write_marker_csv(staged[i], table)
        if tables:
            data["flights"] = [{"file": str(staged[i])} if i in tables else e for i, e in enumerate(flights)]
        first = config_from_mapping(_plain_except_flights(data), label, output_override=output)
        folder = Path(first.output) / INPUT_DIR
        folder.mkdir(parents=True, exist_ok=True)
        entries = []
        for i, file in enumerate(first.files):
            if i in tables:
                shutil.copyfile(staged[i], folder / staged[i].name)
                entries.append({"file": staged[i].name})
            else:
                entries.append({"file": str(Path(file).resolve())})
    persisted = {**_plain_except_flights(data), "flights": entries, "output": str(Path(first.output).resolve())}
    if first.truth is not None:
        persisted["truth"] = str(Path(first.truth).resolve())
    path = folder / "config.yaml"
    path.write_text("# written by bayes_disc.api from a configuration given as a dict\n"
                    + yaml.safe_dump(persisted, sort_keys=False, allow_unicode=True))
    logger.debug(f"configuration and in-memory flights written to {folder}")
    return load_config(path)


def _plain_except_flights(data: dict) -> dict:
    return {k: (v if k == "flights" else _plain(v)) for k, v in data.items()}


def run_config(config, *, output=None, base_dir=None) -> RunConfig:
    """A validated run configuration from a path, a RunConfig or a dict.

    Parameters
    ----------
    config : str, Path, RunConfig or dict
        CONFIG.yaml; an already loaded configuration; or a dict with the keys of CONFIG.yaml whose
        ``flights`` entries are ``{"file": path}`` or ``{"data": table}`` (``table``: pandas DataFrame or
        mapping of column → 1-D array with columns ``flight, t [s], marker, x, y, z [m]``). ``flights``
        may also be a single table.
    output : str or Path, optional
        Replaces the configuration's output folder.
    base_dir : str or Path, optional
        For a dict: folder against which its relative paths resolve (default: the working directory).

    Returns
    -------
    RunConfig
        For a dict, loaded from ``<output>/input/config.yaml`` written beside the in-memory flights.

    Raises
    ------
    ConfigError
        For a bad key (a dict is named ``<base_dir>/<config dict>`` in the message).
    MarkerFileError
        For bad marker rows (named ``flights[i].data`` and the row position).
    TypeError
        For a ``config`` of another type.
    """
    from .inference.model.config import RunConfig, load_config
    if isinstance(config, RunConfig):
        return config if output is None else replace(config, output=Path(output))
    if isinstance(config, (str, os.PathLike)):
        return load_config(config, output_override=output)
    if isinstance(config, Mapping):
        return _config_from_dict(config, output, base_dir)
    raise TypeError(f"config must be a path, a RunConfig or a dict, got {type(config).__name__}")


# ------------------------------------------------------------------------------------------ the jobs
def sample(config, *, output=None, progress: bool = True, resume: bool = False, report: bool = False,
           base_dir=None) -> SampleResult:
    """Sample the posterior of a run (least squares, then emcee), as ``bayes-disc sample``.

    Parameters
    ----------
    config : str, Path, RunConfig or dict
        The run (see :func:`run_config`).
    output : str or Path, optional
        Replaces the configuration's output folder.
    progress : bool
        Show a progress bar while sampling.
    resume : bool
        Continue an interrupted run from its chain files.
    report : bool
        Also build ``reports/<name>.html`` (otherwise call :meth:`SampleResult.report`).
    base_dir : str or Path, optional
        For a dict config: folder of its relative paths (default: the working directory).

    Returns
    -------
    SampleResult
        ``.summary`` (table of every parameter), ``.idata`` (ArviZ), ``.report(path)``, ``.output``.
    """
    from . import pipeline
    cfg = run_config(config, output=output, base_dir=base_dir)
    outcome = pipeline.sample(cfg, resume=resume, progress=progress, report=report,
                              reports_dir=pipeline.reports_dir(output))
    return SampleResult(output=Path(cfg.output), raw=outcome.result)


def identifiability(config, *, output=None, profiles: bool = False, design: bool = True,
                    base_dir=None) -> IdentifiabilityResult:
    """Which coefficients the flights determine, and the next throw, as ``bayes-disc identifiability``.

    Parameters
    ----------
    config : str, Path, RunConfig or dict
        The run (see :func:`run_config`).
    output : str or Path, optional
        Replaces the configuration's output folder.
    profiles : bool
        Also profile the likelihood of every coefficient.
    design : bool
        Rank candidate throws.
    base_dir : str or Path, optional
        For a dict config: folder of its relative paths.

    Returns
    -------
    IdentifiabilityResult
        ``.verdicts``, ``.summary`` (table per coefficient), ``.recommendation``, ``.raw``.
    """
    from . import pipeline
    cfg = run_config(config, output=output, base_dir=base_dir)
    outcome = pipeline.identifiability(cfg, profiles=profiles, design=design)
    return IdentifiabilityResult(output=Path(cfg.output), raw=outcome.result)


def diagnose(config, *, output=None, sample: bool = True, processes: int = 2, progress: bool = True,
             report: bool = False, base_dir=None, learn: bool = True) -> DiagnosisResult:
    """Name the physics the model misses (and resample with it), as ``bayes-disc diagnose``.

    Parameters
    ----------
    config : str, Path, RunConfig or dict
        The run (see :func:`run_config`).
    output : str or Path, optional
        Replaces the configuration's output folder.
    sample : bool
        Resample with the accepted terms (otherwise least-squares estimates only).
    processes : int
        Parallel candidate fits.
    progress : bool
        Show a progress bar while resampling.
    report : bool
        Also rebuild ``reports/<name>.html`` when the folder holds a sampled run.
    base_dir : str or Path, optional
        For a dict config: folder of its relative paths.
    learn : bool
        Learn a correction in height, α and spin when the base model leaves structure.

    Returns
    -------
    DiagnosisResult
        ``.verdict``, ``.effects``, ``.words``, ``.summary`` (candidates), ``.rms_mm``, ``.refit``.
    """
    from . import pipeline
    cfg = run_config(config, output=output, base_dir=base_dir)
    outcome = pipeline.diagnose(cfg, sample=sample, processes=processes, progress=progress, report=report,
                                reports_dir=pipeline.reports_dir(output), learn=learn)
    return DiagnosisResult(output=Path(cfg.output), raw=outcome.result)


def load(run_dir) -> SampleResult:
    """A sampled run read back from its folder.

    Parameters
    ----------
    run_dir : str or Path
        Output folder of ``sample`` (summary.json, posterior.nc).

    Returns
    -------
    SampleResult
        The same object :func:`sample` returned for that run.

    Raises
    ------
    FileNotFoundError
        If the folder is not a sampled run.
    """
    return SampleResult.from_dir(run_dir)


def compare(run_dirs):
    """PSIS-LOO comparison (``az.compare``) of sampled runs of the same observations, e.g. the same flights
    fitted with different noise models or physics terms.

    Parameters
    ----------
    run_dirs : sequence of str, Path or SampleResult, or dict {label: any of these}
        Two or more sampled runs (output folders of :func:`sample`, or its results); labels default to the
        folder's name (its parent's name for a folder called ``out``).

    Returns
    -------
    pandas.DataFrame
        One row per run, best first: ``elpd_loo`` (expected log predictive density of the observed marker
        points, natural log), ``se``, ``elpd_diff`` and ``dse`` (difference to the best and its standard
        error), ``p_loo`` (effective number of parameters), ``weight`` (stacking), ``warning`` and
        ``pareto_k_high`` (points with Pareto k̂ above ArviZ's threshold min(1 − 1/log10 S, 0.7), S draws).

    Raises
    ------
    ValueError
        If fewer than two runs are given, a run has no pointwise log-likelihood, or the runs' observed
        marker points differ.
    """
    from .inference.results.compare import compare_runs

    def folder(run):
        return run.output if isinstance(run, SampleResult) else run
    if isinstance(run_dirs, Mapping):
        return compare_runs({label: folder(r) for label, r in run_dirs.items()})
    return compare_runs([folder(r) for r in run_dirs])

