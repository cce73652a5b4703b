"""Block-arrow normal equations (bayes_disc.inference.fitting.arrow) and the Levenberg–Marquardt minimiser built on
them: the structured solves against dense linear algebra, and the new solver's optimum and
covariance against scipy's dense trust-region fit on a small problem."""
import numpy as np
import pytest
from scipy.optimize import least_squares

from bayes_disc.inference.fitting.arrow import ArrowJacobian
from bayes_disc.inference.model.initial import initial_state_from_data
from bayes_disc.inference.fitting import profile
from bayes_disc.inference.fitting.residuals import (FAILED_RESIDUAL, jacobian_blocks, whitened_costs,
                                                    whitened_jacobian, whitened_residuals)
from bayes_disc.inference.fitting.minimiser import MU_NEAR, decrement, minimise
from bayes_disc.inference.fitting.leastsq import START_DECREMENT, refine_least_squares, _rms
from bayes_disc.inference.fitting.covariance import covariance_from_jacobian
from bayes_disc.inference.model.problem import Problem
from bayes_disc.observation.synth import DEFAULT_MARKERS, LaunchSpec, SynthSpec, synthesize


def _random_jacobian(rng, s=4, own=(3, 5, 2), rows=(30, 40, 25)):
    """A random block Jacobian whose columns span ~8 decades (as the coefficients beside positions do)."""
    n = s + sum(own)
    order = rng.permutation(n)              # unknowns need not be contiguous
    shared, parts, j = order[:s], [], s
    for p in own:
        parts.append(order[j: j + p])
        j += p
    scale = 10.0 ** rng.uniform(-4, 4, size=n)
    blocks = tuple(rng.normal(size=(m, s + p)) * np.r_[scale[shared], scale[o]]
                   for m, p, o in zip(rows, own, parts))
    return ArrowJacobian(shared=shared, own=tuple(parts), blocks=blocks, prior=rng.uniform(0.1, 2.0, size=n) / scale)


def test_structured_solves_equal_dense_linear_algebra():
    rng = np.random.default_rng(0)
    J = _random_jacobian(rng)
    D = J.dense()
    H = J.information()
    Hd = D.T @ D
    np.testing.assert_allclose(H.dense(), Hd, rtol=1e-10, atol=1e-12 * np.abs(Hd).max())
    r = [rng.normal(size=b.shape[0]) for b in J.blocks]
    rp = rng.normal(size=J.n)
    np.testing.assert_allclose(J.gradient(r, rp), D.T @ np.concatenate(r + [rp]), rtol=1e-10,
                               atol=1e-12 * np.abs(D).max())
    g = rng.normal(size=J.n)
    for mu in (0.0, 1e-3, 10.0):
        expected = np.linalg.solve(Hd + mu * np.diag(np.diag(Hd)), g)
        np.testing.assert_allclose(H.solve(g, mu), expected, rtol=1e-7)
    x = rng.normal(size=J.n)
    np.testing.assert_allclose(H.matvec(x), Hd @ x, rtol=1e-10, atol=1e-12 * np.abs(Hd @ x).max())
    np.testing.assert_allclose(H.inverse(), np.linalg.inv(Hd), rtol=1e-6, atol=1e-12 * np.abs(np.linalg.inv(Hd)).max())
    s = J.shared
    own = np.setdiff1d(np.arange(J.n), s)
    schur = Hd[np.ix_(s, s)] - Hd[np.ix_(s, own)] @ np.linalg.solve(Hd[np.ix_(own, own)], Hd[np.ix_(own, s)])
    np.testing.assert_allclose(H.schur(), schur, rtol=1e-7, atol=1e-10 * np.abs(schur).max())
    d = np.sqrt(np.diag(Hd))
    ev = np.linalg.eigvalsh(Hd / np.outer(d, d))
    assert H.condition_number() == pytest.approx(ev[-1] / ev[0], rel=1e-8)
    # the dense covariance of the same Jacobian is the structured inverse
    np.testing.assert_allclose(covariance_from_jacobian(D), H.inverse(), rtol=1e-6,
                               atol=1e-12 * np.abs(np.linalg.inv(Hd)).max())


