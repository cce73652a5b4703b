"""Each marker flight's noise model chosen by evidence: ``noise: {model: auto}``, the default.

One function, :func:`choose_noise`, makes the choice; ``sample``, ``identifiability`` and ``diagnose`` call it
at the same least-squares optimum, so they cannot disagree. It starts from the run fitted with white Gaussian noise on
every ``auto`` flight (per-point errors as its ``per_point`` says: :func:`~bayes_disc.inference.model.data.
build_problem`) and decides per flight:

1. **Gross errors.** The inlier/outlier/label-swap mixture judges the flight's points and frames at that fit
   (:func:`.robust.suspected_gross_errors`: a gross error or a swap with probability ≥ 0.99). If it finds
   any, the flight gets ``robust`` noise: its gross errors are judged, removed and refitted before sampling
   (:func:`.robust.robust_refit`). Evidence does not rank ``robust`` against the others: it is fitted to
   other data (the cleaned ones). When more than :data:`.robust.MANY_SUSPECTS` (2 %) of the flight's
   points are judged gross errors, the noise more likely varies along the flight than that many slips
   occurred: the flight is judged by evidence instead, and its record says why (``not_robust``).
2. **Evidence.** Otherwise the least squares are refitted with each other candidate on every such flight at
   once: ``white`` (one σ per flight), ``per_point`` (white noise shaped by the file's ``sigma_m`` or
   covariance columns; only when the flight has them and ``per_point`` is not false), ``ar1`` (AR(1) in
   time; only on a regular frame grid) and ``ar1_per_point``. With σ_f integrated out (prior 1/σ_f) the
   log marginal likelihood of a flight's n_f marker coordinates is −(n_f/2) ln S̃_f plus a constant that is
   the same for every candidate (S̃_f the effective sum of squares, :mod:`bayes_disc.observation.models.
   noise`), so the Bayesian information criterion of candidate c against the reference (``white``, or
   ``per_point`` when ``per_point: true`` is set) is

       ΔBIC_f(c) = n_f ln(S̃_f,reference / S̃_f,c) − k_c ln n_f,

   S̃_f,c at candidate c's joint least-squares optimum (its ρ_f fitted first with the rest held, then
   everything), S̃_f,reference the reference's lowest at any of the candidates' optima (so that a candidate
   gains nothing from a start fit that stopped short of its optimum), k_c the candidate's own parameters per
   flight (1 for AR(1)'s ρ_f, 0 otherwise). The candidate with the largest ΔBIC is chosen when it exceeds
   :data:`NOISE_EVIDENCE` = 10 (the threshold of ``diagnose``'s candidate terms); otherwise the reference
   stays.
3. The run is refitted with every flight's choice (no refit when one candidate's fit already is it).

A flight whose ``noise.model`` is set (at the top level or under ``flight_options``) keeps it as given.
Inertial channels have their own noise scale per sensor group and are never changed; a flight seen only
by an inertial logger has no marker noise to choose.
"""
from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ...observation.models import MarkerPositions
from ...observation.models.noise import AR1Noise, RobustNoise, frame_index
from ..model.config import AUTO, NoiseSettings, RunConfig
from ..model.problem import Problem
from .leastsq import REFINE_DECREMENT, LeastSquaresResult, refine_least_squares
from .minimiser import minimise
from .robust import MANY_SUSPECTS, suspected_gross_errors

#: ΔBIC a candidate needs over the reference to be chosen
NOISE_EVIDENCE = 10.0
#: candidates within this ΔBIC of the best are tied and the simplest (first in :data:`CANDIDATES`) is taken:
#: per-point errors that are all alike give the white likelihood itself, up to the refits' round-off
TIE = 0.1
#: the choice a run made, in its output folder
NOISE_CHOICE = "noise_choice.json"
#: candidates compared by evidence: label → (noise.model, noise.per_point)
CANDIDATES = {"white": ("gaussian", "false"), "per_point": ("gaussian", "true"),
              "ar1": ("ar1", "false"), "ar1_per_point": ("ar1", "true")}
