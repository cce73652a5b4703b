"""Where and how a fit misses the data: the onset of the mismatch along each flight, the signature of a term
(how its effect grows with time and which series it shows in), the attitude offset a marker error mimics, and
the fingerprint and words that describe where the residuals say the model falls short.
"""
from __future__ import annotations

import numpy as np
from scipy.optimize import least_squares

from ..inference.fitting.residuals import whitened_residuals
from ..inference.model.problem import Problem
from ..observation.models.markers import MarkerPositions
from .residuals import ROTATIONS, channel_runs, localise
from .missing_physics import ModelFit, STRUCTURE_ALPHA, structure_level, structured


# -- onset of an unexplained mismatch -------------------------------------------------------------------

#: shortest prefix [s] the onset search considers
ONSET_MIN_S = 0.15


def onset_unavailable(problem: Problem, k: int) -> str | None:
    """Why the onset search cannot run on flight k (None when it can): it refits a window of a flight's
    marker recording, so the flight must be observed by markers alone."""
    ch = problem.channels[k]
    if len(ch) == 1 and isinstance(ch[0], MarkerPositions):
        return None
    return ("not searched: the onset search refits the first part of a marker recording; this flight is "
            "observed by " + ", ".join(c.id for c in ch) + " (a window of an inertial log would start with "
            "an unknown filter state)")


def _prefix_is_white(fit: ModelFit, k: int, t_end: float, alpha: float) -> bool:
    """Whether flight k's first part [t_0, t_end], refitted over its own parameters (12 initial conditions and
    its noise model's, e.g. ρ) with the coefficients and extra parameters of ``fit`` held, leaves white
    residuals (all nine series)."""
    p = fit.problem
    f = p.flights[k].window(None, t_end)
    sub = p.subset(k, f)
    fixed = fit.ls.theta[: p.ic_start]
    sigma = fit.ls.sigma[k: k + 1]

    def resid(x):
        return whitened_residuals(np.r_[fixed, x], sub, sigma)[: int(sub.n_coords[0])]

    x0 = fit.ls.theta[p.layout.flight_slice(k)]        # initial conditions, then the flight's own parameters
    res = least_squares(resid, x0, x_scale=sub.prior_sd[sub.ic_start:], max_nfev=50, xtol=1e-10, ftol=1e-10)
    theta = np.r_[fixed, res.x]
    rms = float(np.sqrt(np.mean((resid(res.x) * sigma[0]) ** 2)))
    loc = localise(sub, theta, np.array([rms]))[f.name]
    level = structure_level(len(loc), alpha)
    return all(not np.isfinite(d["ljung_box_p"]) or d["ljung_box_p"] >= level for d in loc.values())


def onset_of_mismatch(fit: ModelFit, k: int, alpha: float = STRUCTURE_ALPHA) -> float | None:
    """Time [s from the flight's start] up to which the model still follows flight k (its first part
    refits to white residuals), by bisection over the sample times; None if even the first
    ONSET_MIN_S seconds are structured. Marker-only flights (:func:`onset_unavailable`)."""
    why = onset_unavailable(fit.problem, k)
    if why is not None:
        raise ValueError(f"flight {fit.problem.flights[k].name!r}: {why}")
    t = fit.problem.flights[k].times
    lo = int(np.searchsorted(t, t[0] + ONSET_MIN_S))
    hi = t.size - 1
    if lo >= hi or not _prefix_is_white(fit, k, t[lo], alpha):
        return None
    while hi - lo > 2:
        mid = (lo + hi) // 2
        if _prefix_is_white(fit, k, t[mid], alpha):
            lo = mid
        else:
            hi = mid
    return float(t[lo] - t[0])


# -- description ----------------------------------------------------------------------------------------

def term_signature(fit: ModelFit, names) -> list[dict]:
    """What the extra parameters ``names`` do in ``fit``: per flight, the noise-free change of every
    channel's prediction when they are switched off (same initial conditions and coefficients), as the
    series of its observation model's ``residual_series`` (markers [m, rad], inertial [rad/s, m/s²]).

    Returns
    -------
    list of dict
        Per flight: ``series`` {name: (n,)} (on − off); ``times`` [s from the start], ``covariates``,
        ``units`` and ``groups`` (the model's noise group) per series name; ``accel`` {marker direction:
        (n,) second derivative [m/s²]}; ``acc_change`` ((n,) |Δ accelerometer| [m/s²] of an inertial
        channel, or None).
    """
    p = fit.problem
    off = fit.ls.theta.copy()
    for j, par in enumerate(p.ext_parameters, start=p.n_coef):
        if par.name in names:
            off[j] = par.off_value
    out = []
    for k in range(p.n_flights):
        on_runs, off_runs = channel_runs(p, fit.ls.theta, k), channel_runs(p, off, k)
        g = {"series": {}, "times": {}, "covariates": {}, "units": {}, "groups": {}, "accel": {}, "acc_change": None}
        for (c, tr, extra, pred, air), (_, _, _, pred_off, _) in zip(on_runs, off_runs):
            rs = c.residual_series(tr, extra, pred, air, reference=pred_off)      # off − on
            for n, x in rs.series.items():
                g["series"][n] = -x
                g["times"][n], g["covariates"][n], g["units"][n] = rs.times - rs.times[0], rs.covariates, rs.units[n]
                g["groups"][n] = rs.groups[n]
                if rs.units[n] == "m":
                    dt = np.diff(rs.times).mean()
                    g["accel"][n] = np.gradient(np.gradient(-x, dt), dt)
            acc = [n for n in rs.series if n.startswith("acc_")]
            if acc:
                g["acc_change"] = np.sqrt(sum(rs.series[n] ** 2 for n in acc))
        out.append(g)
    return out


