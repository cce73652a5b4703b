"""The inertial observation model: measurement equations against an independent synthesizer, the filter
and interpolation, the inertial initial conditions, real logs wired into a run, and recovery (slow)."""
import numpy as np
import pytest

from bayes_disc.inference.model.problem import Problem
from bayes_disc.observation.inertial_synth import LoggerSpec, logger_readings, synthetic_log
from bayes_disc.observation.models.inertial import InertialMeasurements, interpolate, low_pass
from bayes_disc.observation.synth import LaunchSpec
from bayes_disc.physics import Disc, Environment, literature_coefficients

from conftest import REPO

COEF = literature_coefficients("hummel2002")
SPEC = LoggerSpec(lpf_state=(1.0, -2.0, 3.0), tilt=(0.01, -0.02), gyro_bias=(0.01, 0.02, -0.01),
                  acc_bias=(0.1, -0.2, 0.05))
TRUE_SHARED = {"imu_offset_x": SPEC.offset[0], "imu_offset_y": SPEC.offset[1], "imu_offset_z": SPEC.offset[2],
               "imu_lpf_tau": SPEC.lpf_tau, "imu_tilt_1": SPEC.tilt[0], "imu_tilt_2": SPEC.tilt[1]}
LAUNCHES = [LaunchSpec(name="a", speed=13.0, launch_angle_deg=5, alpha_deg=8, spin=55, roll_deg=3, p=2, q=-3,
                       duration=2.0),
            LaunchSpec(name="b", speed=11.0, launch_angle_deg=10, alpha_deg=20, spin=50, roll_deg=-5, duration=1.6),
            LaunchSpec(name="c", speed=15.0, launch_angle_deg=2, alpha_deg=3, spin=60, roll_deg=8, duration=2.2)]


def _problem(logs, starts, prior="weak"):
    models = [(InertialMeasurements(log, Environment().g, period=0.0125),) for log in logs]
    return Problem(flights=list(logs), marker_body=np.zeros((1, 3)), disc=Disc(), env=Environment(),
                   prior_name=prior, start_states=list(starts), observations=models)


def _true_theta(p, launches, spec=SPEC):
    theta = p.prior_mean.copy()
    theta[: p.n_coef] = COEF.as_array()
    for name, v in TRUE_SHARED.items():
        theta[p.layout.index(name)] = v
    for k, ls in enumerate(launches):
        f = ls.name
        theta[p.ic_slice(k)] = p.state_to_ic(ls.initial_state(), k)
        own = {"imu_period": spec.period, "gyro_bias_x": spec.gyro_bias[0], "gyro_bias_y": spec.gyro_bias[1],
               "gyro_bias_z": spec.gyro_bias[2], "acc_bias_x": spec.acc_bias[0], "acc_bias_y": spec.acc_bias[1],
               "acc_bias_z": spec.acc_bias[2], "lpf_state_x": spec.lpf_state[0], "lpf_state_y": spec.lpf_state[1],
               "lpf_state_z": spec.lpf_state[2]}
        for n, v in own.items():
            theta[p.layout.index(f"{n}_{f}")] = v
    return theta


def test_low_pass_is_exact_for_linear_and_matches_the_analytic_sinusoid_response():
    h, tau = 0.002, 0.15
    t = np.arange(2000) * h
    ramp = (3.0 + 2.0 * t)[None, :, None].repeat(3, axis=2)
    y = low_pass(ramp, np.full((1, 3), 1.0), np.array([tau]), h)[0, :, 0]
    exact = 3.0 + 2.0 * (t - tau) + (1.0 - 3.0 + 2.0 * tau) * np.exp(-t / tau)
    assert np.max(np.abs(y - exact)) < 1e-10
    w = 2 * np.pi * 9.0                               # spin-rate ripple: attenuated to 1/√(1 + (ωτ)²)
    x = np.sin(w * t)[None, :, None].repeat(3, axis=2)
    y = low_pass(x, np.zeros((1, 3)), np.array([tau]), h)[0, :, 0]
    late = t > 10 * tau
    amp = np.max(np.abs(y[late]))
    assert abs(amp - 1 / np.hypot(1, w * tau)) < 2e-3 * amp


def test_cubic_interpolation_is_exact_for_cubics_and_nan_outside():
    h = 0.01
    grid = np.arange(50) * h
    f = (1 + grid - 3 * grid ** 2 + 5 * grid ** 3)[None, :, None]
    t = np.array([[0.0, 0.0123, 0.2555, 0.48, 0.49, 0.5]])
    out = interpolate(f, h, t)[0, :, 0]
    want = 1 + t[0] - 3 * t[0] ** 2 + 5 * t[0] ** 3
    assert np.allclose(out[:-1], want[:-1], atol=1e-12) and np.isnan(out[-1])


def test_inertial_initial_conditions_round_trip_up_to_heading():
    """state → (tilt, u_B, ω) → state keeps the body-frame velocity, the rates and the tilt of b3; the
    heading (unobservable) is turned to the reference."""
    rng = np.random.default_rng(0)
    log = synthetic_log("a", LAUNCHES[0].initial_state(), COEF, 0.3, SPEC, rng)
    p = _problem([log], [LAUNCHES[0].initial_state()])
    from bayes_disc.physics.frames import quat_to_matrix
    for ls in LAUNCHES:
        y = ls.initial_state()
        back = p.ic_to_state(p.state_to_ic(y, 0), 0)[0]
        R, Rb = quat_to_matrix(y[6:10]), quat_to_matrix(back[6:10])
        assert np.allclose(R.T @ y[3:6], Rb.T @ back[3:6], atol=1e-12)          # u_B
        assert np.allclose(back[10:13], y[10:13])                                   # ω_B
        assert np.isclose(R[2, 2], Rb[2, 2], atol=1e-12)                            # tilt of b3 to vertical
        assert np.allclose(back[:3], [0.0, 0.0, 1.0])


