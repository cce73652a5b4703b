"""Missing physics: locate a mismatch, name the term of the library that explains it, show the gain.

Every candidate — the physics terms and data explanations of :mod:`bayes_disc.observation.registry`
(``MODEL_EXTENSIONS``) not already in the model — is added to the model
and the joint least-squares fit is refined from the base optimum. With the noise scale σ_g of every
noise group profiled out (one per marker flight; four per inertial throw: gyro axial/transverse,
accelerometer axial/transverse), the Gaussian log-likelihood is −½ Σ_g n_g ln S_g + const (S_g: the
group's summed squared residuals, n_g its residuals), so the Bayesian information criterion in favour of
the candidate is

    ΔBIC = Σ_g n_g ln(S_g,base / S_g,cand) − k ln N,

k its extra parameters, N = Σ_g n_g. An extension must earn its place: ΔBIC > 10 ("very strong",
Kass & Raftery 1995; a Bayes factor above e⁵) — for one parameter that is χ²₁ > 10 + ln N ≈ 18, a
chance of 2e−5 when nothing is missing.

Evidence alone would force any mismatch onto some term: a gust in one flight "improves" with a wind,
a ground effect or a roll term, each absorbing a little of it. A candidate is therefore accepted only
if it also explains the mismatch: after it, the residual series of every flight (markers: six directions
and three attitude angles; inertial: gyro and accelerometer along the sensor axes, :mod:`.residuals`) are
white by Ljung–Box at a Bonferroni-corrected level.
When no single candidate does, the strongest is combined with each of the others (at most two terms).

Partial explanations. Nature rarely uses the library's formula: a ground effect that decays with another
law is found by the ground-effect term (by far the largest ΔBIC) and still leaves structure. How much of
the misfit a candidate accounts for is measured against a noise floor that does not need the right model,
σ̂_g from the second differences of the base fit's residual series (:func:`.residuals.noise_floor`): the
base model's excess misfit is E = Σ_g max(S_g,base − n_g σ̂_g², 0) and a candidate's share of it

    share = Σ_g (S_g,base − S_g,cand) / E,   clipped to [0, 1],

undefined (NaN) when E is within noise of zero (E ≤ ``EXCESS_MIN_SD`` standard deviations of Σ_g S_g
under white noise, σ̂_g² √(2 n_g) per group): there is then no excess to share. A candidate is

* ``explains``: ΔBIC > threshold and every flight's residuals white;
* ``partially_explains``: ΔBIC > threshold, structure left, share ≥ ``SHARE_PARTIAL``, and replicated:
  at least two flights (the only one of a one-flight run) have an excess of their own of which the
  candidate removes at least half ``SHARE_PARTIAL`` (:func:`replicating_flights`; a gust marks one flight),
  or the candidate, as fitted, acts only in the flights where it removes excess (:func:`reached_flights`: a
  ground effect that only the one low flight reaches);
* ``insufficient``: ΔBIC > threshold, structure left, share below it (or undefined, or not replicated);
* ``no_evidence``: ΔBIC ≤ threshold.

Shares always refer to the base model (a pair's share is that of both terms together). When nothing
explains the data, the best partial explanation is adopted as the diagnosis' effect — the strongest
single candidate, or the strongest pair if its partner earns its place over the single (ΔBIC >
threshold) and the pair's share is at least ``SHARE_PARTIAL`` — and the structure it leaves is reported
as the rest of that effect, not as a disturbance no term describes. Structure that no candidate largely
removes (a gust: localised in one flight, every candidate's share small) is reported as unexplained,
with its flight, series and the time window where it is strongest.

A candidate's fit starts from more places than the base fit did (:func:`candidate_starts`), so part of
its gain can be a better optimum rather than better physics (inertial throws, with their many nuisance
parameters, show it on data with nothing missing). Before candidates are judged, the base model is
therefore refitted from the strongest candidate's optimum with the candidate switched off; if that
improves the base (Σ_g n_g ln S_g lower by more than ``BASE_REFIT_MIN``), it becomes the base and the
candidates are fitted again (at most ``BASE_REFITS`` times). The data explanations of marker recordings (``marker_geometry``,
``time_offset``) are candidates only when some flight has markers.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..physics.parallel import mp_context
from ..inference.fitting.leastsq import LeastSquaresResult, refine_least_squares
from ..inference.fitting.residuals import jacobian_blocks
from ..inference.fitting.minimiser import minimise
from ..inference.fitting.residuals import flight_residuals as flight_residuals_whitened
from ..inference.model.problem import Problem
from ..observation.models.markers import MarkerPositions
from ..observation.registry import DATA_EXPLANATION, MODEL_EXTENSIONS, unit
from ..physics import TERMS, literature_coefficients
from .residuals import flight_residuals, localise, noise_floor


#: every candidate, physics terms first
CANDIDATES = MODEL_EXTENSIONS
#: ΔBIC an extension must exceed
EVIDENCE_THRESHOLD = 10.0
#: family-wise chance of calling a correctly specified data set structured (Bonferroni over its series)
STRUCTURE_ALPHA = 1e-3
#: most terms combined
MAX_TERMS = 2
#: candidates tried together with the strongest one when it alone leaves structure
PAIR_PARTNERS = 3
#: times the base model may be replaced by its refit from a candidate's optimum
BASE_REFITS = 2
#: least improvement of the base (Σ_g n_g ln S_g) that replaces it
BASE_REFIT_MIN = 2.0
#: least share of the base model's excess misfit a candidate that leaves structure must remove to be
#: adopted as a partial explanation (half: it then accounts for more of the mismatch than all else together)
SHARE_PARTIAL = 0.5
#: the excess misfit counts as zero (share undefined) below this many standard deviations of Σ_g S_g
#: under white noise
EXCESS_MIN_SD = 3.0
#: candidate statuses, from best to worst
STATUSES = ("explains", "partially_explains", "insufficient", "no_evidence")


def applicable_candidates(problem: Problem, candidates=CANDIDATES) -> tuple[list, dict]:
    """The candidates that can act on the problem's data, and {id: reason} for those skipped (data
    explanations of marker recordings when no flight has markers).

    Parameters
    ----------
    problem : Problem
    candidates : sequence of str
        Candidate ids (physics terms and data explanations).

    Returns
    -------
    keep : list of str
    skipped : dict
        {id: reason in words}.
    """
    has_markers = any(isinstance(c, MarkerPositions) for ch in problem.channels for c in ch)
    keep, skipped = [], {}
    for cid in candidates:
        if unit(cid).kind == DATA_EXPLANATION and not has_markers:
            skipped[cid] = "explains marker recordings; no flight of the run has markers"
        else:
            keep.append(cid)
    return keep, skipped


@dataclass
class ModelFit:
    """A least-squares fit of one model: its extra term ids, problem, result, S_g per noise group [unit²]
    and residual series."""

    ids: tuple
    problem: Problem
    ls: LeastSquaresResult
    ss: np.ndarray
    residuals: list = field(default_factory=list)
    localisation: dict = field(default_factory=dict)

    @property
    def noise_floor(self) -> np.ndarray:
        """n_g σ̂_g² (n_groups,) [unit²]: the sums of squares noise alone would give, σ̂_g from the second
        differences of this fit's residual series (:func:`.residuals.noise_floor`)."""
        sigma = noise_floor(self.residuals, self.problem.n_groups)
        return self.problem.n_coords * sigma ** 2

    @property
    def rms(self) -> dict:
        """{flight: {channel: {"rms", "unit"}}}: RMS residual per recorded quantity of each flight
        (``markers`` [m] per coordinate, ``gyro`` [rad/s], ``acc`` [m/s²] per sensor axis)."""
        out = {}
        for f, fr in zip(self.problem.flights, self.residuals):
            acc = {}
            for part, off in zip(fr.parts, fr.group_offsets):
                for g, (chan, u) in enumerate(part.group_channels):
                    s, n, _ = acc.get(chan, (0.0, 0, u))
                    acc[chan] = (s + float(self.ss[off + g]), n + int(self.problem.n_coords[off + g]), u)
            out[f.name] = {c: {"rms": float(np.sqrt(s / n)) if n else float("nan"), "unit": u}
                           for c, (s, n, u) in acc.items()}
        return out

    @property
    def rms_mm(self) -> dict:
        """{flight: marker RMS [mm] per coordinate} of the flights with markers (docs/outputs.md)."""
        return {f: d["markers"]["rms"] * 1e3 for f, d in self.rms.items() if "markers" in d}