def test_an_indefinite_block_is_an_error_not_a_silent_answer():
    rng = np.random.default_rng(1)
    H = _random_jacobian(rng).information()
    bad = type(H)(H.shared, H.own, H.A, H.B, (H.C[0] - 2 * np.diag(np.diag(H.C[0])),) + H.C[1:])
    with pytest.raises(np.linalg.LinAlgError):
        bad.solve(rng.normal(size=H.n))


@pytest.fixture(scope="module")
def small_problem():
    flights = (LaunchSpec(name="a", speed=13.0, launch_angle_deg=3, alpha_deg=6, spin=60, duration=0.8, noise_mm=1.0),
               LaunchSpec(name="b", speed=11.0, launch_angle_deg=8, alpha_deg=14, spin=55, duration=0.8, noise_mm=1.0))
    spec = SynthSpec(name="arrow", flights=flights, seed=7)
    data = synthesize(spec)
    mb = np.array(list(DEFAULT_MARKERS.values()))
    starts = [initial_state_from_data(f, mb) for f in data.flights]
    return Problem(flights=data.flights, marker_body=mb, disc=spec.disc, env=spec.env, prior_name="potts_crowther",
                   start_states=starts)


def test_block_jacobian_is_the_dense_one(small_problem):
    p = small_problem
    x = p.start_vector()
    sigma = p.nominal_noise
    free = np.ones(p.dim, bool)
    free[[2, p.ic_start + 4]] = False
    dense = whitened_jacobian(x, p, sigma, free)
    blocks = jacobian_blocks(x, p, sigma, free)
    n_data = dense.shape[0] - p.dim
    np.testing.assert_array_equal(blocks.dense()[:n_data], dense[:n_data][:, free])
    assert np.all(dense[:n_data][:, ~free] == 0.0)


def test_selected_columns_are_the_jacobian_over_the_free_parameters(small_problem):
    """A Jacobian over every parameter restricted to the free ones (``ArrowJacobian.select``, what a profile
    fit solves with) is the Jacobian computed over the free ones alone: the same blocks, numbering and prior."""
    p = small_problem
    x = p.start_vector()
    sigma = p.nominal_noise
    free = np.ones(p.dim, bool)
    free[[2, p.ic_start + 4, p.dim - 1]] = False
    own = jacobian_blocks(x, p, sigma, free)
    chosen = jacobian_blocks(x, p, sigma).select(free)
    np.testing.assert_array_equal(chosen.shared, own.shared)
    for a, b in zip(chosen.own, own.own):
        np.testing.assert_array_equal(a, b)
    for a, b in zip(chosen.blocks, own.blocks):
        np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(chosen.prior, own.prior)
    # and on a random arrow with scattered unknowns: the dense Jacobian's free columns
    J = _random_jacobian(np.random.default_rng(5))
    keep = np.random.default_rng(6).uniform(size=J.n) < 0.7
    np.testing.assert_array_equal(J.select(keep).dense()[: -keep.sum()], J.dense()[: -J.n][:, keep])
    np.testing.assert_array_equal(J.select(keep).prior, J.prior[keep])


