"""Marker noise models (likelihoods): per-point errors and AR(1) noise against brute-force densities,
σ integrated out against numerical integration, least squares on defective data, the plain model unchanged."""
from dataclasses import replace

import numpy as np
import pytest
from scipy.integrate import quad
from scipy.stats import multivariate_normal

from bayes_disc.inference.model.initial import initial_state_from_data
from bayes_disc.inference.fitting.leastsq import _rms, refine_least_squares
from bayes_disc.inference.fitting.residuals import jacobian_blocks
from bayes_disc.inference.model.problem import Problem
from bayes_disc.observation.markers import FlightObservation, flights_from_table, read_marker_csv
from bayes_disc.observation.models import MarkerPositions, gaussian_marginal_loglik
from bayes_disc.observation.models.noise import AR1Noise, WhiteNoise, frame_index, marker_noise
from bayes_disc.observation.synth import DEFAULT_MARKERS, LaunchSpec, SynthSpec, synthesize
from bayes_disc.physics import Disc, Environment, literature_coefficients

from conftest import run_config, write_two_flights

MB = np.array(list(DEFAULT_MARKERS.values()))
IDS = tuple(DEFAULT_MARKERS)


def _flight(n=9, seed=0, missing=((2, 0), (3, 0), (5, 1)), gap_frames=(6,), sigma=False, cov=False):
    """A small flight with missing points and dropped frames (frames 0..n+len(gaps) without ``gap_frames``)."""
    rng = np.random.default_rng(seed)
    frames = np.array([f for f in range(n + len(gap_frames)) if f not in gap_frames])
    times = frames / 120.0
    pos = rng.normal(size=(frames.size, len(IDS), 3))
    for i, j in missing:
        pos[i, j] = np.nan
    sig = rng.uniform(0.5e-3, 5e-3, size=pos.shape[:2]) if sigma else None
    cv = None
    if cov:
        A = rng.normal(scale=2e-3, size=pos.shape[:2] + (3, 3))
        cv = A @ np.swapaxes(A, -1, -2) + 1e-7 * np.eye(3)
    return FlightObservation("f", "", times, IDS, pos, sigma=sig, cov=cv)


def _point_cov(data, sigma_f, g):
    """(P, 3, 3) per-point covariance σ_f² Σ_i / ḡ² of the observed points (σ_f² I without per-point errors)."""
    seen = data.observed
    if data.cov is not None:
        return sigma_f ** 2 * data.cov[seen] / g ** 2
    if data.sigma is not None:
        return (sigma_f * data.sigma[seen] / g)[:, None, None] ** 2 * np.eye(3)
    return np.repeat((sigma_f ** 2 * np.eye(3))[None], int(seen.sum()), axis=0)


def _ar1_covariance(data, rho, g):
    """Dense covariance K (3P, 3P) of AR(1) noise of unit σ_f (per marker and coordinate, exponent = frame
    distance) shaped per point: r = D z, z ~ AR(1), D the per-point scale (Cholesky)."""
    seen = data.observed
    ti, mi = np.nonzero(seen)
    frames = frame_index(data.times, "f")[ti]
    P = ti.size
    if data.cov is not None:
        S = np.linalg.cholesky(data.cov[seen]) / g
    elif data.sigma is not None:
        S = (data.sigma[seen] / g)[:, None, None] * np.eye(3)
    else:
        S = np.repeat(np.eye(3)[None], P, axis=0)
    same = mi[:, None] == mi[None, :]
    corr = np.where(same, rho ** np.abs(frames[:, None] - frames[None, :]).astype(float), 0.0)
    Kz = np.kron(corr, np.eye(3))
    D = np.zeros((3 * P, 3 * P))
    for a in range(P):
        D[3 * a: 3 * a + 3, 3 * a: 3 * a + 3] = S[a]
    return D @ Kz @ D.T


def _dense_logpdf(K1, r):
    """σ ↦ log N(r | 0, σ² K1), by dense linear algebra."""
    Q = float(r @ np.linalg.solve(K1, r))
    logdet = np.linalg.slogdet(2 * np.pi * K1)[1]
    return lambda s: -0.5 * Q / s ** 2 - 0.5 * (logdet + r.size * np.log(s ** 2))


def _conditional(model, r, sigma_f, extra):
    """The model's log p(y | θ, σ_f) = Σ [log N(e | 0, σ_f²) + log W_ii] (the pointwise sum)."""
    e = model.whiten(r[None], extra)[0]
    ld = model.log_diagonal(extra)
    out = np.sum(-0.5 * np.log(2 * np.pi * sigma_f ** 2) - 0.5 * e * e / sigma_f ** 2)
    return out + (0.0 if ld is None else float(np.sum(ld)))


def _marginal_numeric(logp_of_sigma):
    """log ∫ p(y | σ) dσ/σ by quadrature in u = log σ (shifted by the maximum for range)."""
    us = np.linspace(np.log(1e-6), np.log(1.0), 801)
    vals = np.array([logp_of_sigma(np.exp(u)) for u in us])
    top, u0 = vals.max(), us[np.argmax(vals)]
    integral, _ = quad(lambda u: np.exp(logp_of_sigma(np.exp(u)) - top), u0 - 3, u0 + 3, points=[u0], limit=200)
    return top + np.log(integral)


