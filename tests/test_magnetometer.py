"""The magnetometer as channels of the inertial unit (bayes_disc.observation.models.magnetometer): its prediction
matches the synthetic logger's independent computation, turning the attitude turns the predicted field, a
wrong row period makes its residuals explode, a least-squares fit recovers the row period and the field
within their Laplace uncertainty, and without it the unit is the gyro/accelerometer one exactly."""
from dataclasses import replace

import numpy as np
import pytest

from bayes_disc.inference.model.inertial import (InertialThrow, heading_start, level_start, magnetometer_shared_start,
                                                 own_start, search_starts)
from bayes_disc.inference.model.problem import R_LEVEL, Problem
from bayes_disc.observation.inertial_synth import LoggerSpec, synthetic_log
from bayes_disc.observation.models.inertial import InertialMeasurements, interpolate
from bayes_disc.observation.models.magnetometer import MAG_OWN_PARAMETERS, body_field, field_world, window_mean
from bayes_disc.observation.synth import LaunchSpec
from bayes_disc.physics import Disc, Environment, literature_coefficients
from bayes_disc.physics.frames import quat_from_rotvec, quat_multiply, quat_to_matrix

COEF = literature_coefficients("hummel2002")
FIELD = (15.0, 10.0, -40.0)                        # world µT: H = 18.0, Z = 40 (down)
SPEC = LoggerSpec(mag_hard_iron=(6.0, -3.0, 25.0), field_uT=FIELD, mag_noise=(0.3, 0.3))
LAUNCHES = [LaunchSpec(name="a", speed=13.0, launch_angle_deg=5, alpha_deg=8, spin=55, roll_deg=3, p=2, q=-3,
                       duration=0.6),
            LaunchSpec(name="b", speed=11.0, launch_angle_deg=10, alpha_deg=20, spin=50, roll_deg=-12, duration=0.6)]
TRUE_SHARED = {"imu_offset_x": SPEC.offset[0], "imu_offset_y": SPEC.offset[1], "imu_offset_z": SPEC.offset[2],
               "imu_lpf_tau": SPEC.lpf_tau, "imu_tilt_1": SPEC.tilt[0], "imu_tilt_2": SPEC.tilt[1],
               "mag_field_horizontal": float(np.hypot(FIELD[0], FIELD[1])), "mag_field_down": -FIELD[2],
               "mag_hard_iron_x": 6.0, "mag_hard_iron_y": -3.0, "mag_hard_iron_z": 25.0}


def _logs(seed=1, launches=LAUNCHES):
    rng = np.random.default_rng(seed)
    return [synthetic_log(ls.name, ls.initial_state(), COEF, ls.duration, SPEC, rng) for ls in launches]


def _problem(logs, magnetometer=True, starts=None, own=None):
    models = [(InertialMeasurements(log, Environment().g, period=0.0125, magnetometer=magnetometer),) for log in logs]
    shared = magnetometer_shared_start(m for ch in models for m in ch)
    p0 = Problem(flights=logs, marker_body=np.zeros((1, 3)), disc=Disc(), env=Environment(),
                 prior_name="potts_crowther", start_states=starts or [ls.initial_state() for ls in LAUNCHES[:len(logs)]],
                 observations=models, own_start=own)
    term_start = np.array([shared.get(q.name, q.off_value) for q in p0.layout.ext_parameters])
    return Problem(flights=logs, marker_body=np.zeros((1, 3)), disc=Disc(), env=Environment(),
                   prior_name="potts_crowther", start_states=p0.start_states, observations=models, own_start=own,
                   term_start=term_start)


def _turn(state):
    """The heading the inertial initial conditions remove from a state (Problem.state_to_ic) [rad]."""
    M = quat_to_matrix(state[6:10]) @ R_LEVEL.T
    return np.arctan2(M[1, 0] - M[0, 1], M[0, 0] + M[1, 1])


def _true_theta(p, launches):
    theta = p.prior_mean.copy()
    theta[: p.n_coef] = COEF.as_array()
    for n, v in TRUE_SHARED.items():
        if n in p.names:
            theta[p.layout.index(n)] = v
    for k, ls in enumerate(launches):
        theta[p.ic_slice(k)] = p.state_to_ic(ls.initial_state(), k)
        theta[p.layout.index(f"imu_period_{ls.name}")] = SPEC.period
        for a, v in zip("xyz", p.channels[k][0].log.acc[0] - np.asarray(SPEC.acc_bias)):
            theta[p.layout.index(f"lpf_state_{a}_{ls.name}")] = v
        name = f"mag_heading_{ls.name}"
        if name in p.names:      # the field's heading in the frame the inertial ICs turn the flight into
            theta[p.layout.index(name)] = np.arctan2(FIELD[1], FIELD[0]) - _turn(ls.initial_state())
    return theta


def _mag_rms(p, theta, k=0):
    (c, pred), = p.channel_predictions(theta[None], k)[0]
    seen = c._seen[:, 6]
    return float(np.sqrt(np.mean((pred[0][seen, 6:] - c.measured[seen, 6:]) ** 2)))


