"""Physical plausibility before fitting (bayes_disc.observation.plausibility) and the absurd-RMS stop
after least squares (bayes_disc.inference.fitting.fit_checks): good data pass, each kind of nonsense is named."""
import dataclasses
from pathlib import Path

import numpy as np
import pytest
import yaml

from bayes_disc.cli import main
from bayes_disc.inference.model.config import load_config
from bayes_disc.inference.model.data import build_problem
from bayes_disc.inference.fitting.fit_checks import MAX_PLAUSIBLE_RMS_M
from bayes_disc.inference.model.initial import initial_state_from_data
from bayes_disc.inference.fitting.leastsq import fit_least_squares
from bayes_disc.inference.model.problem import Problem
from bayes_disc.observation.markers import (MarkerFileError, load_flights, read_marker_csv, table_from_flights,
                                            write_marker_csv)
from bayes_disc.observation.plausibility import (ImplausibleDataError, check_flight, check_flights,
                                                 frame_poses, window_kinematics)
from bayes_disc.observation.synth import DEFAULT_MARKERS, LaunchSpec, SynthSpec, synthesize
from bayes_disc.physics import Disc, Environment

REPO = Path(__file__).resolve().parents[1]
DEMO = REPO / "runs" / "demo"
IDS = tuple(DEFAULT_MARKERS)
MB = np.array(list(DEFAULT_MARKERS.values()))
G = Environment().g


def demo_flights():
    return load_flights(DEMO / "flights.csv", IDS)


def y_up(obs):
    """The flight as a y-up motion-capture tool exports it: (x, y, z) → (x, z, −y)."""
    p = obs.positions
    return dataclasses.replace(obs, positions=np.stack([p[..., 0], p[..., 2], -p[..., 1]], axis=-1))


@pytest.fixture(scope="module")
def synthetic():
    """High-α, slow, fast-and-rolled, wobbling and short throws; clean and with wind or a side force."""
    launches = (LaunchSpec("high", speed=8, launch_angle_deg=15, pitch_deg=50, spin=40, duration=0.8),
                LaunchSpec("very_high", speed=7, launch_angle_deg=25, alpha_deg=60, spin=-40, duration=0.7),
                LaunchSpec("fast", speed=30, launch_angle_deg=5, alpha_deg=5, spin=90, roll_deg=20, duration=1.2),
                LaunchSpec("slow", speed=5, launch_angle_deg=30, alpha_deg=20, spin=30, duration=0.6),
                LaunchSpec("short", speed=12, alpha_deg=5, duration=0.25),
                LaunchSpec("wobble", speed=12, alpha_deg=5, p=8, q=8, duration=1.0))
    out = []
    for seed, physics in ((4, {}), (1, {"wind": {"wind_x": -3.0, "wind_y": 3.0}}), (3, {"side_force": {"CY": 0.05}})):
        noisy = tuple(dataclasses.replace(f, noise_mm=3.0, dropout=0.05) for f in launches)
        out += synthesize(SynthSpec(name="s", flights=noisy, physics=physics, seed=seed)).flights
    return out


# -- good data pass ----------------------------------------------------------------------------------------

@pytest.mark.parametrize("run", ["demo", "concealed"])
def test_committed_runs_pass(run):
    check_flights(load_flights(REPO / "runs" / run / "flights.csv", IDS), MB, G)


def test_synthetic_flights_pass_including_high_alpha_wind_and_side_force(synthetic):
    check_flights(synthetic, MB, G)


def test_markers_a_few_mm_off_their_layout_pass():
    """Markers glued 3 mm off their nominal spots are for the marker_geometry explanation, not an error."""
    true = dict(DEFAULT_MARKERS, **{"1": [DEFAULT_MARKERS["1"][0] + 0.003, DEFAULT_MARKERS["1"][1] - 0.002, -0.015]})
    data = synthesize(SynthSpec(name="g", markers=true, seed=2,
                                flights=(LaunchSpec("a", speed=13, alpha_deg=6, noise_mm=1.5),)))
    check_flights(data.flights, MB, G)


# -- y-up export ---------------------------------------------------------------------------------------

def test_y_up_export_is_named_with_the_fix():
    for obs in demo_flights():
        with pytest.raises(ImplausibleDataError) as err:
            check_flight(y_up(obs), MB, G)
        msg = str(err.value)
        assert f"flight {obs.name!r}" in msg and "y-up export" in msg and "along -y" in msg, msg
        assert "swap the y and z columns" in msg, msg


def test_y_up_synthetic_flights_fail(synthetic):
    for obs in synthetic:
        with pytest.raises(ImplausibleDataError, match="do not fit gravity along −z"):
            check_flight(y_up(obs), MB, G)


def test_y_up_vertical_acceleration_alone_would_not_tell():
    """Why the check does not test a_z ≈ −g: in a good fast throw the lift exceeds the weight."""
    obs = next(f for f in demo_flights() if f.name == "fffl10")
    kin = window_kinematics(frame_poses(obs, MB))
    assert kin.a[:, 2].max() > 0.3 * G


