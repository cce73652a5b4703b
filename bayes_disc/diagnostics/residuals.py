"""Locating a mismatch between the model and the recordings: residuals in physical directions.

For parameters θ (the least-squares optimum or a posterior draw) the residuals r = measured − predicted
[m] of every flight are averaged over the markers seen at each sample (r̄(t), noise σ/√n_seen per
component) and projected on two frames:

* flight path: along-track t̂ = v̂, lateral ŝ = (ẑ × v̂)/|ẑ × v̂| (to the left), normal n̂ = t̂ × ŝ (up);
* disc (velocity-aligned D frame of SPEC §1): d1, d2 (to the right), d3 = b3 (down through the disc).

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
from ..physics.frames import angle_of_attack, quat_to_matrix

DIRECTIONS = ("along", "lateral", "normal", "d1", "d2", "d3")
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


def flight_residuals(problem: Problem, theta: np.ndarray) -> list[FlightResiduals]:
    out = []
    for k, f in enumerate(problem.flights):
        tr = problem.simulate(theta[None], k, want_states=True)
        st, pred = tr.states[0], tr.markers[0]
        seen = f.observed                                          # (n, m)
        n_seen = np.sum(seen, axis=1)
        total = np.sum(np.where(seen[..., None], f.positions - pred, 0.0), axis=1)
        r = np.where(n_seen[:, None] > 0, total / np.maximum(n_seen, 1)[:, None], np.nan)   # (n, 3)
        v = st[:, 3:6]
        t_hat = v / np.linalg.norm(v, axis=1, keepdims=True)
        s = np.cross(np.array([0.0, 0.0, 1.0]), t_hat)
        s_hat = s / np.linalg.norm(s, axis=1, keepdims=True)
        n_hat = np.cross(t_hat, s_hat)
        d3 = quat_to_matrix(st[:, 6:10])[:, :, 2]                   # b3 (world), D frame of SPEC §1
        v_perp = v - np.einsum("ni,ni->n", v, d3)[:, None] * d3
        d1 = v_perp / np.linalg.norm(v_perp, axis=1, keepdims=True)
        axes = {"along": t_hat, "lateral": s_hat, "normal": n_hat, "d1": d1, "d2": np.cross(d3, d1), "d3": d3}
        proj = {name: np.einsum("ni,ni->n", r, axis) for name, axis in axes.items()}
        cov = {"alpha": angle_of_attack(v, st[:, 6:10]), "speed": np.linalg.norm(v, axis=1), "spin": st[:, 12],
               "height": st[:, 2], "time": f.times - f.times[0]}
        out.append(FlightResiduals(f.name, f.times, r, n_seen, proj, cov))
    return out


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


def localise(problem: Problem, theta: np.ndarray, sigma: np.ndarray) -> dict:
    """Per flight and direction: RMS [mm], Ljung–Box Q and p, structured windows, correlations with the
    flight's covariates. ``sigma``: each flight's noise scale [m] (per coordinate)."""
    out = {}
    for fr, s in zip(flight_residuals(problem, theta), sigma):
        se = s / np.sqrt(np.maximum(fr.n_seen, 1))
        per = {}
        for name in DIRECTIONS:
            x = fr.projections[name]
            ok = np.isfinite(x)
            q, p = ljung_box(x)
            corr = {}
            for cname, c in fr.covariates.items():
                a, b = x[ok], c[ok]
                corr[cname] = float(np.corrcoef(a, b)[0, 1]) if a.size > 2 and np.std(b) > 0 and np.std(a) > 0 else 0.0
            per[name] = {"rms_mm": float(np.sqrt(np.mean(x[ok] ** 2)) * 1e3), "ljung_box_q": q, "ljung_box_p": p,
                         "windows_s": structured_windows(x, se, fr.times), "correlation": corr}
        out[fr.name] = per
    return out