#: own parameters per flight of each candidate (the k of ΔBIC)
CANDIDATE_PARAMETERS = {"white": 0, "per_point": 0, "ar1": 1, "ar1_per_point": 1}
#: each label in words
TITLES = {"white": "white noise", "per_point": "white noise shaped by the stated per-point errors",
          "ar1": "AR(1) noise", "ar1_per_point": "AR(1) noise shaped by the stated per-point errors",
          "robust": "robust noise"}


def marker_channel(problem: Problem, k: int) -> MarkerPositions | None:
    """Flight k's marker model, None for a flight seen only by an inertial logger."""
    return next((c for c in problem.channels[k] if isinstance(c, MarkerPositions)), None)


def noise_label(model: MarkerPositions) -> str:
    """The label (:data:`CANDIDATES`, or ``robust``) of a marker model's noise."""
    if isinstance(model.noise, RobustNoise):
        return "robust"
    ar1 = isinstance(model.noise, AR1Noise)
    if model.noise.points is None:
        return "ar1" if ar1 else "white"
    return "ar1_per_point" if ar1 else "per_point"


def flight_candidates(model: MarkerPositions, setting: NoiseSettings) -> tuple[list[str], dict]:
    """The candidates of one ``auto`` flight and why any is left out.

    Parameters
    ----------
    model : MarkerPositions
        The flight's marker model.
    setting : NoiseSettings
        Its noise settings (``per_point`` decides which per-point candidates exist).

    Returns
    -------
    labels : list of str
        Candidate labels (:data:`CANDIDATES`), reference first.
    notes : dict
        {label: why it is not a candidate}.
    """
    data = model.data
    has_points = getattr(data, "cov", None) is not None or data.sigma is not None
    notes = {}
    if setting.per_point == "true":
        per_point = ["true"]
    elif has_points and setting.per_point == "auto":
        per_point = ["false", "true"]
    else:
        per_point = ["false"]
        notes["per_point"] = ("per_point: false" if has_points else
                              "the marker file has no sigma_m or covariance columns")
    models = ["gaussian", "ar1"]
    try:
        frame_index(data.times, data.name)
    except ValueError as e:
        models = ["gaussian"]
        notes["ar1"] = str(e)
    labels = [lab for lab, mp in CANDIDATES.items() if mp[0] in models and mp[1] in per_point]
    return labels, notes


@dataclass
class CandidateFit:
    """The least squares with one candidate on a set of flights (the others as in the start)."""

    label: str
    flights: list
    problem: Problem
    ls: LeastSquaresResult
    ss: np.ndarray = field(init=False)

    def __post_init__(self):
        self.ss = self.problem.sum_squares(self.ls.theta[None])[0]

    def flight_ss(self, k: int, ss: np.ndarray | None = None) -> tuple[float, int]:
        """(S̃, n) of flight k's marker coordinates at this fit (or in the sums of squares ``ss``)."""
        j = next(i for i, c in enumerate(self.problem.channels[k]) if isinstance(c, MarkerPositions))
        g = self.problem.channel_groups(k)[j].start
        return float((self.ss if ss is None else ss)[g]), int(self.problem.n_coords[g])

    def ss_at(self, other: "CandidateFit") -> np.ndarray:
        """(n_groups,) this candidate's S̃ per noise group at ``other``'s optimum (the shared entries and
        initial conditions; this fit's own noise parameters where ``other`` has none)."""
        x = self.problem.layout.transfer(other.ls.theta, other.problem.layout, self.ls.theta)
        return self.problem.sum_squares(x[None])[0]

    def rho(self, flight: str) -> float | None:
        name = f"rho_{flight}"
        return float(self.ls.theta[self.problem.names.index(name)]) if name in self.problem.names else None


def _refit(problem: Problem, ls: LeastSquaresResult, noise: dict, max_nfev: int) -> tuple[Problem, LeastSquaresResult]:
    """The problem with the marker noise ``noise`` ({flight: (model, per_point)}) refitted from ``ls``: the
    new noise parameters (ρ_f) first, everything else held at ``ls`` (a smooth fit of a few parameters), then
    everything. The first stage lets ρ_f reach its estimate even where the joint fit cannot move (a start
    that stalled: its steps along a coefficient rejected)."""
    other = problem.with_marker_noise(noise)
    x0 = other.layout.transfer(ls.theta, problem.layout, other.start_vector())
    new = np.isin(other.names, [n for n in other.names if n not in problem.names])
    if new.any():          # the noise scales of the start: they only weigh the flights' separate fits of ρ_f
        x0 = minimise(other, x0, ls.sigma, free=new, max_nfev=max_nfev, dtol=REFINE_DECREMENT).x
    return other, refine_least_squares(other, x0, max_nfev=max_nfev)


