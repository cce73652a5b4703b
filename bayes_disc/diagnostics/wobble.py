"""Wobble of an inertial throw: the transverse rates split into nutation, precession and a sensor-fixed part.

A gyro fixed in the disc reads the transverse angular velocity as one complex series in sensor axes,

    z(t) = g_x(t) + i g_y(t)                                                              [rad/s]

and the spin phase φ(t) = ∫₀ᵗ g_z dt' [rad] (trapezoid rule on the samples; g_z ≈ r, the spin rate). Three
motions make up z:

(a) nutation — the transverse ω turning in the body in the spin's sense at κ times the spin. For the rigid
    axisymmetric disc (I = diag(Id, Id, Ia)) without torque, Euler's equations Id ω̇₁ = (Id − Ia) r ω₂,
    Id ω̇₂ = (Ia − Id) r ω₁ give ż = iκ r z with

        κ₀ = (Ia − Id) / Id                                                               [1]

    and a pitch moment −k θ₂ about d2 proportional to the pitch tilt θ₂ (k = −Q A d C_Mα [N m/rad]; a
    roll tilt about d1, along the air velocity, leaves α unchanged) turns the space-frame nutation
    Id θ̈ − i Ia r θ̇ + … = 0 into Id² s² + Id k + Ia² r² = 0, s = iω_n, so that in the body

        κ = (Ia / Id) √(1 + Id k / (Ia² r²)) − 1                                          (:func:`rigid_kappa`);

(b) precession — a transverse ω fixed in space, which the spinning body sees turning at −1 × spin;
(c) a part fixed in sensor axes — gyro bias and the mount tilt ε (C ω_B ≈ ω_B + r (ε₂, −ε₁, 0)).

Method (local fit of three rotating phasors). In sliding windows of ``WINDOW_S`` [s] every ``STEP_S`` [s],
centred at t_c with phase φ_c = φ(t_c),

    z(t) ≈ N e^{iκ(φ(t) − φ_c)} + S e^{−i(φ(t) − φ_c)} + K,

with complex amplitudes N (nutation), S (precession), K (sensor-fixed) [rad/s] found by linear least squares
for each κ of a grid (``KAPPA_BOUNDS``, step ``KAPPA_STEP``) and κ refined around the grid's best by a
bounded scalar minimisation of the residual sum of squares. κ, |N|, |S|, |K| and the mean spin are
reported per window. A window of 0.25 s spans about two spin turns at r ≈ 55 rad/s, enough to separate
phasors whose rates differ by ≳ 0.5 r (nutation at κ ≈ 0.9 is 0.9 r from the constant part and 1.9 r from
the precession); two nutation phasors closer in κ than that (a beat) give one κ weighted by their powers.

Decay of the nutation amplitude: λ = −d ln|N| / dt [1/s] (positive: decaying; negative: growing), the
least-squares slope of ln|N(t_c)| over the window centres of a span (``DECAY_SPANS``: early and late).
Overlapping windows of constant length scale an exponential's amplitude by a constant factor, so the slope
is unbiased. κ and the amplitudes per span (``KAPPA_SPANS``) are the medians over the window centres in it.
The tilt equivalent of the sensor-fixed part is |K| / |r| [rad] (bias included).

Over the late span the windows' one nutation can be two: :mod:`.wobble_beat` fits the span at once with a
nutation locked to the spin and a free one (a beat), for data and model alike (``beat`` in the record).

The comparison of data and model (:func:`wobble_words`) names a κ mismatch when the spans' κ differ by more
than ``KAPPA_TOL``, a decay mismatch when the decay rates differ by more than ``DECAY_TOL`` [1/s], and an
amplitude mismatch when the early nutation amplitudes differ by more than the factor ``AMPLITUDE_RATIO``, and
a missing late free nutation (:func:`.wobble_beat.free_missing`).
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from scipy.optimize import minimize_scalar

from ..physics import axial_inertia
from .wobble_beat import beat_words, free_missing, late_beat, phasor_solve, resolved

__all__ = ["WobbleTrack", "decay_rate", "phasor_fit", "rigid_kappa", "rigid_nutation", "spin_phase", "throw_wobble",
           "wobble_summary", "wobble_track", "wobble_words"]

#: sliding window length [s] and step between window centres [s]
WINDOW_S = 0.25
STEP_S = 0.05
#: fewest finite samples a window needs
MIN_SAMPLES = 8
#: κ searched (dimensionless) and the grid step before refinement
KAPPA_BOUNDS = (0.3, 1.6)
KAPPA_STEP = 0.01
#: spans of window centres [s] for κ and amplitudes, and for the decay rate
KAPPA_SPANS = {"early": (0.0, 0.45), "middle": (0.45, 1.5), "late": (1.5, np.inf)}
DECAY_SPANS = {"early": (0.0, 0.45), "late": (0.45, np.inf)}
#: span [s] after release over which the transverse RMS at release is taken
START_S = 0.075
#: thresholds of a data–model mismatch: κ [1], decay rate [1/s], early nutation amplitude ratio
KAPPA_TOL = 0.02
DECAY_TOL = 1.0
AMPLITUDE_RATIO = 1.3


def spin_phase(t: np.ndarray, spin: np.ndarray) -> np.ndarray:
    """Spin phase φ(t) = ∫₀ᵗ r dt' [rad] by the trapezoid rule.

    Parameters
    ----------
    t : (n,) array
        Sample times [s], increasing.
    spin : (n,) array
        Spin rate r [rad/s] (gyro z); NaN samples are bridged linearly.

    Returns
    -------
    (n,) array
        φ [rad], φ(t₀) = 0.
    """
    ok = np.isfinite(spin)
    r = np.interp(t, t[ok], spin[ok])
    return np.concatenate([[0.0], np.cumsum(0.5 * (r[1:] + r[:-1]) * np.diff(t))])


def phasor_fit(z: np.ndarray, dphi: np.ndarray, kappa: float) -> tuple[np.ndarray, float]:
    """Least-squares amplitudes of z ≈ N e^{iκΔφ} + S e^{−iΔφ} + K for one κ.

    Parameters
    ----------
    z : (n,) complex array
        Transverse rate g_x + i g_y [rad/s].
    dphi : (n,) array
        Spin phase from the window centre, φ − φ_c [rad].
    kappa : float
        Nutation rate as a fraction of the spin [1].

    Returns
    -------
    ((3,) complex array, float)
        (N, S, K) [rad/s] and the residual sum of squares [rad²/s²].
    """
    return phasor_solve(np.stack([np.exp(1j * kappa * dphi), np.exp(-1j * dphi), np.ones_like(dphi)], axis=1), z)


def _window(z: np.ndarray, dphi: np.ndarray) -> tuple[float, np.ndarray]:
    """(κ, (N, S, K)) of one window: grid search over ``KAPPA_BOUNDS`` then bounded refinement; κ NaN where
    the nutation is not resolved (:class:`WobbleTrack`)."""
    grid = np.arange(KAPPA_BOUNDS[0], KAPPA_BOUNDS[1] + 0.5 * KAPPA_STEP, KAPPA_STEP)
    ss = np.array([phasor_fit(z, dphi, k)[1] for k in grid])
    j = int(np.argmin(ss))
    lo, hi = grid[max(j - 1, 0)], grid[min(j + 1, grid.size - 1)]
    best = minimize_scalar(lambda k: phasor_fit(z, dphi, k)[1], bounds=(lo, hi), method="bounded",
                           options={"xatol": 1e-5})
    kappa = float(best.x) if best.fun <= ss[j] else float(grid[j])
    c, rss = phasor_fit(z, dphi, kappa)
    return (kappa if resolved(abs(c[0]), rss, z.size, 6) else float("nan")), c


@dataclass
class WobbleTrack:
    """The phasor fit of one series of transverse rates in sliding windows (module docstring).

    Attributes
    ----------
    times : (m,) array
        Window centres [s] since release.
    kappa : (m,) array
        Nutation rate over spin rate [1]; NaN where the nutation is not resolved (|N| below
        :data:`~.wobble_beat.NUTATION_SNR` standard errors √(RSS/(n − 6)/n) or below
        :data:`~.wobble_beat.NUTATION_MIN`: :func:`~.wobble_beat.resolved`).
    nutation, space_fixed, constant : (m,) complex arrays
        N, S, K [rad/s] (phases at the window centre).
    spin : (m,) array
        Mean spin rate in the window [rad/s].
    start_rms : float
        RMS of |z| over the first ``START_S`` after release [rad/s].
    """

    times: np.ndarray
    kappa: np.ndarray
    nutation: np.ndarray
    space_fixed: np.ndarray
    constant: np.ndarray
    spin: np.ndarray
    start_rms: float


def wobble_track(t: np.ndarray, gyro: np.ndarray, window: float = WINDOW_S, step: float = STEP_S) -> WobbleTrack:
    """Nutation, precession and sensor-fixed parts of a throw's transverse rates in sliding windows.

    Parameters
    ----------
    t : (n,) array
        Sample times [s] since release.
    gyro : (n, 3) array
        Gyro g_x, g_y, g_z in sensor axes [rad/s] (NaN where not recorded).
    window, step : float
        Window length and step between centres [s].

    Returns
    -------
    WobbleTrack
    """
    t = np.asarray(t, float)
    g = np.asarray(gyro, float)
    z = g[:, 0] + 1j * g[:, 1]
    phi = spin_phase(t, g[:, 2])
    ok = np.isfinite(z)
    centres = np.arange(t[0] + 0.5 * window, t[-1] - 0.5 * window + 1e-9, step)
    rows = []
    for tc in centres:
        m = ok & (np.abs(t - tc) <= 0.5 * window)
        if m.sum() < MIN_SAMPLES:
            continue
        kappa, (N, S, K) = _window(z[m], phi[m] - np.interp(tc, t, phi))
        rows.append((tc, kappa, N, S, K, float(np.nanmean(g[m, 2]))))
    start = ok & (t - t[0] <= START_S)
    start_rms = float(np.sqrt(np.mean(np.abs(z[start]) ** 2))) if start.any() else float("nan")
    if not rows:
        e = np.zeros(0)
        return WobbleTrack(e, e, e.astype(complex), e.astype(complex), e.astype(complex), e, start_rms)
    tc, kappa, N, S, K, spin = (np.array(c) for c in zip(*rows))
    return WobbleTrack(tc, kappa, N, S, K, spin, start_rms)


def decay_rate(track: WobbleTrack, span: tuple) -> float:
    """λ = −d ln|N|/dt [1/s] over the window centres in ``span`` = (t0, t1) [s]; NaN for fewer than three."""
    m = (track.times >= span[0]) & (track.times < span[1]) & (np.abs(track.nutation) > 0)
    if m.sum() < 3:
        return float("nan")
    return float(-np.polyfit(track.times[m], np.log(np.abs(track.nutation[m])), 1)[0])


def _median(x: np.ndarray, m: np.ndarray) -> float | None:
    m = m & np.isfinite(x)
    return float(np.median(x[m])) if m.any() else None


def wobble_summary(track: WobbleTrack) -> dict:
    """Per span: κ and the amplitudes (medians); the early and late decay rates; the sensor-fixed part.

    Parameters
    ----------
    track : WobbleTrack

    Returns
    -------
    dict
        ``kappa`` {span: κ [1] or None}, ``nutation_rad_s``, ``space_fixed_rad_s``, ``constant_rad_s``
        {span: amplitude [rad/s] or None}, ``decay_per_s`` {early, late: λ [1/s] or None},
        ``constant_tilt_deg`` (|K|/|r| over the whole throw [deg]), ``constant_direction_deg`` (arg of the
        mean K·sign(r) in sensor axes [deg]) and ``start_rms_rad_s`` (RMS of |z| over ``START_S``).
    """
    out = {"kappa": {}, "nutation_rad_s": {}, "space_fixed_rad_s": {}, "constant_rad_s": {}}
    for name, (a, b) in KAPPA_SPANS.items():
        m = (track.times >= a) & (track.times < b)
        out["kappa"][name] = _median(track.kappa, m)
        out["nutation_rad_s"][name] = _median(np.abs(track.nutation), m)
        out["space_fixed_rad_s"][name] = _median(np.abs(track.space_fixed), m)
        out["constant_rad_s"][name] = _median(np.abs(track.constant), m)
    out["decay_per_s"] = {name: decay_rate(track, span) for name, span in DECAY_SPANS.items()}
    if track.times.size:
        sign = np.sign(np.median(track.spin))
        out["constant_tilt_deg"] = float(np.degrees(np.median(np.abs(track.constant) / np.abs(track.spin))))
        out["constant_direction_deg"] = float(np.degrees(np.angle(np.mean(track.constant) * sign)))
    else:
        out["constant_tilt_deg"] = out["constant_direction_deg"] = None
    out["start_rms_rad_s"] = track.start_rms
    return out


def rigid_kappa(Ia: float, Id: float, spin, stiffness=0.0):
    """Body-frame nutation rate over spin of the rigid axisymmetric disc with a pitch stiffness only.

    Parameters
    ----------
    Ia, Id : float
        Axial and diametral moments of inertia [kg m²].
    spin : float or array
        Spin rate r [rad/s].
    stiffness : float or array
        k = −Q A d C_Mα [N m/rad], the pitch moment's stiffness to pitch tilt (0: torque-free).

    Returns
    -------
    float or array
        κ = (Ia/Id) √(1 + Id k/(Ia² r²)) − 1 [1]; κ₀ = (Ia − Id)/Id for k = 0.
    """
    r = np.asarray(spin, float)
    return (Ia / Id) * np.sqrt(1.0 + Id * np.asarray(stiffness, float) / (Ia ** 2 * r ** 2)) - 1.0


def rigid_nutation(Ia: float, Id: float, spin: float, stiffness: float = 0.0, roll_damping: float = 0.0,
                   pitch_damping: float = 0.0) -> tuple[float, float]:
    """Nutation of the rigid disc with the linear pitch and roll moments: κ and the decay rate.

    Small tilts θ₁ about d1 (roll) and θ₂ about d2 (pitch), p = θ̇₁, q = θ̇₂, with the moments
    c_p p about d1 and c_q q − k θ₂ about d2:

        Id θ̈₁ + Ia r θ̇₂ = c_p θ̇₁,     Id θ̈₂ − Ia r θ̇₁ = c_q θ̇₂ − k θ₂,

    so that θ ∝ e^{st} with (Id s − c_p)(Id s² − c_q s + k) + Ia² r² s = 0. The nutation root
    s = −λ + i ω_n gives κ = ω_n/|r| − 1 in the body and the amplitude's decay rate λ.

    Parameters
    ----------
    Ia, Id : float
        Axial and diametral moments of inertia [kg m²].
    spin : float
        Spin rate r [rad/s].
    stiffness : float
        k = −Q A d C_Mα [N m/rad].
    roll_damping, pitch_damping : float
        c_p = Q A d C_Rp and c_q = Q A d C_Mq [N m s/rad] (negative: damping).

    Returns
    -------
    (float, float)
        κ [1] and λ [1/s] (positive: decaying). Without moments κ = (Ia − Id)/Id, λ = 0.
    """
    poly = np.polyadd(np.polymul([Id, -roll_damping], [Id, -pitch_damping, stiffness]), [0.0, 0.0, (Ia * spin) ** 2, 0.0])
    roots = np.roots(poly)
    s = roots[np.argmax(np.abs(roots.imag))]
    return float(abs(s.imag) / abs(spin) - 1.0), float(-s.real)


def _series(track: WobbleTrack) -> dict:
    return {"time_s": track.times, "kappa": track.kappa, "nutation_rad_s": np.abs(track.nutation),
            "space_fixed_rad_s": np.abs(track.space_fixed), "constant_rad_s": np.abs(track.constant),
            "spin_rad_s": track.spin}


def _mismatch(data: dict, model: dict, beat: dict) -> list[str]:
    out = []
    if any(data["kappa"][s] is not None and model["kappa"][s] is not None
           and abs(data["kappa"][s] - model["kappa"][s]) > KAPPA_TOL for s in KAPPA_SPANS):
        out.append("kappa")
    for s in DECAY_SPANS:
        a, b = data["decay_per_s"][s], model["decay_per_s"][s]
        if np.isfinite(a) and np.isfinite(b) and abs(a - b) > DECAY_TOL:
            out.append(f"decay_{s}")
    a, b = data["nutation_rad_s"]["early"], model["nutation_rad_s"]["early"]
    if a and b and max(a / b, b / a) > AMPLITUDE_RATIO:
        out.append("amplitude")
    if free_missing(beat["data"], beat["model"]):
        out.append("free_late")
    return out


def throw_wobble(t: np.ndarray, measured: np.ndarray, predicted: np.ndarray, Ia: float, Id: float) -> dict:
    """The wobble record of one throw: data and model decomposed alike, compared (module docstring).

    Parameters
    ----------
    t : (n,) array
        Sample times [s] since release.
    measured, predicted : (n, 3) arrays
        Gyro g_x, g_y, g_z in sensor axes [rad/s]: the log and the model at the fit.
    Ia, Id : float
        The model's moments of inertia [kg m²] (the axial one with a fitted inertia ratio:
        :func:`bayes_disc.physics.axial_inertia`).

    Returns
    -------
    dict
        ``data``, ``model`` (:func:`wobble_summary`), ``series`` {data, model: {time_s, kappa,
        nutation_rad_s, space_fixed_rad_s, constant_rad_s, spin_rad_s} (m,) each}, ``torque_free_kappa``
        ((Ia − Id)/Id), ``mismatch`` (list of ``kappa``, ``decay_early``, ``decay_late``, ``amplitude``,
        ``free_late``: the data's late free nutation missing from the model), ``beat`` {data, model:
        :func:`~.wobble_beat.late_beat` record or None} (the late span as a beat of a nutation locked to the spin
        and a free one), ``method`` and its ``window_s``, ``step_s``.
    """
    td, tm = wobble_track(t, measured), wobble_track(t, predicted)
    data, model = wobble_summary(td), wobble_summary(tm)
    beat = {who: late_beat(t, g, spin_phase(t, np.asarray(g, float)[:, 2]))
            for who, g in (("data", measured), ("model", predicted))}
    return {"data": data, "model": model, "series": {"data": _series(td), "model": _series(tm)},
            "torque_free_kappa": float(rigid_kappa(Ia, Id, 1.0)), "mismatch": _mismatch(data, model, beat),
            "beat": beat,
            "window_s": WINDOW_S, "step_s": STEP_S,
            "method": "local least-squares fit of N e^{iκΔφ} + S e^{−iΔφ} + K to g_x + i g_y in sliding windows, "
                      "φ the spin phase integrated from g_z"}


def _k(x) -> str:
    return "—" if x is None else f"{x:.2f}"


def _rate(x) -> str:
    return f"{abs(x):.1f} /s"


def _decay_text(who: str, x: float) -> str:
    if not np.isfinite(x):
        return f"{who} is not measured"
    return f"{who} {'decays' if x >= 0 else 'grows'} at {_rate(x)}"


def _spans(summary: dict) -> tuple[str, str]:
    have = [s for s in KAPPA_SPANS if summary["kappa"][s] is not None]
    return (have[0], have[-1]) if have else ("early", "late")


def _kappa_text(summary: dict, who: str) -> str:
    a, b = _spans(summary)
    ka, kb = summary["kappa"][a], summary["kappa"][b]
    if ka is None:
        return f"{who} has no measurable wobble"
    if a == b or abs(kb - ka) <= KAPPA_TOL:
        return f"{who} turns at a fixed κ {_k(0.5 * (ka + kb))}"
    return f"{who} turns at κ {_k(ka)} {a} {'rising' if kb > ka else 'falling'} to {_k(kb)} {b}"


def _rigid_text(rec: dict) -> str:
    """'; the linear moments at the model's 70 m/s: κ 0.83, decay 2.9 /s' from ``model_rigid``, or ''."""
    rigid = (rec.get("model_rigid") or {}).get("early")
    if not rigid:
        return ""
    return (f"; the fitted linear moments at the model's {rigid['speed_m_s']:.0f} m/s give κ {rigid['kappa']:.2f}, "
            f"decay {rigid['decay_per_s']:.1f} /s")