def test_new_solver_matches_the_dense_optimum_and_covariance(small_problem):
    """Levenberg–Marquardt on the arrow and scipy's dense trust-region reflective fit reach the same optimum
    (within a small fraction of each parameter's sd) and the same Gauss–Newton covariance."""
    p = small_problem
    x0 = p.start_vector()
    sigma = p.nominal_noise
    new = minimise(p, x0, sigma, max_nfev=200)
    assert new.status > 0, new.message
    dense = least_squares(whitened_residuals, x0, jac=whitened_jacobian, args=(p, sigma), method="trf",
                          x_scale=p.prior_sd, max_nfev=200, xtol=1e-10, ftol=1e-10)
    assert dense.status > 0
    cov_dense = covariance_from_jacobian(whitened_jacobian(dense.x, p, sigma))
    cov_new = jacobian_blocks(new.x, p, sigma).information().inverse()
    sd = np.sqrt(np.diag(cov_dense))
    assert new.cost == pytest.approx(dense.cost, rel=1e-6)
    assert np.max(np.abs(new.x - dense.x) / sd) < 1e-3
    np.testing.assert_allclose(np.sqrt(np.diag(cov_new)), sd, rtol=1e-3)
    corr = lambda c: c / np.outer(np.sqrt(np.diag(c)), np.sqrt(np.diag(c)))  # noqa: E731
    assert np.max(np.abs(corr(cov_new) - corr(cov_dense))) < 1e-3
    # the refined result (σ re-estimated) carries the structured covariance
    ls = refine_least_squares(p, new.x)
    np.testing.assert_allclose(ls.cov, jacobian_blocks(ls.theta, p, _rms(p, ls.theta)).information().inverse())
    # its output: one marker RMS per flight, in mm, and every noise group with its unit
    out = ls.to_dict()
    assert out["rms_mm"] == {f.name: pytest.approx(1e3 * s) for f, s in zip(p.flights, ls.sigma)}
    assert out["noise"] == {f"sigma_{f.name}": {"value": s, "unit": "m", "n": int(n)}
                            for f, s, n in zip(p.flights, ls.sigma, p.n_coords)}


def test_profile_fits_started_near_the_optimum_reach_it(small_problem, monkeypatch):
    """A profile point's fit (:func:`profile._fixed_fit`, little initial damping: ``MU_NEAR``) ends within the
    deviance tolerance of the constrained optimum found by a tight fit, for a point one and three sds out; and
    refitting a converged optimum with ``MU_NEAR`` stays there."""
    p = small_problem
    sigma = p.nominal_noise
    best = minimise(p, p.start_vector(), sigma, max_nfev=200, xtol=1e-13, ftol=1e-13)
    assert best.status > 0, best.message
    cov = jacobian_blocks(best.x, p, sigma).information().inverse()
    again = minimise(p, best.x, sigma, mu0=MU_NEAR, xtol=1e-13, ftol=1e-13)
    assert again.cost <= best.cost + 1e-9 and again.njev <= 3
    for index in (1, 7):                                   # CLa and CMq
        for t in (1.0, -3.0):
            value = best.x[index] + t * np.sqrt(cov[index, index])
            fits = []
            with monkeypatch.context() as m:
                m.setattr(profile, "minimise", lambda *a, **k: fits.append(minimise(*a, **k)) or fits[-1])
                fit = profile._fixed_fit(p, sigma, best.x, cov, index, value, 40, best.cost)
            x, cost, J = fit.x, fit.cost, fit.J
            assert fit.ok and x[index] == value
            # the Jacobian it hands back is the fit's last: at the point, or (a cost stop, status 3, or the final
            # step, 5) one step before it, within the final step's reach of the point
            (res,) = fits
            assert fit.njev == res.njev and fit.nfev == res.nfev + 1       # its work, the batched starts included
            np.testing.assert_allclose(J.dense(), jacobian_blocks(res.jacobian_x, p, sigma).dense(), rtol=0,
                                       atol=1e-12)
            if res.status in (3, 5):
                assert res.njev >= 1 and not np.array_equal(res.jacobian_x, x)
                r = whitened_residuals(res.jacobian_x, p, sigma)
                assert 0.0 < 0.5 * float(r @ r) - cost <= profile.FINAL_DECREMENT + profile.DECREMENT_TOL
            else:
                np.testing.assert_array_equal(res.jacobian_x, x)
            free = np.ones(p.dim, bool)
            free[index] = False
            tight = minimise(p, x, sigma, free=free, max_nfev=200, xtol=1e-13, ftol=1e-13)
            assert 0.0 <= 2 * (cost - tight.cost) < profile.DEVIANCE_TOL


def test_the_decrement_is_half_the_gradients_inverse_information_norm():
    J = _random_jacobian(np.random.default_rng(3))
    rng = np.random.default_rng(4)
    r = tuple(rng.normal(size=B.shape[0]) for B in J.blocks)
    g = J.gradient(r, rng.normal(size=J.n))
    D = J.dense()
    assert decrement(J.information(), g) == pytest.approx(0.5 * g @ np.linalg.solve(D.T @ D, g), rel=1e-8)


