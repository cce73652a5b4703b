"""A randomly forced nutation in the transverse gyro (``gyro_noise: nutation``): the Kalman filter whitens
exactly, the logger model wires it to its rows, times and spin, and its parameters are recovered."""

import numpy as np
import pytest
from scipy.optimize import minimize

from bayes_disc.inference.model.config import load_config
from bayes_disc.observation.config_io import ConfigError
from bayes_disc.observation.imu import InertialLog
from bayes_disc.observation.models.inertial import InertialMeasurements
from bayes_disc.observation.models.nutation import nutation_covariance, nutation_filter, sample_nutation


def _rows(n=60, sign=1.0, seed=0):
    """Irregular row times [s] and a decaying spin [rad/s] (sign: the spin's sense)."""
    rng = np.random.default_rng(seed)
    t = np.r_[0.0, np.cumsum(rng.uniform(0.008, 0.03, n - 1))]
    return t, sign * (60.0 - 5.0 * t) + rng.normal(0.0, 0.01, n)


def _filter(r, t, spin, lam, kap, a):
    """The filter on one residual series r (2n,) ordered x₁ y₁ x₂ y₂ …: whitened (2n,) and log |W|."""
    dt = np.r_[0.0, np.diff(t)][None]
    ex, ey, ld = nutation_filter(r[0::2][None].copy(), r[1::2][None].copy(), dt, spin,
                                 np.array([lam]), np.array([kap]), np.array([a]))
    e = np.empty_like(r)
    e[0::2], e[1::2] = ex[0], ey[0]
    return e, 2.0 * ld.sum()


@pytest.mark.parametrize("sign", [1.0, -1.0])
def test_filter_is_the_cholesky_whitening_of_the_nutation_covariance(sign):
    t, spin = _rows(sign=sign)
    r = np.random.default_rng(1).standard_normal(2 * t.size)
    L = np.linalg.cholesky(nutation_covariance(t, spin, 2.0, 0.94, 3.0))
    e, logdet = _filter(r, t, spin, 2.0, 0.94, 3.0)
    np.testing.assert_allclose(e, np.linalg.solve(L, r), atol=1e-10)
    np.testing.assert_allclose(logdet, -np.sum(np.log(np.diag(L))), rtol=1e-12)


def test_no_nutation_is_white_noise_and_outside_the_truncations_is_nan():
    t, spin = _rows()
    r = np.random.default_rng(2).standard_normal(2 * t.size)
    e, logdet = _filter(r, t, spin, 2.0, 0.94, 0.0)
    np.testing.assert_array_equal(e, r)
    assert logdet == 0.0
    for lam, a in ((0.0, 1.0), (-1.0, 1.0), (2.0, -0.5), (np.nan, 1.0)):
        assert np.isnan(_filter(r, t, spin, lam, 0.94, a)[0]).all()


def _profile_nll(par, r, t, spin):
    """−log p(r | λ, κ, a) with σ integrated out (Jeffreys), up to a constant."""
    lam, kap, a = par
    if lam <= 0 or a < 0:
        return np.inf
    e, logdet = _filter(r, t, spin, lam, kap, a)
    return 0.5 * r.size * np.log(np.sum(e * e)) - logdet


def _fit(r, t, spin):
    best = None
    for kap0 in (0.85, 0.95):
        o = minimize(_profile_nll, [3.0, kap0, 1.0], args=(r, t, spin), method="Nelder-Mead",
                     options={"maxiter": 4000, "xatol": 1e-6, "fatol": 1e-6})
        best = o if best is None or o.fun < best.fun else best
    return best.x


def test_a_drawn_nutation_is_recovered_and_white_noise_shows_none():
    rng = np.random.default_rng(5)
    t, spin = _rows(n=1500, seed=5)
    sigma, lam, kap, a = 0.1, 2.0, 0.93, 3.0
    z = sample_nutation(t, spin, lam, kap, a * sigma, rng)
    r = (z + sigma * rng.standard_normal(z.shape)).ravel()
    lam_f, kap_f, a_f = _fit(r, t, spin)
    assert abs(kap_f - kap) < 0.01
    assert 0.6 * lam < lam_f < 1.6 * lam
    assert 0.8 * a < a_f < 1.25 * a
    # white noise: no evidence for a nutation (3 more parameters; 6 nats is beyond their 99.9 % chance gain)
    white = (sigma * rng.standard_normal(z.shape)).ravel()
    gain = _profile_nll([lam, kap, 0.0], white, t, spin) - _profile_nll(_fit(white, t, spin), white, t, spin)
    assert 0.0 <= gain < 6.0
    assert _profile_nll([lam, kap, 0.0], r, t, spin) - _profile_nll([lam_f, kap_f, a_f], r, t, spin) > 100.0


def test_drawn_nutation_has_the_covariance_the_filter_assumes():
    """Many draws of sample_nutation against nutation_covariance (the same process twice)."""
    t, spin = _rows(n=12, seed=7)
    rng = np.random.default_rng(8)
    draws = np.array([sample_nutation(t, spin, 4.0, 0.9, 0.5, rng).ravel() for _ in range(20000)])
    cov = nutation_covariance(t, spin, 4.0, 0.9, 1.0) - np.eye(2 * t.size)       # a = 1: unit RMS
    np.testing.assert_allclose(np.cov(draws.T), 0.25 * cov, atol=0.012)