def model_fit(problem: Problem, ls: LeastSquaresResult, ids) -> ModelFit:
    """Residuals and localisation of a fitted model."""
    ss = problem.sum_squares(ls.theta[None])[0]
    res = flight_residuals(problem, ls.theta)
    return ModelFit(tuple(ids), problem, ls, ss, res, localise(problem, ls.theta, ls.sigma, res))


def structure_level(n_series: int, alpha: float = STRUCTURE_ALPHA) -> float:
    """Ljung–Box p-value below which one of ``n_series`` series counts as structured."""
    return alpha / max(n_series, 1)


def structured(fit: ModelFit, alpha: float = STRUCTURE_ALPHA) -> dict:
    """{flight: [series whose residuals are not white]} (empty lists for white flights)."""
    n_series = sum(len(per) for per in fit.localisation.values())
    level = structure_level(n_series, alpha)
    return {name: [s for s, d in per.items() if np.isfinite(d["ljung_box_p"]) and d["ljung_box_p"] < level]
            for name, per in fit.localisation.items()}


def extend_theta(theta: np.ndarray, source: Problem, target: Problem) -> np.ndarray:
    """θ of ``source`` mapped into ``target`` (same flights, more extra parameters): shared entries copied,
    new extra parameters at their starting values (the value that switches them off)."""
    return target.layout.transfer(theta, source.layout, target.start_vector())


