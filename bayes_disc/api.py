"""Python API for notebooks and scripts: ``import bayes_disc as bd``.

``bd.sample(config)``, ``bd.identifiability(config)`` and ``bd.diagnose(config)`` run the same jobs as the
command line and return result objects; ``bd.load(run_dir)`` reads a sampled run back from disk. A
``config`` is a CONFIG.yaml path, a :class:`~.inference.model.config.RunConfig`, or a dict with the keys of
CONFIG.yaml (docs/configuration.md) whose flights may be given in memory::

    {"name": "demo", "markers": {...}, "flights": [{"data": dataframe}], ...}

where ``dataframe`` is a pandas DataFrame (or a mapping of column name → 1-D array) with the columns of a
marker file, ``flight, t, marker, x, y, z`` (docs/data-formats.md; extra columns such as ``sigma_m`` allowed). In-memory
rows are validated exactly like a file's (:mod:`.observation.tables`); they are then written, with the
configuration, to ``<output>/input/`` (``flights_<i>.csv``, ``config.yaml``) so that the run folder is
self-contained: its report, ``bd.load`` and the command line work on it later. Progress is logged (module
loggers under ``bayes_disc``; ``logging.basicConfig(level=logging.INFO)`` shows it).
"""
from __future__ import annotations

import logging
import os
import shutil
import tempfile
from collections.abc import Mapping
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING

from .jobs.results import DiagnosisResult, IdentifiabilityResult, RunResult, SampleResult

if TYPE_CHECKING:                                  # imported lazily at run time: `import bayes_disc` stays light
    from .inference.model.config import RunConfig

logger = logging.getLogger(__name__)

#: sub-folder of a run's output that holds the configuration and data given as a dict / in memory
INPUT_DIR = "input"


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
           overwrite: bool = False, base_dir=None) -> SampleResult:
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
        Also build ``<output>/reports/<name>.html`` (otherwise call :meth:`SampleResult.report`).
    overwrite : bool
        Replace an earlier run in the output folder (without it, or ``resume``, such a folder is refused).
    base_dir : str or Path, optional
        For a dict config: folder of its relative paths (default: the working directory).

    Returns
    -------
    SampleResult
        ``.summary`` (table of every parameter), ``.idata`` and ``.ensembles`` (ArviZ), ``.report(path)``,
        ``.output``.

    Raises
    ------
    ConfigError
        For a bad configuration, or an output folder that holds an earlier run.
    """
    from .jobs.outputs import check_fresh_output
    from .jobs.sample import sample as sample_job
    cfg = run_config(config, output=output, base_dir=base_dir)
    check_fresh_output(cfg, "sample", overwrite=overwrite, resume=resume)
    outcome = sample_job(cfg, resume=resume, progress=progress, report=report)
    return SampleResult(output=Path(cfg.output), raw=outcome.result)


def identifiability(config, *, output=None, profiles: bool = False, design: bool = True, overwrite: bool = False,
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
    overwrite : bool
        Replace an earlier ``identifiability.json`` in the output folder (refused otherwise).
    base_dir : str or Path, optional
        For a dict config: folder of its relative paths.

    Returns
    -------
    IdentifiabilityResult
        ``.verdicts``, ``.summary`` (table per coefficient), ``.recommendation``, ``.raw``.
    """
    from .jobs.identifiability import identifiability as identifiability_job
    from .jobs.outputs import check_fresh_output
    cfg = run_config(config, output=output, base_dir=base_dir)
    check_fresh_output(cfg, "identifiability", overwrite=overwrite)
    outcome = identifiability_job(cfg, profiles=profiles, design=design)
    return IdentifiabilityResult(output=Path(cfg.output), raw=outcome.result)


def diagnose(config, *, output=None, sample: bool = True, processes: int = 2, progress: bool = True,
             report: bool = False, overwrite: bool = False, base_dir=None, learn: bool = True) -> DiagnosisResult:
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
        Also rebuild ``<output>/reports/<name>.html`` when the folder holds a sampled run.
    overwrite : bool
        Replace an earlier ``diagnosis.json`` in the output folder (refused otherwise).
    base_dir : str or Path, optional
        For a dict config: folder of its relative paths.
    learn : bool
        Learn a correction in height, α and spin when the base model leaves structure.

    Returns
    -------
    DiagnosisResult
        ``.verdict``, ``.effects``, ``.words``, ``.summary`` (candidates), ``.rms_mm``, ``.refit``.
    """
    from .jobs.diagnose import diagnose as diagnose_job
    from .jobs.outputs import check_fresh_output
    cfg = run_config(config, output=output, base_dir=base_dir)
    check_fresh_output(cfg, "diagnose", overwrite=overwrite)
    outcome = diagnose_job(cfg, sample=sample, processes=processes, progress=progress, report=report, learn=learn)
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
    run_dirs : sequence of str, Path or RunResult, or dict {label: any of these}
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
        return run.output if isinstance(run, RunResult) else run
    if isinstance(run_dirs, Mapping):
        return compare_runs({label: folder(r) for label, r in run_dirs.items()})
    return compare_runs([folder(r) for r in run_dirs])