def wobble_words(name: str, rec: dict) -> str:
    """One throw's wobble in words, data against model (module docstring's thresholds).

    Parameters
    ----------
    name : str
        The throw.
    rec : dict
        Its record (:func:`throw_wobble`).

    Returns
    -------
    str
        E.g. "Wobble of throw T: the data's wobble turns at κ 0.84 early rising to 0.97 late; the model's
        turns at a fixed κ 0.93. …", or that the model's wobble matches the data's.
    """
    d, m, mis = rec["data"], rec["model"], rec["mismatch"]
    e0, e1 = DECAY_SPANS["early"][1], DECAY_SPANS["late"][0]
    dn, mn = d["nutation_rad_s"]["early"], m["nutation_rad_s"]["early"]
    parts = []
    if "kappa" in mis:
        parts.append(f"{_kappa_text(d, 'the data’s wobble')}; {_kappa_text(m, 'the model’s')} "
                     f"(the model's torque-free rigid disc: κ {rec['torque_free_kappa']:.2f}{_rigid_text(rec)})")
    if "decay_early" in mis:
        parts.append(f"{_decay_text('the data’s wobble', d['decay_per_s']['early'])} in the first {e0:.2f} s; "
                     f"{_decay_text('the model’s', m['decay_per_s']['early'])}")
    if "decay_late" in mis:
        parts.append(f"after {e1:.2f} s {_decay_text('the data’s', d['decay_per_s']['late'])}; "
                     f"{_decay_text('the model’s', m['decay_per_s']['late'])}")
    if "amplitude" in mis:
        parts.append(f"early nutation amplitude {dn:.2f} rad/s in the data, {mn:.2f} rad/s in the model")
    beat = beat_words(*(rec.get("beat", {}).get(who) for who in ("data", "model")))
    beat = " " + beat if beat else ""
    if not parts and "free_late" not in mis:
        a, b = _spans(d)
        return (f"Wobble of throw {name}: the model's wobble matches the data's (κ {_k(d['kappa'][a])} {a}, "
                f"{_k(d['kappa'][b])} {b}; {_decay_text('it', d['decay_per_s']['early'])} early; nutation "
                f"{_k(dn)} rad/s early)." + beat)
    fixed = d["constant_rad_s"][_spans(d)[0]]
    tail = (f" Precession (space-fixed) {_k(d['space_fixed_rad_s'][_spans(d)[0]])} rad/s; sensor-fixed part "
            f"{_k(fixed)} rad/s ({d['constant_tilt_deg']:.2f}° × spin)." if fixed is not None else "")
    return f"Wobble of throw {name}: " + ("; ".join(parts) + "." if parts else "") + tail + beat


