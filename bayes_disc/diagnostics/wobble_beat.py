"""The late wobble of an inertial throw as a beat of two nutations: one locked to the spin, one free.

Late in a flight the wobble of the real logger throws fades and grows again. A sliding window of a quarter
second (:mod:`.wobble`) sees one nutation whose κ wanders between the two; over the whole late span the
transverse rates z = g_x + i g_y [rad/s] are fitted instead by three phasors,

    z(t) ≈ K + L e^{iΔφ} e^{−λ_L τ} + F e^{iκ_F Δφ} e^{−λ_F τ},

with Δφ = φ(t) − φ(t_c) the spin phase from the span's centre t_c, τ = t − t_c [s]:

* K — the part fixed in sensor axes (the mount tilt and the gyro bias) [rad/s];
* L — a nutation locked to the spin, κ = 1 (it turns at twice the spin in space): the response to a moment
  fixed in the disc (an asymmetry), at amplitude |L| [rad/s] and decay rate λ_L [1/s] (positive: decaying);
* F — a free nutation at κ_F, its own turning rate over the spin: the rigid disc's torque-free wobble shifted by
  the aerodynamic moments (:func:`.wobble.rigid_nutation`), at |F| [rad/s], decaying at λ_F [1/s].

Two nutations whose rates differ by (1 − κ_F) r beat: the wobble's amplitude swings between ||L| − |F|| and
|L| + |F| every

    T_beat = 2π / ((1 − κ_F) |r|)                                                         [s]

so a wobble that fades and grows again late in the flight is two undamped nutations, not a forcing that
switches on. A model whose free nutation has decayed (or whose κ_F differs) cannot follow the beat.

Method: variable projection. For each (κ_F, λ_L, λ_F) the complex amplitudes are a linear least-squares fit;
κ_F is searched on a grid (``KAPPA_STEP``) between ``KAPPA_MIN`` and the largest κ_F whose beat turns at least
half a cycle over the span, 1 − π/(|r̄| T) (closer to 1 the two phasors cannot be told apart), with no decay;
then κ_F, λ_L, λ_F are refined together from the best grid point (Nelder–Mead; decay rates bounded by
``DECAY_BOUND``). The free nutation is *resolved* when |F| exceeds ``NUTATION_SNR`` standard errors
√(RSS/(n − 9)/n) and ``NUTATION_MIN``. The record also gives the RMS left by the three phasors and by K and L
alone: the share of the late wobble the free nutation carries is 1 − RSS₃/RSS₂. The locked nutation is
resolved by the same rule.
"""
from __future__ import annotations

import numpy as np
from scipy.optimize import minimize

__all__ = ["beat_fit", "beat_words", "free_missing", "late_beat", "phasor_solve", "resolved"]

#: the late span starts this long after release [s] (after the release wobble's fast early decay)
START_S = 1.0
#: shortest late span fitted [s]
MIN_SPAN_S = 1.0
#: lowest κ_F searched and the grid step [1]
KAPPA_MIN = 0.7
KAPPA_STEP = 0.0025
#: decay rates λ_L, λ_F are bounded to ±DECAY_BOUND [1/s]
DECAY_BOUND = 3.0
#: a nutation is resolved above this many standard errors of its fit and above NUTATION_MIN [rad/s] (the rule of
#: the sliding windows of :mod:`.wobble` and of the late span's fit alike: :func:`resolved`)
NUTATION_SNR = 5.0
NUTATION_MIN = 0.02
#: a free nutation of the data is missing from the model when the model's is below this fraction of it
MISSING_RATIO = 0.5


def _design(dphi: np.ndarray, tau: np.ndarray, kappa: float, lam_l: float, lam_f: float) -> np.ndarray:
    """(n, 3) columns 1, e^{iΔφ − λ_L τ}, e^{iκΔφ − λ_F τ}."""
    return np.stack([np.ones_like(dphi, complex), np.exp(1j * dphi - lam_l * tau),
                     np.exp(1j * kappa * dphi - lam_f * tau)], axis=1)


