"""`synth` with an inertial logger: flatball-ins and imu-csv logs that read back to the synthesizer's
readings, throws found at the true release row, per-flight overrides, and configuration errors."""
import json
from dataclasses import replace

import numpy as np
import pytest

from bayes_disc.cli import main
from bayes_disc.observation.config_io import ConfigError
from bayes_disc.observation.imu import find_throws, read_flatball_ins, read_imu_csv
from bayes_disc.observation.inertial_synth import LoggerSpec, logger_readings, rest_readings
from bayes_disc.observation.synth_config import load_synth_spec
from bayes_disc.observation.synth import synthesize

SYNTH = """
name: mix
seed: 3
output: {{markers: flights.csv, truth: truth.json}}
imu:
  offset: [0.02, 0.005, -0.01]
  lpf_tau: 0.12
  tilt: [0.01, -0.02]
  period: 0.0122
  gyro_noise: {gyro}
  acc_noise: {acc}
  acc_bias: [0.1, -0.2, 0.05]
  format: {fmt}
  output: {out}
  first_row: 37
flights:
  - {{name: a, speed: 13.0, launch_angle_deg: 5, alpha_deg: 8, spin: 55, roll_deg: 3, p: 2, q: -3, duration: 1.2}}
  - {{name: b, speed: 11.0, launch_angle_deg: 10, alpha_deg: 20, spin: 50, duration: 1.0,
      imu: {{period: 0.0118, gyro_bias: [0.01, 0.0, -0.02]}}}}
  - {{name: c, speed: 12.0, alpha_deg: 5, spin: 50, duration: 0.6, imu: false}}
"""


def _write(folder, gyro="[0.0, 0.0]", acc="[0.0, 0.0]", fmt="flatball-ins", out="logs"):
    p = folder / "synth.yaml"
    p.write_text(SYNTH.format(gyro=gyro, acc=acc, fmt=fmt, out=out))
    return p


def _throw_spec(spec, name):
    return spec.imu.flights[name]


def test_noise_free_flatball_logs_read_back_to_the_synthesizer_and_the_throw_is_found(tmp_path):
    path = _write(tmp_path)
    assert main(["synth", str(path)]) == 0
    spec, _, _ = load_synth_spec(path)
    truth = json.loads((tmp_path / "truth.json").read_text())
    assert sorted(truth["imu"]["throws"]) == ["a", "b"]                      # c: imu: false
    assert not (tmp_path / "logs" / "c.csv").exists()
    for f in spec.flights[:2]:
        t = truth["imu"]["throws"][f.name]
        log = read_flatball_ins(tmp_path / t["file"])
        assert log.repairs == [] and log.name == f.name
        assert log.rows[0] == 37
        (seg,) = find_throws(log)
        assert abs(seg.start - t["release_row"]) <= 2 and abs(seg.end - t["end_row"]) <= 2, (seg, t)
        assert seg.orientation == "right_side_up"
        lspec = _throw_spec(spec, f.name)
        assert t["period_s"] == lspec.period
        y0 = np.array(truth["flights"][f.name]["initial_state"]["position_m"]
                      + truth["flights"][f.name]["initial_state"]["velocity_m_s"]
                      + truth["flights"][f.name]["initial_state"]["quaternion_wxyz_body_to_world"]
                      + truth["flights"][f.name]["initial_state"]["omega_body_rad_s"])
        n = t["end_row"] - t["release_row"]
        gyro, acc, mag, states = logger_readings(y0, spec.coefficients, n, lspec, spec.disc, spec.env)
        a = log.position(t["release_row"])
        fly = slice(a, a + n)
        np.testing.assert_allclose(log.gyro[fly], gyro, rtol=0, atol=1e-9)
        np.testing.assert_allclose(log.acc[fly], acc, rtol=0, atol=1e-9)
        np.testing.assert_allclose(log.mag[fly], mag, rtol=0, atol=1e-9)
        np.testing.assert_allclose(acc[0] - lspec.acc_bias, t["lpf_state_m_s2"], atol=1e-9)
        # still before release: gyro = bias, accelerometer = gravity's specific force at the release attitude
        g0, a0, _ = rest_readings(states[0, 6:10], lspec, spec.env.g)
        np.testing.assert_allclose(log.gyro[:a], np.tile(g0, (a, 1)), atol=1e-9)
        np.testing.assert_allclose(log.acc[:a], np.tile(a0, (a, 1)), atol=1e-9)
        assert a * lspec.period == pytest.approx(1.0, abs=lspec.period)
        assert np.linalg.norm(a0 - np.asarray(lspec.acc_bias)) == pytest.approx(spec.env.g)
        # still after the end: spin gone
        assert np.all(np.abs(log.gyro[a + n:]) < 1e-9 + np.abs(lspec.gyro_bias))
        assert (len(log) - a - n) * lspec.period == pytest.approx(0.3, abs=lspec.period)


