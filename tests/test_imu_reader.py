"""Inertial log readers (docs/data-formats.md): the four real flatball-ins files, crafted defects, imu-csv."""
import math
from pathlib import Path

import numpy as np
import pytest

from bayes_disc.observation.imu import (G_STANDARD, ImuFileError, InertialLog, read_flatball_ins, read_imu,
                                        read_imu_csv, write_imu_csv)
from bayes_disc.observation.imu.formats import FLATBALL_COLUMNS

from conftest import SHARED

DATA = SHARED / "data" / "flatball"
FILES = sorted(DATA.glob("*.csv")) if DATA.is_dir() else []
needs_data = pytest.mark.skipif(not FILES, reason="flatball data folder not available")


def _raw_line_count(path):
    return sum(1 for ln in Path(path).read_text().split("\n") if ln)


@needs_data
@pytest.mark.parametrize("path", FILES, ids=lambda p: p.stem)
def test_real_file_shapes_units_and_rest(path):
    log = read_flatball_ins(path)
    n = len(log)
    assert log.name == path.stem and log.times is None and log.fmt == "flatball-ins"
    assert log.gyro.shape == (n, 3) and log.acc.shape == (n, 3) and log.mag.shape == (n, 3)
    assert log.pressure.shape == (n,) and log.rows.shape == (n,) and log.lines.shape == (n,)
    assert np.all(np.diff(log.rows) >= 1)
    # every data line is either a sample or named by a repair
    assert n + len([r for r in log.repairs if "dropped" in r]) >= _raw_line_count(path) - 2
    # at rest (|gyro| < 5 dps) the specific force is 1 g: acc converted from g to m/s²
    rest = np.linalg.norm(log.gyro, axis=1) < math.radians(5.0)
    assert rest.sum() > 100
    assert np.median(np.linalg.norm(log.acc[rest], axis=1)) == pytest.approx(G_STANDARD, rel=0.05)
    # gyro in rad/s: the spin peaks at thousands of dps, i.e. tens of rad/s, below full scale
    peak = np.abs(log.gyro[:, 2]).max()
    assert 40.0 < peak < math.radians(4000.0)
    # a few tens of µT of Earth field (plus hard iron), pressure in Pa near 950 hPa
    assert 20.0 < np.median(np.linalg.norm(log.mag, axis=1)) < 150.0
    assert 80e3 < np.median(log.pressure) < 110e3
    assert any(w.startswith("gyro:") for w in log.warnings)


@needs_data
def test_real_file_repairs_named():
    logs = {p.stem[-6:]: read_flatball_ins(p) for p in FILES}
    assert any("gx, gy, gz" in r for r in logs["001-rb"].repairs)
    assert any("stray spaces" in r and "' qx'" in r for r in logs["002-rb"].repairs)
    rf = logs["003-rf"].repairs
    assert any(r.startswith("line 1: header cut after 'fe-acc-z'") and "idx 2428" in r for r in rf)
    assert any(r.startswith("line 2: rest of the header") for r in rf)
    assert any("idx 2311 missing" in r for r in rf)
    assert any("duplicate of line" in r and "idx 2312" in r for r in rf)
    rows = logs["003-rf"].rows
    assert rows[0] == 0 and 2311 not in rows and np.sum(rows == 2312) == 1
    rh = logs["005-rh"]
    assert any("idx 1727 missing" in r for r in rh.repairs)
    assert any("32 fields" in r and "dropped" in r for r in rh.repairs)
    assert rh.rows[-1] == 1728 and 1727 not in rh.rows
    assert any("stale sample" in w for w in logs["002-rb"].warnings)


@needs_data
def test_ahrs_columns_not_returned():
    log = read_flatball_ins(FILES[1])
    fields = set(vars(log))
    for ahrs in ("roll", "pitch", "yaw", "qw", "fe-acc-x", "fl-acc-x"):
        assert ahrs not in fields and ahrs not in log.extra


HEADER = ",".join(FLATBALL_COLUMNS)


def _row(idx, gz=0.0, acc_z=1.0, mag=(20.0, 10.0, -30.0)):
    vals = {c: 0.0 for c in FLATBALL_COLUMNS}
    vals.update({"idx": idx, "patm-Pa": 95000.0 + idx, "acc-z": acc_z, "gyro-z": gz, "mag-x": mag[0] + idx * 0.01,
                 "mag-y": mag[1], "mag-z": mag[2], "ahrs_flgs": 48})
    return ",".join(str(int(vals[c])) if c in ("idx", "ahrs_flgs") else f"{vals[c]:.6f}" for c in FLATBALL_COLUMNS)


def _write(tmp_path, lines, name="2025-01-01-009-rb.csv"):
    p = tmp_path / name
    p.write_text("\n".join(lines) + "\n")
    return p


def test_clean_crafted_file_no_repairs(tmp_path):
    log = read_flatball_ins(_write(tmp_path, [HEADER] + [_row(i, gz=100.0) for i in range(5)]))
    assert log.repairs == []
    np.testing.assert_allclose(log.gyro[:, 2], math.radians(100.0))
    np.testing.assert_allclose(log.acc[:, 2], G_STANDARD)
    np.testing.assert_array_equal(log.lines, [2, 3, 4, 5, 6])


def test_crafted_glued_header(tmp_path):
    cut = HEADER.index("fe-acc-z") + len("fe-acc-z")
    first = HEADER[:cut] + _row(77)
    rest = "," + HEADER[cut + 1:]
    log = read_flatball_ins(_write(tmp_path, [first, rest] + [_row(i) for i in range(4)]))
    assert len(log) == 4 and log.rows.tolist() == [0, 1, 2, 3]
    assert any(r.startswith("line 1:") and "idx 77" in r for r in log.repairs)
    assert log.lines[0] == 3


