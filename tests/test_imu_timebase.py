"""Row period from magnetometer vs gyro, and the barometer cadence: synthetic and real logs."""

import numpy as np
import pytest

from bayes_disc.observation.imu import (InertialLog, baro_cadence, estimate_timebase, find_throws,
                                        period_from_mag_gyro, read_flatball_ins)
from bayes_disc.observation.imu.timebase import FLATBALL_BARO_SLEEP

from conftest import SHARED

DATA = SHARED / "data" / "flatball"
FILES = sorted(DATA.glob("*.csv")) if DATA.is_dir() else []
needs_data = pytest.mark.skipif(not FILES, reason="flatball data folder not available")


def _rotating_log(period, n=320, spin_sign=1, mag_clock=0.010, baro_period=0.1013, seed=11, drop_row=None):
    """Sensor spinning about z (decaying spin, wobble-free), world-fixed field seen in sensor axes.

    Rows every ``period`` s; the magnetometer samples on its own clock ``mag_clock`` (held, then
    averaged over its last two samples as the flatball firmware does); hard-iron offset; noise.
    """
    rng = np.random.default_rng(seed)
    t_row = period * np.arange(n)
    w = lambda t: spin_sign * 56.0 * np.exp(-t / 30.0)              # rad/s
    angle = lambda t: spin_sign * 56.0 * 30.0 * (1 - np.exp(-t / 30.0))
    t_mag = mag_clock * np.floor(t_row / mag_clock)                  # latest magnetometer sample
    field = lambda t: np.column_stack([22.0 * np.cos(-angle(t) + 0.4), 22.0 * np.sin(-angle(t) + 0.4)])
    xy = 0.5 * (field(t_mag) + field(t_mag - mag_clock)) + np.array([16.0, -1.0]) + rng.normal(0, 0.5, (n, 2))
    mag = np.column_stack([xy, np.full(n, 70.0)])
    gyro = np.column_stack([rng.normal(0, 0.3, n), rng.normal(0, 0.3, n), w(t_row) + rng.normal(0, 0.01, n)])
    k_baro = np.floor(t_row / baro_period + 0.37)
    pressure = 95000.0 + 0.7 * k_baro + 0.01 * k_baro ** 2
    rows = np.arange(n)
    keep = np.ones(n, bool)
    if drop_row is not None:
        keep[drop_row] = False
    return InertialLog(name="synth", source="", fmt="flatball-ins", rows=rows[keep], lines=rows[keep] + 2,
                       gyro=gyro[keep], acc=np.zeros((keep.sum(), 3)), mag=mag[keep], pressure=pressure[keep])


@pytest.mark.parametrize("period, sign", [(0.0122, 1), (0.0133, -1), (0.0100, 1)])
def test_synthetic_period_recovered(period, sign):
    log = _rotating_log(period, spin_sign=sign)
    est = period_from_mag_gyro(log, 5, 315)
    assert est.phase_sign == -1
    assert abs(est.period / period - 1) < 0.005
    assert est.sd > 0 and abs(est.period - period) < 4 * est.sd + 1e-4 * period


def test_synthetic_gap_in_rows_kept():
    log = _rotating_log(0.0122, drop_row=150)
    est = period_from_mag_gyro(log, 5, 315)
    assert abs(est.period / 0.0122 - 1) < 0.005


def test_synthetic_baro_cadence_and_agreement():
    period, baro = 0.0122, 0.1013
    log = _rotating_log(period, n=2000, baro_period=baro)
    cad = baro_cadence(log)
    assert cad.rows_per_update == pytest.approx(baro / period, rel=0.003)
    assert cad.period_lower_bound == pytest.approx(FLATBALL_BARO_SLEEP / cad.rows_per_update)
    tb = estimate_timebase(log, 5, 1995)
    assert tb.baro_task_period == pytest.approx(baro, rel=0.01)
    assert tb.consistent_with_bound


def test_too_short_or_not_spinning():
    log = _rotating_log(0.0122)
    with pytest.raises(ValueError, match="too short"):
        period_from_mag_gyro(log, 5, 20)
    log.gyro[:, 2] = 0.001
    with pytest.raises(ValueError, match="less than one revolution"):
        period_from_mag_gyro(log, 5, 315)


@needs_data
def test_real_files_periods_and_baro_agree():
    results = []
    for path in FILES:
        log = read_flatball_ins(path)
        (seg,) = find_throws(log)
        tb = estimate_timebase(log, seg.start + 5, seg.end, seg.name)
        est = tb.mag_gyro
        # a world-fixed field turns against the spin in sensor axes
        assert est.phase_sign == -1
        # the firmware sleeps 10 ms per logging step: the row period exceeds it
        assert est.period > 0.010 and est.sd < 0.01 * est.period
        assert tb.consistent_with_bound
        results.append((tb.baro_task_period, tb.baro_task_period_sd))
    # one firmware, one barometer task: its implied period agrees across the four files
    task = np.array([r[0] for r in results])
    sd = np.array([r[1] for r in results])
    mean = np.sum(task / sd ** 2) / np.sum(1 / sd ** 2)
    chi2 = float(np.sum(((task - mean) / sd) ** 2))
    assert chi2 < 11.3          # 99 % point of chi² with 3 degrees of freedom
    assert mean > FLATBALL_BARO_SLEEP
