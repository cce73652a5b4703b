"""Locating a mismatch between the model and the recordings: residuals in physical directions.

For parameters θ (the least-squares optimum or a posterior draw) every observation model of every flight
gives its residuals as named series (:meth:`~bayes_disc.observation.models.base.ObservationModel.residual_series`):

* markers (:mod:`bayes_disc.observation.models.markers`): the marker mean projected on the flight-path
  frame (along, lateral, normal) and the D frame (d1, d2, d3) [m], and the attitude residual (roll, pitch,
  spin phase) [rad] — a fit that cannot reproduce the motion often hides a missing force in the attitude;
* an inertial logger (:mod:`bayes_disc.observation.models.inertial`): gyro and accelerometer residuals
  along the sensor axes (gyro_x…z [rad/s], acc_x…z [m/s²]).

Per flight and series: RMS (in the series' unit; ``rms_mm``/``rms_mrad`` for markers); whiteness —
autocorrelation and the Ljung–Box statistic Q = n(n+2) Σ_{k=1..h} ρ_k² / (n − k) with its χ²_h p-value
(white residuals: p uniform; structure: p → 0); the time windows where the running mean strays beyond 3
standard errors (σ of the series' noise group × its unit standard error); and the correlation of the
residual with α, air speed, spin, height and time — the fingerprints the missing-physics ranking reads.

Noise floor without the right model (:func:`noise_floor`). The second difference of a time-ordered series,
Δ²x_t = x_{t+1} − 2x_t + x_{t−1}, of white noise with standard errors σ u_t has variance
σ² (u_{t+1}² + 4u_t² + u_{t−1}²) (6σ² for u ≡ 1), whereas a smooth model error s(t) adds only about
s''(t)² Δt⁴ to it: a sinusoid of frequency f and amplitude A adds A² (2πfΔt)⁴ / 2 on average, at
Δt = 1/120 s 4e−6 A² for 1 Hz and 0.04 A² for a 10 Hz wobble. So, per noise group g, pooled
over its primary series x (markers: the marker mean along, lateral, normal with u_t = 1/√(markers seen);
inertial: the six sensor series),

    σ̂_g² = Σ_x Σ_t (Δ²x_t)² / Σ_x Σ_t (u_{t+1}² + 4u_t² + u_{t−1}²),

over the triples of finite samples. Assumption: the noise is white (independent in time) and the model
error is smooth on the scale of three samples. Structure at the sample rate (vibration, tracking jitter,
a sudden collision) is counted as noise, which makes the floor higher and the excess misfit smaller;
positively correlated noise (AR(1) with ρ > 0) looks smooth and makes the floor lower — by the factor
(6 − 8ρ + 2ρ²)/6 in σ², 0.11 at ρ = 0.85 — so that its correlation is counted as excess misfit (which no
term removes: correlated noise is judged separately, :mod:`.diagnosis`).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.stats import chi2

from ..inference.model.problem import Problem
from ..observation.models.base import ResidualSeries
from ..observation.models.markers import DIRECTIONS, ROTATIONS, flight_axes, marker_series
from ..physics import flight_conditions

__all__ = ["DIRECTIONS", "ROTATIONS", "FlightResiduals", "channel_runs", "flight_axes", "flight_residuals",
           "ljung_box", "localise", "marker_series", "noise_floor", "peak_window", "second_difference_variance",
           "series_of", "structured_windows"]

#: lags of the Ljung–Box statistic (about 0.1 s at 120 Hz)
LJUNG_BOX_LAGS = 12
#: running-mean window [samples] of the structure search
WINDOW = 15


@dataclass
class FlightResiduals:
    """The residual series of one flight: one :class:`ResidualSeries` per observation model (``parts``, in
    the flight's channel order), the models' ids and the global index (into ``Problem.sigma_names``) of
    each part's first noise group. Series names are unique within a flight."""

    name: str
    parts: list
    channel_ids: tuple
    group_offsets: tuple
    _where: dict = field(init=False, repr=False)

    def __post_init__(self):
        self._where = {}
        for i, part in enumerate(self.parts):
            for n in part.series:
                if n in self._where:
                    raise ValueError(f"flight {self.name!r}: residual series {n!r} given by two observation models")
                self._where[n] = i

    @property
    def series(self) -> dict:
        """{name: (n,)} every series of the flight."""
        return {n: x for part in self.parts for n, x in part.series.items()}

    def part(self, name: str) -> ResidualSeries:
        """The :class:`ResidualSeries` holding series ``name``."""
        return self.parts[self._where[name]]

    def group(self, name: str) -> int:
        """Global noise-group index (into ``Problem.sigma_names``) of series ``name``."""
        i = self._where[name]
        return self.group_offsets[i] + self.parts[i].groups[name]

    def se(self, name: str, sigma: np.ndarray) -> np.ndarray:
        """(n,) standard error of series ``name`` for the noise scales ``sigma`` (n_groups,) of the problem."""
        return self.part(name).unit_se[name] * sigma[self.group(name)]

    def has(self, name: str) -> bool:
        return name in self._where


def channel_runs(problem: Problem, theta: np.ndarray, k: int) -> list[tuple]:
    """Flight k's channels simulated for θ (dim,) with states: [(model, trajectories, extra, prediction,
    conditions)], one simulation per distinct grid.

    Reads ``Problem._run`` and ``Problem._columns`` (simulation on a channel's own grid with states, and the
    θ columns of a channel's extra parameters): the Problem has no public accessor for them yet."""
    theta2 = np.atleast_2d(theta)
    runs, out = {}, []
    first = problem.channels[k][0].times
    for i, c in enumerate(problem.channels[k]):
        key = id(c.times)
        if key not in runs:
            tr = problem._run(theta2, k, want_states=True, times=c.times)
            st = tr.states[0]
            if c.times is first:
                air = problem.conditions(st, theta2[0], k)
            else:
                air = flight_conditions(st, c.times, problem.terms, theta2[0, problem.layout.term_slice])
            runs[key] = (tr, air)
        tr, air = runs[key]
        cols = problem._columns[k][i]
        extra = theta2[:, cols] if cols.size else None
        out.append((c, tr, extra, c.predict(tr, extra), air))
    return out


def _group_offsets(problem: Problem, k: int) -> tuple:
    offs, g = [], int(problem.flight_groups(k)[0])
    for c in problem.channels[k]:
        offs.append(g)
        g += len(c.noise_names)
    return tuple(offs)


def flight_residuals(problem: Problem, theta: np.ndarray) -> list[FlightResiduals]:
    """Measured − predicted residual series of every flight for θ (dim,).

    Parameters
    ----------
    problem : Problem
    theta : (dim,) array

    Returns
    -------
    list of FlightResiduals
        One per flight, in problem order.
    """
    out = []
    for k, f in enumerate(problem.flights):
        runs = channel_runs(problem, theta, k)
        parts = [c.residual_series(tr, extra, pred, air) for c, tr, extra, pred, air in runs]
        out.append(FlightResiduals(f.name, parts, tuple(c.id for c in problem.channels[k]), _group_offsets(problem, k)))
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


def _peak_run(part: ResidualSeries, sig: np.ndarray, window: int) -> tuple[np.ndarray, int]:
    z = np.zeros(part.times.size)
    for name in part.primary:
        x = part.series[name] / (sig[part.groups[name]] * part.unit_se[name])
        z += np.where(np.isfinite(x), x * x, 0.0)
    run = np.convolve(z, np.ones(window) / window, "same")
    return run, int(np.argmax(run))


def peak_window(fr: FlightResiduals, sigma: np.ndarray, window: int = WINDOW) -> list:
    """[t0, t1] [s] around the strongest residual structure of a flight: the running mean (``window``
    samples) of the whitened squared primary series (markers: along, lateral, normal; inertial: the six
    sensor series), where it stays above half its maximum around the maximum; of the observation model
    whose running mean peaks highest. ``sigma``: the problem's noise scales (n_groups,)."""
    best = None
    for part, off in zip(fr.parts, fr.group_offsets):
        run, i = _peak_run(part, np.asarray(sigma)[off:], window)
        if best is None or run[i] > best[1][best[2]]:
            best = (part, run, i)
    part, run, i = best
    above = run >= 0.5 * run[i]
    lo, hi = i, i
    while lo > 0 and above[lo - 1]:
        lo -= 1
    while hi < run.size - 1 and above[hi + 1]:
        hi += 1
    return [float(part.times[lo]), float(part.times[hi])]


def second_difference_variance(x: np.ndarray, se: np.ndarray | None = None) -> tuple[float, float]:
    """The sums of the second-difference noise estimate of one time-ordered series (module docstring).

    Parameters
    ----------
    x : (n,) array
        The series on an even time grid (NaN where nothing was recorded), in its unit.
    se : (n,) array, optional
        Standard error of each sample per unit noise scale (u_t); default 1.

    Returns
    -------
    (float, float)
        Σ_t (Δ²x_t)² [unit²] and Σ_t (u_{t+1}² + 4u_t² + u_{t−1}²) over the triples of finite samples:
        their ratio estimates σ²; both 0 when the series has no such triple.
    """
    x = np.asarray(x, float)
    u2 = np.ones(x.size) if se is None else np.asarray(se, float) ** 2
    if x.size < 3:
        return 0.0, 0.0
    d2 = x[2:] - 2.0 * x[1:-1] + x[:-2]
    w = u2[2:] + 4.0 * u2[1:-1] + u2[:-2]
    ok = np.isfinite(d2) & np.isfinite(w)
    return float(np.sum(d2[ok] ** 2)), float(np.sum(w[ok]))


def noise_floor(residuals: list, n_groups: int) -> np.ndarray:
    """σ̂_g of every noise group from the second differences of its primary residual series (module
    docstring): an estimate of the noise that does not need the right model.

    Parameters
    ----------
    residuals : list of FlightResiduals
        Every flight's residual series (:func:`flight_residuals`) of any reasonable fit.
    n_groups : int
        Number of noise groups of the problem (``Problem.n_groups``).

    Returns
    -------
    (n_groups,) array
        σ̂_g in each group's unit; NaN for a group without a primary series of three finite samples.
    """
    num, den = np.zeros(n_groups), np.zeros(n_groups)
    for fr in residuals:
        for part, off in zip(fr.parts, fr.group_offsets):
            for name in part.primary:
                g = off + part.groups[name]
                a, b = second_difference_variance(part.series[name], part.unit_se[name])
                num[g] += a
                den[g] += b
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(den > 0, np.sqrt(num / np.where(den > 0, den, 1.0)), np.nan)


def series_of(fr: FlightResiduals) -> dict:
    """All residual series of a flight (markers: six translation directions [m], three rotations [rad];
    inertial: six sensor series [rad/s, m/s²])."""
    return fr.series


def localise(problem: Problem, theta: np.ndarray, sigma: np.ndarray, residuals: list | None = None) -> dict:
    """Where the residuals are structured.

    Parameters
    ----------
    problem : Problem
    theta : (dim,) array
    sigma : (n_groups,) array
        Noise scale of every noise group of the problem (``Problem.sigma_names``), in its data's unit.
    residuals : list of FlightResiduals, optional
        The :func:`flight_residuals` of θ if already computed.

    Returns
    -------
    dict
        {flight: {series: {"rms", "unit", "noise_ratio" (RMS over the RMS noise alone would give),
        "ljung_box_q", "ljung_box_p", "windows_s" ([[t0, t1]] [s]), "correlation" ({covariate: r})}}};
        marker series also carry ``rms_mm`` (translations) or ``rms_mrad`` (attitude).
    """
    residuals = flight_residuals(problem, theta) if residuals is None else residuals
    sigma = np.asarray(sigma, float)
    out = {}
    for fr in residuals:
        per = {}
        for name, x in fr.series.items():
            part = fr.part(name)
            ok = np.isfinite(x)
            se = fr.se(name, sigma)
            q, p = ljung_box(x)
            corr = {}
            for cname, c in part.covariates.items():
                a, b = x[ok], c[ok]
                corr[cname] = float(np.corrcoef(a, b)[0, 1]) if a.size > 2 and np.std(b) > 0 and np.std(a) > 0 else 0.0
            rms = float(np.sqrt(np.mean(x[ok] ** 2))) if ok.any() else float("nan")
            noise = float(np.sqrt(np.mean(se[ok] ** 2))) if ok.any() else float("nan")
            unit = part.units[name]
            d = {"rms": rms, "unit": unit}
            if unit == "m":
                d["rms_mm"] = rms * 1e3
            elif unit == "rad":
                d["rms_mrad"] = rms * 1e3
            d.update({"noise_ratio": rms / noise if noise > 0 else float("nan"),
                      "ljung_box_q": q, "ljung_box_p": p,
                      "windows_s": structured_windows(x, se, part.times), "correlation": corr})
            per[name] = d
        out[fr.name] = per
    return out