def test_prediction_matches_the_synthetic_logger_and_a_wrong_period_explodes():
    """At the truth the magnetometer residuals are its noise (0.3 µT): the model's window mean (Gauss–Legendre
    on the simulation grid) and the synthetic logger's (trapezoid on a 4× finer grid) agree; a row period
    1 % (4 %) off leaves the field's phase behind by the spin times the elapsed time: the residuals grow to
    about twice (six times) the noise over this 0.6 s throw (Δχ² in the hundreds), and further on longer ones."""
    logs = _logs(launches=LAUNCHES[:1])
    p = _problem(logs)
    theta = _true_theta(p, LAUNCHES[:1])
    rms = _mag_rms(p, theta)
    assert 0.2 < rms < 0.4, rms
    n = 3 * int(p.channels[0][0]._seen[:, 6].sum())
    for factor, times_noise in ((1.01, 1.8), (1.04, 5.0)):
        wrong = theta.copy()
        wrong[p.layout.index("imu_period_a")] *= factor
        bad = _mag_rms(p, wrong)
        assert bad > times_noise * rms, (factor, bad, rms)
        assert n * (bad ** 2 - rms ** 2) / SPEC.mag_noise[0] ** 2 > 200     # Δχ² of the magnetometer alone
    wrong = theta.copy()
    wrong[p.layout.index("mag_heading_a")] += 0.05      # 0.05 rad of heading: ~0.9 µT in the transverse axes
    assert _mag_rms(p, wrong) > 2 * rms


def test_turning_the_attitude_turns_the_predicted_field():
    """Turning the disc about its axis b3 by χ turns the body-axis field by Rz(χ)ᵀ; turning the world (the
    attitude and the field together) leaves it unchanged; ∂m/∂ψ is the field turned by 90° in the horizontal."""
    rng = np.random.default_rng(3)
    B, J, h = 2, 40, 0.003
    rv = np.cumsum(rng.normal(0, 0.2, (B, J, 3)), axis=1)
    states = np.zeros((B, J, 13))
    states[..., 6:10] = quat_from_rotvec(rv.reshape(-1, 3)).reshape(B, J, 4)
    bw = field_world(np.array([18.0, 25.0]), np.array([40.0, -30.0]), np.array([0.3, 2.0]))
    t = np.tile(np.linspace(0.03, 0.1, 7), (B, 1))
    base = window_mean(body_field(states, bw), h, t, interpolate)
    chi = 0.7
    turned = states.copy()
    turned[..., 6:10] = quat_multiply(states[..., 6:10].reshape(-1, 4),
                                      np.tile(quat_from_rotvec(np.array([[0, 0, chi]])), (B * J, 1))).reshape(B, J, 4)
    Rz = quat_to_matrix(quat_from_rotvec(np.array([0, 0, chi])))
    got = window_mean(body_field(turned, bw), h, t, interpolate)
    np.testing.assert_allclose(got, np.einsum("ji,bnj->bni", Rz, base), atol=1e-9)
    world = states.copy()
    world[..., 6:10] = quat_multiply(np.tile(quat_from_rotvec(np.array([[0, 0, chi]])), (B * J, 1)),
                                     states[..., 6:10].reshape(-1, 4)).reshape(B, J, 4)
    np.testing.assert_allclose(window_mean(body_field(world, bw @ Rz.T), h, t, interpolate), base, atol=1e-9)
    eps = 1e-6
    up = window_mean(body_field(states, field_world(np.array([18.0, 25.0]), np.array([40.0, -30.0]),
                                                    np.array([0.3, 2.0]) + eps)), h, t, interpolate)
    d_bw = np.stack([-bw[:, 1], bw[:, 0], np.zeros(B)], axis=1)
    np.testing.assert_allclose((up - base) / eps, window_mean(body_field(states, d_bw), h, t, interpolate), atol=1e-4)


def test_switched_off_the_unit_is_the_gyro_and_accelerometer_one():
    logs = _logs(launches=LAUNCHES[:1])
    on, off = _problem(logs), _problem(logs, magnetometer=False)
    assert [n for n in on.names if not n.startswith("mag_")] == off.names
    assert set(on.names) - set(off.names) == {"mag_field_horizontal", "mag_field_down", "mag_hard_iron_x",
                                              "mag_hard_iron_y", "mag_hard_iron_z", "mag_heading_a"}
    assert on.sigma_names == off.sigma_names + ["sigma_mag_axial_a", "sigma_mag_transverse_a"]
    t_on = _true_theta(on, LAUNCHES[:1])
    t_off = _true_theta(off, LAUNCHES[:1])
    (_, p_on), = on.channel_predictions(t_on[None], 0)[0]
    (_, p_off), = off.channel_predictions(t_off[None], 0)[0]
    assert p_off.shape[2] == 6 and p_on.shape[2] == 9
    np.testing.assert_array_equal(p_on[..., :6], p_off)
    ss_on, ss_off = on.sum_squares(t_on[None]), off.sum_squares(t_off[None])
    np.testing.assert_array_equal(ss_on[:, :4], ss_off)


