"""Rows placed in time by the magnetometer's phase: a logger loop that now and then takes two or three ticks."""

import numpy as np
import pytest

from bayes_disc.inference.model.config import load_config
from bayes_disc.inference.model.inertial import load_run_throws
from bayes_disc.observation.config_io import ConfigError
from bayes_disc.observation.imu import InertialLog, row_offsets_from_magnetometer
from bayes_disc.observation.models.inertial import InertialMeasurements
from bayes_disc.physics import Environment
from bayes_disc.report.inertial import period_label

from conftest import SHARED

TICK = 0.010            # the logger loop's tick [s]
DATA = SHARED / "data" / "flatball"
needs_data = pytest.mark.skipif(not DATA.is_dir(), reason="flatball data folder not available")


def _spin(t, sign):
    """Spin rate [rad/s] and its integral [rad] at t [s]: 56 rad/s decaying over 30 s."""
    return sign * 56.0 * np.exp(-t / 30.0), sign * 56.0 * 30.0 * (1 - np.exp(-t / 30.0))


def _irregular_log(n=300, sign=1, seed=3, mag_clock=None, gap=None, stale=None, field_sign=-1):
    """A spinning sensor whose rows come after 1, 2 or 3 loop ticks (70 / 25 / 5 %).

    The field is world-fixed (it turns against the spin in sensor axes, ``field_sign`` −1); the magnetometer
    is read at the row's time, or, with ``mag_clock``, holds its latest sample on its own clock (averaged over
    two samples). ``gap``: a logger row missing (its index skipped, 60 ms between its neighbours);
    ``stale``: a row repeating the row before's magnetometer reading. Returns the log and the rows' true times [s].
    """
    rng = np.random.default_rng(seed)
    steps = rng.choice([1, 2, 3], size=n - 1, p=[0.7, 0.25, 0.05])
    if gap is not None:                 # the missing row's neighbours each took three ticks
        steps[gap - 1] = steps[gap] = 3
    ticks = np.cumsum(np.r_[0, steps])
    t = TICK * ticks
    w, angle = _spin(t, sign)
    if mag_clock is None:
        phase = field_sign * angle + 0.4
        xy = 22.0 * np.column_stack([np.cos(phase), np.sin(phase)])
    else:
        tm = mag_clock * np.floor(t / mag_clock)
        phases = [field_sign * _spin(s, sign)[1] + 0.4 for s in (tm, tm - mag_clock)]
        xy = sum(22.0 * np.column_stack([np.cos(p), np.sin(p)]) for p in phases) / 2
    xy = xy + np.array([16.0, -1.0]) + rng.normal(0.0, 0.1, (n, 2))
    mag = np.column_stack([xy, np.full(n, 70.0)])
    if stale is not None:
        mag[stale] = mag[stale - 1]
    gyro = np.column_stack([np.zeros(n), np.zeros(n), w + rng.normal(0.0, 0.01, n)])
    rows = np.arange(n)
    keep = np.ones(n, bool)
    if gap is not None:
        keep[gap] = False
    log = InertialLog(name="synth", source="", fmt="flatball-ins", rows=rows[keep], lines=rows[keep] + 2,
                      gyro=gyro[keep], acc=np.zeros((keep.sum(), 3)), mag=mag[keep], pressure=None)
    return log, t[keep]


@pytest.mark.parametrize("sign", [1, -1])
def test_irregular_rows_are_placed_where_they_were_logged(sign):
    log, t = _irregular_log(sign=sign)
    u, summary = row_offsets_from_magnetometer(log)
    period = t[-1] / (log.rows[-1] - log.rows[0])
    assert summary["mean_period_s"] == pytest.approx(period, rel=1e-3)
    assert np.max(np.abs(u * period - t)) < 1e-3                      # s; the field's noise only
    uniform = (log.rows - log.rows[0]) * period
    assert np.max(np.abs(uniform - t)) > 5 * TICK                        # equally spaced rows are far off
    assert summary["deviation_max_rows"] > 2.0
    assert summary["longest_step_s"] == pytest.approx(3 * TICK, abs=1e-3)
    assert summary["shortest_step_s"] == pytest.approx(TICK, abs=1e-3)
    assert summary["sample_period_s"] == pytest.approx(TICK, abs=2e-4)
    ticks = np.round(np.diff(t) / TICK).astype(int)
    assert summary["rows_by_samples"] == {str(k): int(np.sum(ticks == k)) for k in (1, 2, 3)}


def test_a_missing_row_whose_phase_wraps_is_unwrapped_by_the_mean_period():
    log, t = _irregular_log(gap=150)
    assert 55.0 * (t[150] - t[149]) > np.pi                             # the phase step wraps
    u, _ = row_offsets_from_magnetometer(log)
    period = t[-1] / (log.rows[-1] - log.rows[0])
    assert np.max(np.abs(u * period - t)) < 1e-3