def _growth_exponent(t: np.ndarray, x: np.ndarray) -> float:
    """k in |x| ∝ t^k, fitted where |x| exceeds a tenth of its maximum (t > 0)."""
    ok = np.isfinite(x) & (t > 0)
    ax = np.abs(x[ok])
    if ok.sum() < 5 or ax.max() == 0:
        return float("nan")
    sel = ax > 0.1 * ax.max()
    if sel.sum() < 5:
        return float("nan")
    return float(np.polyfit(np.log(t[ok][sel]), np.log(ax[sel]), 1)[0])


def _corr(a: np.ndarray, b: np.ndarray) -> float:
    ok = np.isfinite(a) & np.isfinite(b)
    if ok.sum() < 3 or np.std(a[ok]) == 0 or np.std(b[ok]) == 0:
        return 0.0
    return float(np.corrcoef(a[ok], b[ok])[0, 1])


#: flight quantities the effect's force is compared with
LINKS = {"α": lambda c: c["alpha"], "α²": lambda c: c["alpha"] ** 2, "speed": lambda c: c["speed"],
         "speed²": lambda c: c["speed"] ** 2, "height": lambda c: c["height"]}
#: |correlation| above which the force "tracks" a flight quantity
LINK_CORRELATION = 0.8

#: lever arm [m] turning an attitude change into marker motion when comparing rotations with translations
LEVER_ARM = 0.1


def attitude_offset(fit: ModelFit, z_min: float = 5.0) -> dict | None:
    """The attitude angle whose mean residual stands out most (median over flights of |mean| / standard
    error): {rotation, mean_deg per flight}, or None unless it exceeds ``z_min`` standard errors. A fit
    that lacks a force often tilts the disc so that its lift supplies it: a steady attitude residual."""
    best, best_z = None, z_min
    for name in ROTATIONS:
        z, means = [], {}
        for fr in fit.residuals:
            if not fr.has(name):
                continue
            x = fr.series[name]
            ok = np.isfinite(x)
            if ok.sum() < 3:
                continue
            se = np.sqrt(np.sum(fr.se(name, fit.ls.sigma)[ok] ** 2)) / ok.sum()
            means[fr.name] = float(np.degrees(np.mean(x[ok])))
            z.append(abs(np.mean(x[ok])) / se)
        if z and np.median(z) > best_z:
            best, best_z = {"rotation": name, "mean_deg": means}, float(np.median(z))
    return best


def _rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.nanmean(x ** 2))) if np.isfinite(x).any() else float("nan")


