"""Locating a mismatch between the model and the recordings: residuals in physical directions.

For parameters θ (the least-squares optimum or a posterior draw) the residuals r = measured − predicted
[m] of every flight are averaged over the markers seen at each sample (r̄(t), noise σ/√n_seen per
component) and projected on two frames:

* flight path: along-track t̂ = v̂, lateral ŝ = (ẑ × v̂)/|ẑ × v̂| (to the left), normal n̂ = t̂ × ŝ (up);
* disc (velocity-aligned D frame of SPEC §1): d1, d2 (to the right), d3 = b3 (down through the disc).

The markers' spread about their mean carries the attitude residual: the small rotation δθ [rad] that
best maps the predicted lever arms p̃_j = p_j − p̄ onto the measured ones,

    δθ = (Σ_j |p̃_j|² I − p̃_j p̃_jᵀ)⁻¹ Σ_j p̃_j × (r_j − r̄),

projected as roll (about d1), pitch (about d2) and spin phase (about d3). A fit that cannot reproduce
the motion often hides a missing force in the attitude, so these series matter as much as r̄.

Per flight and direction: RMS [mm]; whiteness — autocorrelation and the Ljung–Box statistic
Q = n(n+2) Σ_{k=1..h} ρ_k² / (n − k) with its χ²_h p-value (white residuals: p uniform; structure: p → 0);
the time windows where the running mean strays beyond 3 standard errors; and the correlation of the
residual with α, speed, spin, height and time — the fingerprints the missing-physics ranking reads.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.stats import chi2

from ..inference.model import Problem

DIRECTIONS = ("along", "lateral", "normal", "d1", "d2", "d3")
ROTATIONS = ("roll", "pitch", "spin_phase")
#: lags of the Ljung–Box statistic (about 0.1 s at 120 Hz)
LJUNG_BOX_LAGS = 12
#: running-mean window [samples] of the structure search
WINDOW = 15


@dataclass
class FlightResiduals:
    """Marker-averaged residuals of one flight: times (n,), r (n, 3) world [m] (NaN where nothing was seen),
    n_seen (n,), projections {direction: (n,)} [m], and the flight's α [rad], speed [m/s], spin r [rad/s]
    and height z [m] along the predicted trajectory."""

    name: str
    times: np.ndarray
    r: np.ndarray
    n_seen: np.ndarray
    projections: dict
    covariates: dict
    rotations: dict      # {roll, pitch, spin_phase: (n,)} attitude residual [rad] (NaN unless all markers seen)
    unit_se: dict        # {series: (n,)} standard error of each series per unit marker noise σ [1 or rad/m]


def flight_axes(states: np.ndarray, conditions) -> dict:
    """Unit vectors (n, 3) of the flight-path frame (along, lateral, normal: ground-relative velocity) and
    the D frame (d1, d2, d3: air-relative, from ``conditions``, the
    :class:`~bayes_disc.physics.FlightConditions` of the same states) along states (n, 13)."""
    v = states[:, 3:6]
    t_hat = v / np.linalg.norm(v, axis=1, keepdims=True)
    s = np.cross(np.array([0.0, 0.0, 1.0]), t_hat)
    s_hat = s / np.linalg.norm(s, axis=1, keepdims=True)
    n_hat = np.cross(t_hat, s_hat)
    return {"along": t_hat, "lateral": s_hat, "normal": n_hat,
            "d1": conditions.d1[0], "d2": conditions.d2[0], "d3": conditions.d3[0]}


def marker_series(diff: np.ndarray, states: np.ndarray, markers: np.ndarray, seen: np.ndarray, conditions):
    """Series of a per-marker difference ``diff`` (n, m, 3) [m] (NaN-free where ``seen``): the marker mean
    r̄ (n, 3), its projections {direction: (n,)}, the attitude angles {rotation: (n,)} [rad] and their unit
    standard errors, given the predicted states (n, 13), markers (n, m, 3) and flight conditions
    (:meth:`bayes_disc.inference.model.Problem.conditions` of the states)."""
    n_seen = np.sum(seen, axis=1)
    total = np.sum(np.where(seen[..., None], diff, 0.0), axis=1)
    r = np.where(n_seen[:, None] > 0, total / np.maximum(n_seen, 1)[:, None], np.nan)   # (n, 3)
    axes = flight_axes(states, conditions)
    proj = {name: np.einsum("ni,ni->n", r, axis) for name, axis in axes.items()}
    rot, rot_se = _attitude_residual(np.where(seen[..., None], diff, 0.0), markers - states[:, None, 0:3], seen, axes)
    return r, proj, rot, rot_se


def flight_residuals(problem: Problem, theta: np.ndarray) -> list[FlightResiduals]:
    out = []
    for k, f in enumerate(problem.flights):
        tr = problem.simulate(theta[None], k, want_states=True)
        st, pred = tr.states[0], tr.markers[0]
        seen = f.observed                                          # (n, m)
        n_seen = np.sum(seen, axis=1)
        air = problem.conditions(st, theta, k)
        r, proj, rot, rot_se = marker_series(f.positions - pred, st, pred, seen, air)
        cov = {"alpha": air.alpha[0], "speed": air.speed[0], "spin": st[:, 12],
               "height": st[:, 2], "time": f.times - f.times[0]}
        unit_se = {name: 1.0 / np.sqrt(np.maximum(n_seen, 1)) for name in DIRECTIONS} | rot_se
        out.append(FlightResiduals(f.name, f.times, r, n_seen, proj, cov, rot, unit_se))
    return out


def _attitude_residual(res: np.ndarray, arms: np.ndarray, seen: np.ndarray, axes: dict) -> tuple[dict, dict]:
    """Attitude residual δθ (module docstring) at samples where every marker is seen, projected on d1, d2,
    d3; and its standard error per unit marker noise. res, arms: (n, m, 3) [m]; seen (n, m)."""
    n, m, _ = res.shape
    full = np.all(seen, axis=1) & (m >= 3)
    p = arms - arms.mean(axis=1, keepdims=True)
    d = res - res.mean(axis=1, keepdims=True)
    A = np.einsum("njc,njc->n", p, p)[:, None, None] * np.eye(3) - np.einsum("nji,njk->nik", p, p)
    b = np.cross(p, d).sum(axis=1)
    A = np.where(full[:, None, None], A, np.eye(3))
    theta = np.linalg.solve(A, b[..., None])[..., 0]
    Ainv = np.linalg.inv(A)
    rot, se = {}, {}
    for name, axis in zip(ROTATIONS, ("d1", "d2", "d3")):
        a = axes[axis]
        rot[name] = np.where(full, np.einsum("ni,ni->n", theta, a), np.nan)
        se[name] = np.sqrt(np.einsum("ni,nik,nk->n", a, Ainv, a))
    return rot, se


def ljung_box(x: np.ndarray, lags: int = LJUNG_BOX_LAGS) -> tuple[float, float]:
    """Ljung–Box Q and its χ²_lags p-value for the finite samples of x (gaps closed up)."""
    x = x[np.isfinite(x)]
    n = x.size
    if n <= lags + 2:
        return float("nan"), float("nan")
    x = x - x.mean()
    c0 = x @ x
    rho = np.array([x[:-k] @ x[k:] / c0 for k in range(1, lags + 1)])
    q = n * (n + 2) * np.sum(rho ** 2 / (n - np.arange(1, lags + 1)))
    return float(q), float(chi2.sf(q, lags))


def structured_windows(x: np.ndarray, se: np.ndarray, times: np.ndarray, window: int = WINDOW) -> list:
    """Time windows [t0, t1] where the running mean of x (window samples) exceeds 3 standard errors
    (se: per-sample standard error of x)."""
    ok = np.isfinite(x)
    xs, ss = np.where(ok, x, 0.0), np.where(ok, se ** 2, 0.0)
    kernel = np.ones(window)
    cnt = np.convolve(ok.astype(float), kernel, "same")
    mean = np.convolve(xs, kernel, "same") / np.maximum(cnt, 1)
    sem = np.sqrt(np.convolve(ss, kernel, "same")) / np.maximum(cnt, 1)
    flag = (cnt >= window // 2) & (np.abs(mean) > 3 * sem)
    out, start = [], None
    for i, f in enumerate(np.r_[flag, False]):
        if f and start is None:
            start = i
        elif not f and start is not None:
            out.append([float(times[start]), float(times[i - 1])])
            start = None
    return out


def peak_window(fr: FlightResiduals, sigma: float, window: int = WINDOW) -> list:
    """[t0, t1] [s] around the strongest residual structure of a flight: the running mean (``window``
    samples) of the whitened squared translation residuals Σ (r̄·e / se)² over along, lateral and normal,
    where it stays above half its maximum around the maximum."""
    z = np.zeros(fr.times.size)
    for name in ("along", "lateral", "normal"):
        x = fr.projections[name] / (sigma * fr.unit_se[name])
        z += np.where(np.isfinite(x), x * x, 0.0)
    run = np.convolve(z, np.ones(window) / window, "same")
    i = int(np.argmax(run))
    above = run >= 0.5 * run[i]
    lo, hi = i, i
    while lo > 0 and above[lo - 1]:
        lo -= 1
    while hi < run.size - 1 and above[hi + 1]:
        hi += 1
    return [float(fr.times[lo]), float(fr.times[hi])]


def series_of(fr: FlightResiduals) -> dict:
    """All residual series of a flight: the six translation directions [m] and three rotations [rad]."""
    return fr.projections | fr.rotations


def localise(problem: Problem, theta: np.ndarray, sigma: np.ndarray, residuals: list | None = None) -> dict:
    """Per flight and series (directions and rotations): RMS (``rms_mm`` or ``rms_mrad``), its ratio to the
    RMS that noise alone would give, Ljung–Box Q and p, structured windows [s], correlations with the
    flight's covariates. ``sigma``: each flight's noise scale [m] (per coordinate); ``residuals``: the
    :func:`flight_residuals` of θ if already computed."""
    residuals = flight_residuals(problem, theta) if residuals is None else residuals
    out = {}
    for fr, s in zip(residuals, sigma):
        per = {}
        for name, x in series_of(fr).items():
            ok = np.isfinite(x)
            se = s * fr.unit_se[name]
            q, p = ljung_box(x)
            corr = {}
            for cname, c in fr.covariates.items():
                a, b = x[ok], c[ok]
                corr[cname] = float(np.corrcoef(a, b)[0, 1]) if a.size > 2 and np.std(b) > 0 and np.std(a) > 0 else 0.0
            rms = float(np.sqrt(np.mean(x[ok] ** 2))) if ok.any() else float("nan")
            noise = float(np.sqrt(np.mean(se[ok] ** 2))) if ok.any() else float("nan")
            unit = "rms_mrad" if name in ROTATIONS else "rms_mm"
            per[name] = {unit: rms * 1e3, "noise_ratio": rms / noise if noise > 0 else float("nan"),
                         "ljung_box_q": q, "ljung_box_p": p,
                         "windows_s": structured_windows(x, se, fr.times), "correlation": corr}
        out[fr.name] = per
    return out