def test_the_magnetometers_own_clock_leaves_at_most_one_of_its_samples():
    log, t = _irregular_log(mag_clock=0.0098)
    u, _ = row_offsets_from_magnetometer(log)
    period = t[-1] / (log.rows[-1] - log.rows[0])
    err = u * period - t
    assert np.max(np.abs(err - np.median(err))) < 0.0098 + 1e-3


def test_bad_magnetometers_are_refused():
    log, _ = _irregular_log(field_sign=1)
    with pytest.raises(ValueError, match="turns with the spin"):
        row_offsets_from_magnetometer(log)
    log, _ = _irregular_log(stale=120)
    with pytest.raises(ValueError, match="does not advance from line 121 to line 122"):
        row_offsets_from_magnetometer(log)
    log, _ = _irregular_log()
    log.mag = None
    with pytest.raises(ValueError, match="need a magnetometer"):
        row_offsets_from_magnetometer(log)


def test_the_inertial_model_samples_at_the_magnetometers_times():
    log, t = _irregular_log()
    period = t[-1] / (log.rows[-1] - log.rows[0])
    g = Environment().g
    placed = InertialMeasurements(log, g, period=period, row_times="magnetometer")
    uniform = InertialMeasurements(log, g, period=period)
    assert np.max(np.abs(placed.sample_times_for(np.array([period]))[0] - t)) < 1e-3
    assert np.array_equal(uniform.sample_times_for(np.array([period]))[0], (log.rows - log.rows[0]) * period)
    assert np.array_equal(placed.row_offsets, uniform.row_offsets)       # rows keep their logger numbers
    assert placed.times[-1] >= t[-1]                                    # the simulation grid reaches the last row
    assert placed.row_time_summary["deviation_max_rows"] > 2.0
    with pytest.raises(ValueError, match="row_times must be one of"):
        InertialMeasurements(log, g, period=period, row_times="gps")


def _config(tmp_path, entry: str):
    data = tmp_path / "log.csv"
    data.write_text("idx\n")
    path = tmp_path / "config.yaml"
    path.write_text(f"name: t\nimu:\n  - {{file: log.csv, {entry}}}\n")
    return path


def test_config_key(tmp_path):
    cfg = load_config(_config(tmp_path, "format: flatball-ins, row_times: magnetometer"))
    assert cfg.imu[0].row_times == "magnetometer"
    assert load_config(_config(tmp_path, "format: flatball-ins")).imu[0].row_times == "uniform"
    with pytest.raises(ConfigError, match="row_times"):
        load_config(_config(tmp_path, "format: flatball-ins, row_times: gps"))
    with pytest.raises(ConfigError, match="only for logs without time column"):
        load_config(_config(tmp_path, "format: imu-csv, row_times: magnetometer"))


@needs_data
def test_the_shipped_throws_have_rows_that_took_three_magnetometer_samples(tmp_path):
    path = tmp_path / "config.yaml"
    path.write_text("name: t\nimu:\n" + "".join(
        f"  - {{file: {DATA / f}, format: flatball-ins, row_times: magnetometer}}\n"
        for f in ("2025-08-31-001-rb.csv", "2025-08-31-002-rb.csv", "2025-08-31-003-rf.csv")))
    throws = load_run_throws(load_config(path))
    for t in throws:
        rec = t.to_dict()
        assert rec["row_times"] == "magnetometer"
        summary = rec["row_time_summary"]
        assert summary["mean_period_s"] == pytest.approx(rec["period_mag_gyro_s"], rel=0.01)
        assert summary["longest_step_s"] > 2.5 * summary["shortest_step_s"]     # a row longer than two samples
        assert summary["deviation_max_rows"] > 1.0


def test_the_report_says_where_the_rows_were_placed():
    log, t = _irregular_log()
    summary = row_offsets_from_magnetometer(log)[1]
    rec = {"period_mag_gyro_s": 0.01224, "period_mag_gyro_sd_s": 0.00009}
    assert period_label("001-rb", rec) == "row period 001-rb (magnetometer vs gyro: 12.240 ± 0.090 ms)"
    label = period_label("001-rb", {**rec, "row_times": "magnetometer", "row_time_summary": summary})
    largest = summary["deviation_max_rows"] * summary["mean_period_s"] * 1e3
    assert label.endswith(f"; rows placed by the magnetometer, {summary['shortest_step_s'] * 1e3:.1f}–"
                          f"{summary['longest_step_s'] * 1e3:.1f} ms apart, up to {largest:.0f} ms from equally spaced")
    assert period_label("x", {}) == "row period x"
