"""Everything a section needs from a run folder, loaded once and computed lazily.

:func:`load_run` validates the folder (``summary.json``, ``posterior.nc``, the run's config and data) and
raises :class:`~.errors.ReportInputError` naming the offending file. :class:`ReportContext` adds the
posterior draws, the rebuilt model and the simulated flights, each computed on first use and cached on
the context (no module-level state). All random choices use ``numpy.random.default_rng(seed)``.
"""
from __future__ import annotations

import json
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path

import numpy as np

from .errors import ReportInputError
from .sections import ReportFigure

#: posterior draws simulated for bands and predictive checks
N_BAND_DRAWS = 150
#: samples shown in the corner plot (thinned at random)
N_CORNER_SAMPLES = 8000


def _read_json(path: Path, required: bool = True) -> dict | None:
    if not path.is_file():
        if required:
            raise ReportInputError(path, "file not found (is this a `bayes-disc sample` output folder?)")
        return None
    try:
        data = json.loads(path.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as e:
        raise ReportInputError(path, f"not valid JSON ({e})") from None
    if not isinstance(data, dict):
        raise ReportInputError(path, "expected a JSON object")
    return data


SUMMARY_KEYS = ("name", "parameters", "coefficients", "convergence", "flights", "literature", "prior")


@dataclass
class RunData:
    """The files of a run folder."""

    run_dir: Path
    summary: dict
    idata: object                 # arviz.InferenceData
    run_info: dict
    config_path: Path
    truth: dict | None
    extras: dict = field(default_factory=dict)   # optional outputs of later capabilities, by file stem


def _find_config(run_dir: Path, recorded: str | None) -> Path:
    """The run's config: the recorded path, else (if it moved) the same name beside the run folder."""
    cands = []
    if recorded:
        p = Path(recorded)
        cands.append(p)
        if not p.is_absolute():
            cands.append(run_dir.parent / p)
        cands.append(run_dir.parent / p.name)
    for c in cands:
        if c.is_file():
            return c
    where = recorded or "summary.json key 'config'"
    raise ReportInputError(where, f"run configuration not found (recorded in {run_dir / 'summary.json'})")


def load_run(run_dir) -> RunData:
    """Read and check a run folder written by ``bayes-disc sample``."""
    run_dir = Path(run_dir)
    if run_dir.is_file() and run_dir.suffix.lower() in (".yaml", ".yml"):
        raise ReportInputError(run_dir, "this is a run configuration; give its run folder (the `output` of the "
                                        "configuration, e.g. runs/demo/out)")
    if not run_dir.is_dir():
        raise ReportInputError(run_dir, "run folder not found")
    sp = run_dir / "summary.json"
    summary = _read_json(sp)
    missing = [k for k in SUMMARY_KEYS if k not in summary]
    if missing:
        raise ReportInputError(sp, f"missing key(s) {missing}")
    pp = run_dir / "posterior.nc"
    if not pp.is_file():
        raise ReportInputError(pp, "file not found (is this a `bayes-disc sample` output folder?)")
    from ..inference.results.draws import has_parameter
    from ..inference.results.posterior_file import load_posterior
    try:
        # eager: a lazily opened file would stay open and block the next `sample` from rewriting it
        idata = load_posterior(pp, groups=("posterior", "sample_stats"))     # all the report reads
    except Exception as e:  # netCDF/HDF errors come in many types
        raise ReportInputError(pp, f"cannot read as ArviZ InferenceData ({type(e).__name__}: {e})") from None
    if "posterior" not in idata.groups():
        raise ReportInputError(pp, "no posterior group")
    absent = [n for n in summary["parameters"] if not has_parameter(idata.posterior, n)]
    if absent:
        raise ReportInputError(pp, f"posterior lacks parameter(s) {absent[:5]} listed in summary.json")
    run_info = _read_json(run_dir / "run_info.json", required=False) or {}
    config_path = _find_config(run_dir, summary.get("config"))
    from ..observation.config_io import ConfigError
    from ..inference.model.config import load_config
    try:
        cfg = load_config(config_path)
    except ConfigError as e:
        raise ReportInputError(config_path, f"run configuration no longer valid: {e.problem}") from None
    truth = None
    if cfg.truth is not None:
        truth = _read_json(Path(cfg.truth))
    extras = {}
    for stem in ("identifiability", "diagnosis", "flagged", "judgement_average"):
        extras[stem] = _read_json(run_dir / f"{stem}.json", required=False)
    return RunData(run_dir=run_dir, summary=summary, idata=idata, run_info=run_info, config_path=config_path,
                   truth=truth, extras=extras)


@dataclass
class FlightSim:
    """Simulations of one flight: the reference draw and the band draws.

    times (n,); measured (n, m, 3) with NaN where missing; ref_markers (n, m, 3), ref_states (n, 13);
    draw_markers (B, n, m, 3), draw_states (B, n, 13) for the posterior draws (NaN where a lane failed);
    sigma (B,) noise scale of each draw [m].
    """

    name: str
    times: np.ndarray
    measured: np.ndarray
    marker_ids: tuple
    ref_markers: np.ndarray
    ref_states: np.ndarray
    draw_markers: np.ndarray
    draw_states: np.ndarray
    sigma: np.ndarray
    sigma_ref: float

    @property
    def residuals(self) -> np.ndarray:
        """Measured − reference prediction (n, m, 3) [m], NaN where missing."""
        return self.measured - self.ref_markers

    @property
    def rms(self) -> float:
        """Root-mean-square residual over observed coordinates [m]."""
        r = self.residuals
        return float(np.sqrt(np.nanmean(r * r)))


class ReportContext:
    """A run plus lazily computed posterior draws and simulations; ``figure_dir`` receives PNG and PDF."""

    def __init__(self, run: RunData, figure_dir: Path, seed: int = 0, n_band_draws: int = N_BAND_DRAWS,
                 n_corner_samples: int = N_CORNER_SAMPLES):
        self.run = run
        self.n_corner_samples = int(n_corner_samples)
        self.summary = run.summary
        self.figure_dir = Path(figure_dir)
        self.seed = int(seed)
        self.n_band_draws = int(n_band_draws)
        self.figures_written: list[ReportFigure] = []

    # -- model ------------------------------------------------------------------------------------------
    @cached_property
    def config(self):
        from ..inference.model.config import load_config
        return load_config(self.run.config_path)

    @cached_property
    def problem(self):
        from ..inference.model.data import build_problem
        from ..observation.config_io import ConfigError
        from ..observation.markers import MarkerFileError
        from ..inference.fitting.noise_choice import with_saved_choice
        from ..inference.fitting.robust import with_saved_flags
        try:      # the noise models the run chose, robust flights cleaned as it judged
            problem = with_saved_flags(with_saved_choice(build_problem(self.config), self.run.run_dir),
                                       self.run.run_dir)
        except (ConfigError, MarkerFileError, FileNotFoundError) as e:
            raise ReportInputError(self.run.config_path, f"cannot rebuild the run's data: {e}") from None
        from ..inference.model.describe import flight_info
        strip = lambda d: {k: {a: b for a, b in v.items() if a != "file"} for k, v in d.items()}  # noqa: E731
        now, then = strip(flight_info(problem)), strip(self.summary["flights"])
        if now != then:
            changed = sorted(set(now) ^ set(then)) or sorted(k for k in now if now[k] != then[k])
            raise ReportInputError(self.run.config_path, f"flight data differ from the run's summary.json "
                                   f"(flight(s) {changed}): data or config changed since the run")
        from ..inference.results.draws import has_parameter
        from ..inference.results.summary import summary_names
        missing = [n for n in summary_names(problem) if not has_parameter(self.run.idata.posterior, n)]
        if missing:
            raise ReportInputError(self.run.run_dir / "posterior.nc",
                                   f"posterior lacks {missing[:5]} that the run's config implies")
        return problem

    @property
    def coefficients(self) -> list[str]:
        return list(self.summary["coefficients"])

    @property
    def flight_names(self) -> list[str]:
        return list(self.summary["flights"])

    # -- posterior --------------------------------------------------------------------------------------
    def posterior_array(self, names) -> np.ndarray:
        """(n_chain, n_draw, len(names)) posterior samples of summary.json parameter names."""
        from ..inference.results.draws import posterior_draws
        post = self.run.idata.posterior
        return np.stack([np.asarray(posterior_draws(post, n), float) for n in names], axis=-1)

    @cached_property
    def n_samples(self) -> int:
        """Number of kept posterior samples (chains × draws)."""
        sizes = self.run.idata.posterior.sizes
        return int(sizes["chain"] * sizes["draw"])

    def theta_at(self, flat_index: np.ndarray) -> np.ndarray:
        """Posterior samples at flat (chain-major) indices as θ rows (len, dim) in model order.

        Reads one parameter at a time, so the posterior is never copied as a whole."""
        from ..inference.results.draws import posterior_draws
        flat_index = np.asarray(flat_index, int)
        post = self.run.idata.posterior
        out = np.empty((flat_index.size, self.problem.dim))
        for i, n in enumerate(self.problem.names):
            out[:, i] = np.asarray(posterior_draws(post, n), float).reshape(-1)[flat_index]
        return out

    @cached_property
    def ref_index(self) -> int:
        """Flat index of the reference draw: the posterior sample with the highest log-posterior
        (``sample_stats.lp``), else the sample nearest the coefficients' medians."""
        ss = getattr(self.run.idata, "sample_stats", None)
        if ss is not None and "lp" in ss:
            lp = np.asarray(ss["lp"].values, float).reshape(-1)
            if lp.size == self.n_samples and np.isfinite(lp).any():
                return int(np.nanargmax(lp))
        x = self.coefficient_samples
        z = (x - np.median(x, axis=0)) / (x.std(axis=0) + 1e-300)
        return int(np.argmin(np.sum(z * z, axis=1)))

    @cached_property
    def band_indices(self) -> np.ndarray:
        """Flat indices of the posterior draws simulated for bands (seeded, without replacement)."""
        rng = np.random.default_rng(self.seed)
        return np.sort(rng.choice(self.n_samples, size=min(self.n_band_draws, self.n_samples), replace=False))

    @cached_property
    def _theta_sel(self) -> np.ndarray:
        return self.theta_at(np.r_[self.ref_index, self.band_indices])

    @cached_property
    def _sigma_sel(self) -> np.ndarray:
        """(1 + B, n_groups) noise scales of the reference and band draws (units of each group's data)."""
        from ..inference.results.draws import posterior_draws
        idx = np.r_[self.ref_index, self.band_indices]
        post = self.run.idata.posterior
        return np.stack([np.asarray(posterior_draws(post, n), float).reshape(-1)[idx]
                         for n in self.problem.sigma_names], axis=1)

    @property
    def theta_ref(self) -> np.ndarray:
        """θ (dim,) of the reference draw."""
        return self._theta_sel[0]

    @property
    def theta_draws(self) -> np.ndarray:
        """θ (B, dim) of the band draws."""
        return self._theta_sel[1:]

    @cached_property
    def coefficient_chains(self) -> np.ndarray:
        """(n_chain, n_draw, n_coef) posterior of the coefficients (all kept samples)."""
        return self.posterior_array(self.coefficients)

    @property
    def coefficient_samples(self) -> np.ndarray:
        """(N, n_coef) flattened posterior of the coefficients."""
        return self.coefficient_chains.reshape(-1, len(self.coefficients))

    @cached_property
    def ensemble_of_chain(self) -> np.ndarray:
        """(n_chain,) independent ensemble of every chain (walker): the ``ensemble`` coordinate of ``chain``
        (posterior.nc of an older version: its ``ensemble_of_chain`` attribute)."""
        post = self.run.idata.posterior
        n_chain = post.sizes["chain"]
        if "ensemble" in post.coords:
            return np.asarray(post["ensemble"].values, int)
        e = np.asarray(post.attrs.get("ensemble_of_chain", np.zeros(n_chain, int))).astype(int).reshape(-1)
        return e if e.size == n_chain else np.zeros(n_chain, int)

    # -- simulations ------------------------------------------------------------------------------------
    def simulate(self, theta: np.ndarray, k: int):
        """States and markers of flight k for θ (B, dim), exactly as the model predicts them."""
        return self.problem.simulate(theta, k, want_states=True)

    @cached_property
    def _trajectories(self) -> list:
        """Per flight, the Trajectories of the reference and band draws (flight k on its first channel's grid)."""
        return [self.simulate(self._theta_sel, k) for k in range(self.problem.n_flights)]

    @property
    def marker_flights(self) -> list[int]:
        """Indices of the flights recorded by markers (the marker figures and tables are about these)."""
        from ..observation.models import MarkerPositions
        return [k for k, ch in enumerate(self.problem.channels) if isinstance(ch[0], MarkerPositions)]

    @property
    def inertial_flights(self) -> list[int]:
        """Indices of the flights recorded by an inertial logger."""
        from ..observation.models.inertial import InertialMeasurements
        return [k for k, ch in enumerate(self.problem.channels) if any(isinstance(c, InertialMeasurements) for c in ch)]

    @cached_property
    def flight_sims(self) -> list[FlightSim]:
        """The marker flights' simulations (reference and band draws)."""
        p = self.problem
        out = []
        for k in self.marker_flights:
            f, tr = p.flights[k], self._trajectories[k]
            sig = self._sigma_sel[:, p.sigma_names.index(f"sigma_{f.name}")]
            out.append(FlightSim(name=f.name, times=f.times, measured=f.positions, marker_ids=tuple(f.marker_ids),
                                 ref_markers=tr.markers[0], ref_states=tr.states[0], draw_markers=tr.markers[1:],
                                 draw_states=tr.states[1:], sigma=sig[1:],
                                 sigma_ref=float(sig[0])))
        return out

    @cached_property
    def kinematics(self) -> list[dict]:
        """Per flight (every flight): α of the reference draw (n,) and of the band draws (B, n) [rad], air speed
        (n,) [m/s] and spin ω·b3 (n,) [rad/s] of the reference draw, and the times (n,) [s]."""
        out = []
        for k, tr in enumerate(self._trajectories):
            ref = self.problem.conditions(tr.states[0], self.theta_ref, k)
            draws = self.problem.conditions(tr.states[1:], self.theta_draws, k)
            out.append({"alpha_ref": ref.alpha[0], "alpha_draws": draws.alpha, "speed": ref.speed[0],
                        "spin": tr.states[0, :, 12], "times": tr.times})
        return out

    @cached_property
    def predictive(self) -> list[tuple]:
        """Per flight: (lo, hi, coverage) of the 90 % posterior predictive interval of measured − reference
        prediction (:func:`.figures.predictive_bands`; lo, hi (n, m, 3) [m], coverage 0…1), seeded."""
        from .figures import predictive_bands
        rng = np.random.default_rng(self.seed + 2)
        return [predictive_bands(s, rng) for s in self.flight_sims]

    @property
    def predictive_coverage(self) -> float:
        """Share of all observed coordinates inside their 90 % posterior predictive interval (0…1)."""
        n_in = n_seen = 0
        for s, (_, _, cov) in zip(self.flight_sims, self.predictive):
            seen = int(np.isfinite(s.residuals).sum())
            n_in += cov * seen
            n_seen += seen
        return float(n_in / max(n_seen, 1))

    def prepare(self) -> None:
        """Compute the state several sections share (the rebuilt problem, the reference and band draws'
        simulations, kinematics and predictive bands, the coefficients' chains), so that section builders
        run in worker processes inherit it instead of each computing it again.

        Raises
        ------
        ReportInputError
            If the run's data can no longer be rebuilt (:attr:`problem`).
        """
        for name in ("problem", "coefficient_chains", "kinematics", "predictive"):     # cached properties
            getattr(self, name)

    # -- truth ------------------------------------------------------------------------------------------
    @property
    def truth_coefficients(self) -> dict | None:
        t = self.run.truth
        if not t or not isinstance(t.get("coefficients"), dict):
            return None
        return {k: float(v) for k, v in t["coefficients"].items()}

    def truth_initial(self, k: int) -> np.ndarray | None:
        """Flight k's true initial condition in model parameters (12,), or None without a truth file.

        Only valid when the flight window starts where the truth's initial state is given."""
        t = self.run.truth
        f = self.problem.flights[k]
        try:
            s = t["flights"][f.name]["initial_state"]
        except (TypeError, KeyError):
            return None
        if abs(float(s.get("t", f.times[0])) - float(f.times[0])) > 1e-9:
            return None
        from ..inference.model.truth import initial_state
        return self.problem.state_to_ic(initial_state(t, f.name), k)

    def truth_sigma(self, name: str) -> float | None:
        t = self.run.truth
        try:
            return float(t["flights"][name]["noise_m"])
        except (TypeError, KeyError, ValueError):
            return None
