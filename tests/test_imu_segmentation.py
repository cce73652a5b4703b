"""Throw segmentation: release, first impact, orientation (real flatball logs and a synthetic log)."""
import math

import numpy as np
import pytest

from bayes_disc.observation.imu import (G_STANDARD, InertialLog, SegmentationSettings, find_throws, flight_names,
                                        read_flatball_ins, throw_logs)

from conftest import SHARED

DATA = SHARED / "data" / "flatball"
FILES = sorted(DATA.glob("*.csv")) if DATA.is_dir() else []
needs_data = pytest.mark.skipif(not FILES, reason="flatball data folder not available")


def _file(tag):
    return next(p for p in FILES if p.stem.endswith(tag))


@needs_data
def test_002_rb_matches_readme_and_free_flight_is_smooth():
    log = read_flatball_ins(_file("002-rb"))
    (seg,) = find_throws(log)
    assert seg.name == log.name
    # README: |gyro| rises above 1000 dps at row ~1003 and falls back at row ~1362
    assert abs(seg.spin_start - 1003) <= 2 and abs(seg.spin_end - 1362) <= 2
    # release at the end of the spin-up: within a few rows of 1003, at >= 99 % of the peak spin
    assert seg.spin_start <= seg.start <= seg.spin_start + 8
    a, b = log.position(seg.start), log.position(seg.end)
    spin = np.abs(log.gyro[:, 2])
    assert spin[a] >= 0.99 * spin[a:b].max()
    assert spin[a - 1] < 0.99 * spin[a:b].max()
    # free flight: the spin decays slowly, never jumps by more than the threshold; at `end` it does
    d = np.diff(spin[a + 6:b])
    assert np.all(np.abs(d) < seg.criteria["impact_threshold"] + abs(seg.criteria["typical_spin_change_per_row"]))
    assert np.mean(d) < 0
    assert abs(spin[b] - spin[b - 1]) > seg.criteria["impact_threshold"]
    # the impact comes before the spin falls under 1000 dps, and the flight covers most of the span
    assert seg.start < seg.end <= seg.spin_end and seg.n_rows > 0.8 * (seg.spin_end - seg.spin_start)
    # README: acc-z stays near -0.85 g in flight; right side up
    assert seg.orientation == "right_side_up"
    assert seg.criteria["acc_z_median_g"] == pytest.approx(-0.85, abs=0.05)


@needs_data
@pytest.mark.parametrize("path", FILES, ids=lambda p: p.stem)
def test_each_real_file_one_throw(path):
    log = read_flatball_ins(path)
    segs = find_throws(log)
    assert len(segs) == 1
    seg = segs[0]
    assert seg.criteria["impact_found"] and 150 < seg.n_rows < 500
    expected = "upside_down" if path.stem.endswith("rh") else "right_side_up"
    assert seg.orientation == expected
    # backhand spins with +gyro-z (r > 0, docs/conventions.md, sensor z like b3), forehand and hammer the other way
    assert np.sign(seg.criteria["spin_median"]) == (1 if path.stem.endswith("rb") else -1)
    (sub,) = throw_logs(log, segs)
    assert sub.rows[0] == seg.start and sub.rows[-1] == seg.end - 1


def _synthetic(throws, n=1500, seed=3):
    """Rest, then per throw (release, impact, spin sign, acc_z sign): spin-up, smooth decay, impact."""
    rng = np.random.default_rng(seed)
    gyro = rng.normal(0, 0.01, (n, 3))
    acc = np.tile([0.0, 0.0, G_STANDARD], (n, 1)) + rng.normal(0, 0.05, (n, 3))
    for rel, imp, sign, up in throws:
        w0 = math.radians(3200.0)
        gyro[rel - 6:rel, 2] = sign * np.linspace(0.1, 0.85, 6) * w0          # arm spin-up
        k = np.arange(imp - rel)
        gyro[rel:imp, 2] = sign * w0 * (1 - 3e-4 * k) + rng.normal(0, 0.003, k.size)
        gyro[rel:imp, 0] = 1.5 * np.sin(0.7 * k)                               # wobble
        gyro[imp:imp + 20, 2] = sign * w0 * np.linspace(0.6, 0.0, 20)          # impact, stop
        acc[rel:imp, 2] = up * 0.85 * G_STANDARD
        acc[rel:imp, 0] = -6.0 * G_STANDARD
    rows = np.arange(n)
    return InertialLog(name="synth", source="", fmt="flatball-ins", rows=rows, lines=rows + 2, gyro=gyro, acc=acc)


def test_synthetic_two_throws_named_and_located():
    log = _synthetic([(200, 520, 1, -1), (900, 1180, -1, 1)])
    segs = find_throws(log)
    assert [s.name for s in segs] == ["synth", "synth_2"] == flight_names("synth", 2)
    assert [(s.start, s.end) for s in segs] == [(200, 520), (900, 1180)]
    assert [s.orientation for s in segs] == ["right_side_up", "upside_down"]


def test_override_and_undetermined_orientation():
    log = _synthetic([(300, 600, 1, -1)])
    (seg,) = find_throws(log, override=[(310, 590)])
    assert (seg.start, seg.end) == (310, 590) and seg.reason.startswith("override")
    log.acc[300:600, 2] = 0.01 * G_STANDARD
    (seg,) = find_throws(log)
    assert seg.orientation == "undetermined"
    with pytest.raises(ValueError, match="before end"):
        find_throws(log, override=[(500, 400)])
    with pytest.raises(KeyError):
        find_throws(log, override=[(300, 99999)])


def test_no_throw_and_bad_settings():
    log = _synthetic([])
    assert find_throws(log) == []
    with pytest.raises(ValueError, match="release_fraction"):
        SegmentationSettings(release_fraction=0.7)
    with pytest.raises(ValueError, match="spin_threshold"):
        SegmentationSettings(spin_threshold=-1.0)