def phasor_solve(A: np.ndarray, z: np.ndarray) -> tuple[np.ndarray, float]:
    """Complex amplitudes c of z ≈ A c by linear least squares and the residual sum of squares [rad²/s²]."""
    c, *_ = np.linalg.lstsq(A, z, rcond=None)
    res = z - A @ c
    return c, float(np.real(np.vdot(res, res)))


def resolved(amplitude: float, rss: float, n: int, n_params: int) -> bool:
    """Whether a fitted phasor's amplitude [rad/s] exceeds ``NUTATION_SNR`` standard errors √(RSS/(n − k)/n) of a
    fit of n complex samples with k real parameters, and ``NUTATION_MIN``."""
    se = np.sqrt(rss / max(n - n_params, 1) / n)
    return bool(amplitude >= max(NUTATION_SNR * se, NUTATION_MIN))


def beat_fit(t: np.ndarray, z: np.ndarray, phi: np.ndarray, spin: float) -> dict | None:
    """The three-phasor fit of one late span (module docstring).

    Parameters
    ----------
    t : (n,) array
        Sample times [s].
    z : (n,) complex array
        Transverse rates g_x + i g_y [rad/s], finite.
    phi : (n,) array
        Spin phase [rad] (:func:`.wobble.spin_phase`).
    spin : float
        Mean spin rate r̄ over the span [rad/s] (its sign is the spin's sense).

    Returns
    -------
    dict or None
        ``kappa_free`` [1], ``free_rad_s``, ``locked_rad_s``, ``constant_rad_s`` (|F|, |L|, |K| at the span's
        centre) [rad/s], ``free_decay_per_s``, ``locked_decay_per_s`` [1/s], ``free_resolved``,
        ``locked_resolved`` (bool), ``beat_period_s`` [s], ``rms_rad_s`` (left by the three phasors) and
        ``rms_locked_only_rad_s`` (left by K and L alone, at the same λ_L) [rad/s], ``free_share``
        (1 − RSS₃/RSS₂), ``span_s`` [t₀, t₁] [s]; None when the span is too short for half a beat at
        ``KAPPA_MIN``.
    """
    n = z.size
    span = float(t[-1] - t[0])
    kappa_max = 1.0 - np.pi / (abs(spin) * span) if span > 0 and spin else -np.inf
    if n < 12 or kappa_max <= KAPPA_MIN:
        return None
    tc = 0.5 * (t[0] + t[-1])
    dphi = (phi - np.interp(tc, t, phi)) * np.sign(spin)
    tau = t - tc
    zs = z if spin > 0 else np.conj(z)         # turning in the spin's sense: positive κ either way
    grid = np.arange(KAPPA_MIN, kappa_max, KAPPA_STEP)
    ss = [phasor_solve(_design(dphi, tau, k, 0.0, 0.0), zs)[1] for k in grid]
    x0 = np.array([grid[int(np.argmin(ss))], 0.0, 0.0])
    lo, hi = np.array([KAPPA_MIN, -DECAY_BOUND, -DECAY_BOUND]), np.array([kappa_max, DECAY_BOUND, DECAY_BOUND])

    def cost(x):
        return phasor_solve(_design(dphi, tau, *np.clip(x, lo, hi)), zs)[1]

    best = minimize(cost, x0, method="Nelder-Mead", options={"xatol": 1e-5, "fatol": 1e-10, "maxiter": 2000})
    x = np.clip(best.x, lo, hi) if best.fun <= cost(x0) else x0
    c, rss = phasor_solve(_design(dphi, tau, *x), zs)
    _, rss2 = phasor_solve(_design(dphi, tau, 1.0, x[1], 0.0)[:, :2], zs)
    kappa = float(x[0])
    return {"kappa_free": kappa, "free_rad_s": float(abs(c[2])), "locked_rad_s": float(abs(c[1])),
            "constant_rad_s": float(abs(c[0])), "free_decay_per_s": float(x[2]), "locked_decay_per_s": float(x[1]),
            "free_resolved": resolved(abs(c[2]), rss, n, 9), "locked_resolved": resolved(abs(c[1]), rss, n, 9),
            "beat_period_s": float(2 * np.pi / ((1 - kappa) * abs(spin))),
            "rms_rad_s": float(np.sqrt(rss / (2 * n))), "rms_locked_only_rad_s": float(np.sqrt(rss2 / (2 * n))),
            "free_share": float(1.0 - rss / rss2) if rss2 > 0 else 0.0, "span_s": [float(t[0]), float(t[-1])]}


