"""Identifiability of runs with inertial logs: the coefficient information with each throw's own parameters
(initial conditions, row period, biases, filter state) marginalised agrees with the Laplace covariance, the
verdicts follow the widths and speak of inertial data, and `bayes-disc identifiability` works on an
IMU-only configuration (the marker-flight design is skipped with its reason)."""
import json

import numpy as np
import pytest

from bayes_disc.cli import main
from bayes_disc.diagnostics.identifiability import (PRIOR_DOMINATED, RELATIVE_SD, coefficient_information,
                                                    data_description, design_skip_reason, verdicts_from_covariance)
from bayes_disc.inference.fitting.covariance import covariance_from_jacobian
from bayes_disc.inference.fitting.residuals import jacobian_blocks
from bayes_disc.inference.model.problem import Problem
from bayes_disc.observation.inertial_synth import LoggerSpec, synthetic_log
from bayes_disc.observation.models.inertial import InertialMeasurements
from bayes_disc.observation.synth import LaunchSpec
from bayes_disc.physics import COEFFICIENT_NAMES, Disc, Environment, literature_coefficients

COEF = literature_coefficients("hummel2002")
SPEC = LoggerSpec()
LAUNCHES = [LaunchSpec(name="a", speed=13.0, launch_angle_deg=5, alpha_deg=8, spin=55, roll_deg=3, p=2, q=-3,
                       duration=0.6),
            LaunchSpec(name="b", speed=11.0, launch_angle_deg=10, alpha_deg=20, spin=50, roll_deg=-5, duration=0.6)]
SHARED = {"imu_offset_x": SPEC.offset[0], "imu_offset_y": SPEC.offset[1], "imu_offset_z": SPEC.offset[2],
          "imu_lpf_tau": SPEC.lpf_tau, "imu_tilt_1": SPEC.tilt[0], "imu_tilt_2": SPEC.tilt[1]}


def _problem_at_truth():
    rng = np.random.default_rng(4)
    logs = [synthetic_log(ls.name, ls.initial_state(), COEF, ls.duration, SPEC, rng) for ls in LAUNCHES]
    models = [(InertialMeasurements(log, Environment().g, period=0.0125),) for log in logs]
    p = Problem(flights=logs, marker_body=np.zeros((1, 3)), disc=Disc(), env=Environment(),
                prior_name="potts_crowther", start_states=[ls.initial_state() for ls in LAUNCHES],
                observations=models)
    theta = p.prior_mean.copy()
    theta[: p.n_coef] = COEF.as_array()
    for n, v in SHARED.items():
        theta[p.layout.index(n)] = v
    for k, ls in enumerate(LAUNCHES):
        theta[p.ic_slice(k)] = p.state_to_ic(ls.initial_state(), k)
        theta[p.layout.index(f"imu_period_{ls.name}")] = SPEC.period
        y0 = logs[k].acc[0] - SPEC.acc_bias                       # settled filter: the input at release
        for a, v in zip("xyz", y0):
            theta[p.layout.index(f"lpf_state_{a}_{ls.name}")] = v
    return p, theta


@pytest.fixture(scope="module")
def at_truth():
    p, theta = _problem_at_truth()
    sigma = np.tile([SPEC.gyro_noise[0], SPEC.gyro_noise[1], SPEC.acc_noise[0], SPEC.acc_noise[1]], len(LAUNCHES))
    return p, theta, jacobian_blocks(theta, p, sigma)


def test_marginal_information_matches_the_laplace_covariance(at_truth):
    """(F_c|i + P_c)⁻¹ (the information with every throw's own parameters marginalised, plus the prior) is
    the shared block of the Laplace covariance (F + P)⁻¹: the nuisance block of an inertial throw holds its
    initial conditions and its logger parameters."""
    p, theta, J = at_truth
    nc = p.ic_start
    assert nc == p.n_coef + 6                                  # ten coefficients and the logger's mount
    info = coefficient_information(p, J)          # Schur complement of the block-arrow information
    cov = covariance_from_jacobian(J.dense())     # dense Laplace covariance
    sd_schur = np.sqrt(np.diag(np.linalg.inv(info + np.diag(1.0 / p.prior_sd[:nc] ** 2))))
    sd_laplace = np.sqrt(np.diag(cov)[:nc])
    np.testing.assert_allclose(sd_schur, sd_laplace, rtol=0.02)
    # the data inform the coefficients: without them the sds would be the prior's
    assert np.all(sd_laplace[: p.n_coef] < p.prior_sd[: p.n_coef])