def inertial_gyro(problem, theta: np.ndarray, k: int):
    """(sample times [s] (n,), measured gyro (n, 3), predicted gyro (n, 3) [rad/s], air speed at the samples
    (n,) [m/s]) of flight k's inertial channel at θ (dim,), or None when the flight has no inertial channel."""
    from ..observation.models.inertial import InertialMeasurements
    from .residuals import channel_runs
    for c, _, extra, pred, air in channel_runs(problem, theta, k):
        if isinstance(c, InertialMeasurements):
            t = c.sample_times_for(c.split(extra)["period"])[0, : c.n_flight]
            speed = np.interp(t, np.asarray(c.times, float), air.speed[0])
            return t, np.asarray(c.log.gyro, float), pred[0, : c.n_flight, :3], speed
    return None


def model_rigid(rec: dict, t: np.ndarray, speed: np.ndarray, coefficients: dict, disc, rho: float) -> dict:
    """{span: {kappa, decay_per_s, speed_m_s, spin_rad_s}}: the linear rigid-disc nutation
    (:func:`rigid_nutation`) of the fitted coefficients at the model's median air speed and spin in each
    span — what the model's κ and decay should be if only the linear moments act."""
    ser = rec["series"]["model"]
    tc, spin = np.asarray(ser["time_s"]), np.asarray(ser["spin_rad_s"])
    out = {}
    for name, (a, b) in KAPPA_SPANS.items():
        m = (tc >= a) & (tc < b)
        if not m.any():
            out[name] = None
            continue
        v = float(np.median(np.interp(tc[m], t, speed)))
        r = float(np.median(spin[m]))
        qad = 0.5 * rho * v ** 2 * disc.area * disc.diameter
        kappa, lam = rigid_nutation(disc.Ia, disc.Id, r, -qad * coefficients["CMa"], qad * coefficients["CRp"],
                                    qad * coefficients["CMq"])
        out[name] = {"kappa": kappa, "decay_per_s": lam, "speed_m_s": v, "spin_rad_s": r}
    return out


def wobble_records(problem, theta: np.ndarray) -> dict:
    """{throw: :func:`throw_wobble` record} for every flight with an inertial channel, at θ (dim,); each
    record also carries ``model_rigid`` (:func:`model_rigid`) and its ``words`` (:func:`wobble_words`).
    The rigid disc of both is the model's: its axial inertia includes a fitted inertia ratio."""
    out = {}
    values = dict(zip(problem.names, np.asarray(theta, float)))
    disc = replace(problem.disc, Ia=axial_inertia(problem.disc.Ia, values))
    for k, f in enumerate(problem.flights):
        got = inertial_gyro(problem, theta, k)
        if got is None:
            continue
        t, measured, predicted, speed = got
        rec = throw_wobble(t, measured, predicted, Ia=disc.Ia, Id=disc.Id)
        rec["model_rigid"] = model_rigid(rec, t, speed, values, disc, problem.env.rho)
        rec["words"] = wobble_words(f.name, rec)
        out[f.name] = rec
    return out