@pytest.mark.parametrize("kind", ["sigma", "cov"])
def test_per_point_likelihood_equals_brute_force_gaussian(kind):
    data = _flight(sigma=kind == "sigma", cov=kind == "cov")
    m = MarkerPositions(data, MB, per_point="true")
    assert m.noise.points.source == ("sigma_m" if kind == "sigma" else "covariance")
    g = m.noise.points.reference
    rng = np.random.default_rng(3)
    r = rng.normal(scale=3e-3, size=m.n_coords)
    for sigma_f in (0.5e-3, 2e-3, 7e-3):          # σ_f fixed: the conditional density
        C = _point_cov(data, sigma_f, g)
        brute = sum(multivariate_normal(np.zeros(3), C[i]).logpdf(r.reshape(-1, 3)[i]) for i in range(C.shape[0]))
        assert _conditional(m, r, sigma_f, None) == pytest.approx(brute, rel=1e-10, abs=1e-8)
    # σ integrated out (1/σ prior): the effective sum of squares gives the numerical integral of the brute force
    ss = m.sum_squares(m.effective_residuals(r[None], None))
    exact = m.log_likelihood(ss)[0]

    def brute_at(sigma_f):
        C = _point_cov(data, sigma_f, g)
        x = r.reshape(-1, 3)
        sol = np.linalg.solve(C, x[..., None])[..., 0]
        return float(np.sum(-0.5 * np.einsum("pi,pi->p", x, sol) - 0.5 * np.linalg.slogdet(2 * np.pi * C)[1]))
    assert exact == pytest.approx(_marginal_numeric(brute_at), abs=1e-6)
    # and it is not the one-σ likelihood (the per-point scales matter)
    assert abs(exact - gaussian_marginal_loglik(np.sum(r * r)[None, None], np.array([r.size]))[0]) > 1.0


@pytest.mark.parametrize("kind", ["white", "sigma", "cov", "ar1"])
def test_effective_sum_squares_of_a_prediction_equals_the_residual_route(kind):
    """MarkerPositions.effective_sum_squares (a compiled pass for W = I, the whitened residuals otherwise) equals
    sum_squares(effective_residuals(residuals(prediction))) on a grid with missing points and dropped frames,
    and is NaN for a failed prediction (NaN markers)."""
    data = _flight(sigma=kind == "sigma", cov=kind == "cov")
    m = MarkerPositions(data, MB, noise_model="ar1" if kind == "ar1" else "gaussian",
                        per_point="false" if kind in ("white", "ar1") else "true")
    assert m.noise.white == (kind == "white")
    rng = np.random.default_rng(5)
    pred = np.nan_to_num(data.positions)[None] + rng.normal(scale=3e-3, size=(4,) + data.positions.shape)
    pred[2] = np.nan
    extra = np.full((4, 1), 0.6) if kind == "ar1" else None
    route = m.sum_squares(m.effective_residuals(m.residuals(pred), extra))
    got = m.effective_sum_squares(pred, extra)
    assert got.shape == route.shape == (4, 1)
    assert np.all(np.isnan(got[2])) and np.all(np.isnan(route[2]))
    ok = [0, 1, 3]
    np.testing.assert_allclose(got[ok], route[ok], rtol=1e-13, atol=0)
    # the observed points only: moving an unseen point's prediction changes nothing
    i, j = 2, 0
    assert np.isnan(data.positions[i, j, 0])
    moved = pred.copy()
    moved[:, i, j] += 1.0
    np.testing.assert_array_equal(m.effective_sum_squares(moved, extra)[ok], got[ok])


@pytest.mark.parametrize("per_point", [False, True])
@pytest.mark.parametrize("rho", [0.85, -0.4])
def test_ar1_likelihood_equals_dense_normal_with_gaps(rho, per_point):
    data = _flight(n=10, sigma=per_point)
    m = MarkerPositions(data, MB, noise_model="ar1", per_point="true" if per_point else "false")
    assert isinstance(m.noise, AR1Noise) and [p.name for p in m.parameters] == ["rho"]
    g = m.noise.points.reference if per_point else 1.0
    r = np.random.default_rng(5).normal(scale=2e-3, size=m.n_coords)
    extra = np.array([[rho]])
    brute = _dense_logpdf(_ar1_covariance(data, rho, g), r)
    for sigma_f in (1e-3, 4e-3):
        assert _conditional(m, r, sigma_f, extra) == pytest.approx(brute(sigma_f), rel=1e-10)
    exact = m.log_likelihood(m.sum_squares(m.effective_residuals(r[None], extra)))[0]
    numeric = _marginal_numeric(brute)
    assert exact == pytest.approx(numeric, abs=1e-6)
    # σ drawn from σ² | θ, y ~ S / χ²_n with S the plain sum of squares of the whitened residuals
    ss = m.sum_squares(m.effective_residuals(r[None].repeat(4, 0), extra.repeat(4, 0)))
    drawn = m.draw_noise(ss, np.random.default_rng(9), extra.repeat(4, 0))
    S = np.sum(m.whiten(r[None], extra) ** 2)
    expected = np.sqrt(S / np.random.default_rng(9).chisquare(m.group_sizes, size=(4, 1)))
    np.testing.assert_allclose(drawn, expected, rtol=1e-12)
    with pytest.raises(ValueError, match="parameter values"):
        m.draw_noise(ss, np.random.default_rng(9))


def test_ar1_outside_the_unit_interval_has_zero_likelihood():
    m = MarkerPositions(_flight(), MB, noise_model="ar1")
    r = np.ones((2, m.n_coords)) * 1e-3
    ss = m.sum_squares(m.effective_residuals(r, np.array([[1.0], [0.5]])))
    assert not np.isfinite(ss[0, 0]) and np.isfinite(ss[1, 0])