def evidence(base: ModelFit, cand: ModelFit, groups: np.ndarray | None = None) -> float:
    """ΔBIC of ``cand`` over ``base`` (module docstring), over all noise groups or the boolean mask
    ``groups`` (n_groups,)."""
    n = base.problem.n_coords.astype(float)
    gain = n * np.log(base.ss / cand.ss)
    mask = np.ones(n.size, bool) if groups is None else groups
    k = cand.problem.n_ext - base.problem.n_ext
    return float(np.sum(gain[mask]) - k * np.log(np.sum(n[mask])))


def excess_share(base_ss: np.ndarray, cand_ss: np.ndarray, floor: np.ndarray, n: np.ndarray,
                 min_sd: float = EXCESS_MIN_SD) -> float:
    """The share of the base model's excess misfit a candidate removes (module docstring).

    share = Σ_g (S_g,base − S_g,cand) / Σ_g max(S_g,base − n_g σ̂_g², 0), clipped to [0, 1].

    Parameters
    ----------
    base_ss, cand_ss : (n_groups,) arrays
        Summed squared residuals S_g of the base model and of the candidate [unit²].
    floor : (n_groups,) array
        n_g σ̂_g²: what noise alone gives [unit²] (:attr:`ModelFit.noise_floor`).
    n : (n_groups,) array
        Residuals per group n_g.
    min_sd : float
        The excess counts as zero below this many standard deviations of Σ_g S_g under white noise
        (Σ_g 2 n_g σ̂_g⁴)^½.

    Returns
    -------
    float
        The share in [0, 1]; NaN when the excess is zero (nothing to share) or the floor unknown.
    """
    base_ss, cand_ss, floor = (np.asarray(a, float) for a in (base_ss, cand_ss, floor))
    n = np.asarray(n, float)
    ok = np.isfinite(floor) & np.isfinite(base_ss) & np.isfinite(cand_ss)
    if not ok.any():
        return float("nan")
    excess = float(np.sum(np.maximum(base_ss[ok] - floor[ok], 0.0)))
    sd = float(np.sqrt(np.sum(2.0 * floor[ok] ** 2 / np.maximum(n[ok], 1.0))))     # σ̂⁴ √(2n) = floor² · 2/n
    if excess <= min_sd * sd or excess <= 0.0:
        return float("nan")
    return float(np.clip(np.sum(base_ss[ok] - cand_ss[ok]) / excess, 0.0, 1.0))