def _log(n=80, seed=3):
    rng = np.random.default_rng(seed)
    spin = 55.0 + rng.normal(0.0, 0.01, n)
    gyro = np.column_stack([rng.normal(0, 1, n), rng.normal(0, 1, n), spin])
    rows = np.arange(n)
    return InertialLog(name="synth", source="", fmt="flatball-ins", rows=rows, lines=rows + 2, gyro=gyro,
                       acc=rng.normal(0, 1, (n, 3)), mag=None, pressure=None)


def test_logger_model_whitens_its_transverse_gyro_with_the_filter():
    """The model's whitening and log-determinant against the dense covariance at its own row times."""
    log = _log()
    m = InertialMeasurements(log, 9.81, period=0.0122, gyro_noise="nutation")
    names = [p.name for p in m.shared_parameters] + [p.name for p in m.parameters]
    assert names[6:9] == ["nutation_decay", "nutation_kappa", "nutation_amplitude"]
    extra = np.array([[p.prior_centre for p in m.shared_parameters] + [p.off_value for p in m.parameters]])
    extra[0, 6:9] = 3.5, 0.92, 2.5
    extra[0, names.index("imu_period")] = 0.0125
    r = np.random.default_rng(4).standard_normal((1, m.group_index.size))
    e = m.whiten(r, extra)
    gyro_xy = np.isin(m.group_index, [1])
    t = 0.0125 * np.arange(log.rows.size)
    L = np.linalg.cholesky(nutation_covariance(t, log.gyro[:, 2], 3.5, 0.92, 2.5))
    np.testing.assert_allclose(e[0, gyro_xy], np.linalg.solve(L, r[0, gyro_xy]), atol=1e-10)
    np.testing.assert_array_equal(e[0, ~gyro_xy], r[0, ~gyro_xy])
    ld = m.log_det(extra)
    assert ld.shape == (1, 4)
    np.testing.assert_allclose(ld[0, 1], -np.sum(np.log(np.diag(L))), rtol=1e-12)
    assert np.all(ld[0, [0, 2, 3]] == 0.0)
    np.testing.assert_allclose(m.log_diagonal(extra)[0, gyro_xy].sum(), ld[0, 1], rtol=1e-12)
    white = InertialMeasurements(log, 9.81, period=0.0122)
    assert "nutation_decay" not in [p.name for p in white.shared_parameters]
    assert white.log_det(extra[:, [i for i in range(len(names)) if i not in (6, 7, 8)]]) is None


def test_gyro_noise_config_key(tmp_path):
    log = tmp_path / "log.csv"
    log.write_text("x\n")
    base = "name: t\nimu:\n  - {file: log.csv, format: flatball-ins%s}\n"
    (tmp_path / "ok.yaml").write_text(base % ", gyro_noise: nutation")
    assert load_config(tmp_path / "ok.yaml").imu[0].gyro_noise == "nutation"
    (tmp_path / "default.yaml").write_text(base % "")
    assert load_config(tmp_path / "default.yaml").imu[0].gyro_noise == "white"
    (tmp_path / "bad.yaml").write_text(base % ", gyro_noise: pink")
    with pytest.raises(ConfigError, match="gyro_noise"):
        load_config(tmp_path / "bad.yaml")
    with pytest.raises(ValueError, match="gyro_noise"):
        InertialMeasurements(_log(), 9.81, period=0.0122, gyro_noise="pink")


def test_synthesizer_adds_the_nutation_to_the_flight_rows_only(tmp_path):
    from dataclasses import replace
    from bayes_disc.observation.synth import synthesize
    from bayes_disc.observation.synth_config import synth_spec_from_mapping
    data = {"name": "n", "seed": 2, "imu": {"gyro_noise": [0.0, 0.0], "acc_noise": [0.0, 0.0],
                                            "nutation": [0.5, 4.0, 0.9]},
            "flights": [{"name": "a", "speed": 12.0, "spin": 55, "duration": 1.5}]}
    spec, _, _ = synth_spec_from_mapping(data, tmp_path / "s.yaml")
    with_nut = synthesize(spec)
    plain = synthesize(replace(spec, imu=replace(spec.imu, flights={
        k: replace(v, nutation=None) for k, v in spec.imu.flights.items()})))
    d = with_nut.imu_logs[0].gyro - plain.imu_logs[0].gyro
    moved = np.flatnonzero(np.any(d != 0.0, axis=1))
    entry = with_nut.truth["imu"]["throws"]["a"]
    assert moved.min() > entry["release_row"] - with_nut.imu_logs[0].rows[0]       # zero at release, then only in flight
    assert moved.max() < entry["end_row"] - with_nut.imu_logs[0].rows[0]
    assert np.all(d[:, 2] == 0.0)
    assert 0.3 < np.sqrt(np.mean(d[moved, :2] ** 2)) < 0.7
    assert with_nut.truth["imu"]["logger"]["nutation"] == {"rms_rad_s": 0.5, "decay_per_s": 4.0, "kappa": 0.9}
    for bad in ([0.5, 0.0, 0.9], [-0.1, 4.0, 0.9], [0.5, 4.0]):
        with pytest.raises(ConfigError, match="nutation"):
            synth_spec_from_mapping({**data, "imu": {**data["imu"], "nutation": bad}}, tmp_path / "s.yaml")