def test_per_point_settings_and_errors():
    plain = _flight()
    assert isinstance(MarkerPositions(plain, MB).noise, WhiteNoise) and MarkerPositions(plain, MB).noise.white
    with pytest.raises(ValueError, match="per_point is true"):
        marker_noise(plain, "gaussian", "true")
    with pytest.raises(ValueError, match="noise.model: unknown value 'student'"):
        marker_noise(plain, "student", "auto")
    with pytest.raises(ValueError, match="noise.per_point: unknown value 'yes'"):
        marker_noise(plain, "gaussian", "yes")
    withsig = _flight(sigma=True)
    assert marker_noise(withsig, "gaussian", "auto").points.source == "sigma_m"
    assert marker_noise(withsig, "gaussian", "false").points is None
    bad = replace(withsig, sigma=np.where(np.arange(withsig.sigma.shape[0])[:, None] == 4, -1.0, withsig.sigma))
    with pytest.raises(ValueError, match=r"sigma_m missing or not positive at t = 0\.0333"):
        marker_noise(bad, "gaussian", "auto")
    irregular = replace(plain, times=plain.times * np.r_[1.0, np.linspace(1.0, 1.3, plain.times.size - 1)])
    with pytest.raises(ValueError, match="regular frame grid"):
        marker_noise(irregular, "ar1", "auto")


def test_covariance_columns_are_read_from_a_marker_file(tmp_path):
    rows = ["flight,t,marker,x,y,z,cov_xx,cov_xy,cov_xz,cov_yy,cov_yz,cov_zz"]
    for i in range(4):
        for j, mid in enumerate(IDS):
            rows.append(f"a,{i / 120:.6f},{mid},{0.1 * j:.3f},{0.01 * i:.3f},1.0,4e-6,1e-6,0,9e-6,-2e-6,1e-6")
    path = tmp_path / "m.csv"
    path.write_text("\n".join(rows) + "\n")
    (f,) = flights_from_table(read_marker_csv(path, IDS), IDS)
    np.testing.assert_allclose(f.cov[2, 1], [[4e-6, 1e-6, 0], [1e-6, 9e-6, -2e-6], [0, -2e-6, 1e-6]])
    assert marker_noise(f, "gaussian", "auto").points.source == "covariance"
    path.write_text("\n".join(r.rsplit(",", 1)[0] for r in rows) + "\n")      # cov_zz dropped
    with pytest.raises(ValueError, match=r"covariance column\(s\) \['cov_zz'\] missing"):
        flights_from_table(read_marker_csv(path, IDS), IDS, source=str(path))


# --------------------------------------------------------------------------------------------- on flights
@pytest.fixture(scope="module")
def clean():
    spec = SynthSpec(name="n", flights=(LaunchSpec(name="a", speed=13.0, launch_angle_deg=4, alpha_deg=7, spin=60,
                                                   duration=0.5, noise_mm=0.0),), seed=4)
    return synthesize(spec).flights[0]


def _problem(flight, **kw):
    m = MarkerPositions(flight, MB, **kw)
    return Problem(flights=[flight], marker_body=MB, disc=Disc(), env=Environment(), prior_name="weak",
                   start_states=[initial_state_from_data(flight, MB)], observations=[(m,)])


def _fit(problem):
    x = problem.start_vector()
    x[: problem.n_coef] = literature_coefficients("hummel2002").as_array()
    return refine_least_squares(problem, x, max_nfev=100)


def with_ar1_noise(flight, rho: float = 0.85, sd: float = 2e-3, seed: int = 11):
    """The flight with stationary AR(1) noise (coefficient ρ per sample, sd [m]) added to every coordinate."""
    rng = np.random.default_rng(seed)
    n, m = flight.positions.shape[:2]
    z = np.empty((n, m, 3))
    z[0] = rng.normal(size=(m, 3))
    for i in range(1, n):
        z[i] = rho * z[i - 1] + np.sqrt(1 - rho ** 2) * rng.normal(size=(m, 3))
    return replace(flight, positions=flight.positions + sd * z)


def test_least_squares_estimates_rho_of_ar1_noise(clean):
    noisy = with_ar1_noise(clean)
    ls = _fit(_problem(noisy, noise_model="ar1"))
    rho = ls.theta[ls.names.index("rho_a")]
    assert 0.7 < rho < 0.95, rho
    white = _fit(_problem(noisy))
    assert "rho_a" not in white.names


@pytest.mark.parametrize("gap, step", [(0.5, 1e-4), (1e-6, 1e-4)])
def test_jacobian_at_the_edge_of_rho_is_finite(clean, gap, step):
    """ρ a fraction ``gap`` of a finite-difference step below 1: the lane beyond 1 has no likelihood
    (non-finite residuals), so ρ's column is recomputed with tenfold smaller steps: the derivative once both
    lanes lie below 1 and the residuals are linear over the step (half a step below), the backward difference
    at the smallest step when no step fits (10⁻⁶ of a step below); every other column stays the central
    difference with the default step."""
    noisy = with_ar1_noise(clean, rho=0.99)
    problem = _problem(noisy, noise_model="ar1")
    i = problem.names.index("rho_a")
    x = _fit(problem).theta.copy()
    h = 1e-4 * problem.prior_sd[i]
    x[i] = 1.0 - gap * h
    sigma = np.ones(problem.n_groups)
    J = jacobian_blocks(x, problem, sigma)
    assert all(np.all(np.isfinite(b)) for b in J.blocks)
    below, above = x.copy(), x.copy()
    below[i] -= step * h
    above[i] += step * h
    r_below = problem.noise_residuals(below, 0)[0][0]
    if gap > step:      # the derivative: a central difference with a step far smaller than any tried
        want = (problem.noise_residuals(above, 0)[0][0] - r_below) / (2 * step * h)
        np.testing.assert_allclose(J.blocks[0][:, -1], want, rtol=0, atol=1e-3 * np.abs(want).max())  # ρ: last own
    else:               # the backward difference with the smallest step tried
        want = (problem.noise_residuals(x, 0)[0][0] - r_below) / (step * h)
        np.testing.assert_allclose(J.blocks[0][:, -1], want, rtol=1e-9, atol=0)
    hc = 1e-4 * problem.prior_sd[0]
    up, down = x.copy(), x.copy()
    up[0] += hc
    down[0] -= hc
    central = (problem.noise_residuals(up, 0)[0][0] - problem.noise_residuals(down, 0)[0][0]) / (2 * hc)
    np.testing.assert_allclose(J.blocks[0][:, 0], central, rtol=1e-9, atol=0)          # CL0: central


