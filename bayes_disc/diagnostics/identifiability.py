"""Identifiability: which coefficients the flights determine, why, and which throw would fix the rest.

Everything here works at the least-squares optimum θ̂ (no MCMC); after ``sample`` the same verdicts are
recomputed from the posterior samples (:func:`verdicts_from_covariance` on their covariance).

* Flight envelope: α, speed |v| and spin r = ω·b3 per flight along the fitted trajectory, and for the set.
* Fisher information of the coefficients, with every flight's initial conditions as nuisance
  parameters: with F = JᵀJ of the whitened marker residuals (data only) split into coefficient (c) and
  initial-condition (i) blocks, the information left for the coefficients is the Schur complement

      F_c|i = F_cc − F_ci (F_ii + P_i)⁻¹ F_ic          (P_i: the weak initial-condition prior precision)

  Its eigen-analysis in scale-free form (each coefficient scaled by its prior sd) gives the condition
  number and the poorly determined directions, put into words through the posterior covariance
  Σ (Laplace: (F + P)⁻¹): for the two coefficients a, b that dominate a weak direction, the data
  determine a + k·b with k = −Σ_ab / Σ_bb, not a and b apart.
* Verdicts per coefficient (:func:`verdict`): ``unidentified`` when the prior, not the data, sets it
  (posterior variance ≥ half the prior variance, or a flat profile); ``weak`` when it is determined only
  in combination with its α partner (the offset–slope pairs CL0/CLa, CD0/CDa, CM0/CMa: |correlation| >
  ``PAIR_CORRELATION``, the signature of a narrow α range, Hummel & Hubbard's central finding), when the
  profile is one-sided, or when it is known only to ±``RELATIVE_SD`` of its size; ``identified``
  otherwise. Each verdict carries its reason tied to the data (α span, correlation, size).
* Experiment design (:func:`rank_throws`): candidate throws on a grid of speed, launch angle, angle of
  attack and spin; each one's expected coefficient information (its own initial conditions as
  nuisance) is added to the current posterior precision; throws are ranked by the D-optimal gain on the
  weak block, ln det Σ_weak − ln det Σ_weak,new, and the best is described in words and numbers. The
  candidates are marker flights (positions at 120 Hz); a run without marker data gets no design
  (:func:`design_skip_reason`).

Inertial recordings (docs/data-formats.md) enter the same Fisher information: every flight's own parameters (initial
conditions, and for a logger its row period, biases and filter state) are the nuisance block, the logger's
shared mount (r_s, τ, tilt) sits beside the coefficients. A logger measures rotation rates and specific
force, not position: the airspeed and the angle of attack reach the data only through the dynamics (the
forces and moments they produce), which :func:`data_description` puts into every reason.
"""
from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

from ..inference.fitting.arrow import ArrowJacobian
from ..inference.fitting.residuals import jacobian_blocks
from ..inference.model.problem import Problem
from ..observation.markers import FlightObservation
from ..observation.models import MarkerPositions
from ..observation.synth import LaunchSpec
from ..physics import LITERATURE

#: offset–slope pairs whose separation needs a spread of angle of attack
ALPHA_PAIRS = (("CL0", "CLa"), ("CD0", "CDa"), ("CM0", "CMa"))
#: |posterior correlation| of an α pair above which the slope is not separated from the offset
PAIR_CORRELATION = 0.9
#: posterior variance / prior variance at or above which the prior sets the coefficient
PRIOR_DOMINATED = 0.5
#: posterior sd / size above which a coefficient counts as weakly determined
RELATIVE_SD = 0.25
#: default grid of candidate throws
THROW_GRID = {"speed": (8.0, 11.0, 14.0, 17.0), "launch_angle_deg": (0.0, 8.0, 16.0),
              "alpha_deg": (0.0, 10.0, 20.0, 30.0), "spin": (45.0, 65.0)}


