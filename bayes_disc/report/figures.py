"""Matplotlib figures of the report (object-oriented API on the Agg canvas: no pyplot state).

Every function returns a :class:`matplotlib.figure.Figure`; :func:`save_figure` writes it as PNG and PDF
and returns the PNG bytes for embedding.
"""
from __future__ import annotations

import io
from pathlib import Path

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from .sections import ReportFigure

PNG_DPI = 90
AXES = ("x", "y", "z")
MARKER_COLORS = ("tab:blue", "tab:orange", "tab:green", "tab:purple", "tab:brown", "tab:pink")
ENSEMBLE_COLORS = ("tab:blue", "tab:orange", "tab:green", "tab:red", "tab:purple", "tab:brown", "tab:pink",
                   "tab:gray", "tab:olive", "tab:cyan")
#: probability mass inside the corner plot's 2-D contours
CORNER_LEVELS = (0.5, 0.9)


def new_figure(width: float, height: float) -> Figure:
    fig = Figure(figsize=(width, height), layout=None)
    FigureCanvasAgg(fig)
    return fig


def save_figure(fig: Figure, folder: Path, name: str, caption: str) -> ReportFigure:
    """Write ``folder/name.png`` and ``folder/name.pdf``; return the embedded-figure record."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=PNG_DPI)
    png = buf.getvalue()
    png_path, pdf_path = folder / f"{name}.png", folder / f"{name}.pdf"
    png_path.write_bytes(png)
    fig.savefig(pdf_path, format="pdf")
    return ReportFigure(name=name, caption=caption, png=png, png_path=str(png_path), pdf_path=str(pdf_path))


def _grid(n: int, ncols: int) -> tuple[int, int]:
    return int(np.ceil(n / ncols)), ncols


# ---------------------------------------------------------------------------------------------- posterior
SUPERSCRIPT = str.maketrans("-0123456789", "⁻⁰¹²³⁴⁵⁶⁷⁸⁹")


def display_exponent(x: np.ndarray, below: float = 1e-2) -> int:
    """Power of ten k that brings small values to readable ticks: x·10^k has its largest |value| in [1, 10)
    when that value is below ``below``, else k = 0.

    Parameters
    ----------
    x : ndarray
        Samples of one quantity.
    below : float
        Values whose largest magnitude is at least this are shown as they are.

    Returns
    -------
    int
        The exponent k ≥ 0.
    """
    m = float(np.nanmax(np.abs(x))) if np.size(x) else 0.0
    if not np.isfinite(m) or m == 0.0 or m >= below:
        return 0
    return int(-np.floor(np.log10(m)))


def scaled_label(name: str, k: int) -> str:
    """``name`` or ``name ×10ᵏ`` (the quantity shown is name·10^k)."""
    return name if k == 0 else f"{name} ×10{str(k).translate(SUPERSCRIPT)}"


def corner_figure(samples: np.ndarray, labels, truths=None, levels=CORNER_LEVELS) -> Figure:
    """corner.py plot of samples (N, K) with 5/50/95 % quantile lines and 2-D contours at ``levels``.

    Small quantities (rate coefficients ~1e-4) are shown multiplied by a power of ten named in their label,
    so tick labels stay short; titles are the names alone (the values are in the report's tables)."""
    import corner
    k = samples.shape[1]
    exps = [display_exponent(samples[:, j]) for j in range(k)]
    factor = 10.0 ** np.asarray(exps, float)
    samples = samples * factor
    labels = [scaled_label(n, e) for n, e in zip(labels, exps)]
    if truths is not None:
        truths = [None if t is None else float(t) * f for t, f in zip(truths, factor)]
    fig = new_figure(1.45 * k, 1.45 * k)
    # a parameter with no spread (degenerate test runs) still needs a range
    rng = []
    for j in range(k):
        lo, hi = np.min(samples[:, j]), np.max(samples[:, j])
        if not hi > lo:
            pad = abs(lo) * 1e-6 + 1e-12
            lo, hi = lo - pad, hi + pad
        rng.append((lo, hi))
    corner.corner(samples, fig=fig, labels=labels, truths=truths, truth_color="tab:red", levels=levels,
                  quantiles=(0.05, 0.5, 0.95), show_titles=True, title_fmt=None, title_kwargs={"fontsize": 10},
                  label_kwargs={"fontsize": 10}, labelpad=0.1, bins=30, range=rng, plot_datapoints=False,
                  plot_density=False, fill_contours=True, color="tab:blue", max_n_ticks=3)
    # filled contours only: fast to draw and a small PDF
    for ax in fig.axes:
        ax.tick_params(labelsize=7)
    # room for rotated tick labels and, beyond them, the axis labels (corner's margins assume its own size)
    margin = 0.75 / fig.get_figwidth()
    fig.subplots_adjust(left=margin, bottom=margin, right=0.99, top=1 - 0.3 / fig.get_figheight())
    return fig


def trace_figure(bands: list[np.ndarray], names, burn: int, step: int = 1) -> Figure:
    """Per-ensemble traces: bands[e] (steps, K, 3) = walker 5/50/95 % quantiles every ``step`` steps.

    One grey band (from the lowest 5 % to the highest 95 % quantile of the ensembles) and each ensemble's
    walker median as a coloured line: overlapping coloured bands would blend into one brown block."""
    k = len(names)
    nr, nc = _grid(k, 2)
    fig = new_figure(11, 1.7 * nr + 0.6)
    axes = fig.subplots(nr, nc, sharex=True, squeeze=False).ravel()
    n_steps = min(b.shape[0] for b in bands)
    stack = np.stack([b[:n_steps] for b in bands])          # (E, steps, K, 3)
    steps = np.arange(n_steps) * step
    for j, name in enumerate(names):
        ax = axes[j]
        e_k = display_exponent(stack[:, :, j, :])
        f = 10.0 ** e_k
        ax.fill_between(steps, np.nanmin(stack[:, :, j, 0], axis=0) * f, np.nanmax(stack[:, :, j, 2], axis=0) * f,
                        color="0.82", lw=0, label="walkers' 5–95 % range (all ensembles)" if j == 0 else None)
        for e in range(stack.shape[0]):
            c = ENSEMBLE_COLORS[e % len(ENSEMBLE_COLORS)]
            ax.plot(steps, stack[e, :, j, 1] * f, color=c, lw=0.9,
                    label=f"ensemble {e} median" if j == 0 else None)
        ax.axvline(burn, color="k", ls="--", lw=0.8, label="end of burn-in" if j == 0 else None)
        ax.set_ylabel(scaled_label(name, e_k), fontsize=9)
        ax.tick_params(labelsize=7)
    for ax in axes[k:]:
        ax.set_visible(False)
    for ax in axes[max(0, k - nc): k]:
        ax.set_xlabel("step", fontsize=9)
    fig.legend(loc="upper center", ncol=min(len(bands) + 2, 7), fontsize=8, frameon=False)
    fig.subplots_adjust(left=0.08, right=0.98, top=1 - 0.45 / fig.get_figheight(), bottom=0.06, hspace=0.12,
                        wspace=0.25)
    return fig


def rank_figure(post: np.ndarray, ensemble_of_chain: np.ndarray, names, bins: int = 20) -> Figure:
    """Rank plots: post (n_chain, n_draw, K); ranks over all kept samples, histogram per ensemble."""
    k = len(names)
    nr, nc = _grid(k, 5)
    fig = new_figure(12, 2.0 * nr + 0.6)
    axes = fig.subplots(nr, nc, squeeze=False).ravel()
    ens = np.unique(ensemble_of_chain)
    n_total = post.shape[0] * post.shape[1]
    edges = np.linspace(0, n_total, bins + 1)
    for j, name in enumerate(names):
        ax = axes[j]
        order = np.argsort(post[..., j].ravel(), kind="stable")
        ranks = np.empty(order.size, dtype=np.int64)
        ranks[order] = np.arange(order.size)
        ranks = ranks.reshape(post.shape[:2])
        for e in ens:
            r = ranks[ensemble_of_chain == e].ravel()
            h, _ = np.histogram(r, bins=edges)
            frac = h / max(r.size, 1) * bins
            ax.step(np.arange(bins + 1), np.r_[frac, frac[-1]], where="post",
                    color=ENSEMBLE_COLORS[int(e) % len(ENSEMBLE_COLORS)], lw=1.0,
                    label=f"ensemble {int(e)}" if j == 0 else None)
        ax.axhline(1.0, color="k", lw=0.6, ls=":")
        ax.set_ylim(0, max(2.0, ax.get_ylim()[1]))
        ax.set_title(name, fontsize=9)
        ax.set_xticks([])
        ax.tick_params(labelsize=7)
        if j % nc == 0:
            ax.set_ylabel("relative frequency", fontsize=8)
        if j >= k - nc:
            ax.set_xlabel("rank: low → high", fontsize=8)
    for ax in axes[k:]:
        ax.set_visible(False)
    fig.legend(loc="upper center", ncol=min(len(ens), 6), fontsize=8, frameon=False)
    fig.subplots_adjust(left=0.06, right=0.98, top=1 - 0.5 / fig.get_figheight(), bottom=0.08, hspace=0.35)
    return fig


# ---------------------------------------------------------------------------------------------- flights
def residual_figure(sims) -> Figure:
    """Measured − predicted marker coordinates (mm) against time: rows x, y, z; one column per flight.

    Residuals are dots (independent measurements, not a path); the grey band is ±2σ of the flight's
    posterior-median noise scale, where white noise should lie."""
    n = len(sims)
    fig = new_figure(max(6.0, 3.2 * n), 6.5)
    axes = fig.subplots(3, n, sharey="row", squeeze=False)
    for c, s in enumerate(sims):
        r = s.residuals * 1e3
        sig = float(np.nanmedian(s.sigma)) * 1e3 if np.isfinite(s.sigma).any() else s.sigma_ref * 1e3
        for a in range(3):
            ax = axes[a, c]
            ax.axhspan(-2 * sig, 2 * sig, color="0.88", lw=0, zorder=0,
                       label="±2σ (posterior noise)" if (a == 0 and c == 0) else None)
            for m, mid in enumerate(s.marker_ids):
                ax.plot(s.times, r[:, m, a], ".", ms=2.5, color=MARKER_COLORS[m % len(MARKER_COLORS)],
                        label=f"marker {mid}" if (a == 0 and c == 0) else None)
            ax.axhline(0, color="k", lw=0.5)
            ax.tick_params(labelsize=7)
            if c == 0:
                ax.set_ylabel(f"{AXES[a]} residual [mm]", fontsize=9)
            if a == 2:
                ax.set_xlabel("t [s]", fontsize=9)
        axes[0, c].set_title(f"{s.name}: RMS {s.rms * 1e3:.2f} mm", fontsize=10)
    fig.legend(loc="upper center", ncol=len(sims[0].marker_ids) + 1, fontsize=8, frameon=False, markerscale=3)
    fig.subplots_adjust(left=0.07, right=0.98, top=0.88, bottom=0.08, hspace=0.15, wspace=0.12)
    return fig


def alpha_figure(sims, alpha_ref: list[np.ndarray], alpha_draws: list[np.ndarray]) -> Figure:
    """Angle of attack (deg) against time per flight: reference draw and 90 % posterior band.

    A tight posterior makes the band thinner than the line, so a lower row magnifies it: the band's 5 % and
    95 % quantiles minus the highest-posterior draw."""
    n = len(sims)
    fig = new_figure(max(6.0, 3.2 * n), 4.6)
    axes = fig.subplots(2, n, sharey="row", sharex="col", squeeze=False, gridspec_kw={"height_ratios": [3, 1.4]})
    for c, s in enumerate(sims):
        ax, bx = axes[0, c], axes[1, c]
        a_ref = np.degrees(alpha_ref[c])
        a_d = np.degrees(alpha_draws[c])
        lo, hi = np.nanquantile(a_d, [0.05, 0.95], axis=0)
        ax.fill_between(s.times, lo, hi, color="tab:blue", alpha=0.3, lw=0, label="90 % posterior band")
        ax.plot(s.times, a_ref, color="tab:blue", lw=1.2, label="highest-posterior draw")
        ax.set_title(f"{s.name}: α {np.nanmin(a_ref):.1f}…{np.nanmax(a_ref):.1f}°", fontsize=10)
        bx.fill_between(s.times, lo - a_ref, hi - a_ref, color="tab:blue", alpha=0.3, lw=0)
        bx.axhline(0, color="tab:blue", lw=1.0)
        bx.set_xlabel("t [s]", fontsize=9)
        for a in (ax, bx):
            a.tick_params(labelsize=7)
            a.grid(alpha=0.3)
    axes[0, 0].set_ylabel("angle of attack α [deg]", fontsize=9)
    axes[1, 0].set_ylabel("band − draw [deg]", fontsize=9)
    axes[0, 0].legend(fontsize=7, loc="best")
    fig.subplots_adjust(left=0.07, right=0.98, top=0.92, bottom=0.11, wspace=0.08, hspace=0.1)
    return fig


def trajectory_figure(sims) -> Figure:
    """Measured markers (dots) and predicted marker paths (lines): top view (y against x), side view (z)."""
    n = len(sims)
    fig = new_figure(max(6.0, 3.2 * n), 5.6)
    axes = fig.subplots(2, n, squeeze=False)
    for c, s in enumerate(sims):
        for row, a in enumerate((1, 2)):
            ax = axes[row, c]
            for m, mid in enumerate(s.marker_ids):
                col = MARKER_COLORS[m % len(MARKER_COLORS)]
                ax.plot(s.measured[:, m, 0], s.measured[:, m, a], ".", ms=2.5, color=col,
                        label=f"marker {mid} measured" if (row == 0 and c == 0) else None)
                ax.plot(s.ref_markers[:, m, 0], s.ref_markers[:, m, a], "-", lw=0.7, color=col,
                        label=f"marker {mid} predicted" if (row == 0 and c == 0) else None)
            ax.set_xlabel("x [m]", fontsize=9)
            ax.set_ylabel(("y [m] (top view)", "z [m] (side view)")[row] if c == 0 else "", fontsize=9)
            ax.tick_params(labelsize=7)
            ax.grid(alpha=0.3)
        axes[0, c].set_title(s.name, fontsize=10)
    fig.legend(loc="upper center", ncol=len(sims[0].marker_ids), fontsize=7, frameon=False)
    fig.subplots_adjust(left=0.1, right=0.98, top=0.84, bottom=0.09, hspace=0.3, wspace=0.22)
    return fig


def predictive_bands(sim, rng: np.random.Generator, mass: float = 0.9):
    """Posterior predictive interval of measured − reference prediction, per time, marker and axis.

    Replicates y_rep = markers(θ_draw) + σ_draw·ε; returns (lo, hi) arrays (n, m, 3) [m] and the share of
    observed coordinates inside their own interval (≈ ``mass`` when the model and noise fit)."""
    d = sim.draw_markers
    ok = np.all(np.isfinite(d.reshape(d.shape[0], -1)), axis=1)
    d, sig = d[ok], sim.sigma[ok]
    rep = d + sig[:, None, None, None] * rng.standard_normal(d.shape)
    dev = rep - sim.ref_markers[None]
    q = (1 - mass) / 2
    lo, hi = np.quantile(dev, [q, 1 - q], axis=0)
    r = sim.residuals
    seen = np.isfinite(r)
    inside = (r >= lo) & (r <= hi) & seen
    coverage = float(inside.sum() / max(seen.sum(), 1))
    return lo, hi, coverage


def predictive_figure(sims, bands) -> Figure:
    """Measured − reference prediction (dots) inside the 90 % posterior predictive band (mean over markers)."""
    n = len(sims)
    fig = new_figure(max(6.0, 3.2 * n), 6.5)
    axes = fig.subplots(3, n, sharey="row", squeeze=False)
    for c, (s, (lo, hi, cov)) in enumerate(zip(sims, bands)):
        r = s.residuals * 1e3
        for a in range(3):
            ax = axes[a, c]
            ax.fill_between(s.times, lo[:, :, a].mean(axis=1) * 1e3, hi[:, :, a].mean(axis=1) * 1e3,
                            color="0.6", alpha=0.45, lw=0, label="90 % predictive band" if a == 0 and c == 0 else None)
            for m in range(r.shape[1]):
                ax.plot(s.times, r[:, m, a], ".", ms=2, color=MARKER_COLORS[m % len(MARKER_COLORS)])
            ax.tick_params(labelsize=7)
            if c == 0:
                ax.set_ylabel(f"{AXES[a]}: measured − predicted [mm]", fontsize=8)
            if a == 2:
                ax.set_xlabel("t [s]", fontsize=9)
        axes[0, c].set_title(f"{s.name}: {cov * 100:.0f} % of coordinates inside", fontsize=10)
    fig.legend(loc="upper center", fontsize=8, frameon=False)
    fig.subplots_adjust(left=0.08, right=0.98, top=0.88, bottom=0.08, hspace=0.15, wspace=0.12)
    return fig


# ---------------------------------------------------------------------------------------------- force curves
def force_curve_figure(coef: dict, alpha_range_deg, tunnel, literature: dict, truth: dict | None) -> Figure:
    """CL(α), CD(α), CM(α): posterior median and 90 % band over the flown α range, on the wind-tunnel points.

    coef: {name: samples (N,)} for CL0 CLa CD0 CDa CM0 CMa; literature: {label: {name: value}}."""
    lo_d, hi_d = alpha_range_deg
    x_lo, x_hi = min(-15.0, lo_d - 10.0), max(50.0, hi_d + 10.0)
    grid_deg = np.linspace(lo_d, hi_d, 80)
    grid = np.radians(grid_deg)
    full_deg = np.linspace(x_lo, x_hi, 120)
    full = np.radians(full_deg)
    curves = {
        "CL": (lambda c, a: c["CL0"] + c["CLa"] * a, tunnel.CL),
        "CD": (lambda c, a: c["CD0"] + c["CDa"] * a**2, tunnel.CD),
        "CM": (lambda c, a: c["CM0"] + c["CMa"] * a, tunnel.CM),
    }
    fig = new_figure(12, 5.8)
    grid_axes = fig.subplots(2, 3, sharex="col", gridspec_kw={"height_ratios": [3, 1.2]})
    axes, band_axes = grid_axes[0], grid_axes[1]
    keep = (tunnel.alpha_deg >= x_lo) & (tunnel.alpha_deg <= x_hi)
    styles = [("--", "tab:green"), (":", "tab:purple"), ("-.", "tab:brown")]
    for ax, bx, (name, (fn, measured)) in zip(axes, band_axes, curves.items()):
        ax.plot(tunnel.alpha_deg[keep], measured[keep], "ks", ms=3.5, label="wind tunnel (Potts 2005)")
        cs = {k: np.asarray(v)[:, None] for k, v in coef.items()}
        q05, q50, q95 = np.quantile(fn(cs, grid[None, :]), [0.05, 0.5, 0.95], axis=0)
        e05, e50, e95 = np.quantile(fn(cs, full[None, :]), [0.05, 0.5, 0.95], axis=0)
        ax.fill_between(full_deg, e05, e95, color="tab:blue", alpha=0.10, lw=0,
                        label="posterior 90 % band, extrapolated")
        ax.plot(full_deg, e50, color="tab:blue", lw=0.7, alpha=0.6, ls=(0, (1, 2)))
        ax.fill_between(grid_deg, q05, q95, color="tab:blue", alpha=0.45, lw=0,
                        label="posterior 90 % band, flown α range")
        ax.plot(grid_deg, q50, color="tab:blue", lw=2.0, label="posterior median")
        for (label, vals_lit), (ls, col) in zip(literature.items(), styles):
            if all(k in vals_lit for k in coef):
                ax.plot(full_deg, fn(vals_lit, full), ls=ls, color=col, lw=1.0, label=label)
        if truth is not None and all(k in truth for k in coef):
            ax.plot(full_deg, fn(truth, full), color="tab:red", lw=0.9, ls=(0, (6, 3)), alpha=0.9, label="truth")
        ax.axvspan(lo_d, hi_d, color="tab:blue", alpha=0.06)
        ax.set_xlim(x_lo, x_hi)
        ylo, yhi = np.nanmin(measured[keep]), np.nanmax(measured[keep])
        pad = 0.15 * (yhi - ylo)
        ax.set_ylim(min(ylo, np.nanmin(q05)) - pad, max(yhi, np.nanmax(q95)) + pad)
        ax.set_ylabel(name, fontsize=10)
        # the band is often thinner than the median line: magnified, relative to the median
        bx.fill_between(full_deg, e05 - e50, e95 - e50, color="tab:blue", alpha=0.10, lw=0)
        bx.fill_between(grid_deg, q05 - q50, q95 - q50, color="tab:blue", alpha=0.45, lw=0)
        bx.axhline(0, color="tab:blue", lw=1.0)
        bx.axvspan(lo_d, hi_d, color="tab:blue", alpha=0.06)
        inner = max(float(np.nanmax(np.abs(np.r_[q05 - q50, q95 - q50]))), 1e-12)
        bx.set_ylim(-3 * inner, 3 * inner)    # the flown range's band fills a third; extrapolation may leave
        bx.set_xlabel("α [deg]", fontsize=9)
        bx.set_ylabel(f"{name} band − median", fontsize=8)
        for a in (ax, bx):
            a.tick_params(labelsize=7)
            a.grid(alpha=0.3)
    fig.legend(*axes[0].get_legend_handles_labels(), loc="lower center", ncol=4, fontsize=8, frameon=False)
    fig.subplots_adjust(left=0.06, right=0.99, top=0.97, bottom=0.2, wspace=0.28, hspace=0.08)
    return fig


# ------------------------------------------------------------------------------------------ identifiability
def alpha_histogram_figure(edges_deg, counts, per_flight: dict) -> Figure:
    """Histogram of α over all flights' samples, with each flight's α range as a bar below."""
    fig = new_figure(7.0, 3.2)
    ax = fig.add_subplot(111)
    edges = np.asarray(edges_deg, float)
    ax.bar(edges[:-1], counts, width=np.diff(edges), align="edge", color="tab:blue", alpha=0.6,
           edgecolor="white", label="samples, all flights")
    top = max(max(counts), 1)
    for j, (name, r) in enumerate(per_flight.items()):
        y = -0.08 * top * (j + 1)
        lo, hi = r["alpha_deg"]
        ax.plot([lo, hi], [y, y], lw=4, color=ENSEMBLE_COLORS[j % len(ENSEMBLE_COLORS)], solid_capstyle="butt")
        ax.text(hi + 0.4, y, name, va="center", fontsize=8)
    ax.axhline(0, color="k", lw=0.5)
    ax.set_xlabel("angle of attack α [deg]")
    ax.set_ylabel("samples")
    ax.legend(loc="upper right", fontsize=8)
    fig.tight_layout()
    return fig


def correlation_figure(corr: np.ndarray, names) -> Figure:
    """Posterior correlation matrix of the coefficients (colour and value)."""
    n = len(names)
    fig = new_figure(0.55 * n + 2.0, 0.55 * n + 1.2)
    ax = fig.add_subplot(111)
    im = ax.imshow(corr, vmin=-1, vmax=1, cmap="RdBu_r")
    ax.set_xticks(range(n), names, rotation=90)
    ax.set_yticks(range(n), names)
    for i in range(n):
        for j in range(n):
            ax.text(j, i, f"{corr[i, j]:.2f}", ha="center", va="center", fontsize=6,
                    color="white" if abs(corr[i, j]) > 0.6 else "black")
    fig.colorbar(im, ax=ax, fraction=0.046, pad=0.04, label="posterior correlation")
    fig.tight_layout()
    return fig


def diagnosis_figure(series: dict, flights: list[str], names: list[str], labels: dict) -> Figure:
    """Residual series before (grey) and after (blue) the accepted terms, one row per series in ``names``,
    one column per flight; the band is ±2 noise standard errors. ``series``: the arrays of
    ``diagnosis_residuals.npz`` (a series' own times ``<c>_times_<name>`` where it has them, else the
    flight's ``<c>_times``); ``labels``: {name: (axis label, factor from the series' unit to the label's)}."""
    n = len(flights)
    height = 2.3 * len(names) + 1.0
    fig = new_figure(max(6.0, 3.2 * n), height)
    axes = fig.subplots(len(names), n, sharey="row", squeeze=False)
    for c, flight in enumerate(flights):
        for r, name in enumerate(names):
            ax = axes[r, c]
            t = series.get(f"{c}_times_{name}", series[f"{c}_times"])
            label, scale = labels[name]
            se = series[f"{c}_se_{name}"] * scale
            ax.fill_between(t, -2 * se, 2 * se, color="tab:blue", alpha=0.15, lw=0, label="±2 noise s.e." if r == c == 0 else None)
            ax.plot(t, series[f"{c}_before_{name}"] * scale, ".", ms=3, color="0.45", label="before" if r == c == 0 else None)
            ax.plot(t, series[f"{c}_after_{name}"] * scale, ".", ms=2, color="tab:blue", label="after" if r == c == 0 else None)
            ax.axhline(0, color="k", lw=0.5)
            ax.tick_params(labelsize=7)
            if c == 0:
                ax.set_ylabel(label, fontsize=8)
            if r == len(names) - 1:
                ax.set_xlabel("t [s]", fontsize=9)
        axes[0, c].set_title(flight, fontsize=10)
    fig.legend(loc="upper center", ncol=3, fontsize=8, frameon=False, markerscale=4)
    fig.subplots_adjust(left=0.08, right=0.98, top=1 - 0.7 / height, bottom=0.5 / height, hspace=0.25, wspace=0.1)
    return fig


#: axis labels and display scales of the learned curve's flight variables
CURVE_AXES = {"height": ("height z [m]", 1.0), "alpha": ("angle of attack α [deg]", 180.0 / np.pi),
              "spin": ("advance ratio μ = r d / 2|v_a|", 1.0)}


def learned_curve_figure(curve: dict, generating: np.ndarray | None = None, generating_label: str = "") -> Figure:
    """The learned correction ΔC against one flight variable (line and ±2 sd band), beside the library
    family fitted as a candidate (dashed) and, for synthetic data, the curve that generated the data (black).
    ``curve``: ``learned_discrepancy.curve`` of ``diagnosis.json`` (its grid starts at the ground; below the
    flown heights the curves are extrapolations)."""
    label, scale = CURVE_AXES[curve["variable"]]
    x = np.asarray(curve["grid"], float) * scale
    value, sd = np.asarray(curve["value"], float), np.asarray(curve["sd"], float)
    fig = new_figure(6.0, 3.6)
    ax = fig.add_subplot(1, 1, 1)
    ax.fill_between(x, value - 2 * sd, value + 2 * sd, color="tab:blue", alpha=0.2, lw=0, label="learned ± 2 sd")
    ax.plot(x, value, color="tab:blue", lw=2, label="learned correction")
    fam = curve.get("family")
    if fam:
        ax.plot(x, np.asarray(fam["value"], float), "--", color="tab:orange", lw=1.5,
                label=f"fitted {fam['id'].replace('_', ' ')} family")
    if generating is not None:
        ax.plot(x, generating, color="k", lw=1.2, label=generating_label or "generating form")
    ax.axhline(0, color="0.5", lw=0.5)
    ax.set_xlabel(label, fontsize=9)
    ax.set_ylabel(f"Δ{curve['direction']} coefficient", fontsize=9)
    ax.tick_params(labelsize=8)
    ax.legend(fontsize=8, frameon=False)
    fig.subplots_adjust(left=0.13, right=0.97, top=0.95, bottom=0.14)
    return fig


def wobble_figure(records: dict) -> Figure:
    """The wobble of each throw (one column per throw), data (dots) against model (line): κ, the nutation
    rate over the spin [1], with the model's torque-free rigid disc's (Ia − Id)/Id dashed (Ia (1 + ε_I) with a
    fitted inertia ratio) and, dotted over the late span, the free nutation's κ_F of the late beat where it is
    resolved (top); the amplitudes of the nutation (log scale), of the space-fixed part and of the
    sensor-fixed part [rad/s] (bottom).

    Parameters
    ----------
    records : dict
        ``diagnosis.json``'s ``wobble``: {throw: {series: {data, model: {time_s, kappa, nutation_rad_s,
        space_fixed_rad_s, constant_rad_s} (m,) lists}, torque_free_kappa, beat (optional)}}.
    """
    n = len(records)
    fig = new_figure(max(6.0, 3.6 * n), 5.6)
    axes = fig.subplots(2, n, squeeze=False, sharex="col")
    for c, (name, rec) in enumerate(records.items()):
        top, bottom = axes[0, c], axes[1, c]
        for who, style, colour in (("data", ".", "tab:blue"), ("model", "-", "k")):
            s = rec["series"][who]
            t = np.asarray(s["time_s"], float)
            top.plot(t, np.asarray(s["kappa"], float), style, ms=4, color=colour, label=f"{who} κ" if c == 0 else None)
            for key, col, lab in (("nutation_rad_s", colour, "nutation"), ("space_fixed_rad_s", "tab:orange", "space-fixed"),
                                  ("constant_rad_s", "tab:green", "sensor-fixed")):
                bottom.plot(t, np.asarray(s[key], float), style, ms=3, lw=1.0,
                            color=colour if key == "nutation_rad_s" else col, alpha=1.0 if who == "data" else 0.7,
                            label=f"{who} {lab}" if c == 0 else None)
        top.axhline(rec["torque_free_kappa"], color="0.5", ls="--", lw=0.8,
                    label="torque-free (Ia − Id)/Id" if c == 0 else None)
        for who, colour in (("data", "tab:blue"), ("model", "k")):
            b = (rec.get("beat") or {}).get(who)
            if b and b["free_resolved"]:
                top.hlines(b["kappa_free"], *b["span_s"], color=colour, ls=":", lw=1.6,
                           label=f"{who}: late free nutation κ_F (beat)" if c == 0 else None)
        bottom.set_yscale("log")
        top.set_title(name, fontsize=10)
        bottom.set_xlabel("window centre, time since release [s]", fontsize=8)
        for ax in (top, bottom):
            ax.tick_params(labelsize=7)
        if c == 0:
            top.set_ylabel("κ = nutation rate / spin", fontsize=8)
            bottom.set_ylabel("amplitude [rad/s]", fontsize=8)
            top.legend(fontsize=7)
            bottom.legend(fontsize=6, ncol=2)
    fig.tight_layout()
    return fig