def candidate_fits(problem: Problem, ls: LeastSquaresResult, labels: dict, max_nfev: int = 200,
                   progress=None) -> dict:
    """Every candidate's least squares over the flights that have it.

    Parameters
    ----------
    problem : Problem
        The run with white noise on the ``auto`` flights (:func:`choose_noise`).
    ls : LeastSquaresResult
        Its optimum.
    labels : dict
        {flight index: candidate labels} of the flights judged by evidence.
    max_nfev : int
        Evaluation budget of each refinement round.
    progress : callable, optional
        ``progress(label, flights)`` before each refit.

    Returns
    -------
    dict
        {label: CandidateFit}; a candidate every flight already has in ``problem`` reuses ``ls``.
    """
    fits = {}
    for label, setting in CANDIDATES.items():
        ks = [k for k, labs in labels.items() if label in labs]
        if not ks:
            continue
        names = [problem.flights[k].name for k in ks]
        if all(noise_label(marker_channel(problem, k)) == label for k in ks):
            fits[label] = CandidateFit(label, names, problem, ls)
            continue
        if progress is not None:
            progress(label, names)
        p, fit = _refit(problem, ls, {n: setting for n in names}, max_nfev)
        fits[label] = CandidateFit(label, names, p, fit)
    return fits


def evidence_record(k: int, name: str, labels: list, notes: dict, fits: dict) -> dict:
    """One flight's evidence: ΔBIC of each candidate against the reference (its first label), ρ̂ of the AR(1)
    candidates, and the label chosen (:data:`NOISE_EVIDENCE`)."""
    reference = labels[0]
    ref = fits[reference]
    # the reference at its best point among the fits: a candidate gains nothing from a start that stalled
    s_ref, n = min(ref.flight_ss(k, ref.ss_at(fits[lab])) for lab in labels)
    delta, rho = {reference: 0.0}, {}
    for lab in labels[1:]:
        s, _ = fits[lab].flight_ss(k)
        d = n * np.log(s_ref / s) - CANDIDATE_PARAMETERS[lab] * np.log(n)
        delta[lab] = float(d) if np.isfinite(d) else None
        if CANDIDATE_PARAMETERS[lab]:
            rho[lab] = fits[lab].rho(name)
    scored = [lab for lab in labels[1:] if delta[lab] is not None]
    top = max((delta[lab] for lab in scored), default=-np.inf)
    best = next((lab for lab in scored if delta[lab] >= top - TIE), None)      # the simplest of a tie
    label = best if best is not None and delta[best] > NOISE_EVIDENCE else reference
    return {"label": label, "by": "evidence", "reference": reference, "delta_bic": delta, "rho": rho,
            "threshold_delta_bic": NOISE_EVIDENCE, "not_tried": notes}


def _merged_start(final: Problem, base: Problem, ls: LeastSquaresResult, chosen: dict, fits: dict) -> np.ndarray:
    """Start of the final refit: shared parameters from the start fit, each flight's own entries from the fit
    of its chosen candidate."""
    x = final.layout.transfer(ls.theta, base.layout, final.start_vector())
    for k, f in enumerate(final.flights):
        fit = fits.get(chosen.get(f.name))
        if fit is None:
            continue
        src = dict(zip(fit.problem.names, fit.ls.theta))
        s = final.layout.flight_slice(k)
        x[s] = [src.get(n, v) for n, v in zip(final.names[s], x[s])]
    return x


def _likelihood_labels(problem: Problem, start: Problem) -> dict:
    """{flight: label} of the marker flights, ``robust`` read as its start's label (the same likelihood
    before the cleaning)."""
    out = {}
    for k, f in enumerate(problem.flights):
        m = marker_channel(problem, k)
        if m is not None:
            lab = noise_label(m)
            out[f.name] = noise_label(marker_channel(start, k)) if lab == "robust" else lab
    return out