# ---------------------------------------------------------------------------------------------- envelope
@dataclass
class FlightEnvelope:
    """α [deg], speed [m/s] and spin r [rad/s] along one fitted flight."""

    name: str
    alpha_deg: np.ndarray
    speed: np.ndarray
    spin: np.ndarray

    def ranges(self) -> dict:
        return {"alpha_deg": [float(self.alpha_deg.min()), float(self.alpha_deg.max())],
                "speed_m_s": [float(self.speed.min()), float(self.speed.max())],
                "spin_rad_s": [float(self.spin.min()), float(self.spin.max())]}


def flight_envelopes(problem: Problem, theta: np.ndarray) -> list[FlightEnvelope]:
    """The envelope of every flight along its trajectory for parameters θ (dim,)."""
    out = []
    for k, f in enumerate(problem.flights):
        tr = problem.simulate(theta[None], k, want_states=True)
        st = tr.states[0]
        air = problem.conditions(st, theta, k)
        out.append(FlightEnvelope(f.name, np.degrees(air.alpha[0]), air.speed[0], st[:, 12]))
    return out


# ------------------------------------------------------------------------------------------- information
def coefficient_information(problem: Problem, J: ArrowJacobian) -> np.ndarray:
    """F_c|i: the data's information on the coefficients (+ extra-term parameters) with the initial
    conditions marginalised (their weak priors regularise the nuisance block).

    Parameters
    ----------
    problem : Problem
    J : ArrowJacobian
        Whitened Jacobian over every parameter (:func:`~bayes_disc.inference.fitting.residuals.jacobian_blocks`).

    Returns
    -------
    (ic_start, ic_start) array
        The Schur complement of the information's arrow (:meth:`ArrowMatrix.schur`), less the shared
        parameters' own prior precision.
    """
    if J.n != problem.dim or J.shared.size != problem.ic_start:
        raise ValueError("coefficient_information needs the Jacobian over every parameter")
    return J.information().schur() - np.diag(J.prior[J.shared] ** 2)


def weak_directions(info: np.ndarray, scale: np.ndarray, cov: np.ndarray, names, n: int = 3) -> list[dict]:
    """The ``n`` least-determined directions of the scale-free information D F D (D = diag(scale)), each
    with its eigenvalue, the dominant coefficients and a sentence: which combination the data determine."""
    Fs = info * np.outer(scale, scale)
    w, V = np.linalg.eigh(0.5 * (Fs + Fs.T))
    out = []
    for j in range(min(n, w.size)):
        v = V[:, j]
        top = [int(t) for t in np.argsort(-np.abs(v))[:2]]
        a, b = top
        r = cov[a, b] / np.sqrt(cov[a, a] * cov[b, b])
        k = -cov[a, b] / cov[b, b]
        sd_comb = np.sqrt(max(cov[a, a] + 2 * k * cov[a, b] + k * k * cov[b, b], 0.0))
        text = (f"{names[a]} and {names[b]} move together (posterior correlation {r:+.2f}): the data determine "
                f"{names[a]} {'+' if k >= 0 else '−'} {abs(k):.3g}·{names[b]} (sd {sd_comb:.2g}) better than "
                f"either alone (sd {np.sqrt(cov[a, a]):.2g}, {np.sqrt(cov[b, b]):.2g})")
        out.append({"eigenvalue": float(w[j]), "components": {names[t]: float(v[t]) for t in np.argsort(-np.abs(v))[:4]},
                    "pair": [names[a], names[b]], "correlation": float(r), "combination_factor": float(k),
                    "text": text})
    return out


# ---------------------------------------------------------------------------------------------- verdicts
def _size(name: str, value: float, floor: float = 0.0) -> float:
    """The size a coefficient's sd is compared with: the largest of its estimate, the literature values and
    ``floor`` (for a sensor parameter whose value may be 0, e.g. a tilt: its plausible range, the prior sd)."""
    lit = [abs(s.values[name]) for s in LITERATURE.values() if s.values.get(name) is not None]
    return max([abs(value), floor] + lit)