def fingerprint(before: ModelFit, after: ModelFit, names) -> dict:
    """Where the mismatch sat (the base fit's structured series and flights) and what the accepted
    parameters ``names`` do.

    Marker flights (when the run has any): main direction of the effect on the markers, its growth t^k,
    whether its sign follows the spin across flights, and how its force (second derivative along the main
    direction) tracks α, α², speed, speed² and height (|correlation|, median over flights). Inertial flights
    only: the sensor series it changes most relative to its noise, and how the size of its accelerometer
    change |Δa| tracks the same flight quantities; growth and spin sign are not read (the sensor axes
    turn with the disc).
    """
    struct = structured(before)
    ratio = {}
    for per in before.localisation.values():
        for s, d in per.items():
            ratio.setdefault(s, []).append(d["noise_ratio"])
    sig = term_signature(after, names)
    common = {"structured_before": struct, "attitude_offset_before": attitude_offset(before),
              "noise_ratio_before": {s: float(np.median(v)) for s, v in ratio.items()}}
    corr = {c: [] for c in LINKS}
    marker = [g for g in sig if "along" in g["series"]]
    if not marker:
        z, size = {}, {}
        for fr, g in zip(after.residuals, sig):
            for n, x in g["series"].items():
                rms = _rms(x)
                size.setdefault(n, []).append(rms)
                z.setdefault(n, []).append(rms / after.ls.sigma[fr.group(n)])
            if g["acc_change"] is not None:
                cov = next(g["covariates"][n] for n in g["series"] if n.startswith("acc_"))
                for c, f in LINKS.items():
                    corr[c].append(abs(_corr(g["acc_change"], f(cov))))
        zm = {n: float(np.nanmedian(v)) for n, v in z.items()}
        main = max(zm, key=zm.get)
        units = sig[0]["units"]
        return common | {"channel": "inertial", "effect_series": main, "effect_rotation": None,
                         "effect_size": {n: {"rms": float(np.nanmedian(size[n])), "unit": units[n],
                                             "noise_ratio": zm[n]} for n in zm},
                         "growth_exponent": None, "sign_follows_spin": None,
                         "force_correlation": {c: float(np.median(v)) if v else 0.0 for c, v in corr.items()}}
    size = {n: np.median([np.sqrt(np.nanmean(g["series"][n] ** 2)) * (LEVER_ARM if n in ROTATIONS else 1.0)
                          for g in marker]) for n in marker[0]["series"] if all(n in g["series"] for g in marker)}
    trans = [n for n in size if n not in ROTATIONS]
    main = max(trans, key=size.get)
    main_rot = max(ROTATIONS, key=size.get)
    growth, signs = [], []
    for g in marker:
        growth.append(_growth_exponent(g["times"][main], g["series"][main]))
        for c, f in LINKS.items():
            corr[c].append(abs(_corr(g["accel"][main], f(g["covariates"][main]))))
        x = g["series"][main]
        signs.append((float(np.sign(x[np.nanargmax(np.abs(x))])),
                      float(np.sign(np.mean(g["covariates"][main]["spin"])))))
    follows = None
    if len({s for _, s in signs}) > 1:
        follows = len({a * s for a, s in signs if a != 0}) == 1
    growth = [x for x in growth if np.isfinite(x)]
    return common | {"channel": "markers", "effect_series": main,
                     "effect_rotation": main_rot if size[main_rot] > 0.5 * size[main] else None,
                     "effect_size_mm": {n: float(v * 1e3) for n, v in size.items()},
                     "growth_exponent": float(np.median(growth)) if growth else None,
                     "force_correlation": {c: float(np.median(v)) for c, v in corr.items()},
                     "sign_follows_spin": follows}


SERIES_WORDS = {"along": "along-track", "lateral": "lateral", "normal": "vertical (flight-path normal)",
                "d1": "disc-plane forward (d1)", "d2": "disc-plane sideways (d2)", "d3": "disc-normal (d3)",
                "roll": "roll attitude (about d1)", "pitch": "pitch attitude (about d2)",
                "spin_phase": "spin phase (about d3)",
                "gyro_x": "gyro x (sensor axis)", "gyro_y": "gyro y (sensor axis)", "gyro_z": "gyro z (spin axis)",
                "acc_x": "accelerometer x (sensor axis)", "acc_y": "accelerometer y (sensor axis)",
                "acc_z": "accelerometer z (disc normal)",
                "mag_x": "magnetometer x (sensor axis)", "mag_y": "magnetometer y (sensor axis)",
                "mag_z": "magnetometer z (disc normal)", "baro": "barometer (height)"}


def describe_where(fp: dict, n_flights: int) -> str:
    """The fingerprint in words: where the residual structure sat, then what the added term does."""
    flights = [f for f, s in fp["structured_before"].items() if s]
    series = sorted({s for v in fp["structured_before"].values() for s in v},
                    key=lambda s: -fp["noise_ratio_before"].get(s, 0.0))
    if flights:
        text = (f"{', '.join(SERIES_WORDS[s] for s in series[:3])} residuals structured in "
                + ("every flight" if len(flights) == n_flights else f"{len(flights)} of {n_flights} flights ({', '.join(flights)})"))
    else:
        text = "residuals white, but the fit improves decisively"
    off = fp.get("attitude_offset_before")
    if off:
        vals = list(off["mean_deg"].values())
        text += (f" (the base fit makes up for it with the attitude: measured − fitted "
                 f"{SERIES_WORDS[off['rotation']].split(' (')[0]} {min(vals):+.1f}…{max(vals):+.1f}° on average)")
    if fp.get("channel") == "inertial":
        effect = [f"the term changes mainly the {SERIES_WORDS[fp['effect_series']]} "
                  f"({fp['effect_size'][fp['effect_series']]['noise_ratio']:.1f}× its noise)"]
    else:
        effect = [f"the term moves the markers mainly {SERIES_WORDS[fp['effect_series']]}"
                  + (f" and turns the {SERIES_WORDS[fp['effect_rotation']]}" if fp["effect_rotation"] else "")]
    g = fp["growth_exponent"]
    if g is not None:
        effect.append(f"growing ∝ t^{g:.1f}")
    if fp["sign_follows_spin"] is True:
        effect.append("sign follows spin")
    elif fp["sign_follows_spin"] is False:
        effect.append("sign independent of spin")
    c = fp["force_correlation"]
    best = max(c, key=c.get)
    what = "its accelerometer change" if fp.get("channel") == "inertial" else "its force"
    effect.append(f"{what} tracks {best} best (|r| {c[best]:.2f})" if c[best] > LINK_CORRELATION
                  else f"{what} follows no single flight quantity")
    return f"{text}; {', '.join(effect)}"