def choice_text(name: str, rec: dict) -> str:
    """One line: flight, the noise model it gets, and why (the evidence, the judgement or the configuration)."""
    label = rec["label"]
    if rec["by"] == "configuration":
        return f"{name}: {TITLES[label]}, as configured"
    if rec["by"] == "gross errors":
        return (f"{name}: robust noise chosen: {rec['outliers']} point(s) judged gross errors and {rec['swaps']} "
                "frame(s) label-swapped at the white fit")
    ref, delta = rec["reference"], rec["delta_bic"]
    varies = f"; not robust: {rec['not_robust']}" if "not_robust" in rec else ""
    others = ", ".join(f"{lab} {_signed(d)}" for lab, d in delta.items() if lab not in (ref, label))
    if label == ref:
        return (f"{name}: {TITLES[ref]} kept (ΔBIC over it: {others or 'no other candidate'}; "
                f"a candidate needs > {NOISE_EVIDENCE:.0f}){varies}")
    rho = rec["rho"].get(label)
    return (f"{name}: {TITLES[label]} chosen (ΔBIC {_signed(delta[label])} over {ref}"
            + (f", ρ̂ = {rho:.2f}" if rho is not None else "") + ")" + (f"; others: {others}" if others else "")
            + varies)


def _signed(d) -> str:
    return "n/a" if d is None else f"{d:+.1f}"


@dataclass
class NoiseChoice:
    """The marker noise of every flight and why (:func:`choose_noise`).

    Attributes
    ----------
    problem : Problem
        The run with the chosen noise models (``robust`` flights not yet cleaned).
    ls : LeastSquaresResult
        Its least-squares optimum.
    records : dict
        {flight: record} per marker flight (docs/outputs.md, ``noise_choice``): ``setting`` (as configured),
        ``chosen`` ({model, per_point}: what the run uses), ``label``, ``by`` (``evidence``, ``gross errors``
        or ``configuration``), ``text``; for ``auto`` flights also ``outliers`` and ``swaps`` (judged at the
        white fit) and, when judged by evidence, ``reference``, ``delta_bic`` {label: ΔBIC}, ``rho``
        {label: ρ̂}, ``threshold_delta_bic``, ``not_tried`` {label: reason} and, when too many points looked
        like gross errors for ``robust``, ``not_robust`` (why).
    """

    problem: Problem
    ls: LeastSquaresResult
    records: dict

    def settings(self) -> dict:
        """{flight: {"model", "per_point"}} of the flights whose model was chosen (not configured)."""
        return {f: dict(r["chosen"]) for f, r in self.records.items() if r["by"] != "configuration"}

    def lines(self) -> list[str]:
        """One line per marker flight (:func:`choice_text`)."""
        return [r["text"] for r in self.records.values()]

    def save(self, run_dir) -> Path:
        """Write ``<run_dir>/noise_choice.json`` ({flight: record}); returns its path."""
        path = Path(run_dir) / NOISE_CHOICE
        path.write_text(json.dumps(self.records, indent=1))
        return path


def run_settings(cfg: RunConfig, problem: Problem) -> dict:
    """{flight: NoiseSettings} of the problem's flights as the configuration sets them."""
    return {f.name: cfg.flight_noise(f.name)[0] for f in problem.flights}


def _final_fit(problem: Problem, ls: LeastSquaresResult, records: dict, fits: dict,
               max_nfev: int) -> tuple[Problem, LeastSquaresResult]:
    """The run with every chosen model: a candidate's fit when it already is that model, else refitted from
    the merged start (:func:`_merged_start`)."""
    changed = {}
    for k, f in enumerate(problem.flights):
        rec = records.get(f.name)
        if rec is not None and rec["by"] != "configuration" and rec["label"] != noise_label(marker_channel(problem, k)):
            changed[f.name] = (rec["chosen"]["model"], rec["chosen"]["per_point"])
    if not changed:
        return problem, ls
    final = problem.with_marker_noise(changed)
    want = _likelihood_labels(final, problem)
    if want == _likelihood_labels(problem, problem):
        return final, ls                                    # robust flights only: the same likelihood
    for fit in fits.values():
        if _likelihood_labels(fit.problem, problem) == want:
            return final, fit.ls
    x0 = _merged_start(final, problem, ls, {n: r["label"] for n, r in records.items()}, fits)
    return final, refine_least_squares(final, x0, max_nfev=max_nfev)