def late_beat(t: np.ndarray, gyro: np.ndarray, phi: np.ndarray, start: float = START_S) -> dict | None:
    """:func:`beat_fit` of a throw's transverse rates after ``start`` [s].

    Parameters
    ----------
    t : (n,) array
        Sample times [s] since release.
    gyro : (n, 3) array
        g_x, g_y, g_z in sensor axes [rad/s] (NaN where not recorded).
    phi : (n,) array
        Spin phase [rad] on ``t``.
    start : float
        Start of the late span [s].

    Returns
    -------
    dict or None
        :func:`beat_fit`'s record; None when fewer than ``MIN_SPAN_S`` of flight follow ``start``.
    """
    t, g, phi = np.asarray(t, float), np.asarray(gyro, float), np.asarray(phi, float)
    z = g[:, 0] + 1j * g[:, 1]
    m = (t >= start) & np.isfinite(z) & np.isfinite(phi)
    if not m.any() or t[m][-1] - t[m][0] < MIN_SPAN_S:
        return None
    return beat_fit(t[m], z[m], phi[m], float(np.nanmean(g[m, 2])))


def _decay(x: float) -> str:
    return f"{'decaying' if x >= 0 else 'growing'} at {abs(x):.1f} /s"


def _part(rec: dict) -> str:
    """'a wobble locked to the spin (κ 1) of 0.37 rad/s decaying at 0.5 /s and a free wobble at κ 0.946 …'."""
    locked = (f"a wobble locked to the spin (κ 1) of {rec['locked_rad_s']:.2f} rad/s "
              f"{_decay(rec['locked_decay_per_s'])}" if rec["locked_resolved"] else "no wobble locked to the spin")
    free = (f"a free wobble at κ {rec['kappa_free']:.3f} of {rec['free_rad_s']:.2f} rad/s "
            f"{_decay(rec['free_decay_per_s'])}" if rec["free_resolved"] else "no free wobble")
    return f"{locked} and {free}"


def free_missing(data: dict | None, model: dict | None) -> bool:
    """Whether the data's late free nutation is resolved and the model's is not, or is below ``MISSING_RATIO``
    of it (:func:`late_beat` records; False when the data's late span was not fitted)."""
    if data is None or not data["free_resolved"]:
        return False
    return model is None or not model["free_resolved"] or model["free_rad_s"] < MISSING_RATIO * data["free_rad_s"]


def beat_words(data: dict | None, model: dict | None) -> str:
    """The late beat of data and model in one sentence, '' when the data's late span was not fitted.

    Parameters
    ----------
    data, model : dict or None
        :func:`late_beat` records of the log and of the model's prediction.

    Returns
    -------
    str
        E.g. "After 1.0 s the data's wobble is a beat of a wobble locked to the spin … and a free wobble at
        κ 0.950 …, every 1.3 s (the free wobble carries 89 % of what the locked one leaves); the model's: …: the
        model lacks the free wobble late."
    """
    if data is None:
        return ""
    start = data["span_s"][0]
    if not data["free_resolved"]:
        return f"After {start:.1f} s the data's wobble is {_part(data)}."
    text = (f"After {start:.1f} s the data's wobble is a beat of {_part(data)}, every {data['beat_period_s']:.1f} s "
            f"(the free wobble carries {100 * data['free_share']:.0f} % of what the locked one leaves; RMS left "
            f"{data['rms_rad_s']:.2f} rad/s)")
    if model is None:
        return text + "."
    text += f"; the model's is {_part(model)}"
    if free_missing(data, model):
        return text + ": the model lacks the free wobble late (its free nutation has decayed or turns at the spin)."
    return text + "."