def test_noise_levels_and_per_flight_overrides(tmp_path):
    spec, _, _ = load_synth_spec(_write(tmp_path, gyro="[0.005, 0.05]", acc="[0.05, 0.1]"))
    noisy = synthesize(spec)
    clean = synthesize(replace(spec, imu=replace(spec.imu, flights={
        k: replace(v, gyro_noise=(0.0, 0.0), acc_noise=(0.0, 0.0)) for k, v in spec.imu.flights.items()})))
    dg = np.vstack([a.gyro - b.gyro for a, b in zip(noisy.imu_logs, clean.imu_logs)])
    da = np.vstack([a.acc - b.acc for a, b in zip(noisy.imu_logs, clean.imu_logs)])
    assert dg[:, 2].std() == pytest.approx(0.005, rel=0.1) and dg[:, :2].std() == pytest.approx(0.05, rel=0.1)
    assert da[:, 2].std() == pytest.approx(0.05, rel=0.1) and da[:, :2].std() == pytest.approx(0.1, rel=0.1)
    assert _throw_spec(spec, "b").period == 0.0118 and _throw_spec(spec, "a").period == 0.0122
    assert _throw_spec(spec, "b").gyro_bias == (0.01, 0.0, -0.02)
    assert _throw_spec(spec, "b").offset == (0.02, 0.005, -0.01)             # shared values stay the logger's
    # adding a logger leaves the marker data of the same seed unchanged
    bare = synthesize(replace(spec, imu=None))
    for f, g in zip(noisy.flights, bare.flights):
        np.testing.assert_array_equal(f.positions, g.positions)
    assert "imu" not in bare.truth and not bare.imu_logs


def test_imu_csv_logs_hold_the_free_flight_from_release(tmp_path):
    path = _write(tmp_path, fmt="imu-csv", out="imu.csv")
    assert main(["synth", str(path)]) == 0
    spec, _, _ = load_synth_spec(path)
    logs = {lg.name: lg for lg in read_imu_csv(tmp_path / "imu.csv")}
    assert sorted(logs) == ["a", "b"]
    res = synthesize(spec)
    markers = {f.name: f for f in res.flights}
    for name, lg in logs.items():
        lspec = _throw_spec(spec, name)
        np.testing.assert_allclose(lg.times, np.arange(len(lg)) * lspec.period, rtol=0, atol=1e-12)
        assert lg.times[0] == markers[name].times[0] == 0.0                   # both start at release
        y0 = res.truth["flights"][name]["initial_state"]
        y0 = np.r_[y0["position_m"], y0["velocity_m_s"], y0["quaternion_wxyz_body_to_world"], y0["omega_body_rad_s"]]
        gyro, acc, _, _ = logger_readings(y0, spec.coefficients, len(lg), lspec)
        np.testing.assert_allclose(lg.gyro, gyro, atol=1e-12)
        np.testing.assert_allclose(lg.acc, acc, atol=1e-12)