def test_the_config_switch_and_a_log_without_magnetometer(tmp_path):
    from bayes_disc.inference.model.config import load_config
    from bayes_disc.inference.model.inertial import inertial_model
    from bayes_disc.observation.imu.formats import write_flatball_ins
    from bayes_disc.observation.inertial_synth import recorded_throw
    ls = LAUNCHES[0]
    rec = recorded_throw("a", ls.initial_state(), COEF, ls.duration, SPEC, np.random.default_rng(2))
    write_flatball_ins(tmp_path / "a.csv", rec.log)
    for flag, expect in (("", True), (", magnetometer: true", True), (", magnetometer: false", False)):
        (tmp_path / "run.yaml").write_text(f"name: t\nimu:\n  - {{file: a.csv, format: flatball-ins{flag}}}\n")
        cfg = load_config(tmp_path / "run.yaml")
        assert cfg.imu[0].magnetometer is expect
        throw = InertialThrow(rec.log, "a.csv", "ok", "synthetic", magnetometer=cfg.imu[0].magnetometer)
        assert inertial_model(throw, Environment()).magnetometer is expect
    bare = replace(rec.log, mag=None)
    assert not inertial_model(InertialThrow(bare, "a.csv", "ok", "synthetic"), Environment()).magnetometer
    with pytest.raises(ValueError, match="magnetometer"):
        InertialMeasurements(bare, 9.81, period=0.0125, magnetometer=True)
    (tmp_path / "run.yaml").write_text("name: t\nimu:\n  - {file: a.csv, format: flatball-ins, magnetometer: 1}\n")
    from bayes_disc.observation.config_io import ConfigError
    with pytest.raises(ConfigError, match="true or false"):
        load_config(tmp_path / "run.yaml")


@pytest.mark.slow
def test_least_squares_recovers_the_row_period_and_the_field():
    """Two synthetic throws (magnetometer noise 0.3 µT) fitted from the data-derived starts (level disc, gyro
    rates, airflow-direction search, field heading search, field and hard iron from the sensor-plane
    circles): each row period, the field's strength and the hard iron within 4 Laplace sd of the truth, and
    the period's sd less than half of the gyro and accelerometer's alone."""
    from bayes_disc.inference.fitting.leastsq import fit_least_squares
    logs = _logs(seed=5)
    throws = [InertialThrow(log, "synth", "ok", "synthetic") for log in logs]
    p = _problem(logs, starts=[level_start(t) for t in throws])
    own = [own_start(ch[0], t) for ch, t in zip(p.channels, throws)]
    p = _problem(logs, starts=[level_start(t) for t in throws], own=own)
    p = _problem(logs, starts=[search_starts(p, k) for k in range(len(logs))], own=own)
    for k in range(len(logs)):
        own[k][p.layout.flight_parameters[k].index(MAG_OWN_PARAMETERS[0])] = heading_start(p, k)
    p = _problem(logs, starts=p.start_states, own=own)
    ls = fit_least_squares(p, starts=1, max_nfev=150)
    truth = _true_theta(p, LAUNCHES)
    sd = np.sqrt(np.diag(ls.cov))
    names = [f"imu_period_{l.name}" for l in LAUNCHES] + ["mag_field_horizontal", "mag_field_down",
                                                            "mag_hard_iron_x", "mag_hard_iron_y", "mag_hard_iron_z"]
    z = {n: (ls.theta[p.layout.index(n)] - truth[p.layout.index(n)]) / sd[p.layout.index(n)] for n in names}
    assert all(abs(v) < 4 for v in z.values()), z
    # the magnetometer fixes the clock: the period's sd is less than half of what gyro and accelerometer
    # alone give (Laplace at the truth, true noise scales)
    from bayes_disc.inference.fitting.covariance import covariance_from_jacobian
    from bayes_disc.inference.fitting.residuals import jacobian_blocks
    off = _problem(logs, magnetometer=False)
    sigma = np.tile([SPEC.gyro_noise[0], SPEC.gyro_noise[1], SPEC.acc_noise[0], SPEC.acc_noise[1]], len(LAUNCHES))
    cov_off = covariance_from_jacobian(jacobian_blocks(_true_theta(off, LAUNCHES), off, sigma).dense())
    for l in LAUNCHES:
        i, j = p.layout.index(f"imu_period_{l.name}"), off.layout.index(f"imu_period_{l.name}")
        assert sd[i] < 0.5 * np.sqrt(cov_off[j, j]), (sd[i], np.sqrt(cov_off[j, j]))
    noise = ls.noise()
    for l in LAUNCHES:
        assert noise[f"sigma_mag_transverse_{l.name}"]["value"] < 0.5


def test_every_inertial_series_has_words_for_the_diagnosis():
    """The diagnosis names structured residual series in words; every series an inertial unit with its
    magnetometer can produce has them (a missing one stopped `diagnose` at its last step)."""
    from bayes_disc.diagnostics.mismatch import SERIES_WORDS
    from bayes_disc.observation.models.inertial import SERIES
    from bayes_disc.observation.models.magnetometer import MAG_SERIES
    assert set(SERIES + MAG_SERIES) <= set(SERIES_WORDS)