def test_crafted_defects_each_reported(tmp_path):
    lines = [HEADER.replace("qx", " qx").replace("gyro-x", "gx").replace("gyro-y", "gy").replace("gyro-z", "gz")]
    lines += [_row(0), _row(1), _row(1), _row(3), _row(4) + ",9.9", _row(5)]
    log = read_flatball_ins(_write(tmp_path, lines))
    text = "\n".join(log.repairs)
    assert "stray spaces" in text and "gx, gy, gz" in text
    assert "line 4: duplicate of line 3 (idx 1)" in text
    assert "line 5: idx 2 missing" in text
    assert "line 6: 32 fields" in text
    assert log.rows.tolist() == [0, 1, 3, 5]


@pytest.mark.parametrize("mutate, line, words", [
    (lambda L: L[:2] + [_row(1, gz=5.0)] + L[2:], 4, "different content"),
    (lambda L: L[:3] + [_row(0)] + L[3:], 4, "goes backwards"),
    (lambda L: L[:2] + [_row(1).replace("95001.000000", "abc")] + L[3:], 3, "not a number"),
    (lambda L: L[:2] + [_row(1).replace("95001.000000", "nan")] + L[3:], 3, "not a finite number"),
    (lambda L: [L[0].replace("mag-z", "mag-w")] + L[1:], 1, "unknown column"),
    (lambda L: [L[0].replace("fe-acc-z", "fe-acc-z2428")] + L[1:], 2, "continuation"),
])
def test_crafted_unrepairable(tmp_path, mutate, line, words):
    lines = mutate([HEADER] + [_row(i) for i in range(4)])
    p = _write(tmp_path, lines)
    with pytest.raises(ImuFileError) as err:
        read_flatball_ins(p)
    assert err.value.line == line and words in str(err.value) and str(p) in str(err.value)
    assert isinstance(err.value, ValueError)


def test_saturation_reported(tmp_path):
    log = read_flatball_ins(_write(tmp_path, [HEADER] + [_row(i, gz=3990.0 if i == 2 else 10.0) for i in range(4)]))
    sat = [w for w in log.warnings if w.startswith("gyro:")]
    assert len(sat) == 1 and "1 sample(s) within 1%" in sat[0] and "rows 2 (line 4)" in sat[0]
    clear = read_flatball_ins(_write(tmp_path, [HEADER] + [_row(i, gz=3950.0) for i in range(4)], "b.csv"))
    assert "no sample within 1%" in [w for w in clear.warnings if w.startswith("gyro:")][0]


# ------------------------------------------------------------------------------------------ imu-csv

def _synthetic_logs(rng):
    logs = []
    for name, n in (("a", 50), ("b", 30)):
        t = 0.3 + np.cumsum(rng.uniform(0.009, 0.011, n))
        logs.append(InertialLog(name=name, source="", fmt="imu-csv", rows=np.arange(n), lines=np.arange(n),
                                gyro=rng.normal(0, 30, (n, 3)), acc=rng.normal(0, 40, (n, 3)), times=t,
                                extra={"mx": rng.normal(0, 20, n)}))
    return logs


def test_imu_csv_round_trip(tmp_path):
    logs = _synthetic_logs(np.random.default_rng(5))
    p = write_imu_csv(tmp_path / "imu.csv", logs)
    back = read_imu(p, "imu-csv")
    assert [lg.name for lg in back] == ["a", "b"]
    for orig, got in zip(logs, back):
        np.testing.assert_array_equal(got.times, orig.times)
        np.testing.assert_array_equal(got.gyro, orig.gyro)
        np.testing.assert_array_equal(got.acc, orig.acc)
        np.testing.assert_array_equal(got.extra["mx"], orig.extra["mx"])
        assert got.mag is None and got.pressure is None


def test_imu_csv_several_flights_interleaved(tmp_path):
    p = tmp_path / "x.csv"
    p.write_text("flight,t,gx,gy,gz,ax,ay,az\nA,0,1,2,3,4,5,6\nB,0,1,2,3,4,5,6\nA,0.01,1,2,3,4,5,6\n")
    a, b = read_imu_csv(p)
    assert a.lines.tolist() == [2, 4] and b.lines.tolist() == [3]


@pytest.mark.parametrize("body, line, words", [
    ("A,0.1,1,2,3,4,5,6\nA,0.1,1,2,3,4,5,6\n", 3, "does not increase"),
    ("A,0.1,1,2,3,4,5,6\nA,0.05,1,2,3,4,5,6\n", 3, "does not increase"),
    ("A,nan,1,2,3,4,5,6\n", 2, "time is NaN"),
    ("A,0.1,1,2,3,4,5\n", 2, "7 fields"),
    ("A,0.1,1,nan,3,4,5,6\n", 2, "some but not all"),
    ("A,0.1,1,2,x,4,5,6\n", 2, "'gz'"),
    (",0.1,1,2,3,4,5,6\n", 2, "empty flight name"),
])
def test_imu_csv_rejects(tmp_path, body, line, words):
    p = tmp_path / "bad.csv"
    p.write_text("flight,t,gx,gy,gz,ax,ay,az\n" + body)
    with pytest.raises(ImuFileError) as err:
        read_imu_csv(p)
    assert err.value.line == line and words in str(err.value)


def test_imu_csv_header_and_format_errors(tmp_path):
    p = tmp_path / "h.csv"
    p.write_text("flight,t,gx,gy,gz,ax,ay\nA,0,1,2,3,4,5\n")
    with pytest.raises(ImuFileError, match="lacks column"):
        read_imu_csv(p)
    with pytest.raises(ValueError, match="unknown IMU format"):
        read_imu(p, "flatball")
