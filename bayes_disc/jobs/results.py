"""The result of a job, read from its run folder: one type, :class:`RunResult`, with one ``report()``.

A job writes its record into the run folder (``summary.json``, ``identifiability.json``,
``diagnosis.json``); a result object is that record (``raw``) and the folder (``output``), with views for
notebooks (pandas tables, ArviZ InferenceData). The three kinds differ only in the file they read and
their views:

* :class:`SampleResult` — the posterior (``sample``); ``.idata`` is posterior.nc as stored (every emcee
  walker a chain), ``.ensembles`` the view in which ArviZ's R-hat is summary.json's;
* :class:`IdentifiabilityResult` — verdicts and the next throw (``identifiability``);
* :class:`DiagnosisResult` — the missing-physics diagnosis (``diagnose``).

``report()`` builds the HTML report of the sampled run in the folder (it includes identifiability and
diagnosis when their files are there), by default inside the folder: ``<output>/reports/<name>.html``.
"""
from __future__ import annotations

import json
import tempfile
import warnings
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import ClassVar

from ..report import build_report
from .outputs import reports_dir

#: columns of :attr:`SampleResult.summary` (the record of every parameter in summary.json), in order
SUMMARY_COLUMNS = ("mean", "sd", "q05", "q50", "q95", "r_hat", "ess_bulk")


def _build_report(run_dir: Path, path, seed: int, processes: int) -> Path:
    """The HTML report of ``run_dir`` at ``path`` (a ``.html`` file, a folder for ``<name>.html``, or None for
    ``<run_dir>/reports/<name>.html``), drawn in ``processes`` worker processes."""
    target = reports_dir(run_dir) if path is None else Path(path)
    if target.suffix.lower() != ".html":
        return build_report(run_dir, reports_dir=target, seed=seed, processes=processes)
    target.parent.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(dir=target.parent) as tmp:
        built = build_report(run_dir, reports_dir=Path(tmp), seed=seed, processes=processes)
        built.replace(target)
    return target


@dataclass
class RunResult:
    """A job's result: its record and its run folder.

    Attributes
    ----------
    output : Path
        The run folder.
    raw : dict
        The content of the job's record (:attr:`FILE`).
    """

    #: the job's record in the run folder
    FILE: ClassVar[str] = ""
    #: the command that writes it (named in errors)
    JOB: ClassVar[str] = ""
    #: further files the folder must hold
    ALSO: ClassVar[tuple[str, ...]] = ()

    output: Path
    raw: dict = field(repr=False)

    @classmethod
    def from_dir(cls, run_dir):
        """Read a run folder.

        Parameters
        ----------
        run_dir : str or Path
            Output folder of the job.

        Returns
        -------
        RunResult
            Of the class it is called on.

        Raises
        ------
        FileNotFoundError
            If the folder lacks the job's record or another file the result needs.
        """
        run_dir = Path(run_dir)
        for name in (cls.FILE,) + cls.ALSO:
            if not (run_dir / name).is_file():
                raise FileNotFoundError(f"{run_dir}: no {name} (not the output folder of `bayes-disc {cls.JOB}`)")
        return cls(output=run_dir, raw=json.loads((run_dir / cls.FILE).read_text()))

    def report(self, path=None, *, seed: int | None = None) -> Path:
        """Build the self-contained HTML report of the sampled run in this folder (figures also in
        ``<output>/figures``); it includes identifiability and the diagnosis when the folder holds them.

        Parameters
        ----------
        path : str or Path, optional
            A ``.html`` file, or a folder for ``<name>.html``; default ``<output>/reports/<name>.html`` (as
            the command line).
        seed : int, optional
            Seed of the report's random draws; default the run's sampler seed (as the command line).
            The figures are drawn in the run's ``processes`` worker processes.

        Returns
        -------
        Path
            The HTML file written.

        Raises
        ------
        FileNotFoundError
            If the folder holds no sampled run (run ``sample`` first).
        """
        run = self if isinstance(self, SampleResult) else SampleResult.from_dir(self.output)
        settings = run.raw["sampler_settings"]
        seed = settings["seed"] if seed is None else seed
        return _build_report(run.output, path, int(seed), int(settings["processes"]))


@dataclass
class SampleResult(RunResult):
    """A sampled run: the posterior of the coefficients, noise scales and initial conditions.

    Attributes
    ----------
    output : Path
        The run folder (summary.json, posterior.nc, run_info.json, least-squares files, chains).
    raw : dict
        The content of ``summary.json`` (docs/outputs.md).
    """

    FILE: ClassVar[str] = "summary.json"
    JOB: ClassVar[str] = "sample"
    ALSO: ClassVar[tuple[str, ...]] = ("posterior.nc",)

    @property
    def name(self) -> str:
        """The run name."""
        return self.raw["name"]

    @property
    def coefficients(self) -> list[str]:
        """Names of the estimated coefficients: the ten of the flight model, then extra terms' parameters."""
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
        """The posterior as stored, ArviZ InferenceData (``posterior.nc``; groups posterior, sample_stats,
        prior, observed_data, log_likelihood, posterior_predictive), read once and fully into memory.

        Every emcee walker is a chain (coordinates ``ensemble`` and ``walker`` on ``chain``): ArviZ's R-hat
        on it compares walkers, which summary.json records as ``r_hat_walkers``; use :attr:`ensembles` for
        the R-hat of summary.json and for trace plots."""
        import arviz as az
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            with az.rc_context({"data.load": "eager"}):
                return az.from_netcdf(str(self.output / "posterior.nc"))

    @cached_property
    def ensembles(self):
        """The posterior with the independent ensembles as chains, as ArviZ InferenceData.

        Each chain is one emcee ensemble, its walkers' draws pooled step by step (draw = step × walkers +
        walker). On it ``az.rhat`` and ``az.summary``'s ``r_hat`` are summary.json's ``r_hat`` (the sampler's
        stopping rule), and ``az.plot_trace`` draws one curve per ensemble.

        Returns
        -------
        arviz.InferenceData
            One group, ``posterior``, dims (chain = ensemble, draw, ...).
        """
        import arviz as az
        from ..inference.results.draws import ensemble_view
        return az.InferenceData(posterior=ensemble_view(self.idata.posterior))


@dataclass
class IdentifiabilityResult(RunResult):
    """Which coefficients the flights determine, and the throw that would help most.

    Attributes
    ----------
    output : Path
        The run folder holding ``identifiability.json``.
    raw : dict
        The content of ``identifiability.json``.
    """

    FILE: ClassVar[str] = "identifiability.json"
    JOB: ClassVar[str] = "identifiability"

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


@dataclass
class DiagnosisResult(RunResult):
    """The missing-physics diagnosis: accepted effects, RMS before/after, the refit.

    Attributes
    ----------
    output : Path
        The run folder holding ``diagnosis.json``.
    raw : dict
        The content of ``diagnosis.json`` (docs/outputs.md).
    """

    FILE: ClassVar[str] = "diagnosis.json"
    JOB: ClassVar[str] = "diagnose"

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
