"""The barometer as a channel of the inertial unit (bayes_disc.observation.models.barometer): its readings are the
rows where the pressure changes, its prediction matches the synthetic logger's independent computation (height,
the port's share of the dynamic pressure, the sensor's lag, the relaxation on the ground after the flight), a
wrong release speed, port coefficient or lag shows in its residuals, it narrows the lift and the release's climb
that gyroscope and accelerometer leave loose, switched off the unit is the one without it exactly, and the shipped
logs carry readings in flight and on the ground."""
from dataclasses import replace

import numpy as np
import pytest

from bayes_disc.inference.fitting.covariance import covariance_at
from bayes_disc.inference.fitting.residuals import jacobian_blocks
from bayes_disc.inference.model.inertial import InertialThrow, inertial_model
from bayes_disc.inference.model.problem import Problem
from bayes_disc.observation.inertial_synth import PRESSURE_PA, LoggerSpec, recorded_throw
from bayes_disc.observation.models.barometer import outside_pressure, reading_rows, relax
from bayes_disc.observation.models.inertial import InertialMeasurements
from bayes_disc.observation.synth import LaunchSpec
from bayes_disc.physics import Disc, Environment, literature_coefficients

COEF = literature_coefficients("hummel2002")
ENV = Environment()
C_Q = 0.2
SPEC = LoggerSpec(baro_dynamic=C_Q, baro_noise=0.02)
LAUNCH = LaunchSpec(name="a", speed=14.0, launch_angle_deg=8, alpha_deg=6, spin=55, roll_deg=5, duration=1.6)


def _throw(spec=SPEC, seed=4, duration=LAUNCH.duration):
    """The free flight of a recorded throw (release row to end row), the rows after it and the recording."""
    rec = recorded_throw("a", LAUNCH.initial_state(), COEF, duration, spec, np.random.default_rng(seed),
                         rest_before=0.3, rest_after=1.0)
    n = len(rec.log.rows)
    return (rec.log.select(rec.release_row, rec.end_row, name="a"), rec.log.select(rec.end_row, n, name="a"), rec)


def _problem(log, landing=None, barometer=True):
    model = InertialMeasurements(log, ENV.g, period=SPEC.period, barometer=barometer, rho=ENV.rho,
                                 landing=landing if barometer else None)
    return Problem(flights=[log], marker_body=np.zeros((1, 3)), disc=Disc(), env=ENV, prior_name="potts_crowther",
                   start_states=[LAUNCH.initial_state()], observations=[(model,)])


def _true_theta(p, rec):
    theta = p.prior_mean.copy()
    theta[: p.n_coef] = COEF.as_array()
    p0 = PRESSURE_PA - ENV.rho * ENV.g * LAUNCH.initial_state()[2]      # at rest before release: settled
    truth = {"imu_offset_x": SPEC.offset[0], "imu_offset_y": SPEC.offset[1], "imu_offset_z": SPEC.offset[2],
             "imu_lpf_tau": SPEC.lpf_tau, "imu_period_a": SPEC.period, "baro_dynamic_coefficient": C_Q,
             "baro_lag": SPEC.baro_lag, "baro_reference_a": p0, "baro_state_a": p0}
    for n, v in truth.items():
        if n in p.names:
            theta[p.layout.index(n)] = v
    for a, v in zip("xyz", rec.lpf_state):
        theta[p.layout.index(f"lpf_state_{a}_a")] = v
    theta[p.ic_slice(0)] = p.state_to_ic(LAUNCH.initial_state(), 0)
    return theta


def _baro_residuals(p, theta):
    (c, pred), = p.channel_predictions(np.atleast_2d(theta), 0)[0]
    seen = c._seen[:, -1]
    return pred[:, seen, -1] - c.measured[seen, -1][None]


def test_readings_are_the_rows_where_the_pressure_changes_and_the_equations():
    p = np.array([5.0, 5.0, 5.0, 4.5, 4.5, np.nan, 4.0, 4.0, 3.0])
    np.testing.assert_array_equal(reading_rows(p), [3, 8])
    got = outside_pressure(np.array([[0.0, 2.0]]), np.array([[10.0, 0.0]]), np.array([100.0]), np.array([0.5]),
                           1.2, 9.8)
    np.testing.assert_allclose(got, [[100.0 + 0.5 * 0.5 * 1.2 * 100.0, 100.0 - 1.2 * 9.8 * 2.0]])
    got = relax(np.array([10.0]), np.array([4.0]), np.array([[0.0, 0.7, 1e3]]), np.array([0.7]))
    np.testing.assert_allclose(got, [[10.0, 4.0 + 6.0 / np.e, 4.0]])