BAD = {
    "imu.lpf_tau": ("lpf_tau: 0.12", "lpf_tau: -0.1"),
    "imu.perod": ("period: 0.0122", "perod: 0.0122"),
    "imu.format": ("format: flatball-ins", "format: csv"),
    "imu.gyro_noise": ("gyro_noise: [0.0, 0.0]", "gyro_noise: [0.0, -1.0]"),
    "flights[1].imu.offset": ("imu: {period: 0.0118,", "imu: {offset: [0, 0, 0], period: 0.0118,"),
}


@pytest.mark.parametrize("key", sorted(BAD))
def test_bad_imu_block_names_the_key(tmp_path, key):
    old, new = BAD[key]
    text = SYNTH.format(gyro="[0.0, 0.0]", acc="[0.0, 0.0]", fmt="flatball-ins", out="logs")
    assert old in text
    p = tmp_path / "s.yaml"
    p.write_text(text.replace(old, new, 1))
    with pytest.raises(ConfigError) as e:
        load_synth_spec(p)
    assert f"key '{key}'" in str(e.value), str(e.value)


def test_flight_imu_without_logger_and_gust_with_logger_are_errors(tmp_path):
    text = SYNTH.format(gyro="[0.0, 0.0]", acc="[0.0, 0.0]", fmt="flatball-ins", out="logs")
    start, end = text.index("imu:\n"), text.index("flights:")
    p = tmp_path / "s.yaml"
    p.write_text(text[:start] + text[end:])
    with pytest.raises(ConfigError) as e:
        load_synth_spec(p)
    assert "key 'flights[1].imu'" in str(e.value)
    p.write_text(text.replace("duration: 1.2}", "duration: 1.2, gust: {t_start: 0.2, t_end: 0.4, wind: [1, 0, 0]}}"))
    with pytest.raises(ConfigError) as e:
        load_synth_spec(p)
    assert "key 'flights[0].gust'" in str(e.value)


def test_rest_readings_point_gravity_along_the_tilted_sensor_axes():
    spec = LoggerSpec(tilt=(0.0, 0.0), acc_bias=(0.0, 0.0, 0.0), gyro_bias=(0.0, 0.0, 0.0))
    level = np.array([0.0, 1.0, 0.0, 0.0])              # b1 along x, b3 down: the level right-side-up disc
    g, a, m = rest_readings(level, spec, 9.8)
    np.testing.assert_allclose(g, 0.0)
    np.testing.assert_allclose(a, [0.0, 0.0, -9.8], atol=1e-12)   # specific force points up = −b3
    np.testing.assert_allclose(m, [20.0, 0.0, 40.0], atol=1e-12)


@pytest.mark.slow
def test_mixed_data_tighten_the_rate_coefficients(tmp_path):
    """benchmarks/bench_mixed.py: three throws seen by markers (120 Hz, 1.5 mm) and a logger (0.005/0.05 rad/s,
    0.05 m/s²). Laplace sds at the least-squares optimum: markers and logger together are at least as tight
    as markers alone for every rate coefficient, each fit lies within 4 sd of the truth, and the logger's
    mount (r_s, τ) and each throw's row period are recovered from the logs alone."""
    import sys
    from conftest import REPO
    sys.path.insert(0, str(REPO / "benchmarks"))
    from bench_mixed import RATE_COEFFICIENTS, mixed_study, table
    r = mixed_study(tmp_path, max_nfev=40)
    print(table(r))
    for n in RATE_COEFFICIENTS:
        assert r["ratios"][n] <= 1.0, (n, r["ratios"])
    for kind, f in r["fits"].items():
        z = {n: (f["value"][n] - r["truth"][n]) / f["sd"][n] for n in f["value"]}
        assert all(abs(v) < 4 for v in z.values()), (kind, z)
    logger = r["fits"]["imu"]["logger"]
    assert set(logger) == set(r["logger_truth"])                     # r_s, τ and the three row periods
    for n, v in logger.items():
        assert abs(v["value"] - r["logger_truth"][n]) < 4 * v["sd"], (n, v)