def choose_noise(problem: Problem, ls: LeastSquaresResult, settings: dict, max_nfev: int = 200,
                 progress=None) -> NoiseChoice:
    """Choose the marker noise model of every ``auto`` flight (module docstring).

    Parameters
    ----------
    problem : Problem
        The run as built from its configuration (``auto`` flights with white noise).
    ls : LeastSquaresResult
        Its least-squares optimum.
    settings : dict
        {flight: NoiseSettings} (:func:`run_settings`); a flight not listed is ``auto``.
    max_nfev : int
        Evaluation budget of each refinement round.
    progress : callable, optional
        ``progress(label, flights)`` before each candidate's refit.

    Returns
    -------
    NoiseChoice
        The run with the chosen models, its optimum and a record per marker flight.
    """
    records, auto = {}, []
    for k, f in enumerate(problem.flights):
        m = marker_channel(problem, k)
        if m is None:
            continue
        s = settings.get(f.name, NoiseSettings())
        records[f.name] = {"setting": {"model": s.model, "per_point": s.per_point}}
        if s.model == AUTO:
            auto.append(k)
        else:
            records[f.name].update(chosen={"model": s.model, "per_point": s.per_point}, label=noise_label(m),
                                   by="configuration")
    suspects = suspected_gross_errors(problem, ls.theta) if auto else {}
    labels, notes = {}, {}
    for k in auto:
        name, s = problem.flights[k].name, settings.get(problem.flights[k].name, NoiseSettings())
        found = suspects.get(name, {"outliers": 0, "swaps": 0, "points": 1})
        records[name].update(outliers=found["outliers"], swaps=found["swaps"])
        if found["outliers"] > MANY_SUSPECTS * found["points"]:
            records[name]["not_robust"] = (f"{found['outliers']} of {found['points']} points judged gross errors, more "
                                           f"than {MANY_SUSPECTS:.0%}: the noise more likely varies along the flight")
        if name in suspects and "not_robust" not in records[name]:
            records[name].update(label="robust", by="gross errors", chosen={"model": "robust", "per_point": s.per_point})
        else:
            labels[k], notes[k] = flight_candidates(marker_channel(problem, k), s)
    fits = candidate_fits(problem, ls, labels, max_nfev=max_nfev, progress=progress)
    for k in labels:
        name = problem.flights[k].name
        rec = evidence_record(k, name, labels[k], notes[k], fits)
        model, per_point = CANDIDATES[rec["label"]]
        records[name].update(rec, chosen={"model": model, "per_point": per_point})
    first = ("setting", "chosen", "label", "by")
    records = {name: {**{key: rec[key] for key in first}, "text": choice_text(name, rec),
                      **{key: v for key, v in rec.items() if key not in first}} for name, rec in records.items()}
    final, final_ls = _final_fit(problem, ls, records, fits, max_nfev)
    return NoiseChoice(final, final_ls, records)


def with_saved_choice(problem: Problem, run_dir) -> Problem:
    """The problem with the noise models a run chose (its ``noise_choice.json``) applied to the flights
    chosen for; unchanged when the folder has no such file (a run made before the choice, or none to make).

    Parameters
    ----------
    problem : Problem
        Rebuilt from the run's configuration.
    run_dir : str or Path
        The run's output folder.

    Returns
    -------
    Problem
    """
    path = Path(run_dir) / NOISE_CHOICE
    if not path.is_file():
        return problem
    records = json.loads(path.read_text())
    names = {f.name for f in problem.flights}
    chosen = {f: (r["chosen"]["model"], r["chosen"]["per_point"]) for f, r in records.items()
              if r["by"] != "configuration" and f in names}
    return problem.with_marker_noise(chosen) if chosen else problem