def test_prediction_matches_the_synthetic_logger_and_a_wrong_speed_port_or_lag_shows():
    """At the truth the barometer residuals are its noise (0.02 Pa), in flight and on the ground after it: the
    model's lag integrated on the simulation grid, read by cubic interpolation half a row before each reading
    row, and its analytic relaxation after the flight agree with the synthetic logger's (a 16× finer grid,
    linear reading). 3 % more release speed (a higher, longer climb), a port that sees no dynamic pressure or
    a lag a fifth shorter move the readings by far more than that."""
    log, landing, rec = _throw()
    p = _problem(log, landing)
    c = p.channels[0][0]
    assert c.series_names[-1] == "baro" and c.noise_names[-1] == "sigma_baro_a"
    n = int(c._seen[:, -1].sum())
    assert n >= int((LAUNCH.duration + 1.0) / 0.105) - 2           # one reading per 0.105 s task period
    assert int(c._seen[c.n_flight:, -1].sum()) >= 8 and not c._seen[c.n_flight:, :-1].any()
    theta = _true_theta(p, rec)
    res = _baro_residuals(p, theta)
    rms = float(np.sqrt(np.mean(res ** 2)))
    assert rms < 0.04, rms
    assert np.ptp(c.measured[c.n_flight:, -1][c._seen[c.n_flight:, -1]]) > 1.0     # it relaxes on the ground
    shorter = theta.copy()
    shorter[p.layout.index("baro_lag")] *= 0.8
    assert float(np.sqrt(np.mean(_baro_residuals(p, shorter) ** 2))) > 10 * rms
    faster = theta.copy()
    u = p.ic_slice(0).start + np.arange(2, 5)
    faster[u] *= 1.03
    assert float(np.sqrt(np.mean(_baro_residuals(p, faster) ** 2))) > 20 * rms
    static = theta.copy()
    static[p.layout.index("baro_dynamic_coefficient")] = 0.0
    assert float(np.sqrt(np.mean(_baro_residuals(p, static) ** 2))) > 5.0     # c_q ½ρV² ≈ 10–25 Pa


def _vertical_speed_gradient(p, theta):
    """∂v_z/∂θ at release (v_z: world vertical velocity of the state the inertial ICs give)."""
    g, sl = np.zeros(theta.size), p.ic_slice(0)
    for j in range(sl.start, sl.stop):
        step = theta.copy()
        step[j] += 1e-6
        g[j] = (p.ic_to_state(step[sl], 0)[0, 5] - p.ic_to_state(theta[sl], 0)[0, 5]) / 1e-6
    return g


def test_the_barometer_narrows_the_lift_and_the_climb():
    """Gauss–Newton sd at the truth of a 3 s throw, with and without the barometer (lag and readings on the
    ground after the flight included), at noise scales like the real logger throws' (gyro 0.02 / 0.6 rad/s
    axial / transverse, accelerometer 0.4 / 0.3 m/s², barometer 0.5 Pa): the height of the flight narrows
    the lift slope CLa and the release's vertical speed, which the rotation and the filtered specific force
    leave loose. (The Jacobian does not depend on the noise draw: the figures are deterministic; with them
    CLa's sd falls to about 0.45 of its value without the barometer and v_z's to about 0.5.)"""
    spec = replace(SPEC, gyro_noise=(0.02, 0.6), acc_noise=(0.4, 0.3), baro_noise=0.5)
    log, landing, rec = _throw(spec, duration=3.0)
    sd = {}
    for flag in (True, False):
        p = _problem(log, landing, barometer=flag)
        theta = _true_theta(p, rec)
        sigma = np.array([*spec.gyro_noise, *spec.acc_noise] + ([spec.baro_noise] if flag else []))
        cov = covariance_at(jacobian_blocks(theta, p, sigma), np.ones(theta.size, bool))
        g = _vertical_speed_gradient(p, theta)
        cla = p.layout.index("CLa")
        sd[flag] = (float(np.sqrt(cov[cla, cla])), float(np.sqrt(g @ cov @ g)))
    assert sd[True][0] < 0.6 * sd[False][0], sd
    assert sd[True][1] < 0.7 * sd[False][1], sd


def test_switched_off_the_unit_is_the_one_without_it():
    log, landing, rec = _throw()
    on, off = _problem(log, landing), _problem(log, barometer=False)
    assert set(on.names) - set(off.names) == {"baro_dynamic_coefficient", "baro_lag", "baro_reference_a",
                                              "baro_state_a"}
    assert [n for n in on.names if not n.startswith("baro_")] == off.names
    assert on.sigma_names == off.sigma_names + ["sigma_baro_a"]
    t_on, t_off = _true_theta(on, rec), _true_theta(off, rec)
    (_, p_on), = on.channel_predictions(t_on[None], 0)[0]
    (_, p_off), = off.channel_predictions(t_off[None], 0)[0]
    np.testing.assert_array_equal(p_on[:, : off.channels[0][0].n_flight, :6], p_off)
    assert np.isnan(p_on[:, off.channels[0][0].n_flight:, :6]).all()
    np.testing.assert_array_equal(on.sum_squares(t_on[None])[:, :4], off.sum_squares(t_off[None]))