def replicating_flights(base_ss: np.ndarray, cand_ss: np.ndarray, floor: np.ndarray, n: np.ndarray,
                        flight_groups: list, min_share: float = 0.5 * SHARE_PARTIAL) -> list[int]:
    """The flights that have an excess misfit of their own (:func:`excess_share` defined for their groups)
    of which the candidate removes at least ``min_share``.

    A partial explanation must be replicated: physics acts in every flight that reaches the state it
    depends on, whereas a disturbance (a gust, a collision) marks one flight, and a term with free
    parameters bent to one flight's excess can remove most of it (a ground effect takes 77 % of a side gust's).

    Parameters
    ----------
    base_ss, cand_ss, floor, n : (n_groups,) arrays
        As for :func:`excess_share`.
    flight_groups : list of (k,) int arrays
        Each flight's noise groups.
    min_share : float
        Least share of a flight's own excess the candidate must remove there.

    Returns
    -------
    list of int
        Flight indices.
    """
    out = []
    for k, g in enumerate(flight_groups):
        share = excess_share(np.asarray(base_ss)[g], np.asarray(cand_ss)[g], np.asarray(floor)[g], np.asarray(n)[g])
        if np.isfinite(share) and share >= min_share:
            out.append(k)
    return out


#: a candidate reaches a flight when, as fitted, it moves the flight's whitened residuals by more than this
#: many sd of their sum of squares under noise (√(2 n_k)), beyond what the flight's own parameters absorb
REACH_SD = EXCESS_MIN_SD


def switched_off(fit: ModelFit, origin: ModelFit) -> np.ndarray:
    """θ of ``fit`` (dim,) with the parameters ``origin``'s model does not have at the values that switch
    them off (:func:`extend_theta`)."""
    back = origin.problem.layout.transfer(fit.ls.theta, fit.problem.layout, origin.ls.theta)
    return extend_theta(back, origin.problem, fit.problem)


def reach(fit: ModelFit, origin: ModelFit) -> np.ndarray:
    """How much the terms ``fit`` adds to ``origin`` act in each flight, in units of the noise.

    With δ_k = r_k(θ̂) − r_k(θ̂_off) the change of flight k's whitened residuals when the added terms are
    switched off (every other parameter at the fit's optimum, :func:`switched_off`) and J_k the whitened
    Jacobian of flight k's own parameters (launch state, per-flight nuisances),

        D_k = |(I − J_k J_k⁺) δ_k|²,

    the part of the terms' action the flight's launch cannot absorb. Under noise alone a flight's sum of
    squares has sd √(2 n_k); D_k above ``REACH_SD`` of them cannot hide in the noise.

    Parameters
    ----------
    fit : ModelFit
        The model with the added terms.
    origin : ModelFit
        The model without them (same flights).

    Returns
    -------
    (n_flights,) array
        D_k / √(2 n_k), n_k the flight's residuals.
    """
    p, sigma = fit.problem, fit.ls.sigma
    on, off = fit.ls.theta, switched_off(fit, origin)
    r_on, r_off = flight_residuals_whitened(on, p, sigma), flight_residuals_whitened(off, p, sigma)
    own = np.zeros(on.size, bool)
    own[p.ic_start:] = True
    J = jacobian_blocks(on, p, sigma, own)
    out = np.empty(p.n_flights)
    for k in range(p.n_flights):
        d = r_on[k] - r_off[k]
        A = J.blocks[k]
        e = d - A @ np.linalg.lstsq(A, d, rcond=None)[0] if A.size else d
        out[k] = float(e @ e) / np.sqrt(2.0 * max(d.size, 1))
    return out


def reached_flights(fit: ModelFit, origin: ModelFit, level: float = REACH_SD) -> list[int]:
    """The flights the terms ``fit`` adds to ``origin`` act in beyond the noise (:func:`reach` > ``level``)."""
    return [int(k) for k in np.flatnonzero(reach(fit, origin) > level)]


