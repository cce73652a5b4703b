"""The report's section on inertial recordings: the logger's parameters, each throw measured against the
model (spin-down, wobble, normal and in-plane specific force), residuals and how the throws were found."""
from __future__ import annotations

import numpy as np
from matplotlib.figure import Figure

from .sections import Section, esc, fmt, table

CHANNEL_ROWS = (("gyro z: spin [rad/s]", (2,)), ("gyro x, y: wobble [rad/s]", (0, 1)),
                ("acc z: normal specific force [m/s²]", (5,)), ("acc x, y: in-plane specific force [m/s²]", (3, 4)))
COLOURS = ("tab:blue", "tab:orange", "tab:green")


def _predictions(ctx, k: int):
    """(model, sample times [s] since release, measured (n, c), predicted (n, c)) of flight k's inertial
    channel at the highest-posterior draw (c = 6 gyro and accelerometer channels, 9 with the magnetometer)."""
    from ..observation.models.inertial import InertialMeasurements
    theta = ctx.theta_ref[None]
    preds, _ = ctx.problem.channel_predictions(theta, k)
    c, pred = next((c, p) for c, p in preds if isinstance(c, InertialMeasurements))
    period = c.split(theta[:, ctx.problem.channel_columns(k)[ctx.problem.channels[k].index(c)]])["period"]
    t = c.sample_times_for(period)[0]
    return c, t, c.measured, pred[0]


def _throw_figure(ctx, data) -> Figure:
    n = len(data)
    fig = Figure(figsize=(4.2 * n + 1.0, 9.0), constrained_layout=True)
    axes = fig.subplots(len(CHANNEL_ROWS), n, squeeze=False, sharex="col")
    for col, (name, t, meas, pred) in enumerate(data):
        for row, (label, idx) in enumerate(CHANNEL_ROWS):
            ax = axes[row, col]
            for j, i in enumerate(idx):
                ax.plot(t, meas[:, i], ".", ms=2.5, color=COLOURS[j], alpha=0.6,
                        label=f"measured {'xyz'[i % 3]}" if col == 0 else None)
                ax.plot(t, pred[:, i], "-", lw=1.2, color="k" if len(idx) == 1 else COLOURS[j], alpha=0.9,
                        label=f"model {'xyz'[i % 3]}" if col == 0 else None)
            if col == 0:
                ax.set_ylabel(label, fontsize=8)
            ax.tick_params(labelsize=7)
        axes[0, col].set_title(name, fontsize=9)
        axes[-1, col].set_xlabel("time since release [s]", fontsize=8)
    axes[0, 0].legend(fontsize=7, loc="best")
    axes[1, 0].legend(fontsize=7, loc="best", ncol=2)
    return fig


def _residual_figure(ctx, data, sigma) -> Figure:
    n = len(data)
    fig = Figure(figsize=(4.2 * n + 1.0, 4.6), constrained_layout=True)
    axes = fig.subplots(2, n, squeeze=False, sharex="col")
    for col, (name, t, meas, pred) in enumerate(data):
        r = meas - pred
        for row, (label, off) in enumerate((("gyro − model [rad/s]", 0), ("acc − model [m/s²]", 3))):
            ax = axes[row, col]
            for j in range(3):
                ax.plot(t, r[:, off + j], ".", ms=2, color=COLOURS[j], label=f"{'xyz'[j]}" if col == 0 else None)
            ax.axhline(0, color="0.5", lw=0.6)
            if col == 0:
                ax.set_ylabel(label, fontsize=8)
            ax.tick_params(labelsize=7)
        axes[0, col].set_title(f"{name}", fontsize=9)
        axes[-1, col].set_xlabel("time since release [s]", fontsize=8)
    axes[0, 0].legend(fontsize=7, ncol=3)
    return fig


def _param_row(p: dict, name: str, label: str, scale: float = 1.0, unit: str = "") -> list:
    q = p[name]
    return [label, f"{fmt(q['q50'] * scale, 4)}", f"{fmt(q['q05'] * scale, 4)} … {fmt(q['q95'] * scale, 4)}", unit,
            fmt(q["r_hat"], 4), f"{q['ess_bulk']:.0f}"]


def period_label(name: str, throw: dict) -> str:
    """The row period's label in the logger table: the magnetometer's own estimate beside it and, when the
    rows were placed by the magnetometer, how far apart they came and how far from equally spaced.

    Parameters
    ----------
    name : str
        The throw.
    throw : dict
        Its ``summary.json`` → ``inertial_throws`` record (may be empty).
    """
    label = f"row period {name}"
    if throw.get("period_mag_gyro_s"):
        label += (f" (magnetometer vs gyro: {throw['period_mag_gyro_s'] * 1e3:.3f} ± "
                  f"{throw['period_mag_gyro_sd_s'] * 1e3:.3f} ms)")
    placed = throw.get("row_time_summary")
    if placed:
        label += (f"; rows placed by the magnetometer, {placed['shortest_step_s'] * 1e3:.1f}–"
                  f"{placed['longest_step_s'] * 1e3:.1f} ms apart, up to "
                  f"{placed['deviation_max_rows'] * placed['mean_period_s'] * 1e3:.0f} ms from equally spaced")
    return label


