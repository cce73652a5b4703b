"""Is the transverse gyro's misfit a randomly forced nutation? The check ``diagnose`` makes on inertial throws
fitted with white gyro noise.

A wobble nudged along the flight by forcing the model does not carry (gusts, turbulence) leaves a narrow-band
residual at the wobble's rate that no deterministic term can follow in phase, yet candidate terms judged with
white noise gain evidence by following part of it (``runs/concealed_nutation/``: ΔBIC 38 for three wobble terms
the data do not contain). The check fits the noise model of ``gyro_noise: nutation``
(:mod:`bayes_disc.observation.models.nutation`) to the base fit's transverse gyro residuals r_k (held fixed):
λ, κ_N and a shared by the throws, σ_f of each throw integrated out (Jeffreys), maximising

    Δℓ(λ, κ_N, a) = Σ_f [ −(n_f/2) ln(S_f / S_f,white) + ln |W_f| ],   S_f = Σ_k |e_k|²,  n_f = 2 rows

(e_k the filter's whitened residuals, S_f,white = Σ_k |r_k|², ln |W_f| = −Σ_k ln S̃_k). With the flight model
refitted under the nutation the gain can only grow, so Δℓ is a lower bound of what ``gyro_noise: nutation``
gains; its evidence is ΔBIC = 2 Δℓ − 3 ln N (N: the transverse gyro residuals). Above the evidence threshold the
candidates' evidence, computed with white gyro noise, is not evidence of physics: the words say so and name the
option that judges them without it.
"""
from __future__ import annotations

import math

import numpy as np
from scipy.optimize import minimize

from ..observation.models.inertial import InertialMeasurements
from ..observation.models.nutation import nutation_filter
from .wobble import inertial_gyro

__all__ = ["gyro_residuals", "nutation_gain", "random_nutation", "nutation_words"]

#: ΔBIC above which the randomly forced nutation counts as found (the candidates' threshold)
THRESHOLD = 10.0
#: starts of the fit (λ [1/s], κ_N, a)
STARTS = ((3.0, 0.8, 5.0), (3.0, 0.95, 5.0), (0.5, 0.9, 3.0))


def gyro_residuals(problem, theta: np.ndarray, k: int):
    """(row times [s] (n,), transverse gyro residuals model − data (n, 2) [rad/s], measured spin (n,) [rad/s]) of
    flight k's inertial channel at θ (dim,), or None when the flight has none or already fits the nutation."""
    got = inertial_gyro(problem, theta, k)
    if got is None or any(isinstance(m, InertialMeasurements) and m.gyro_noise != "white"
                          for m in problem.observations[k]):
        return None
    t, measured, predicted, _ = got
    return t, predicted[:, :2] - measured[:, :2], measured[:, 2].copy()


def nutation_gain(params, series: list) -> float:
    """Δℓ (module docstring) of the nutation (λ [1/s], κ_N, a) over white noise for the throws' ``series``
    [(t, r, spin), …]; −inf outside λ > 0, a ≥ 0."""
    lam, kap, a = (float(v) for v in params)
    if not (lam > 0 and a >= 0):
        return -math.inf
    gain = 0.0
    for t, r, spin in series:
        dt = np.diff(t, prepend=t[0])[None]
        ex, ey, ld = nutation_filter(r[None, :, 0].copy(), r[None, :, 1].copy(), dt, spin, np.array([lam]),
                                     np.array([kap]), np.array([a]))
        n = 2 * t.size
        gain += -0.5 * n * math.log((np.sum(ex * ex) + np.sum(ey * ey)) / np.sum(r * r)) + 2.0 * float(np.sum(ld))
    return gain


def random_nutation(problem, theta: np.ndarray) -> dict | None:
    """The check at θ (dim,) (module docstring): ``log_likelihood_gain`` Δℓ, ``evidence`` ΔBIC, ``found``,
    ``decay_per_s`` λ, ``kappa`` κ_N, ``amplitude`` a and per throw ``rms`` (the residuals'), ``white_sigma``,
    ``nutation_rms`` a σ and ``innovation_rms`` [rad/s], and ``words``; None without an inertial throw fitted
    with white gyro noise."""
    names, series = [], []
    for k, f in enumerate(problem.flights):
        got = gyro_residuals(problem, theta, k)
        if got is not None:
            names.append(f.name)
            series.append(got)
    if not series:
        return None
    best = min((minimize(lambda p: -nutation_gain(p, series), s, method="Nelder-Mead",
                         options={"maxiter": 2000, "xatol": 1e-4, "fatol": 1e-3}) for s in STARTS),
               key=lambda o: o.fun)
    lam, kap, a = (float(v) for v in best.x)
    gain = -float(best.fun)
    n_total = sum(2 * t.size for t, _, _ in series)
    throws = {}
    for name, (t, r, spin) in zip(names, series):
        dt = np.diff(t, prepend=t[0])[None]
        ex, ey, ld = nutation_filter(r[None, :, 0].copy(), r[None, :, 1].copy(), dt, spin, np.array([lam]),
                                     np.array([kap]), np.array([a]))
        e = np.c_[ex[0], ey[0]]
        sigma = float(np.sqrt(np.mean(e ** 2)))
        throws[name] = {"rms": float(np.sqrt(np.mean(r ** 2))), "white_sigma": sigma, "nutation_rms": a * sigma,
                        "innovation_rms": float(np.sqrt(np.mean((e * np.exp(-ld[0])[:, None]) ** 2)))}
    evidence = 2.0 * gain - 3.0 * math.log(n_total)
    rec = {"log_likelihood_gain": gain, "evidence": evidence, "found": evidence > THRESHOLD, "decay_per_s": lam,
           "kappa": kap, "amplitude": a, "throws": throws}
    rec["words"] = nutation_words(rec)
    return rec


def nutation_words(rec: dict) -> str:
    """The check in words: found (with its size, rate, decay and what it means for the candidates) or not."""
    if not rec["found"]:
        return (f"The transverse gyro misfit is not a randomly forced nutation (ΔBIC {rec['evidence']:.0f} at the "
                f"base fit, threshold {THRESHOLD:.0f}).")
    th = rec["throws"].values()
    nut = [v["nutation_rms"] for v in th]
    sig = [v["white_sigma"] for v in th]
    return (f"The transverse gyro misfit behaves as a randomly forced nutation (ΔBIC {rec['evidence']:.0f} at the "
            f"base fit for 3 parameters): turning at {rec['kappa']:.2f} × the spin in the disc, relaxing at "
            f"{rec['decay_per_s']:.1f} /s, {min(nut):.2f}–{max(nut):.2f} rad/s RMS on white noise of "
            f"{min(sig):.2f}–{max(sig):.2f} rad/s. A wobble forced along the way by something the flight model does "
            "not carry (gusts, turbulence) has a phase no term can follow, and candidates judged with white gyro "
            "noise gain evidence from it: refit with `gyro_noise: nutation` under the logs' `imu:` entries to "
            "judge them without it.")