def replication(base: ModelFit, fit: ModelFit, floor: np.ndarray, reached=reached_flights) -> dict:
    """Whether a candidate's removal of excess misfit is replicated: in two flights (:func:`replicating_flights`),
    in the only flight of a one-flight run, or in every flight the candidate, as fitted, acts in (``reached(fit,
    base)``, default :func:`reached_flights`): physics of a state only some flights visit (a ground effect only
    the low flight reaches) is seen only there, whereas a term bent to a gust in one flight acts in the others too
    (a lower flight feels a ground effect more), where it removes nothing.

    Returns
    -------
    dict
        ``replicated`` (bool), ``removing`` (flight indices whose own excess it removes) and ``reached`` (flight
        indices it acts in; None when not needed: two removing flights suffice).
    """
    p = base.problem
    groups = [p.flight_groups(k) for k in range(p.n_flights)]
    removing = replicating_flights(base.ss, fit.ss, floor, p.n_coords, groups)
    if len(removing) >= min(2, p.n_flights):
        return {"replicated": True, "removing": removing, "reached": None}
    acts = list(reached(fit, base)) if removing else None
    return {"replicated": bool(removing) and set(acts) <= set(removing), "removing": removing, "reached": acts}


@dataclass
class Candidate:
    """One candidate judged against the model it extends (statuses: module docstring); ``share``: the
    share of the base model's excess misfit it (with the terms it extends) removes, in [0, 1] or NaN."""

    id: str
    fit: ModelFit
    delta_bic: float
    per_flight_gain: dict
    structured_after: dict
    status: str = ""          # explains | partially_explains | insufficient | no_evidence
    clean_evidence: float = float("nan")
    extra_parameters: int = 0
    share: float = float("nan")
    replication: dict | None = None      # :func:`replication`, when the share was large enough to ask


def judge(base: ModelFit, cand_id: str, fit: ModelFit, floor: np.ndarray, threshold: float = EVIDENCE_THRESHOLD,
          origin: ModelFit | None = None, share_partial: float = SHARE_PARTIAL, reached=reached_flights) -> Candidate:
    """One candidate judged against the model it extends.

    Parameters
    ----------
    base : ModelFit
        The model the candidate extends (the base, or the strongest single candidate in the pair round).
    cand_id : str
    fit : ModelFit
        The fit of ``base`` extended by the candidate.
    floor : (n_groups,) array
        n_g σ̂_g² of the base model (:attr:`ModelFit.noise_floor`) [unit²].
    threshold : float
        ΔBIC the candidate must exceed over ``base``.
    origin : ModelFit, optional
        The base model of the diagnosis, whose excess misfit the share refers to; default ``base``.
    share_partial : float
        Least share of a partial explanation.
    reached : callable
        ``reached(fit, origin)``: the flights the candidate acts in (:func:`replication`).

    Returns
    -------
    Candidate
        ΔBIC over ``base``, per-flight gain Σ_{g ∈ flight} n_g ln(S_g,base/S_g,cand), whiteness after, the
        share of ``origin``'s excess misfit removed and the status (module docstring).
    """
    p = base.problem
    origin = base if origin is None else origin
    gain = p.n_coords * np.log(base.ss / fit.ss)
    c = Candidate(cand_id, fit, evidence(base, fit),
                  {f.name: float(np.sum(gain[p.flight_groups(k)])) for k, f in enumerate(p.flights)},
                  structured(fit), extra_parameters=fit.problem.n_ext - p.n_ext,
                  share=excess_share(origin.ss, fit.ss, floor, p.n_coords))
    clean = np.array([not c.structured_after[f.name] for f in p.flights])
    if c.delta_bic <= threshold:
        c.status = "no_evidence"
    else:
        if clean.all():
            c.status = "explains"
        elif np.isfinite(c.share) and c.share >= share_partial:
            c.replication = replication(origin, fit, floor, reached)
            c.status = "partially_explains" if c.replication["replicated"] else "insufficient"
        else:
            c.status = "insufficient"
        if clean.any():
            mask = np.zeros(p.n_groups, bool)
            for k in np.flatnonzero(clean):
                mask[p.flight_groups(k)] = True
            c.clean_evidence = evidence(base, fit, mask)
    return c