def _pair_of(name: str):
    for off, slope in ALPHA_PAIRS:
        if name in (off, slope):
            return off, slope
    return None


def data_description(problem: Problem) -> dict:
    """What the flights record, for the verdicts' reasons.

    Parameters
    ----------
    problem : Problem

    Returns
    -------
    dict
        ``markers``, ``inertial``, ``inertial_only`` (numbers of flights with marker data, with an inertial
        logger, with the logger alone) and ``text``: a phrase (empty for marker data alone) saying how the
        α span was obtained and, without markers, that airspeed and α are seen only through the dynamics.
    """
    kinds = [{"imu" if not isinstance(c, MarkerPositions) else "markers" for c in ch} for ch in problem.channels]
    n_markers = sum("markers" in k for k in kinds)
    n_imu = sum("imu" in k for k in kinds)
    n_only = sum(k == {"imu"} for k in kinds)
    if n_imu == 0:
        text = ""
    elif n_markers == 0:
        text = ("inertial data only: no positions, airspeed and α are seen only through the forces and moments "
                "they produce; this α span is the fitted model's")
    else:
        text = (f"markers on {n_markers} flight(s), an inertial logger on {n_imu}"
                + (f" ({n_only} without markers: there airspeed and α are seen only through the dynamics)"
                   if n_only else ""))
    return {"markers": n_markers, "inertial": n_imu, "inertial_only": n_only, "text": text}


def verdict(name: str, index: dict, value: np.ndarray, cov: np.ndarray, prior_sd: np.ndarray, alpha_span,
            profile_shape: str | None = None, profile_halfwidth: float | None = None, data: str = "",
            size_floor: float = 0.0) -> dict:
    """Verdict and reason for coefficient ``name`` from the posterior mean ``value`` and covariance ``cov``
    (coefficient block, indexed by ``index``), the prior sds and the α span [deg] of the flights. With a
    profile, its shape and half-width (:meth:`.ProfilePath.halfwidth`) count too: the sd used is the larger
    of the covariance's and the profile's. ``data``: what the flights record (:func:`data_description`
    ``text``), added to the reason; ``size_floor``: the smallest size the sd is compared with (:func:`_size`)."""
    i = index[name]
    sd = float(np.sqrt(cov[i, i]))
    if profile_halfwidth is not None and np.isfinite(profile_halfwidth):
        sd = max(sd, float(profile_halfwidth))
    ratio = sd ** 2 / prior_sd[i] ** 2
    lo, hi = alpha_span
    span = f"α spans {lo:.0f}–{hi:.0f}° over all flights" + (f" ({data})" if data else "")
    size = _size(name, value[i], size_floor)
    rel = sd / size if size > 0 else float("inf")          # a parameter at 0 with no scale of its own
    out = {"value": float(value[i]), "sd": sd, "prior_sd": float(prior_sd[i]), "variance_ratio": float(ratio),
           "contraction": float(1 - ratio), "relative_sd": rel}
    if ratio >= PRIOR_DOMINATED:
        return out | {"verdict": "unidentified",
                      "reason": f"the prior sets it: posterior sd {sd:.2g} is {np.sqrt(ratio):.0%} of the prior sd "
                                f"{prior_sd[i]:.2g}; {span}"}
    if profile_shape == "flat":
        return out | {"verdict": "unidentified", "reason": f"flat profile likelihood: the data do not bound it; {span}"}
    pair = _pair_of(name)
    if pair is not None:
        a, b = index[pair[0]], index[pair[1]]
        r = cov[a, b] / np.sqrt(cov[a, a] * cov[b, b])
        out["pair_correlation"] = float(r)
        if abs(r) > PAIR_CORRELATION:
            k = -cov[a, b] / cov[b, b]
            need = "drag curvature needs" if pair[1] == "CDa" else "separating them needs"
            target = 5 * np.ceil(max(15.0, hi + 10.0) / 5)
            return out | {"verdict": "weak",
                          "reason": f"{span}: {pair[0]} and {pair[1]} move together (correlation {r:+.2f}); only "
                                    f"{pair[0]} {'+' if k >= 0 else '−'} {abs(k):.2g}·{pair[1]} is determined; "
                                    f"{need} flights reaching α ≈ {target:.0f}°"}
    if profile_shape == "one-sided":
        return out | {"verdict": "weak", "reason": f"one-sided profile likelihood: bounded on one side only; {span}"}
    if rel > RELATIVE_SD:
        return out | {"verdict": "weak", "reason": f"known only to ±{sd:.2g} ({rel:.0%} of its size {size:.2g}); "
                                                   f"{span}"}
    return out | {"verdict": "identified",
                  "reason": f"sd {sd:.2g} ({sd / size:.1%} of its size), {1 - ratio:.1%} of the prior variance "
                            f"removed; {span}"}


