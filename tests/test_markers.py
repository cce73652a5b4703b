"""Marker files (docs/data-formats.md): round trip, and every rejection names file, line and problem."""
import numpy as np
import pytest

from bayes_disc.cli import main
from bayes_disc.observation.markers import (FlightObservation, MarkerFileError, flights_from_table,
                                            read_marker_csv, table_from_flights, write_marker_csv)

IDS = ("0", "1", "2")
GOOD = """flight,t,marker,x,y,z,sigma_m
f1,0.0,0,0.10,0.00,1.00,0.002
f1,0.0,1,-0.03,0.08,1.00,0.002
f1,0.0,2,-0.07,-0.08,1.00,0.002
f1,0.00833,0,0.21,0.00,1.01,0.002
f1,0.00833,2,nan,nan,nan,0.002
f1,0.01667,1,0.09,0.08,1.02,0.002
f1,0.01667,2,0.05,-0.08,1.02,0.002
f2,0.5,0,1.10,0.00,1.00,0.001
f2,0.5,1,0.97,0.08,1.00,0.001
f2,0.5,2,0.93,-0.08,1.00,0.001
"""


def _write(tmp_path, text, name="m.csv"):
    p = tmp_path / name
    p.write_text(text)
    return p


def test_read_arranges_flights_with_gaps(tmp_path):
    table = read_marker_csv(_write(tmp_path, GOOD), IDS)
    assert table.flights == ["f1", "f2"]
    f1, f2 = flights_from_table(table, IDS)
    assert f1.times.tolist() == [0.0, 0.00833, 0.01667]
    assert f1.observed.tolist() == [[True, True, True], [True, False, False], [False, True, True]]
    assert f1.sigma[0, 0] == pytest.approx(0.002)
    assert f2.n_points == 3


def test_write_read_round_trip(tmp_path, rng):
    pos = rng.normal(0, 1, (50, 3, 3)) * 0.1 + np.array([1.0, 0.0, 1.0])
    pos[rng.random((50, 3)) < 0.1] = np.nan
    obs = FlightObservation("a", "", np.arange(50) / 120.0, IDS, pos)
    p = tmp_path / "rt.csv"
    write_marker_csv(p, table_from_flights([obs]))
    (back,) = flights_from_table(read_marker_csv(p, IDS), IDS)
    np.testing.assert_array_equal(np.isnan(back.positions), np.isnan(pos[np.isfinite(pos).all(-1).any(-1)]))
    kept = np.isfinite(pos).all(-1).any(-1)
    np.testing.assert_allclose(back.positions, pos[kept], atol=1e-9, equal_nan=True)


BAD = {
    "unknown marker": (GOOD.replace("f1,0.0,1,", "f1,0.0,7,"), 3, "unknown marker '7'"),
    "time goes back": (GOOD.replace("f1,0.01667,1,", "f1,0.001,1,"), 7, "goes back"),
    "millimetres by magnitude": (GOOD.replace("f1,0.0,0,0.10,0.00,1.00", "f1,0.0,0,100.0,0.0,1000.1"), 2,
                                 "millimetres"),
    "millimetres by spacing": (GOOD.replace("f2,0.5,0,1.10,0.00,1.00", "f2,0.5,0,110.0,0.0,100.0")
                               .replace("f2,0.5,1,0.97,0.08,1.00", "f2,0.5,1,97.0,8.0,100.0")
                               .replace("f2,0.5,2,0.93,-0.08,1.00", "f2,0.5,2,93.0,-8.0,100.0"), 9, "millimetres"),
    "fewer than 3 markers": (GOOD.replace("f2,0.5,2,0.93,-0.08,1.00", "f2,0.5,2,nan,nan,nan"), 9,
                             "only 2 marker"),
    "NaN time": (GOOD.replace("f1,0.00833,0,", "f1,nan,0,"), 5, "time is NaN"),
    "not a number": (GOOD.replace("0.21,", "abc,"), 5, "not a number"),
    "partial NaN": (GOOD.replace("0.21,0.00,1.01", "0.21,nan,1.01"), 5, "not all coordinates"),
    "missing column": (GOOD.replace("flight,t,marker,x,y,z", "flight,t,marker,x,y,q"), 1, "lacks column"),
    "duplicate point": (GOOD.replace("f1,0.0,2,", "f1,0.0,1,"), 4, "repeats line"),
    "wrong field count": (GOOD.replace("f1,0.00833,0,0.21,0.00,1.01,0.002", "f1,0.00833,0,0.21,0.00"), 5,
                          "fields"),
}


@pytest.mark.parametrize("kind", sorted(BAD))
def test_rejections_name_file_line_and_problem(tmp_path, kind):
    text, line, words = BAD[kind]
    p = _write(tmp_path, text)
    with pytest.raises(MarkerFileError) as err:
        read_marker_csv(p, IDS)
    msg = str(err.value)
    assert msg.startswith(f"{p}:{line}:"), msg
    assert words in msg, msg


def test_missing_file_is_an_error(tmp_path):
    with pytest.raises(MarkerFileError, match="file not found"):
        read_marker_csv(tmp_path / "nope.csv", IDS)


def test_cli_bad_input_exits_nonzero_with_one_line(tmp_path, capsys):
    bad = tmp_path / "case.json"
    bad.write_text("{not json")
    assert main(["simulate", str(bad), "-o", str(tmp_path / "o.csv")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "case.json:1" in err
    assert not (tmp_path / "o.csv").exists()