# -- time units, speed, samples ---------------------------------------------------------------------------

def test_time_in_milliseconds_is_named():
    obs = demo_flights()[0]
    with pytest.raises(ImplausibleDataError, match="time looks like milliseconds") as err:
        check_flight(dataclasses.replace(obs, times=obs.times * 1e3), MB, G)
    assert str(err.value).startswith(f"{DEMO / 'flights.csv'}:{obs.line}: flight {obs.name!r}")


def test_time_in_microseconds_is_named():
    obs = demo_flights()[0]
    with pytest.raises(ImplausibleDataError, match="microseconds"):
        check_flight(dataclasses.replace(obs, times=obs.times * 1e6), MB, G)


def test_impossible_speed_is_named():
    """Time ten times too small: the interval (0.8 ms) is possible, the speed (90–150 m/s) is not."""
    obs = demo_flights()[1]
    with pytest.raises(ImplausibleDataError, match=r"moves at up to .* m/s"):
        check_flight(dataclasses.replace(obs, times=obs.times / 10), MB, G)


# -- marker layout ---------------------------------------------------------------------------------------

def test_swapped_marker_ids_are_named():
    obs = demo_flights()[0]
    swapped = MB[[2, 1, 0]]
    with pytest.raises(ImplausibleDataError) as err:
        check_flight(obs, swapped, G)
    msg = str(err.value)
    assert "mm apart in the data" in msg and "configured layout" in msg, msg
    assert "'0'" in msg or "'2'" in msg, msg


def test_layout_in_other_units_is_named():
    obs = demo_flights()[0]
    with pytest.raises(ImplausibleDataError, match="0.1× those of the configured layout"):
        check_flight(obs, MB * 10, G)


# -- through build_problem and the command line -----------------------------------------------------------

def _write_run(folder: Path, flights, markers=None) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    write_marker_csv(folder / "flights.csv", table_from_flights(flights))
    cfg = dict(name="t", flights=[dict(file="flights.csv")], markers=markers or DEFAULT_MARKERS, output="out")
    (folder / "config.yaml").write_text(yaml.safe_dump(cfg))
    return folder / "config.yaml"


def test_build_problem_stops_y_up_data_naming_file_and_line(tmp_path):
    cfg = load_config(_write_run(tmp_path, [y_up(f) for f in demo_flights()[:2]]))
    with pytest.raises(ImplausibleDataError) as err:
        build_problem(cfg)
    assert str(err.value).startswith(f"{tmp_path / 'flights.csv'}:2: flight 'bsfl5'"), err.value


def test_cli_exits_2_with_one_line_for_milliseconds(tmp_path, capsys):
    ms = [dataclasses.replace(f, times=f.times * 1e3) for f in demo_flights()[:1]]
    cfg = _write_run(tmp_path, ms)
    assert main(["identifiability", str(cfg), "--no-design"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "milliseconds" in err and "flights.csv:2" in err, err


def test_one_sample_flight_is_blamed_on_its_csv_line(tmp_path):
    text = (DEMO / "flights.csv").read_text().splitlines()
    lone = [text[0]] + [r.replace("bsfl5,", "lone,", 1) for r in text[1:4]] + text[4:400]
    p = tmp_path / "flights.csv"
    p.write_text("\n".join(lone) + "\n")
    (tmp_path / "config.yaml").write_text(yaml.safe_dump(
        dict(name="t", flights=[dict(file="flights.csv")], markers=DEFAULT_MARKERS)))
    table = read_marker_csv(p, IDS)  # the file itself is well-formed
    assert table.flights[0] == "lone"
    with pytest.raises(MarkerFileError) as err:
        build_problem(load_config(tmp_path / "config.yaml"))
    assert str(err.value).startswith(f"{p}:2: flight 'lone': has only 1 sample"), err.value


# -- absurd RMS after least squares -----------------------------------------------------------------------

def test_absurd_rms_stops_after_least_squares():
    """The issue's case: a y-up export that reaches least squares (here by building the Problem by hand,
    past build_problem's checks) must stop with the flight and its RMS instead of going on to sampling."""
    obs = y_up(demo_flights()[2]).window(0.0, 0.5)
    start = initial_state_from_data(obs, MB)
    problem = Problem(flights=[obs], marker_body=MB, disc=Disc(), env=Environment(), prior_name="weak",
                      start_states=[start])
    problem.rates = [problem.flight_rate(start)]
    with pytest.raises(ImplausibleDataError) as err:
        fit_least_squares(problem, starts=1, max_nfev=30)
    msg = str(err.value)
    assert f"flight {obs.name!r}" in msg and "least-squares fit leaves a marker RMS" in msg, msg
    rms_mm = float(msg.split("marker RMS of ")[1].split(" mm")[0])
    assert rms_mm > MAX_PLAUSIBLE_RMS_M * 1e3
