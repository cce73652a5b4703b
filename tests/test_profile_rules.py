"""The profile path's stopping rule and the Laplace marginal's volume term (bayes_disc.inference.fitting.profile)."""
import numpy as np
import pytest

from bayes_disc.inference.fitting.profile import (EXTENDED_POINTS, FAILED_DEVIANCE_FACTOR, MARGINAL_RISE,
                                                  MAX_DEVIANCE, MAX_POINTS, conditional_log_volume, side_done)


def test_conditional_log_volume_is_half_the_log_determinant_of_the_conditional_covariance():
    rng = np.random.default_rng(4)
    a = rng.standard_normal((7, 7))
    scales = np.array([1.0, 1e-7, 3e-3, 0.2, 5.0, 1e-4, 0.05])      # CNr ~ 1e−7 beside positions ~ 1e−3
    cov = (a @ a.T + 0.5 * np.eye(7)) * np.outer(scales, scales)
    for i in (0, 1, 4):
        rest = np.r_[0:i, i + 1:7]
        cond = cov[np.ix_(rest, rest)] - np.outer(cov[rest, i], cov[i, rest]) / cov[i, i]
        cond_scaled = cond / np.outer(scales[rest], scales[rest])
        expected = 0.5 * (np.linalg.slogdet(cond_scaled)[1] + 2 * np.sum(np.log(scales[rest])))
        assert conditional_log_volume(cov, i) == pytest.approx(expected, abs=1e-9)


def test_a_side_stops_where_the_profile_or_else_the_marginal_says():
    # flat profile: max_points, as before, when the marginal has not risen along the side
    assert not side_done(MAX_POINTS - 1, 2.0, -1.0, 0.0)
    assert side_done(MAX_POINTS, 2.0, -1.0, 0.0)
    assert side_done(MAX_POINTS, 2.0, MARGINAL_RISE, MARGINAL_RISE)
    # flat profile whose marginal rises (the valley widens): go on while ln g is within max_deviance/2 of its
    # best, up to the cap
    assert not side_done(MAX_POINTS, 2.7, 35.7, 35.7)
    assert not side_done(MAX_POINTS + 2, 3.0, 36.0 - 0.5 * MAX_DEVIANCE + 0.01, 36.0)
    assert side_done(MAX_POINTS + 2, 3.0, 36.0 - 0.5 * MAX_DEVIANCE - 0.01, 36.0)
    assert side_done(EXTENDED_POINTS, 3.0, 40.0, 40.0)
    # the deviance has risen and so has fallen the marginal: stop at once
    assert side_done(3, MAX_DEVIANCE + 1, -0.5 * (MAX_DEVIANCE + 1), 0.0)
    # the deviance has risen but the valley widens (ln g still near its best): go on, up to the cap
    assert not side_done(3, MAX_DEVIANCE + 6, -1.0, 0.0)
    assert not side_done(MAX_POINTS + 1, MAX_DEVIANCE + 6, 0.5, 1.0)
    assert side_done(EXTENDED_POINTS, MAX_DEVIANCE + 6, -1.0, 0.0)
    # once ln g has fallen max_deviance/2 below its best on the side
    assert side_done(5, MAX_DEVIANCE + 6, 2.0 - 0.5 * MAX_DEVIANCE - 0.01, 2.0)
    assert not side_done(5, MAX_DEVIANCE + 6, 2.0 - 0.5 * MAX_DEVIANCE + 0.01, 2.0)
    # a cliff or failed fit ends the side whatever the marginal
    assert side_done(2, FAILED_DEVIANCE_FACTOR * MAX_DEVIANCE + 1, 10.0, 10.0)


def test_conditional_start_is_the_constrained_optimum_of_a_quadratic():
    """For a Gaussian posterior (quadratic cost ½ (x − μ)ᵀ H (x − μ)) the start of a profile fit is its exact
    optimum with θ_i held: the free block solves H_ff (x_f − μ_f) = −H_fi (v − μ_i)."""
    from bayes_disc.inference.fitting.profile import conditional_start
    rng = np.random.default_rng(5)
    A = rng.normal(size=(6, 6))
    H = A @ A.T + 6 * np.eye(6)
    mu, i, v = rng.normal(size=6), 2, 1.7
    free = np.arange(6) != i
    want = mu.copy()
    want[i] = v
    want[free] = mu[free] - np.linalg.solve(H[np.ix_(free, free)], H[free, i] * (v - mu[i]))
    np.testing.assert_allclose(conditional_start(mu, np.linalg.inv(H), i, v), want, rtol=1e-10, atol=1e-12)


def test_bent_start_is_exact_on_a_parabolic_path():
    """A path θ_1*(v) = c v² profiled along θ_0 = v: the conditional start follows the tangent and misses by
    c h² over a step h; :func:`bent_start` adds the last miss scaled by the steps' ratio squared and lands on
    the path exactly, for any step."""
    from bayes_disc.inference.fitting.profile import bent_start, conditional_start
    c = 0.7

    def point(v):
        return np.array([v, c * v * v])

    def cov_at(v):                                       # regression of θ_1 on θ_0: the tangent 2 c v
        return np.array([[1.0, 2 * c * v], [2 * c * v, 4 * c * c * v * v + 1.0]])

    v0, v1, v2 = 0.3, 0.8, 1.55                          # unequal steps
    miss = point(v1) - conditional_start(point(v0), cov_at(v0), 0, v1)
    np.testing.assert_allclose(miss, [0.0, c * (v1 - v0) ** 2])
    plain = conditional_start(point(v1), cov_at(v1), 0, v2)
    bent = bent_start(point(v1), cov_at(v1), 0, v2, miss, (v2 - v1) / (v1 - v0))
    np.testing.assert_allclose(bent, point(v2), rtol=1e-12)
    assert abs(plain[1] - point(v2)[1]) > 0.3            # the tangent alone misses by c h²