def inertial_section(ctx) -> Section | None:
    """Logger parameters, throws measured vs predicted, residuals, segmentation; None without inertial data."""
    from .content import _figure, flights_table
    ks = ctx.inertial_flights
    if not ks:
        return None
    p = ctx.summary["parameters"]
    data = []
    for k in ks:
        c, t, meas, pred = _predictions(ctx, k)
        data.append((ctx.problem.flights[k].name, t, meas, pred))
    figs = [_figure(ctx, _throw_figure(ctx, data), "inertial_throws",
                    "Each throw measured (dots) against the model at the highest-posterior draw (lines): the spin "
                    "(gyro z) decaying under the spin-down moment, the wobble (gyro x, y), the specific force "
                    "normal to the disc (acc z: lift and drag seen by the logger, low-pass filtered) and in its "
                    "plane (acc x, y: dominated by the centripetal acceleration of the off-centre sensor)."),
            _figure(ctx, _residual_figure(ctx, data, None), "inertial_residuals",
                    "Measured − model for the gyro and the accelerometer, sensor axes, per throw.")]
    wobble = (ctx.run.extras.get("diagnosis") or {}).get("wobble")
    if wobble:
        from .figures import wobble_figure
        window = next(iter(wobble.values()))
        figs.append(_figure(ctx, wobble_figure(wobble), "inertial_wobble",
                            "The wobble of each throw, from diagnosis.json: the transverse gyro rates g_x + i g_y fitted "
                            f"in sliding {window['window_s']:.2f} s windows by a nutation phasor turning at κ × spin in "
                            "the body, a space-fixed (precession) phasor and a part fixed in sensor axes. Top: κ of the "
                            "data (dots) and of the model (line), the torque-free rigid disc's (Ia − Id)/Id dashed, "
                            "and dotted over the late span the free nutation's κ_F where the late wobble is a beat of "
                            "it and a nutation locked to the spin; bottom: the three amplitudes. "
                            + " ".join(r["words"] for r in wobble.values())))
    rows = [_param_row(p, "imu_offset_x", "sensor position r_s, b1", 1e3, "mm"),
            _param_row(p, "imu_offset_y", "sensor position r_s, b2", 1e3, "mm"),
            _param_row(p, "imu_offset_z", "sensor position r_s, b3", 1e3, "mm"),
            _param_row(p, "imu_lpf_tau", "accelerometer filter τ", 1e3, "ms"),
            _param_row(p, "imu_tilt_1", "sensor tilt about b1", 180 / np.pi, "deg"),
            _param_row(p, "imu_tilt_2", "sensor tilt about b2", 180 / np.pi, "deg")]
    throws = ctx.summary.get("inertial_throws", {})
    for k in ks:
        name = ctx.problem.flights[k].name
        key = f"imu_period_{name}"
        if key in p:
            rows.append(_param_row(p, key, period_label(name, throws.get(name, {})), 1e3, "ms"))
    html = ("<p>The logger's parameters, shared by the run's throws (its position and filter) or per throw "
            "(the row period). The row period is estimated by the flight model; the magnetometer against the gyro "
            "gives an independent estimate (in brackets).</p>"
            + table(["parameter", "median", "90 % interval", "unit", "R-hat", "ESS"], rows, "num")
            + flights_table(ctx))
    seg_rows = [[name, v.get("status", ""), v.get("segment", {}).get("start_row", "—"),
                 v.get("segment", {}).get("end_row", "—"), v.get("rows", ""), v.get("reason", "")]
                for name, v in throws.items()]
    if seg_rows:
        html += ("<p class=note>How the throws were found in the logs (release: end of the spin-up; end: first "
                 "impact). A throw flown upside down is outside the right-side-up model and is not fitted.</p>"
                 + table(["throw", "status", "release row", "end row", "rows", "how"], seg_rows))
        repairs = sorted({r for v in throws.values() for r in v.get("repairs", [])})
        if repairs:
            html += ("<details><summary>Repairs made while reading the logs</summary><ul>"
                     + "".join(f"<li>{esc(r)}</li>" for r in repairs) + "</ul></details>")
    if ctx.config.credit:
        html += f"<p class=note>Data: {esc(ctx.config.credit)}</p>"
    return Section("inertial", "Inertial recordings",
                   "What the logger measured against what the model predicts, the logger's own parameters, and "
                   "how the throws were cut out of the logs.", html, figs)