def test_prediction_matches_the_independent_synthesizer():
    """Same throw, same parameters: the fitting path (finite differences, grid filter, cubic interpolation at
    row·P) against the synthesizer (exact derivatives, 4× finer filter grid, rows read directly). The model's
    grid (nominal period 12.5 ms / 4) does not land on the rows (12.2 ms): the interpolation error stays
    below 6 % of the smallest gyro noise of such loggers (0.005 rad/s) and the accelerometer error below 6 %
    of its noise (0.05 m/s²)."""
    y0 = LAUNCHES[0].initial_state()
    log = synthetic_log("a", y0, COEF, 2.0, SPEC, np.random.default_rng(0))
    gyro, acc, _, _ = logger_readings(y0, COEF, log.rows.size, SPEC)
    p = _problem([log], [y0])
    theta = _true_theta(p, LAUNCHES[:1])
    (c, pred), = p.channel_predictions(theta[None], 0)[0]
    assert np.max(np.abs(pred[0, :, :3] - gyro)) < 3e-4                  # rad/s
    assert np.max(np.abs(pred[0, :, 3:] - acc)) < 3e-3                   # m/s² (noise of such loggers ≥ 0.05)
    assert np.max(np.abs(acc[:, 0])) > 40                                 # the centripetal term is there
    theta_wrong = theta.copy()
    theta_wrong[p.layout.index("imu_period_a")] *= 1.01                    # a 1 % period error is visible
    (c, pred2), = p.channel_predictions(theta_wrong[None], 0)[0]
    assert np.max(np.abs(pred2[0, :, :3] - gyro)) > 10 * 3e-4


def test_real_logs_enter_a_run_and_the_hammer_is_out_of_model():
    from bayes_disc.inference.model.config import load_config
    from bayes_disc.inference.model.data import build_problem
    from bayes_disc.inference.model.inertial import load_run_throws
    cfg = load_config(REPO / "runs" / "flatball" / "config.yaml")
    throws = load_run_throws(cfg)
    status = {t.name: t.status for t in throws}
    assert status == {"2025-08-31-001-rb": "ok", "2025-08-31-002-rb": "ok", "2025-08-31-003-rf": "ok",
                      "2025-08-31-005-rh": "out_of_model"}
    p = build_problem(cfg, throws=throws)
    assert [f.name for f in p.flights] == ["2025-08-31-001-rb", "2025-08-31-002-rb", "2025-08-31-003-rf"]
    names = p.names
    for n in ("imu_offset_x", "imu_offset_y", "imu_offset_z", "imu_lpf_tau", "imu_period_2025-08-31-002-rb"):
        assert n in names
    assert not any(n.startswith(("x_", "y_", "z_")) for n in names)     # position is not a parameter
    assert len(p.sigma_names) == 18                  # per throw: gyro and acc (axial, transverse), magnetometer
    assert "mag_heading_2025-08-31-002-rb" in names and "mag_field_horizontal" in names
    r, ok = p.residuals(p.start_vector()[None], 1)
    assert ok[0] and np.all(np.isfinite(r))
    from dataclasses import replace
    off = build_problem(cfg, throws=[replace(t, magnetometer=False) for t in throws])
    assert len(off.sigma_names) == 12 and not any(n.startswith("mag_") for n in off.names)


@pytest.mark.slow
def test_least_squares_recovers_coefficients_and_logger_parameters():
    """Three synthetic throws (noise 0.005/0.05 rad/s, 0.05 m/s²): the joint least-squares optimum lies
    within 4 Laplace sd of the truth for the coefficients, r_s, τ, the tilt and each row period, from the
    data-derived starts (level disc, gyro rates, airflow-direction search)."""
    from bayes_disc.inference.model.inertial import InertialThrow, level_start, own_start, search_starts
    from bayes_disc.inference.fitting.leastsq import fit_least_squares
    rng = np.random.default_rng(1)
    logs = [synthetic_log(ls.name, ls.initial_state(), COEF, ls.duration, SPEC, rng) for ls in LAUNCHES]
    throws = [InertialThrow(log, "synth", "ok", "synthetic") for log in logs]
    models = [(InertialMeasurements(log, Environment().g, period=0.0125),) for log in logs]
    own = [own_start(m[0], t) for m, t in zip(models, throws)]
    starts = [level_start(t) for t in throws]

    def make(st):
        return Problem(flights=logs, marker_body=np.zeros((1, 3)), disc=Disc(), env=Environment(),
                       prior_name="potts_crowther", start_states=st, observations=models, own_start=own)
    p = make(starts)
    p = make([search_starts(p, k) for k in range(3)])
    ls = fit_least_squares(p, starts=2, max_nfev=100)
    truth = _true_theta(p, LAUNCHES)
    sd = np.sqrt(np.diag(ls.cov))
    check = list(range(p.n_coef)) + [p.layout.index(n) for n in TRUE_SHARED] + \
        [p.layout.index(f"imu_period_{ls_.name}") for ls_ in LAUNCHES]
    z = {p.names[i]: (ls.theta[i] - truth[i]) / sd[i] for i in check}
    assert all(abs(v) < 4 for v in z.values()), z