def test_a_start_stops_near_its_optimum(small_problem):
    """With ``dtol`` (the least-squares starts: START_DECREMENT) the fit stops once the Gauss–Newton model
    expects less than that still to gain: close above the full fit's optimum, with fewer Jacobians."""
    p = small_problem
    x0 = p.start_vector()
    full = minimise(p, x0, p.nominal_noise, max_nfev=200, xtol=1e-13, ftol=1e-13)
    early = minimise(p, x0, p.nominal_noise, max_nfev=200, dtol=START_DECREMENT)
    assert early.status == 4 and early.njev < full.njev
    assert 0.0 <= early.cost - full.cost < 5 * START_DECREMENT


def test_held_parameters_stay_put(small_problem):
    p = small_problem
    x0 = p.start_vector()
    free = np.ones(p.dim, bool)
    free[[0, p.ic_start]] = False
    res = minimise(p, x0, p.nominal_noise, free=free, max_nfev=30)
    assert res.x[0] == x0[0] and res.x[p.ic_start] == x0[p.ic_start]
    assert res.cost < 0.5 * np.sum(whitened_residuals(x0, p, p.nominal_noise) ** 2)


def test_holding_every_shared_parameter_fits_the_flights_alone(small_problem):
    p = small_problem
    free = np.zeros(p.dim, bool)
    free[p.ic_start:] = True                                   # each flight's own block; no shared unknowns
    x0 = p.start_vector()
    ls = refine_least_squares(p, x0, max_nfev=20, rounds=1, free=free)
    assert np.array_equal(ls.theta[: p.ic_start], x0[: p.ic_start])
    assert np.all(ls.cov[: p.ic_start] == 0.0) and np.all(np.diag(ls.cov)[p.ic_start:] > 0)


class _SharpProblem:
    """The parts of a Problem that jacobian_blocks reads, for two flights whose residuals
    r_k,j = sin(ω θ_0 t_j) + θ_(1+k) t_j² (θ_0 shared, θ_(1+k) flight k's own) have a known Jacobian; ω sets how
    sharply the data pin θ_0 down (the default step 1e-4 of the prior sd spans ω·1e-4 radians per unit t)."""

    ic_start, n_flights = 1, 2

    def __init__(self, omega: float, reach: float = np.inf, centre: float = 0.37):
        self.omega, self.reach, self.centre = omega, reach, centre
        self.t = np.linspace(0.1, 1.0, 25)
        self.prior_sd = np.array([1.0, 2.0, 2.0])
        self.prior_mean = np.zeros(3)

        class _Layout:
            @staticmethod
            def flight_slice(k):
                return slice(1 + k, 2 + k)
        self.layout = _Layout()

    def residual_groups(self, k):
        return np.full(self.t.size, k)

    def noise_residuals(self, theta, k):
        theta = np.atleast_2d(theta)
        r = np.sin(self.omega * theta[:, :1] * self.t) + theta[:, 1 + k: 2 + k] * self.t ** 2
        return r, np.abs(theta[:, 0] - self.centre) < self.reach       # θ_0 beyond reach: "cannot integrate"

    def exact(self, x, sigma):
        rows = []
        for k in range(2):
            d0 = self.omega * self.t * np.cos(self.omega * x[0] * self.t)
            rows.append(np.c_[d0, self.t ** 2] / sigma[k])
        return rows


@pytest.mark.parametrize("omega", [1.0, 3e4])
def test_jacobian_columns_that_bend_over_the_step_are_recomputed_with_smaller_steps(omega):
    """Where the residuals are linear over the default step the Jacobian is the plain central difference;
    where a parameter is pinned down far below its prior scale (ω = 3·10⁴: the step spans 3 radians, as CRr's
    did on the inertial logs) the central difference across the bend is wrong by O(1) and the recomputed
    column matches the exact derivative."""
    problem = _SharpProblem(omega)
    x, sigma = np.array([0.37, 0.5, -0.2]), np.array([0.1, 0.2])
    J = jacobian_blocks(x, problem, sigma)
    for got, want in zip(J.blocks, problem.exact(x, sigma)):
        np.testing.assert_allclose(got, want, rtol=2e-3, atol=1e-6 * np.abs(want).max())
    # the plain central difference with the default step, for comparison: exact for ω = 1, far off for 3·10⁴
    h = 1e-4 * problem.prior_sd[0]
    central = (np.sin(omega * (x[0] + h) * problem.t) - np.sin(omega * (x[0] - h) * problem.t)) / (2 * h) / sigma[0]
    error = np.abs(central - problem.exact(x, sigma)[0][:, 0]).max() / np.abs(problem.exact(x, sigma)[0][:, 0]).max()
    assert (error < 1e-6) if omega == 1.0 else (error > 0.3)