def candidate_starts(base: ModelFit, problem: Problem) -> list[np.ndarray]:
    """Starts of a candidate's fit: the base optimum extended, and the data-derived initial conditions with
    the base coefficients and with the wind-tunnel (Potts & Crowther) ones. The base optimum alone is not
    enough: its initial conditions have absorbed part of the missing effect (a tilted, wobbling launch
    mimicking a side force, say), a valley from which the extension's parameter does not escape."""
    extended = extend_theta(base.ls.theta, base.problem, problem)
    fresh = problem.start_vector()
    fresh[: problem.n_coef] = base.ls.theta[: problem.n_coef]
    literature = fresh.copy()
    literature[: problem.n_coef] = literature_coefficients("potts_crowther").as_array()
    return [extended, fresh, literature]


#: evaluations each start gets before the best one is refined to convergence
SCOUT_NFEV = 40


def _fit_task(task):
    problem, starts, sigma, max_nfev = task
    best = None
    for x0 in starts:
        res = minimise(problem, x0, sigma, max_nfev=min(SCOUT_NFEV, max_nfev))
        if best is None or res.cost < best.cost:
            best = res
    return refine_least_squares(problem, best.x, max_nfev=max_nfev)


def fit_candidates(base: ModelFit, build, ids, processes: int = 1, max_nfev: int = 200) -> dict:
    """Least-squares fits of ``base`` extended by each candidate id in ``ids`` (best of
    :func:`candidate_starts`); ``build(ids)`` makes the :class:`Problem` of a model. Returns {id: ModelFit}."""
    problems = {c: build(base.ids + (c,)) for c in ids}
    for p in problems.values():
        p.kernel_terms = tuple(TERMS.values())      # one compiled kernel for every candidate
    tasks = [(p, candidate_starts(base, p), base.ls.sigma, max_nfev) for p in problems.values()]
    if processes > 1 and len(tasks) > 1:
        # compile the shared kernel (both batch widths) here, once: forked workers inherit it, spawned ones
        # load it from the disk cache (physics.kernel_cache)
        p, x0 = next(iter(problems.values())), tasks[0][1][0]
        p.residuals(x0[None], 0)
        p.residuals(np.repeat(x0[None], 2 * p.flight_columns(0).size, axis=0), 0)
        with mp_context().Pool(min(processes, len(tasks))) as pool:
            results = pool.map(_fit_task, tasks, chunksize=1)
    else:
        results = [_fit_task(t) for t in tasks]
    return {c: model_fit(p, ls, base.ids + (c,)) for (c, p), ls in zip(problems.items(), results)}


def refit_base(base: ModelFit, fits: dict, max_nfev: int = 200, threshold: float = EVIDENCE_THRESHOLD,
               minimum: float = BASE_REFIT_MIN) -> tuple[ModelFit, str, float] | None:
    """The base model refitted from the strongest candidate's optimum (its extra parameters dropped).

    Parameters
    ----------
    base : ModelFit
    fits : dict
        {candidate id: ModelFit} of the candidates.
    max_nfev : int
        Function evaluations of the refit.
    threshold : float
        Only a candidate with ΔBIC above it is used.
    minimum : float
        Least improvement Σ_g n_g ln(S_g,base / S_g,refit) that counts.

    Returns
    -------
    (ModelFit, str, float) or None
        The better base fit, the candidate it started from and the improvement; None if none.
    """
    scored = sorted(((evidence(base, f), c, f) for c, f in fits.items()), key=lambda t: -t[0])
    if not scored or scored[0][0] <= threshold:
        return None
    _, cid, fit = scored[0]
    p = base.problem
    x0 = p.layout.transfer(fit.ls.theta, fit.problem.layout, base.ls.theta)
    ls = refine_least_squares(p, x0, max_nfev=max_nfev)
    ss = p.sum_squares(ls.theta[None])[0]
    gain = float(np.sum(p.n_coords * np.log(base.ss / ss)))
    if not np.isfinite(gain) or gain <= minimum:
        return None
    return model_fit(p, ls, base.ids), cid, gain