def test_per_point_errors_weight_the_fit(clean):
    """10× noise on the second half of the flight: with sigma_m the scale factor is ≈ 1 and the fit's
    coefficient uncertainties are smaller, overall, than with one σ for the flight (a coefficient pinned by its
    prior may not gain). Both covariances are taken at the per-point optimum: this 0.5 s flight leaves CM0–CMa
    in a flat, curved valley where the one-σ fit's optimum (and its local curvature, ×6 in CM0's sd) depends on
    the minimiser's path (scipy's TRF and the block Levenberg–Marquardt end 0.16 apart in cost), which is not
    what the weighting changes."""
    rng = np.random.default_rng(12)
    n = clean.times.size
    s = np.where(np.arange(n)[:, None] < n // 2, 1e-3, 1e-2) * np.ones(clean.positions.shape[:2])
    noisy = replace(clean, positions=clean.positions + s[..., None] * rng.normal(size=clean.positions.shape), sigma=s)
    per_point = _problem(noisy)                                    # auto: the sigma column is used
    assert per_point.channels[0][0].noise.points.source == "sigma_m"
    ls_pp = _fit(per_point)
    g = per_point.channels[0][0].noise.points.reference
    assert 0.8 < ls_pp.sigma[0] / g < 1.25, ls_pp.sigma[0] / g
    one = _problem(noisy, per_point="false")
    cov_one = jacobian_blocks(ls_pp.theta, one, _rms(one, ls_pp.theta)).information().inverse()
    sd_pp, sd_one = np.sqrt(np.diag(ls_pp.cov))[:10], np.sqrt(np.diag(cov_one))[:10]
    assert np.exp(np.mean(np.log(sd_pp / sd_one))) < 0.85, sd_pp / sd_one


def test_plain_gaussian_log_prob_is_unchanged_on_the_demo_data():
    """The default model's log-posterior is the prior plus ½ Γ(n/2)(π S)^(−n/2) of the plain residuals (the
    effective residuals are the residuals themselves), to rounding: S is summed in one compiled pass over the
    observed points (:meth:`MarkerPositions.effective_sum_squares`), in another order than numpy's pairwise
    sum of the residual array."""
    from conftest import REPO
    from bayes_disc.inference.model.config import load_config
    from bayes_disc.inference.model.data import build_problem
    cfg = load_config(REPO / "runs" / "demo" / "config.yaml")
    problem = build_problem(cfg)
    assert all(c.noise.white for ch in problem.channels for c in ch)
    theta = problem.start_vector()[None] + 1e-4 * problem.prior_sd * np.random.default_rng(1).normal(size=(3, problem.dim))
    ss = np.column_stack([np.sum(problem.residuals(theta, k)[0] ** 2, axis=1) for k in range(problem.n_flights)])
    ll = 0.0
    for k in range(problem.n_flights):              # the sum as the one-σ code forms it, flight by flight
        ll = ll + gaussian_marginal_loglik(ss[:, k: k + 1], problem.n_coords[k: k + 1])
    expected = problem.log_prior(theta) + ll
    np.testing.assert_allclose(problem.log_prob(theta), expected, rtol=1e-13, atol=0)
    np.testing.assert_allclose(problem.sum_squares(theta), ss, rtol=1e-13, atol=0)


# --------------------------------------------------------------------------------------------- the pipeline


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    """Two short synthetic flights; flight b's rows carry a sigma_m column (flight a's are empty)."""
    from bayes_disc.observation.markers import write_marker_csv
    d = tmp_path_factory.mktemp("noise")
    write_two_flights(d, 0.25)
    table = read_marker_csv(d / "flights.csv")
    table.extra["sigma_m"] = np.where(table.flight == "b", np.linspace(1e-3, 4e-3, len(table)), np.nan)
    write_marker_csv(d / "flights.csv", table)
    return d


def _config(folder, name, extra):
    from bayes_disc.inference.model.config import load_config
    path = folder / f"{name}.yaml"
    path.write_text(run_config(name, extra))
    return load_config(path)


def test_noise_configuration_keys_and_errors(folder):
    from bayes_disc.inference.model.data import build_problem
    from bayes_disc.observation.config_io import ConfigError
    cfg = _config(folder, "c", "noise: {model: ar1}\nflight_options: {b: {noise: {per_point: false}}}")
    assert cfg.flight_noise("a")[0].model == "ar1" and cfg.flight_noise("b")[0].per_point == "false"
    assert cfg.flight_noise("b")[0].model == "ar1"
    with pytest.raises(ConfigError, match=r"noise\.model.*one of \['auto', 'gaussian', 'ar1', 'robust'\], got 'student'"):
        _config(folder, "c", "noise: {model: student}")
    with pytest.raises(ConfigError, match=r"noise\.per_point.*got 'maybe'"):
        _config(folder, "c", "noise: {per_point: maybe}")
    with pytest.raises(ConfigError, match=r"noise\.rho.*unknown key"):
        _config(folder, "c", "noise: {rho: 0.5}")
    with pytest.raises(ConfigError, match=r"flight_options\.a\.noise\.per_point"):
        _config(folder, "c", "flight_options: {a: {noise: {per_point: yes please}}}")
    # flight a has no sigma_m values: asking for them names the flight's key, the point and the fix
    with pytest.raises(ConfigError, match=r"flight_options\.a\.noise.*sigma_m missing.*per_point: false"):
        build_problem(_config(folder, "c", "flight_options: {a: {noise: {per_point: true}}}"))
    with pytest.raises(ConfigError, match=r"'noise'.*flight 'a'.*sigma_m missing"):
        build_problem(_config(folder, "c", "noise: {per_point: true}"))


def test_ar1_and_per_point_run_through_the_outputs(folder):
    """Fake chains around the truth through σ draws, posterior.nc (rho with a flight dimension, pointwise
    log-likelihood = the exact conditional log-likelihood, predictive draws) and summary.json."""
    from bayes_disc.inference.model.data import build_problem
    from bayes_disc.inference.results.idata import build_inference_data
    from bayes_disc.inference.results.summary import build_summary
    from bayes_disc.inference.model.describe import noise_info, noise_words
    from bayes_disc.inference.sampling.chains import Chains
    cfg = _config(folder, "r", "flight_options: {a: {noise: {model: ar1, per_point: false}}}")
    problem = build_problem(cfg)
    info = noise_info(problem)
    assert info["a"]["model"] == "ar1" and info["a"]["per_point"] is None
    assert info["b"]["model"] == "gaussian" and info["b"]["per_point"] == "sigma_m"
    assert "a: ar1, one σ" in noise_words(info) and "b: gaussian, per-point errors from sigma_m" in noise_words(info)
    assert "rho_a" in problem.names and "rho_b" not in problem.names
    rng = np.random.default_rng(0)
    n_ens, n_steps, n_w = 2, 6, 4
    x = problem.start_vector()
    x[problem.names.index("rho_a")] = 0.5
    chain = x + 1e-5 * problem.prior_sd * rng.standard_normal((n_ens, n_steps, n_w, problem.dim))
    flat = chain.reshape(-1, problem.dim)
    ss = problem.sum_squares(flat)
    sigma = problem.draw_sigma(ss, np.random.default_rng(1), flat)
    # flight a's σ is the marginal one: S (plain sum of whitened squares) / χ², not the effective S̃
    m = problem.channels[0][0]
    S = np.sum(m.whiten(problem.residuals(flat, 0)[0], flat[:, problem.channel_columns(0)[0]]) ** 2, axis=1)
    ref = np.random.default_rng(1).chisquare(problem.n_coords[0], size=(ss.shape[0], 1))[:, 0]   # flight a first
    np.testing.assert_allclose(sigma[:, 0], np.sqrt(S / ref), rtol=1e-12)
    lp = problem.log_prob(flat).reshape(n_ens, n_steps, n_w)
    chains = Chains(chain=chain, log_prob=lp, sigma=sigma.reshape(n_ens, n_steps, n_w, -1),
                    acceptance=np.full((n_ens, n_w), 0.3), burn=0, total_steps=n_steps,
                    tau=np.ones((n_ens, problem.dim)), converged=False, reason="test")
    idata = build_inference_data(problem, chains, np.random.default_rng(2), n_prior=20,
                                 n_log_likelihood=n_ens * n_w * n_steps, n_predictive=n_ens * n_w * 2)
    post = idata.posterior
    assert post["rho"].dims == ("chain", "draw", "flight") and np.isnan(post["rho"].sel(flight="b")).all()
    summary = build_summary(problem, chains, idata, {}, {"name": "r", "noise": info})
    assert "rho_a" in summary["parameters"] and summary["noise"]["b"]["per_point"] == "sigma_m"
    # pointwise log-likelihood of flight a sums to its exact conditional log-likelihood for the draw's σ, ρ
    ll = idata.log_likelihood["markers"]
    a_points = ll["point_flight"].values == "a"
    total = ll.values[0, 0][a_points].sum()                       # chain 0 = ensemble 0 walker 0, step 0
    th, s_a = chain[0, 0, 0], chains.sigma[0, 0, 0, 0]
    extra = th[None, problem.channel_columns(0)[0]]
    e = m.whiten(problem.residuals(th[None], 0)[0], extra)[0]
    exact = (-0.5 * e.size * np.log(2 * np.pi * s_a ** 2) - 0.5 * np.sum(e * e) / s_a ** 2
             + np.sum(m.log_diagonal(extra)))
    assert total == pytest.approx(exact, rel=1e-5)
    pp = idata.posterior_predictive
    assert np.all(np.isfinite(pp["markers_a"].values)) and np.all(np.isfinite(pp["markers_b"].values))


# --------------------------------------------------------------------------------------------- robust
def test_robust_flags_an_outlier_and_recognises_a_swap(clean):
    """A 5 cm outlier and one frame with markers 0 and 2 exchanged, on a least-squares fit of a short flight:
    the outlier is listed as an outlier, the frame as a swap of 0 and 2 (not as two outliers), and the
    refit on the cleaned data recovers the clean fit."""
    from bayes_disc.inference.fitting.robust import robust_refit
    rng = np.random.default_rng(21)
    pos = clean.positions + 1.5e-3 * rng.normal(size=clean.positions.shape)
    plain = replace(clean, positions=pos.copy())
    pos[10, 1] += np.array([0.03, -0.04, 0.0])                 # |Δ| = 5 cm
    pos[25, [0, 2]] = pos[25, [2, 0]]
    bad = replace(clean, positions=pos)
    problem = _problem(bad, noise_model="robust")
    ls0 = _fit(problem)
    cleaned, ls, flags = robust_refit(problem, ls0, max_nfev=100)
    f = flags["a"]
    assert [(o["t"], o["marker"]) for o in f["outliers"]] == [(clean.times[10], IDS[1])], f
    assert [(s["t"], s["markers"]) for s in f["swaps"]] == [(clean.times[25], [IDS[0], IDS[2]])], f
    assert f["swaps"][0]["probability"] > 0.99 and f["outliers"][0]["probability"] > 0.99
    assert cleaned.flights[0].n_points == bad.n_points - 1
    np.testing.assert_array_equal(cleaned.flights[0].positions[25], plain.positions[25])
    ref = refine_least_squares(_problem(plain), ls0.theta, max_nfev=100)     # the clean data, same start
    sd = np.sqrt(np.diag(ref.cov))[:10]
    assert np.all(np.abs(ls.theta[:10] - ref.theta[:10]) < 0.5 * sd)
    assert np.any(np.abs(ls0.theta[:10] - ref.theta[:10]) > 0.5 * sd)      # the defects did pull the plain fit


def test_gaussian_runs_are_warned_of_gross_errors_and_clean_data_are_not(clean, caplog):
    """With plain Gaussian noise, outliers and a swapped frame in the data are reported with the fix
    (`noise: {model: robust}`) before sampling; on clean data (and with robust noise) nothing is said."""
    import logging

    from bayes_disc.inference.fitting.robust import gross_error_advice, suspected_gross_errors
    from bayes_disc.jobs.sample import _robust
    rng = np.random.default_rng(22)
    pos = clean.positions + 1.5e-3 * rng.normal(size=clean.positions.shape)
    plain = _problem(replace(clean, positions=pos.copy()))
    assert suspected_gross_errors(plain, _fit(plain).theta) == {}
    assert gross_error_advice({}) is None
    for i, j in ((5, 0), (17, 1), (33, 2)):
        pos[i, j] += rng.choice([-1, 1], size=3) * 0.02
    pos[40, [0, 1]] = pos[40, [1, 0]]
    bad = _problem(replace(clean, positions=pos))
    ls = _fit(bad)
    suspects = suspected_gross_errors(bad, ls.theta)
    assert suspects == {"a": {"outliers": 3, "swaps": 1, "points": bad.flights[0].observed.sum()}}
    assert "noise more likely varies" not in gross_error_advice(suspects)
    assert "noise more likely varies" in gross_error_advice({"a": {"outliers": 30, "swaps": 0, "points": 600}})
    with caplog.at_level(logging.WARNING, logger="bayes_disc"):
        _robust(bad, ls, {}, None, None)
    assert "a: 3 point(s) as gross errors, 1 frame(s) as swapped labels" in caplog.text
    assert "noise: {model: robust}" in caplog.text
    # AR(1) flights are not judged (their residuals are correlated by design)
    ar1 = _problem(replace(clean, positions=pos), noise_model="ar1")
    assert suspected_gross_errors(ar1, ar1.start_vector()) == {}


def test_classification_probabilities_by_hand():
    """Two markers far apart, one frame: exchanged labels are a swap; one displaced marker is an outlier."""
    from bayes_disc.observation.models.outliers import (OUTLIER_FRACTION, OUTLIER_WIDTH_M, SWAP_FRACTION,
                                                        classify, clean_flight)
    pred = np.array([[[0.0, 0.0, 1.0], [0.1, 0.0, 1.0], [0.0, 0.1, 1.0]]] * 3)
    obs = pred.copy()
    obs[1, [0, 1]] = obs[1, [1, 0]]
    obs[2, 2] += [0.0, 0.0, 0.03]
    s = np.full((3, 3), 2e-3)
    c = classify("f", np.arange(3) / 120, IDS, pred, obs, s)
    assert c.swapped_frames() == [(1, 0, 1, pytest.approx(1.0))]
    assert [(i, j) for i, j, _ in c.outlier_points()] == [(2, 2)]
    # frame 2 by hand: H0 with point 2 an outlier against every swap hypothesis
    ln3 = lambda r, sd: -1.5 * np.log(2 * np.pi * sd ** 2) - 0.5 * np.sum(np.square(r)) / sd ** 2
    inl = lambda r: np.logaddexp(np.log1p(-OUTLIER_FRACTION) + ln3(r, 2e-3), np.log(OUTLIER_FRACTION) + ln3(r, OUTLIER_WIDTH_M))
    out2 = np.log(OUTLIER_FRACTION) + ln3([0, 0, 0.03], OUTLIER_WIDTH_M) - inl([0, 0, -0.03])
    assert c.outlier[2, 2] == pytest.approx(np.exp(out2) * (1 - c.swap[2].sum()), rel=1e-6)
    data = FlightObservation("f", "", np.arange(3) / 120, IDS, obs)
    fixed = clean_flight(data, c.records())
    np.testing.assert_array_equal(fixed.positions[1], pred[1])
    assert np.isnan(fixed.positions[2, 2]).all() and fixed.n_points == 8
    with pytest.raises(ValueError, match="no sample at t = 5"):
        clean_flight(data, {"outliers": [{"t": 5.0, "marker": IDS[0]}]})
    assert SWAP_FRACTION == 0.01


def test_sample_with_robust_and_ar1_noise_writes_the_flags(tmp_path, monkeypatch):
    """`bayes-disc sample` end to end (short chains): flight a (robust) has a 4 cm outlier and a swapped frame
    edited into its CSV, flight b has AR(1) noise; flagged.json, the log, summary.json and posterior.nc say so."""
    import json
    import logging
    import arviz as az
    from bayes_disc.cli import main
    from bayes_disc.observation.markers import write_marker_csv
    from bayes_disc.observation.synth import write_synth
    monkeypatch.chdir(tmp_path)
    flights = (LaunchSpec(name="a", speed=12.0, launch_angle_deg=4, alpha_deg=8, spin=55, duration=0.3, noise_mm=1.5),
               LaunchSpec(name="b", speed=10.0, launch_angle_deg=8, alpha_deg=12, spin=-50, duration=0.3, noise_mm=1.5))
    write_synth(synthesize(SynthSpec(name="s", flights=flights, seed=6)), tmp_path / "flights.csv", tmp_path / "truth.json")
    table = read_marker_csv(tmp_path / "flights.csv")
    rows_a = np.flatnonzero(table.flight == "a")
    t_out, t_swap = table.t[rows_a[30]], table.t[rows_a[45]]
    table.xyz[rows_a[30]] += [0.0, 0.04, 0.0]
    frame = rows_a[table.t[rows_a] == t_swap]
    m = {str(table.marker[r]): r for r in frame}
    table.xyz[[m["0"], m["1"]]] = table.xyz[[m["1"], m["0"]]]
    write_marker_csv(tmp_path / "flights.csv", table)
    (tmp_path / "config.yaml").write_text(run_config("rob", (
        "output: out\nnoise: {model: robust}\nflight_options: {b: {noise: {model: ar1}}}\n"
        "sampler: {ensembles: 2, max_steps: 30, adapt_steps: 10, check_every: 10, min_steps: 10, seed: 5}\n"
        "least_squares: {starts: 1}")))
    records = []
    handler = logging.Handler()
    handler.emit = lambda rec: records.append(rec.getMessage())
    logging.getLogger("bayes_disc").addHandler(handler)
    try:
        assert main(["sample", str(tmp_path / "config.yaml"), "--no-progress"]) == 0
    finally:
        logging.getLogger("bayes_disc").removeHandler(handler)
    flags = json.loads((tmp_path / "out" / "flagged.json").read_text())
    assert [(o["t"], o["marker"]) for o in flags["a"]["outliers"]] == [(pytest.approx(t_out), str(table.marker[rows_a[30]]))]
    assert [(w["t"], w["markers"]) for w in flags["a"]["swaps"]] == [(pytest.approx(t_swap), ["0", "1"])]
    assert "b" not in flags
    assert any("labels swapped" in r for r in records) and any("outlier (p =" in r for r in records)
    assert any("marker noise: a: robust" in r and "b: ar1" in r for r in records)
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert summary["flagged"] == {"file": "flagged.json", "outliers": 1, "swaps": 1}
    assert summary["noise"]["a"]["model"] == "robust" and summary["noise"]["b"]["model"] == "ar1"
    assert "rho_b" in summary["parameters"] and "rho_a" not in summary["parameters"]
    post = az.from_netcdf(str(tmp_path / "out" / "posterior.nc")).posterior
    assert np.isfinite(post["rho"].sel(flight="b")).all() and np.isnan(post["rho"].sel(flight="a")).all()
    # the posterior averaged over the judgement: the sampled draws (at most JUDGEMENT_DRAWS) reweighted
    from bayes_disc.inference.fitting.robust import JUDGEMENT_DRAWS
    avg = json.loads((tmp_path / "out" / "judgement_average.json").read_text())
    assert avg["draws"] == min(JUDGEMENT_DRAWS, post.sizes["chain"] * post.sizes["draw"]) and avg["failed"] == 0
    assert np.isfinite(avg["pareto_k"]) and 1 <= avg["ess"] <= avg["draws"]
    assert set(avg["conditional"]) == set(summary["coefficients"])
    n_draws = post.sizes["chain"] * post.sizes["draw"]
    for name, c in avg["conditional"].items():      # equally weighted: a subset of the draws summarised
        if avg["draws"] == n_draws:
            assert c["q50"] == pytest.approx(float(post[name].median()), rel=1e-9), name
        assert c["q05"] < c["q50"] < c["q95"] and c["q05"] >= float(post[name].min()), name
    assert avg["reliable"] == (avg["pareto_k"] <= 0.7) and (set(avg["averaged"]) == set(avg["conditional"])) == avg["reliable"]
    assert any(r.startswith("averaged over the judgement:") for r in records)


@pytest.mark.slow
def test_four_flights_with_outliers_and_swaps_sampled_inside_the_clean_intervals(tmp_path, monkeypatch):
    """Four flights with 2–6 cm outliers on 1 % of the points and labels swapped in a few frames, sampled with
    the default configuration (``noise: auto``): every flight gets the robust model and the log and summary.json
    say so, every injected defect is listed, and every coefficient's median lies inside the 90 % interval of
    the same data without the defects (sampled with the default configuration too), both given the judgement and
    averaged over it."""
    import json
    from bayes_disc.cli import main
    from bayes_disc.observation.markers import write_marker_csv
    from bayes_disc.observation.synth import write_synth
    monkeypatch.chdir(tmp_path)
    flights = (LaunchSpec(name="f1", speed=13.0, launch_angle_deg=4, alpha_deg=6, spin=60, duration=0.6, noise_mm=1.5),
               LaunchSpec(name="f2", speed=11.0, launch_angle_deg=8, alpha_deg=14, spin=55, duration=0.6, noise_mm=1.5),
               LaunchSpec(name="f3", speed=14.0, launch_angle_deg=2, alpha_deg=2, spin=65, duration=0.6, noise_mm=1.5),
               LaunchSpec(name="f4", speed=12.0, launch_angle_deg=6, alpha_deg=10, spin=58, duration=0.6, noise_mm=1.5))
    for d in ("clean", "defects"):
        (tmp_path / d).mkdir()
        write_synth(synthesize(SynthSpec(name="s", flights=flights, seed=16)), tmp_path / d / "flights.csv",
                    tmp_path / d / "truth.json")
    table = read_marker_csv(tmp_path / "defects" / "flights.csv")
    rng = np.random.default_rng(16)
    outliers = rng.choice(len(table), size=max(1, len(table) // 100), replace=False)
    u = rng.normal(size=(outliers.size, 3))
    table.xyz[outliers] += (u / np.linalg.norm(u, axis=1, keepdims=True)) * rng.uniform(0.02, 0.06, (outliers.size, 1))
    swaps = []
    for name in ("f1", "f3", "f4"):
        rows = np.flatnonzero(table.flight == name)
        t = np.unique(table.t[rows])[rng.integers(10, 60)]
        frame = [r for r in rows if table.t[r] == t and r not in outliers][:2]
        table.xyz[frame] = table.xyz[frame[::-1]]
        swaps.append((name, float(t)))
    write_marker_csv(tmp_path / "defects" / "flights.csv", table)
    for d in ("clean", "defects"):
        (tmp_path / d / "config.yaml").write_text(run_config(d, "output: out\nsampler: {seed: 3, max_steps: 1500}"))
        assert main(["sample", str(tmp_path / d / "config.yaml"), "--no-progress"]) == 0
    clean_s = json.loads((tmp_path / "clean" / "out" / "summary.json").read_text())
    robust_s = json.loads((tmp_path / "defects" / "out" / "summary.json").read_text())
    assert all(r["label"] == "white" for r in clean_s["noise_choice"].values()), clean_s["noise_choice"]
    for name, r in robust_s["noise_choice"].items():
        assert r["label"] == "robust" and r["by"] == "gross errors", (name, r)
        assert robust_s["noise"][name]["model"] == "robust"
        assert r["text"].startswith(f"{name}: robust noise chosen")
    flags = json.loads((tmp_path / "defects" / "out" / "flagged.json").read_text())
    listed = {(o["flight"], round(o["t"], 6), o["marker"]) for f in flags.values() for o in f["outliers"]}
    injected = {(str(table.flight[r]), round(float(table.t[r]), 6), str(table.marker[r])) for r in outliers}
    assert injected <= listed and len(listed) <= len(injected) + 2, (injected, listed)
    assert {(w["flight"], round(w["t"], 6)) for f in flags.values() for w in f["swaps"]} == \
        {(n, round(t, 6)) for n, t in swaps}
    for c in clean_s["coefficients"]:
        lo, hi = clean_s["parameters"][c]["q05"], clean_s["parameters"][c]["q95"]
        assert lo <= robust_s["parameters"][c]["q50"] <= hi, (c, robust_s["parameters"][c]["q50"], lo, hi)
    # averaged over the judgement (importance weights to the mixture likelihood): trusted weights, and the
    # averaged medians inside the clean data's 90 % intervals too
    avg = json.loads((tmp_path / "defects" / "out" / "judgement_average.json").read_text())
    assert avg["reliable"] and avg["pareto_k"] <= 0.7 and avg["failed"] == 0, avg["pareto_k"]
    for c in clean_s["coefficients"]:
        lo, hi = clean_s["parameters"][c]["q05"], clean_s["parameters"][c]["q95"]
        assert lo <= avg["averaged"][c]["q50"] <= hi, (c, avg["averaged"][c], lo, hi)


def _defective_frames(rng, n, outlier_share, width, swap_share, sigma=2e-3):
    """n frames of three markers 0.1 m from a wandering centre, N(0, σ²) noise; a share of the points
    displaced by N(0, width²) per coordinate, a share of the frames with one random pair's labels exchanged."""
    ang = np.deg2rad([0.0, 120.0, 240.0])
    disc = 0.1 * np.stack([np.cos(ang), np.sin(ang), np.zeros(3)], axis=1)
    pred = np.cumsum(0.05 * rng.normal(size=(n, 1, 3)), axis=0) + disc[None]
    obs = pred + sigma * rng.normal(size=pred.shape)
    out = rng.random((n, 3)) < outlier_share
    obs[out] += width * rng.normal(size=(out.sum(), 3))
    swapped = np.flatnonzero(rng.random(n) < swap_share)
    pair = [(0, 1), (0, 2), (1, 2)]
    truth = {}
    for i in swapped:
        j, l = pair[rng.integers(3)]
        obs[i, [j, l]] = obs[i, [l, j]]
        truth[int(i)] = (j, l)
    return pred, obs, out, truth, np.full((n, 3), sigma)


def test_mixture_shares_and_spread_are_estimated_and_fix_the_judgement():
    """EM estimates π, w, π_s near the truth (10 % gross errors of 30 cm, 5 % swapped frames), and at them
    every gross error and swap is found with no false flag, where the priors' centre (1 %, 5 cm, 1 %)
    flags points and frames wrongly. Without defects the shares stay small and w near its prior centre;
    the result is a fixed point of EM."""
    from bayes_disc.observation.models.outliers import PRIOR_SHAPE, classify, estimate_shape, fit_mixture
    rng = np.random.default_rng(31)
    n = 1000
    pred, obs, out, swaps, s = _defective_frames(rng, n, 0.10, 0.30, 0.05)
    times = np.arange(n) / 120

    def errors(c):
        flagged = np.nan_to_num(c.outlier) > 0.5
        found = {i: (j, l) for i, j, l, _ in c.swapped_frames()}
        return (int(np.sum(flagged & ~out)), int(np.sum(~flagged & out)),
                len(set(found.items()) ^ set(swaps.items())))
    em = fit_mixture("f", times, IDS, pred, obs, s)
    sh = em.shape
    assert 0.08 < sh.outlier_fraction < 0.12 and 0.26 < sh.width < 0.34 and 0.035 < sh.swap_fraction < 0.065, sh
    assert errors(em) == (0, 0, 0)
    fixed = classify("f", times, IDS, pred, obs, s, PRIOR_SHAPE)
    wrong = errors(fixed)
    assert wrong[0] + wrong[2] > 10, wrong                      # the priors' centre misjudges: measured gain
    again = estimate_shape(classify("f", times, IDS, pred, obs, s, sh))
    np.testing.assert_allclose([again.outlier_fraction, again.width, again.swap_fraction],
                               [sh.outlier_fraction, sh.width, sh.swap_fraction], rtol=1e-5)
    assert em.records()["mixture"] == sh.record()
    pred, obs, out, swaps, s = _defective_frames(rng, n, 0.0, 0.0, 0.0)
    quiet = fit_mixture("f", times, IDS, pred, obs, s)
    q = quiet.shape
    assert q.outlier_fraction < 2.5 / (3 * n + 200) and q.swap_fraction < 2.5 / (n + 200), q
    assert 0.035 < q.width < 0.05 and errors(quiet) == (0, 0, 0), q