@pytest.mark.parametrize("reach", [0.3e-4, 0.3e-6])
def test_a_column_whose_steps_fail_on_both_sides_is_recomputed_with_smaller_steps(reach):
    """θ_0 can be simulated only within ``reach`` of its value (as next to an unstable wobble mode, where a
    step of a transverse rate makes the simulation diverge): both lanes of the default step fail. The column
    is recomputed with tenfold smaller steps until both succeed and matches the exact derivative (a step 100
    times smaller is needed for the narrower reach); the other columns stay exact."""
    problem = _SharpProblem(1.0, reach=reach)
    x, sigma = np.array([0.37, 0.5, -0.2]), np.array([0.1, 0.2])
    J = jacobian_blocks(x, problem, sigma)
    for got, want in zip(J.blocks, problem.exact(x, sigma)):
        assert np.all(np.abs(got[:, 0]) > 0)
        np.testing.assert_allclose(got, want, rtol=1e-6)


def test_a_final_step_ends_a_fit_near_its_optimum_without_another_jacobian(small_problem):
    """From a start whose Gauss–Newton decrement is between ``dtol`` and ``final_step``, the fit takes one step
    and stops (status 5) with the start's Jacobian; without ``final_step`` it computes another. Both end within
    ``dtol`` of the optimum."""
    p = small_problem
    sigma = p.nominal_noise
    best = minimise(p, p.start_vector(), sigma, max_nfev=200, xtol=1e-13, ftol=1e-13)
    cov = jacobian_blocks(best.x, p, sigma).information().inverse()
    z = np.random.default_rng(5).normal(size=p.dim)
    x0 = best.x + np.linalg.cholesky(cov) @ (z * np.sqrt(2 * 1e-3) / np.linalg.norm(z))   # decrement ≈ 10⁻³
    dtol, final = 2.5e-4, 2.5e-3
    plain = minimise(p, x0, sigma, mu0=MU_NEAR, dtol=dtol, keep_jacobian=True)
    short = minimise(p, x0, sigma, mu0=MU_NEAR, dtol=dtol, keep_jacobian=True, final_step=final)
    assert plain.status == 4 and plain.njev == 2
    assert short.status == 5 and short.njev == 1 and short.nfev == 2
    np.testing.assert_array_equal(short.jacobian_x, x0)
    np.testing.assert_allclose(short.jacobian.dense(), jacobian_blocks(x0, p, sigma).dense(), rtol=0, atol=1e-12)
    for res in (plain, short):
        assert 0.0 <= res.cost - best.cost <= dtol


def test_batched_costs_are_each_points_own(small_problem):
    """:func:`whitened_costs` of several points (one simulation per flight) equals each point's
    ½ |:func:`whitened_residuals`|², a point whose simulation fails (a launch faster than the speed cap)
    included."""
    p = small_problem
    sigma = p.nominal_noise
    x = p.start_vector()
    X = np.array([x, x + 1e-3 * p.prior_sd, x.copy()])
    X[2, p.ic_start + 3] = 1e3                                           # flight a's vx [m/s]
    one = [0.5 * float(np.sum(np.square(whitened_residuals(z, p, sigma)))) for z in X]
    np.testing.assert_allclose(whitened_costs(X, p, sigma), one, rtol=1e-12)
    n_a = p.noise_residuals(x[None], 0)[0].shape[1]
    assert one[2] >= 0.5 * n_a * FAILED_RESIDUAL ** 2                   # flight a failed