@dataclass
class Diagnosis:
    """The outcome: base and final fits, every candidate judged (per round), the accepted ids and the
    structure left unexplained.

    ``partial``: the accepted terms are the best partial explanation (module docstring), so the structure
    in ``unexplained`` is the rest of their effect; ``share``: the share of the base model's excess misfit
    the accepted terms remove (NaN when none are accepted or the excess is zero)."""

    base: ModelFit
    final: ModelFit
    rounds: list            # [[Candidate ranked best first], ...]
    accepted: list          # [Candidate]
    unexplained: dict       # {flight: [series]}
    partial: bool = False
    share: float = float("nan")

    @property
    def verdict(self) -> str:
        return "missing_physics" if self.accepted or any(self.unexplained.values()) else "adequate"


def best_partial(single: Candidate | None, pairs: list) -> list:
    """The best partial explanation: [single, partner] when the strongest partner earns its place over the
    single (ΔBIC > threshold: status other than ``no_evidence``) and the pair's share is at least
    ``SHARE_PARTIAL`` (status ``partially_explains``); else [single] when the single partially explains;
    else [].

    Parameters
    ----------
    single : Candidate or None
        The strongest single candidate (the first round).
    pairs : list of Candidate
        The partners judged against it (the second round), ranked best first.

    Returns
    -------
    list of Candidate
    """
    if single is None:
        return []
    if pairs and pairs[0].status == "partially_explains":
        return [single, pairs[0]]
    return [single] if single.status == "partially_explains" else []


def diagnose(base: ModelFit, build, processes: int = 1, max_nfev: int = 200, candidates=CANDIDATES,
             threshold: float = EVIDENCE_THRESHOLD, log=lambda msg: None) -> Diagnosis:
    """Rank the candidates (module docstring), accept those that earn their place and explain the data, or
    else adopt the best partial explanation."""
    current, accepted, rounds = base, [], []
    pending, floor = None, None
    ids = [c for c in candidates if c not in base.ids]
    for r in range(MAX_TERMS):
        if not ids:
            break
        fits = fit_candidates(current, build, ids, processes=processes, max_nfev=max_nfev)
        for _ in range(BASE_REFITS if r == 0 else 0):
            better = refit_base(current, fits, max_nfev=max_nfev, threshold=threshold)
            if better is None:
                break
            current, cid, gain = better
            base = current
            log(f"  the base model refits to a better optimum from the {cid} fit (Σ n ln S lower by {gain:.1f}); "
                "fitting the candidates again")
            fits = fit_candidates(current, build, ids, processes=processes, max_nfev=max_nfev)
        if floor is None:
            floor = base.noise_floor
        ranked = sorted((judge(current, c, f, floor, threshold, origin=base) for c, f in fits.items()),
                        key=lambda c: c.delta_bic, reverse=True)
        rounds.append(ranked)
        log("  " + ", ".join(f"{c.id} ΔBIC {c.delta_bic:.1f} ({c.status}, share {c.share:.2f})" for c in ranked))
        good = [c for c in ranked if c.status == "explains"]
        if good:
            accepted += ([pending] if pending is not None else []) + [good[0]]
            break
        if pending is not None or ranked[0].status not in ("insufficient", "partially_explains"):
            break
        # the strongest candidate leaves structure: try it together with each of the next strongest
        pending = ranked[0]
        current = ranked[0].fit
        ids = [c.id for c in ranked[1: 1 + PAIR_PARTNERS] if c.status != "no_evidence"]
    partial = False
    if not accepted:
        accepted = best_partial(pending, rounds[1] if len(rounds) > 1 else [])
        partial = bool(accepted)
        if partial:
            log("  no candidate leaves white residuals; adopting the best partial explanation: "
                + " + ".join(c.id for c in accepted) + f" (share {accepted[-1].share:.2f} of the excess misfit)")
    final = accepted[-1].fit if accepted else base
    left = structured(final)
    share = accepted[-1].share if accepted else float("nan")
    return Diagnosis(base=base, final=final, rounds=rounds, accepted=accepted, unexplained=left, partial=partial,
                     share=share)