def verdicts_from_covariance(names, value, cov, prior_sd, alpha_span, profiles=None, data: str = "",
                             size_floors: dict | None = None) -> dict:
    """Verdicts of every coefficient; ``profiles``: {name: ProfilePath} (optional); ``data``: what the
    flights record (:func:`data_description` ``text``); ``size_floors``: {name: smallest size} for
    parameters that may be 0 (:func:`_size`)."""
    index = {n: i for i, n in enumerate(names)}
    prof = profiles or {}
    floors = size_floors or {}
    return {n: verdict(n, index, value, cov, prior_sd, alpha_span,
                       prof[n].classify() if n in prof else None, prof[n].halfwidth() if n in prof else None,
                       data, floors.get(n, 0.0))
            for n in names}


# ------------------------------------------------------------------------------------- experiment design
def candidate_launches(grid: dict = THROW_GRID, spin_sign: float = 1.0, duration: float = 1.0):
    """LaunchSpecs on the grid (roll 0, released 1 m above the ground)."""
    out = []
    for sp, ga, al, r in itertools.product(grid["speed"], grid["launch_angle_deg"], grid["alpha_deg"], grid["spin"]):
        out.append(LaunchSpec(name=f"v{sp:g}_g{ga:g}_a{al:g}_r{r:g}", speed=sp, launch_angle_deg=ga, alpha_deg=al,
                              spin=spin_sign * r, duration=duration))
    return out


def design_skip_reason(problem: Problem) -> str | None:
    """Why the next-throw design cannot run for this problem (None when it can): the candidates are marker
    flights, so the run needs marker data (their ids and noise)."""
    if not any(isinstance(c, MarkerPositions) for ch in problem.channels for c in ch):
        return ("not computed: the candidate throws are simulated as marker flights (positions at 120 Hz) and "
                "this run has no marker data; a design for inertial throws would need the logger's per-throw "
                "parameters (row period, biases, filter state), which a candidate throw does not have")
    return None


def marker_noise(problem: Problem, sigma: np.ndarray) -> float:
    """Median noise scale [m] of the marker noise groups (``sigma``: one value per noise group)."""
    names = {n for ch in problem.channels for c in ch if isinstance(c, MarkerPositions) for n in c.noise_names}
    vals = [s for n, s in zip(problem.sigma_names, sigma) if n in names]
    if not vals:
        raise ValueError("marker_noise: the problem has no marker data")
    return float(np.median(vals))