def test_the_config_switch_and_a_log_without_barometer(tmp_path):
    from bayes_disc.inference.model.config import load_config
    from bayes_disc.observation.config_io import ConfigError
    from bayes_disc.observation.imu.formats import write_flatball_ins
    log, landing, rec = _throw()
    write_flatball_ins(tmp_path / "a.csv", rec.log)
    for flag, expect in (("", False), (", barometer: true", True), (", barometer: false", False)):
        (tmp_path / "run.yaml").write_text(f"name: t\nimu:\n  - {{file: a.csv, format: flatball-ins{flag}}}\n")
        cfg = load_config(tmp_path / "run.yaml")
        assert cfg.imu[0].barometer is expect
        throw = InertialThrow(rec.log, "a.csv", "ok", "synthetic", barometer=cfg.imu[0].barometer)
        assert inertial_model(throw, ENV).barometer is expect
    bare = replace(rec.log, pressure=None)
    assert not inertial_model(InertialThrow(bare, "a.csv", "ok", "synthetic", barometer=True), ENV).barometer
    with pytest.raises(ValueError, match="barometer"):
        InertialMeasurements(bare, ENV.g, period=0.0125, barometer=True, rho=ENV.rho)
    with pytest.raises(ValueError, match="air density"):
        InertialMeasurements(rec.log, ENV.g, period=0.0125, barometer=True)
    (tmp_path / "run.yaml").write_text("name: t\nimu:\n  - {file: a.csv, format: flatball-ins, barometer: 1}\n")
    with pytest.raises(ConfigError, match="true or false"):
        load_config(tmp_path / "run.yaml")


def test_the_shipped_logs_give_readings_in_flight_and_on_the_ground():
    """The shipped real logs with the barometer on: every right-side-up throw has a reading about every 0.1 s in
    flight and 1.5 s of readings after the impact, and on the ground the reading keeps rising for more than a
    second (from the reading after the impact to the last by more than 3 Pa, in steps that mostly rise): the
    sensor lags the outside pressure, which is constant once the disc lies still."""
    from conftest import REPO

    from bayes_disc.inference.model.config import load_config
    from bayes_disc.inference.model.inertial import load_run_throws
    cfg = load_config(REPO / "runs" / "flatball" / "config.yaml")
    cfg = replace(cfg, imu=tuple(replace(s, barometer=True) for s in cfg.imu))
    fitted = [t for t in load_run_throws(cfg) if t.status == "ok"]
    assert len(fitted) == 3
    for t in fitted:
        m = inertial_model(t, ENV)
        assert m.barometer and m.landing is not None
        flight = int(m._seen[: m.n_flight, -1].sum())
        assert flight >= 0.9 * m.n_flight * m.period / 0.105, (t.name, flight)
        on_ground = m.measured[m.n_flight:, -1][m._seen[m.n_flight:, -1]]
        assert on_ground.size >= 12, (t.name, on_ground.size)
        assert on_ground[-1] - on_ground[1] > 3.0, (t.name, on_ground)
        assert np.mean(np.diff(on_ground[1:]) > 0) > 0.7, (t.name, on_ground)


def test_the_posterior_file_places_each_channel_by_name():
    """posterior.nc with two throws, one logged with magnetometer and barometer and one with the barometer only:
    the barometer of both is the channel ``baro`` (not the first free column), the missing magnetometer NaN."""
    from bayes_disc.inference.results.idata import build_inference_data
    from bayes_disc.inference.sampling.chains import Chains
    logs, models, starts = [], [], []
    for name, mag in (("a", True), ("b", False)):
        rec = recorded_throw(name, LAUNCH.initial_state(), COEF, 0.8, SPEC, np.random.default_rng(7), rest_before=0.3)
        log = rec.log.select(rec.release_row, rec.end_row, name=name)
        logs.append(log)
        models.append((InertialMeasurements(log, ENV.g, period=SPEC.period, magnetometer=mag, barometer=True,
                                            rho=ENV.rho),))
        starts.append(LAUNCH.initial_state())
    p = Problem(flights=logs, marker_body=np.zeros((1, 3)), disc=Disc(), env=ENV, prior_name="potts_crowther",
                start_states=starts, observations=models)
    rng = np.random.default_rng(0)
    theta = p.start_vector()[None, None] + 1e-6 * rng.standard_normal((1, 3, 4, p.dim))
    ss = p.sum_squares(theta.reshape(-1, p.dim))
    sigma = np.sqrt(ss / np.concatenate([np.bincount(m[0].group_index) for m in models]))
    chains = Chains(chain=theta, log_prob=p.log_prob(theta.reshape(-1, p.dim)).reshape(1, 3, 4),
                    sigma=sigma.reshape(1, 3, 4, -1), acceptance=np.full((1, 4), 0.3), burn=0, total_steps=3,
                    tau=np.ones((1, p.dim)), converged=False, reason="test")
    idata = build_inference_data(p, chains, rng, n_prior=4, n_log_likelihood=4, n_predictive=2)
    channels = list(idata.observed_data["imu_channel"].values)
    assert channels == ["gx", "gy", "gz", "ax", "ay", "az", "mx", "my", "mz", "baro"]
    for (m,), name in zip(models, ("a", "b")):
        obs = idata.observed_data[f"imu_{name}"].values
        np.testing.assert_array_equal(obs[:, channels.index("baro")], m.measured[:, -1])
        assert np.isnan(obs[:, 6:9]).all() == (name == "b")
        assert np.isfinite(idata.posterior_predictive[f"imu_{name}"].values[..., channels.index("baro")]).any()