def test_verdicts_follow_the_widths_and_speak_of_inertial_data(at_truth):
    p, theta, J = at_truth
    nc = p.ic_start
    cov = J.information().inverse()[:nc, :nc]
    data = data_description(p)
    assert (data["markers"], data["inertial"], data["inertial_only"]) == (0, 2, 2)
    assert "only through the forces and moments" in data["text"]
    floors = {q.name: q.prior_sd for q in p.layout.observation_parameters}
    names = p.names[:nc]
    v = verdicts_from_covariance(names, theta[:nc], cov, p.prior_sd[:nc], (5.0, 20.0), data=data["text"],
                                 size_floors=floors)
    kinds = set()
    for i, n in enumerate(names):
        sd, ratio = np.sqrt(cov[i, i]), cov[i, i] / p.prior_sd[i] ** 2
        assert v[n]["sd"] == pytest.approx(sd)
        assert "inertial data only" in v[n]["reason"], v[n]
        if v[n]["verdict"] == "unidentified":
            assert ratio >= PRIOR_DOMINATED
        else:
            assert ratio < PRIOR_DOMINATED
        if v[n]["verdict"] == "identified":
            assert v[n]["relative_sd"] <= RELATIVE_SD
        kinds.add(v[n]["verdict"])
    # the logger's mount is determined by these throws (sd ≪ its plausible range)
    for n in ("imu_offset_x", "imu_offset_y", "imu_offset_z", "imu_lpf_tau"):
        assert v[n]["verdict"] == "identified", v[n]
    # a coefficient the data barely see is not called identified: make one prior-dominated by hand
    weak = cov.copy()
    j = names.index("CMq")
    weak[j, :] = weak[:, j] = 0.0
    weak[j, j] = (0.9 * p.prior_sd[j]) ** 2
    w = verdicts_from_covariance(names, theta[:nc], weak, p.prior_sd[:nc], (5.0, 20.0), data=data["text"])
    assert w["CMq"]["verdict"] == "unidentified" and "the prior sets it" in w["CMq"]["reason"]
    assert design_skip_reason(p) is not None


# 0.8 s: the run's time-base check needs ≥ 5 barometer updates (one per ~0.1 s) within a throw
SYNTH = """
name: imuid
seed: 5
output: {markers: flights.csv, truth: truth.json}
imu: {period: 0.0122, output: logs}
flights:
  - {name: a, speed: 13.0, launch_angle_deg: 5, alpha_deg: 8, spin: 55, roll_deg: 3, p: 2, q: -3, duration: 0.8}
  - {name: b, speed: 11.0, launch_angle_deg: 10, alpha_deg: 20, spin: 50, roll_deg: -5, duration: 0.8}
"""
CONFIG = """
name: imuid
imu:
  - {file: logs/a.csv, format: flatball-ins}
  - {file: logs/b.csv, format: flatball-ins}
prior: potts_crowther
least_squares: {starts: 1, max_nfev: %d}
output: out
"""


def _imu_run(folder, max_nfev):
    (folder / "synth.yaml").write_text(SYNTH)
    assert main(["synth", str(folder / "synth.yaml")]) == 0
    (folder / "config.yaml").write_text(CONFIG % max_nfev)
    assert main(["identifiability", str(folder / "config.yaml")]) == 0
    return json.loads((folder / "out" / "identifiability.json").read_text())


def test_cli_identifiability_on_an_imu_only_run(tmp_path):
    r = _imu_run(tmp_path, 8)
    for n in COEFFICIENT_NAMES:
        assert r[n]["verdict"] in ("identified", "weak", "unidentified")
        assert "inertial data only" in r[n]["reason"]
    assert "imu_lpf_tau" in r["coefficients"]
    assert r["data"]["inertial_only"] == 2
    assert "no marker data" in r["design"]["skipped"]
    assert r["least_squares"]["rms_mm"] == {}
    units = {n: v["unit"] for n, v in r["least_squares"]["noise"].items()}
    assert units["sigma_gyro_axial_a"] == "rad/s" and units["sigma_acc_transverse_b"] == "m/s²"
    assert set(r["envelope"]["flights"]) == {"a", "b"}


@pytest.mark.slow
def test_identified_coefficients_and_logger_recovered_within_their_intervals(tmp_path):
    """Two short synthetic throws seen by the logger alone, fitted to convergence: every parameter called
    identified lies within 3 Laplace sd of the truth (coefficients, r_s, τ)."""
    r = _imu_run(tmp_path, 100)
    truth = json.loads((tmp_path / "truth.json").read_text())
    want = dict(truth["coefficients"])
    lg = truth["imu"]["logger"]
    want.update({"imu_offset_x": lg["offset_m"][0], "imu_offset_y": lg["offset_m"][1],
                 "imu_offset_z": lg["offset_m"][2], "imu_lpf_tau": lg["lpf_tau_s"]})
    checked = {n: (v["value"] - want[n]) / v["sd"] for n, v in r["coefficients"].items()
               if v["verdict"] == "identified" and n in want}
    assert {"imu_offset_x", "imu_lpf_tau"} <= set(checked)
    assert sum(n in checked for n in COEFFICIENT_NAMES) >= 5, r["coefficients"]
    assert all(abs(z) < 3 for z in checked.values()), checked