def throw_information(problem: Problem, theta: np.ndarray, launch: LaunchSpec, sigma: float,
                      rate_hz: float = 120.0) -> np.ndarray | None:
    """Expected information (coefficient block, its initial conditions marginalised) of one throw simulated
    with the coefficients of θ and observed at ``rate_hz`` with noise ``sigma`` [m]; None if the throw does
    not fly (simulation failure or the disc below the ground).

    The candidate is a marker flight: its information is returned on the problem's whole shared block
    (``problem.ic_start`` square), zero for the observation models' shared parameters (e.g. an inertial
    logger's mount) that a marker flight does not see."""
    times = np.arange(int(round(launch.duration * rate_hz)) + 1) / rate_hz
    y0 = launch.initial_state()
    marker = [c for ch in problem.channels for c in ch if isinstance(c, MarkerPositions)]
    if not marker:
        raise ValueError(design_skip_reason(problem))
    ids = marker[0].data.marker_ids
    n_shared = problem.layout.explanation_slice.stop          # coefficients, terms, explanations

    def one_flight(positions) -> Problem:
        obs = FlightObservation(name=launch.name, source="design", times=times, marker_ids=ids, positions=positions)
        return Problem(flights=[obs], marker_body=problem.marker_body, disc=problem.disc, env=problem.env,
                       prior_name=problem.prior_name, terms=problem.terms, explanations=problem.explanations,
                       term_start=problem.term_start[: n_shared - problem.n_coef], start_states=[y0],
                       settings=problem.settings)

    sub = one_flight(np.zeros((times.size, len(ids), 3)))
    x = np.r_[theta[:n_shared], sub.state_to_ic(y0, 0)]
    tr = sub.simulate(x[None], 0, want_states=True)
    if not tr.ok[0] or np.any(tr.states[0, :, 2] < 0.0):
        return None
    sub = one_flight(tr.markers[0])   # observed = predicted: the information does not depend on the values
    J = jacobian_blocks(x, sub, np.array([sigma]))
    F = np.zeros((problem.ic_start, problem.ic_start))
    F[:n_shared, :n_shared] = coefficient_information(sub, J)
    return F


def rank_throws(problem: Problem, theta: np.ndarray, cov_coef: np.ndarray, weak: list[int], sigma: float,
                launches=None) -> list[dict]:
    """Candidate throws ranked by the D-optimal gain on the weak block (indices into the coefficient block):
    ln det Σ_weak − ln det Σ_weak,new with Σ_new = (Σ⁻¹ + F_throw)⁻¹; also each weak coefficient's sd now
    and after the throw."""
    if launches is None:
        spins = [s[12] for s in problem.start_states]        # the flights' dominant sense of spin
        launches = candidate_launches(spin_sign=1.0 if np.sum(np.sign(spins)) >= 0 else -1.0)
    P = np.linalg.inv(cov_coef)
    W = np.asarray(weak, int)
    _, ld0 = np.linalg.slogdet(cov_coef[np.ix_(W, W)])
    out = []
    for launch in launches:
        F = throw_information(problem, theta, launch, sigma)
        if F is None:
            continue
        C = np.linalg.inv(P + F)
        _, ld = np.linalg.slogdet(C[np.ix_(W, W)])
        out.append({"launch": launch, "gain": float(ld0 - ld), "sd_before": np.sqrt(np.diag(cov_coef)[W]),
                    "sd_after": np.sqrt(np.diag(C)[W])})
    out.sort(key=lambda d: -d["gain"])
    return out


def describe_throw(best: dict, names) -> str:
    L = best["launch"]
    hand = "right-handed backhand (clockwise from above)" if L.spin > 0 else "forehand / left-handed backhand"
    changes = ", ".join(f"{n} sd {a:.2g} → {b:.2g}" for n, a, b in zip(names, best["sd_before"], best["sd_after"]))
    return (f"Throw at {L.speed:g} m/s, {L.launch_angle_deg:g}° above horizontal, angle of attack {L.alpha_deg:g}° at "
            f"release, spin {abs(L.spin):g} rad/s {hand}, {L.duration:g} s of tracking: expected {changes} "
            f"(uncertainty volume of the weak block ÷ {np.exp(best['gain']):.3g}).")
