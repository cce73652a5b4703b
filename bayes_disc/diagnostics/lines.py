"""Oscillations left in the residuals: a periodic line a residual series carries, named by its frequency (also as
a multiple of the spin rate), its amplitude and the share of the series it explains.

For one residual series x_i at times t_i [s] (n samples over a span T), a sinusoid with an offset is fitted by
least squares at each trial frequency f [Hz],

    x_i ≈ a cos 2πf t_i + b sin 2πf t_i + c,

and its share of the series is

    s(f) = 1 − RSS(f) / Σ (x_i − x̄)²

(the Lomb–Scargle periodogram with a floating mean, normalised to the variance), on a grid from
:data:`MIN_CYCLES`/T (at least that many cycles in the flight: a slower change is a trend, not an oscillation)
to the Nyquist frequency 1/(2 Δt) (Δt: the median sample step), spaced 1/(:data:`OVERSAMPLING` T). The line is
the highest peak of s inside the grid (where s only rises towards the slowest trial frequency, the series holds
a trend), its amplitude √(a² + b²) in the series' unit; it is reported when s ≥ :data:`LINE_SHARE`. For white
residuals the largest share over the n/2 independent frequencies is about 2 ln(n/2)/n (0.04 for 240 samples),
far below the threshold: a reported line is structure the model leaves — a beat, a mode of the flight the
model lacks, or a sensor effect.

The spin's multiple f / (|r̄|/2π) (r̄: the mean spin rate along the predicted trajectory, rad/s) ties the line to
the disc's rotation: 1 is once per revolution in the body, the wobble turns at about Ia/Id − 1 ≈ 0.93 of it, and
(1 − κ) is the beat of the wobble against a forcing at the spin.
"""
from __future__ import annotations

import numpy as np

#: share of a residual series' variance at or above which its strongest sinusoid is reported
LINE_SHARE = 0.3
#: cycles in the series' span the slowest trial frequency must complete
MIN_CYCLES = 2.0
#: frequency grid spacing: 1 / (OVERSAMPLING · span)
OVERSAMPLING = 8
#: trial frequencies fitted at once (bounds the memory of a long series)
CHUNK = 256


def strongest_line(t: np.ndarray, x: np.ndarray) -> dict | None:
    """The sinusoid (with an offset) that explains most of ``x`` (module docstring).

    Parameters
    ----------
    t : (n,) array
        Sample times [s]; NaN samples of ``x`` are left out.
    x : (n,) array
        Residual series, any unit.

    Returns
    -------
    dict or None
        ``frequency_hz``, ``amplitude`` (unit of x), ``share`` (of the series' variance about its mean) and
        ``cycles`` (in the span); None when fewer than 8 finite samples, a span too short for
        :data:`MIN_CYCLES` cycles below the Nyquist frequency, or no peak of the share inside the grid.
    """
    ok = np.isfinite(x) & np.isfinite(t)
    t, x = np.asarray(t, float)[ok], np.asarray(x, float)[ok]
    if t.size < 8:
        return None
    span = float(t.max() - t.min())
    f_lo, f_hi = MIN_CYCLES / span, 0.5 / float(np.median(np.diff(np.sort(t))))
    if not f_hi > f_lo:
        return None
    freqs = np.arange(f_lo, f_hi, 1.0 / (OVERSAMPLING * span))
    xc = x - x.mean()
    total = float(xc @ xc)
    if total == 0.0:
        return None
    chunks = np.array_split(freqs, -(-freqs.size // CHUNK))
    coef = np.concatenate([_sinusoid_fits(f, t - t.mean(), xc) for f in chunks])
    explained = coef[:, 3]
    inner = np.flatnonzero((explained[1:-1] >= explained[:-2]) & (explained[1:-1] >= explained[2:])) + 1
    if inner.size == 0:
        return None
    k = int(inner[np.argmax(explained[inner])])
    return {"frequency_hz": float(freqs[k]), "amplitude": float(np.hypot(coef[k, 0], coef[k, 1])),
            "share": float(explained[k] / total), "cycles": float(freqs[k] * span)}


def _sinusoid_fits(freqs: np.ndarray, t: np.ndarray, x: np.ndarray) -> np.ndarray:
    """(m, 4): a, b, c of x ≈ a cos 2πf t + b sin 2πf t + c at each f, and the squared norm of that fit."""
    phase = 2.0 * np.pi * np.outer(freqs, t)                                  # (m, n)
    basis = np.stack([np.cos(phase), np.sin(phase), np.ones_like(phase)], axis=2)
    gram = np.einsum("mni,mnj->mij", basis, basis)
    rhs = np.einsum("mni,n->mi", basis, x)
    coef = np.linalg.solve(gram, rhs[..., None])[..., 0]
    return np.column_stack([coef, np.einsum("mi,mi->m", coef, rhs)])        # ‖projection‖² = cᵀ Bᵀ x


def flight_lines(fr, share: float = LINE_SHARE) -> dict:
    """Every series of one flight's residuals whose strongest line reaches ``share``.

    Parameters
    ----------
    fr : FlightResiduals
        One flight's residual series (:func:`.residuals.flight_residuals`).
    share : float
        Reporting threshold on the line's share of the series.

    Returns
    -------
    dict
        {series: line} in decreasing share; each line as :func:`strongest_line` plus ``unit`` and
        ``per_spin`` (f over the mean spin frequency; None without a spin covariate or with no spin).
    """
    found = {}
    for part in fr.parts:
        spin = part.covariates.get("spin")
        spin_hz = float(np.nanmean(np.abs(spin))) / (2.0 * np.pi) if spin is not None else 0.0
        for name, x in part.series.items():
            line = strongest_line(part.times, x)
            if line is None or line["share"] < share:
                continue
            line["unit"] = part.units[name]
            line["per_spin"] = line["frequency_hz"] / spin_hz if spin_hz > 0 else None
            found[name] = line
    return dict(sorted(found.items(), key=lambda kv: -kv[1]["share"]))


def residual_lines(residuals: list) -> dict:
    """{flight: :func:`flight_lines`} for the flights that carry a line (empty when none does).

    Parameters
    ----------
    residuals : list of FlightResiduals
        Every flight's residuals at the fit (:func:`.residuals.flight_residuals`).

    Returns
    -------
    dict
    """
    out = {fr.name: flight_lines(fr) for fr in residuals}
    return {k: v for k, v in out.items() if v}
