"""The sampler's Metropolis–Hastings proposals: the ridge-aware Gaussian mixture and its exactness."""
import emcee
import numpy as np
import pytest
from scipy.stats import multivariate_normal

from bayes_disc.inference.fitting.covariance import EIGENVALUE_FLOOR, scaled_cholesky
from bayes_disc.inference.sampling.proposals import MixtureProposal


def _mixture():
    means = [np.array([0.0, 0.0, 0.0]), np.array([2.0, -1.0, 0.5])]
    covs = [np.diag([1.0, 0.5, 2.0]), np.array([[1.0, 0.6, 0.0], [0.6, 1.0, 0.2], [0.0, 0.2, 0.3]])]
    return MixtureProposal.from_components(means, covs, np.log([0.3, 0.7])), means, covs


def test_mixture_density_matches_scipy():
    mix, means, covs = _mixture()
    x = np.random.default_rng(0).normal(size=(50, 3)) * 2
    expected = np.log(0.3 * multivariate_normal(means[0], covs[0]).pdf(x)
                      + 0.7 * multivariate_normal(means[1], covs[1]).pdf(x))
    np.testing.assert_allclose(mix.log_density(x), expected, rtol=1e-10, atol=1e-10)


def test_mixture_draws_have_its_moments():
    mix, _, _ = _mixture()
    x = mix.draw(200_000, np.random.RandomState(1))
    mean, cov = mix.moments()
    np.testing.assert_allclose(x.mean(axis=0), mean, atol=0.02)
    np.testing.assert_allclose(np.cov(x.T), cov, atol=0.03)


def test_mixture_jumps_leave_the_target_invariant():
    """An emcee run with only independence jumps from a Gaussian mixture on a correlated Gaussian target
    whose shape differs from the proposal's recovers the target's mean and covariance (a wrong acceptance
    ratio biases them)."""
    m = np.array([1.0, -0.5])
    S = np.array([[0.5, 0.3], [0.3, 0.4]])
    Si = np.linalg.inv(S)

    def log_prob(x):
        d = x - m
        return -0.5 * np.einsum("ni,ij,nj->n", d, Si, d)

    move = MixtureProposal.from_components([np.zeros(2), np.array([1.5, 0.0])], [np.eye(2), 0.5 * np.eye(2)],
                                           np.log([0.5, 0.5]))
    sampler = emcee.EnsembleSampler(32, 2, log_prob, vectorize=True, moves=[emcee.moves.MHMove(move)])
    sampler.random_state = np.random.RandomState(3).get_state()
    p0 = np.random.default_rng(4).normal(size=(32, 2))
    sampler.run_mcmc(p0, 3000, progress=False)
    x = sampler.get_chain(discard=300, flat=True)
    np.testing.assert_allclose(x.mean(axis=0), m, atol=0.03)
    np.testing.assert_allclose(np.cov(x.T), S, atol=0.03)


# ------------------------------------------------------------------------------ ridge proposals
class _Target:
    """A correlated 3-D Gaussian posterior standing in for the run's Problem."""

    def __init__(self):
        self.dim = 3
        self.m = np.array([0.5, -1.0, 2.0])
        self.S = np.array([[1.0, 0.8, 0.2], [0.8, 1.0, 0.1], [0.2, 0.1, 0.5]])
        self.Si = np.linalg.inv(self.S)

    def log_prob(self, x):
        d = np.atleast_2d(x) - self.m
        return -0.5 * np.einsum("ni,ij,nj->n", d, self.Si, d)


def _ridge(target, widen=1.5):
    """A ridge proposal along parameter 0 from the exact profile path of the Gaussian target, with local
    covariances deliberately too wide (a proposal, not the target)."""
    from types import SimpleNamespace
    from bayes_disc.inference.sampling.proposals import RidgeProposal
    S, m = target.S, target.m
    pts = []
    for t in np.arange(-3, 4):
        v = m[0] + t * np.sqrt(S[0, 0])
        theta = m + S[:, 0] / S[0, 0] * (v - m[0])
        pts.append(SimpleNamespace(value=v, theta=theta, cov=widen * S, ok=True, t=float(t)))
    return RidgeProposal.from_path(target, SimpleNamespace(index=0, points=pts))


def test_ridge_density_is_normalised_and_matches_its_draws():
    target = _Target()
    ridge = _ridge(target)
    rs = np.random.RandomState(5)
    # ∫ q = 1: importance average of q / p0 under a wide Gaussian p0
    p0 = multivariate_normal(target.m, 9 * np.eye(3))
    x = p0.rvs(400_000, random_state=6)
    ratio = np.exp(ridge.log_density(x) - p0.logpdf(x))
    assert ratio.mean() == pytest.approx(1.0, abs=0.02)
    # draws follow the density: the mean of the draws equals the q-weighted mean under p0
    draws = ridge.draw(200_000, rs)
    np.testing.assert_allclose(draws.mean(axis=0), (ratio[:, None] * x).sum(axis=0) / ratio.sum(), atol=0.03)


def _dense_conditional(ridge, vi):
    """The ridge's conditional of the other parameters given θ_i = vi, with every point's interpolated
    factor L(v) = (1 − a) L_k + a L_k+1 formed as a dense (n, d, d) array: the reference the compiled
    algebra is checked against."""
    k, a, mean = ridge._segment(vi)
    return mean, (1 - a)[:, None, None] * ridge.chols[k] + a[:, None, None] * ridge.chols[k + 1]


def test_ridge_density_equals_its_conditional_gaussian_point_by_point():
    """The batched forward substitution of RidgeProposal.log_density gives, at every point, ln g(x_i) plus
    the conditional normal density with the interpolated Cholesky factor (scipy, one point at a time)."""
    from bayes_disc.inference.sampling.proposals import RidgeProposal
    rng = np.random.default_rng(3)
    K, d = 5, 6
    chols = np.array([np.tril(rng.normal(size=(d, d)), -1) + np.diag(rng.uniform(0.5, 2.0, d)) for _ in range(K)])
    ridge = RidgeProposal(index=2, v=np.sort(rng.normal(size=K)), log_g=rng.normal(size=K), s=rng.uniform(0.2, 1, K),
                          means=rng.normal(size=(K, d)), slopes=rng.normal(size=(K, d)), chols=chols)
    x = rng.normal(size=(50, d + 1)) * 1.5
    mean, L = _dense_conditional(ridge, x[:, 2])
    rest = np.delete(x, 2, axis=1)
    want = ridge.log_g_density(x[:, 2]) + np.array(
        [multivariate_normal(mean[n], L[n] @ L[n].T).logpdf(rest[n]) for n in range(x.shape[0])])
    np.testing.assert_allclose(ridge.log_density(x), want, rtol=1e-10, atol=1e-10)


def test_ridge_draw_uses_the_interpolated_factor_of_its_density():
    """A ridge draw is θ_i from g, then mean(θ_i) + L(θ_i) ε with the same interpolated factor the density
    uses (compiled product checked against the dense (n, d, d) factors, same random numbers)."""
    from bayes_disc.inference.sampling.proposals import RidgeProposal
    rng = np.random.default_rng(4)
    K, d = 4, 7
    chols = np.array([np.tril(rng.normal(size=(d, d)), -1) + np.diag(rng.uniform(0.5, 2.0, d)) for _ in range(K)])
    ridge = RidgeProposal(index=0, v=np.sort(rng.normal(size=K)), log_g=rng.normal(size=K), s=rng.uniform(0.2, 1, K),
                          means=rng.normal(size=(K, d)), slopes=rng.normal(size=(K, d)), chols=chols)
    x = ridge.draw(300, np.random.RandomState(9))
    random = np.random.RandomState(9)
    vi = ridge.draw_g(300, random)
    mean, L = _dense_conditional(ridge, vi)
    want = mean + np.einsum("nij,nj->ni", L, random.randn(300, d))
    np.testing.assert_allclose(x[:, 0], vi)
    np.testing.assert_allclose(x[:, 1:], want, rtol=1e-12, atol=1e-12)


def test_composite_independence_move_leaves_the_target_invariant(tmp_path):
    from bayes_disc.inference.sampling.moves import IndependenceJump
    from bayes_disc.inference.sampling.proposals import CompositeProposal
    target = _Target()
    laplace = MixtureProposal.from_components([target.m + 0.5], [np.eye(3)], [0.0])
    comp = CompositeProposal((laplace, _ridge(target)), np.log([0.3, 0.7]))
    comp.save(tmp_path / "q.npz")
    loaded = CompositeProposal.load(tmp_path / "q.npz")
    x = np.random.default_rng(1).normal(size=(20, 3))
    np.testing.assert_allclose(loaded.log_density(x), comp.log_density(x))
    sampler = emcee.EnsembleSampler(32, 3, target.log_prob, vectorize=True, moves=[IndependenceJump(loaded)])
    sampler.random_state = np.random.RandomState(3).get_state()
    sampler.run_mcmc(np.random.default_rng(4).normal(size=(32, 3)), 2000, progress=False)
    x = sampler.get_chain(discard=200, flat=True)
    np.testing.assert_allclose(x.mean(axis=0), target.m, atol=0.03)
    np.testing.assert_allclose(np.cov(x.T), target.S, atol=0.03)


def test_reweighting_moves_weight_to_the_part_that_explains_the_samples():
    from bayes_disc.inference.sampling.proposals import CompositeProposal
    a = MixtureProposal.from_components([np.zeros(2)], [np.eye(2)], [0.0])
    b = MixtureProposal.from_components([np.full(2, 6.0)], [np.eye(2)], [0.0])
    comp = CompositeProposal((a, b), np.log([0.8, 0.2]))
    samples = b.draw(3000, np.random.RandomState(0))
    w = np.exp(comp.reweighted(samples, floor=0.02).log_weights)
    assert w[1] > 0.95 and w[0] == pytest.approx(0.02 / 1.02, rel=0.05)


# ------------------------------------------------------------------------------ flight-block moves
class _ArrowTarget:
    """A linear-Gaussian posterior with the run's block structure: shared θ_s (2), three flights with their
    own θ_k (2 each); flight k's data y_k = A_k θ_s + B_k θ_k + noise (σ = 1): the Problem interface the
    block moves read (per-flight sums of squares and likelihoods, diagonal prior)."""

    class _Layout:
        def __init__(self, s, p, n):
            self.s, self.p, self.n = s, p, n

        def flight_slice(self, k):
            return slice(self.s + k * self.p, self.s + (k + 1) * self.p)

    def __init__(self, seed=0, s=2, p=2, n_flights=3, m=6):
        rng = np.random.default_rng(seed)
        self.n_flights, self.ic_start, self.dim, self.n_groups = n_flights, s, s + n_flights * p, n_flights
        self.layout = self._Layout(s, p, n_flights)
        self.A = [rng.normal(size=(m, s)) for _ in range(n_flights)]
        self.B = [rng.normal(size=(m, p)) for _ in range(n_flights)]
        self.y = [rng.normal(size=m) for _ in range(n_flights)]
        self.prior_mean = rng.normal(size=self.dim)
        self.prior_sd = rng.uniform(0.5, 2.0, size=self.dim)

    def flight_groups(self, k):
        return np.array([k])

    def flight_sum_squares(self, theta, k):
        sl = self.layout.flight_slice(k)
        r = theta[:, : self.ic_start] @ self.A[k].T + theta[:, sl] @ self.B[k].T - self.y[k]
        return np.sum(r * r, axis=1)[:, None]

    def flight_log_likelihood(self, ss, k):
        return -0.5 * ss[:, 0]

    def log_prior(self, theta):
        z = (np.atleast_2d(theta) - self.prior_mean) / self.prior_sd
        return -0.5 * np.sum(z * z, axis=1)

    def log_likelihood_from_ss(self, ss):
        return -0.5 * np.sum(ss, axis=1)

    def log_prob(self, theta):
        return self.log_prob_blobs(theta)[:, 0]

    def log_prob_blobs(self, theta):
        theta = np.atleast_2d(theta)
        ss = np.column_stack([self.flight_sum_squares(theta, k) for k in range(self.n_flights)])
        return np.column_stack([self.log_prior(theta) + self.log_likelihood_from_ss(ss), ss])

    def exact(self):
        """The posterior's mean and covariance."""
        P = np.diag(1.0 / self.prior_sd**2)
        b = self.prior_mean / self.prior_sd**2
        for k in range(self.n_flights):
            J = np.zeros((self.y[k].size, self.dim))
            J[:, : self.ic_start] = self.A[k]
            J[:, self.layout.flight_slice(k)] = self.B[k]
            P += J.T @ J
            b += J.T @ self.y[k]
        cov = np.linalg.inv(P)
        return cov @ b, cov


def test_flight_block_moves_leave_the_posterior_invariant():
    """emcee with only the Gibbs sweep over flights and the shared shift, both shaped by a reference
    covariance that is deliberately wrong (1.7× too wide, correlations dropped), recovers the exact
    posterior's mean and covariance: the per-flight acceptance ratios are exact."""
    from bayes_disc.inference.sampling.moves import FlightBlockMove, SharedShift, block_factors
    t = _ArrowTarget()
    mean, cov = t.exact()
    reference = np.diag(np.diag(cov)) * 1.7**2
    conditional, shared, regression = block_factors(t, reference)
    moves = [(FlightBlockMove(t, conditional), 0.6), (emcee.moves.MHMove(SharedShift(shared, regression)), 0.4)]
    nw = 24
    sampler = emcee.EnsembleSampler(nw, t.dim, t.log_prob_blobs, vectorize=True, moves=moves, blobs_dtype=float)
    sampler.random_state = np.random.RandomState(5).get_state()
    p0 = mean + np.random.default_rng(6).normal(size=(nw, t.dim)) @ np.linalg.cholesky(cov).T
    sampler.run_mcmc(p0, 6000, progress=False)
    x = sampler.get_chain(discard=500, flat=True)
    sd = np.sqrt(np.diag(cov))
    assert np.max(np.abs(x.mean(axis=0) - mean) / sd) < 0.06
    np.testing.assert_allclose(np.sqrt(np.diag(np.cov(x.T))), sd, rtol=0.06)
    # the stored log-posterior is the one a full evaluation gives (the sweep assembles it from its parts)
    last = sampler.get_last_sample()
    np.testing.assert_allclose(last.log_prob, t.log_prob_blobs(last.coords)[:, 0], rtol=1e-10)
    np.testing.assert_allclose(np.asarray(last.blobs).reshape(nw, -1), t.log_prob_blobs(last.coords)[:, 1:], rtol=1e-10)
    assert 0.05 < np.mean(sampler.acceptance_fraction) < 0.95


def test_block_factors_of_a_gaussian_are_its_conditionals():
    from bayes_disc.inference.sampling.moves import block_factors
    t = _ArrowTarget(seed=2)
    _, cov = t.exact()
    conditional, shared, regression = block_factors(t, cov)
    P = np.linalg.inv(cov)
    for k, L in enumerate(conditional):
        sl = t.layout.flight_slice(k)
        np.testing.assert_allclose(L @ L.T, np.linalg.inv(P[sl, sl]), rtol=1e-8)
    s = t.ic_start
    np.testing.assert_allclose(shared @ shared.T, cov[:s, :s], rtol=1e-8)
    np.testing.assert_allclose(regression, cov[s:, :s] @ np.linalg.inv(cov[:s, :s]), rtol=1e-8, atol=1e-12)


def test_observation_shift_pieces_are_the_conditionals_given_the_coefficients():
    """observation_shift: the shared observation-model parameters' covariance given the coefficients (a Schur
    complement of the covariance) and the flights' regression on them under the same conditioning."""
    from bayes_disc.inference.sampling.moves import observation_shift, shared_conditional
    t = _ArrowTarget(seed=3, s=3)
    t.layout.observation_slice = slice(1, 3)                       # one coefficient, two observation parameters
    _, cov = t.exact()
    columns, chol, regression = observation_shift(t, cov)
    np.testing.assert_array_equal(columns, [1, 2])
    c, o, f = [0], [1, 2], np.arange(3, t.dim)
    rest = np.r_[o, f]
    given = cov[np.ix_(rest, rest)] - cov[np.ix_(rest, c)] @ np.linalg.solve(cov[np.ix_(c, c)], cov[np.ix_(c, rest)])
    np.testing.assert_allclose(chol @ chol.T, given[:2, :2], rtol=1e-8)
    np.testing.assert_allclose(regression, given[2:, :2] @ np.linalg.inv(given[:2, :2]), rtol=1e-8, atol=1e-12)
    held = shared_conditional(t, cov)
    np.testing.assert_allclose(held @ held.T, np.linalg.inv(np.linalg.inv(cov)[:3, :3]), rtol=1e-8)
    t.layout.observation_slice = slice(3, 3)                       # no observation-model parameters
    assert observation_shift(t, cov)[0].size == 0


def test_observation_shift_follows_a_position_bias_valley_the_held_walk_cannot():
    """A logger's offset o and every throw's bias b_k seen only as o + b_k (to 0.01): the observation shift,
    shaped by the exact covariance, carries the biases along and moves o across its posterior; the walk with
    the flights held moves it by its tiny conditional sd only (MH acceptance ratios of exact draws)."""
    from types import SimpleNamespace
    from bayes_disc.inference.sampling.moves import SharedShift, observation_shift, shared_conditional
    P = np.eye(5)                                                  # θ = (c, o, b_1, b_2, b_3), priors N(0, 1)
    for k in range(3):
        a = np.zeros(5)
        a[[1, 2 + k]] = 1.0 / 0.01
        P += np.outer(a, a)
    cov = np.linalg.inv(P)
    t = SimpleNamespace(ic_start=2, dim=5, layout=SimpleNamespace(observation_slice=slice(1, 2)))
    rng = np.random.default_rng(4)
    x = rng.normal(size=(20000, 5)) @ np.linalg.cholesky(cov).T

    def jumps(move):
        new, factor = move(x, np.random.RandomState(5))
        assert np.all(factor == 0)
        log_a = -0.5 * (np.einsum("ni,ij,nj->n", new, P, new) - np.einsum("ni,ij,nj->n", x, P, x))
        accept = np.exp(np.minimum(log_a, 0.0))
        return accept.mean(), np.mean(accept * (new[:, 1] - x[:, 1]) ** 2) / cov[1, 1]

    columns, chol, regression = observation_shift(t, cov)
    carried = jumps(SharedShift(chol, regression, 0.5, columns))
    held = jumps(SharedShift(shared_conditional(t, cov), None))
    assert carried[0] > 0.5 and carried[1] > 0.3                  # a third of o's variance per step
    assert held[1] < 0.01


def test_move_mixture_with_ridges_and_block_moves():
    """With ridge proposals and block moves, the mixture holds both kinds of ridge carry (shared places redrawn,
    and every place kept), the flight sweeps, the shared walk with the flights held and the observation shift,
    with the configured shares: block moves ``block_fraction`` of the weight, the carries half of the
    Metropolis–Hastings share, split evenly."""
    from bayes_disc.inference.sampling.mixing import _moves
    from bayes_disc.inference.sampling.moves import RidgeCarry
    from bayes_disc.inference.sampling.proposals import CompositeProposal, Proposal, RidgeProposal
    t = _ArrowTarget(seed=5, s=3)
    t.layout.observation_slice = slice(1, 3)
    mean, cov = t.exact()
    d = t.dim - 1
    ridge = RidgeProposal(index=0, v=np.array([-1.0, 0.0, 1.0]), log_g=np.zeros(3), s=np.ones(3),
                          means=np.tile(mean[1:], (3, 1)), slopes=np.zeros((3, d)), chols=np.tile(np.eye(d), (3, 1, 1)))
    independence = CompositeProposal((MixtureProposal.from_components([mean], [cov], [0.0]), ridge), np.log([0.5, 0.5]))
    moves = _moves(t, Proposal.from_cov(mean, cov), independence, 0.8, 0.3, walkers=4)
    weight = {m.label: w for m, w in moves}
    assert {"flight sweep, ridge refresh", "flight sweep, random walk", "shared walk, flights held",
            "observation shift, flights carried"} <= set(weight)
    block = [w for label, w in weight.items() if label.startswith(("flight sweep", "shared walk", "observation"))]
    assert sum(block) == pytest.approx(0.3)
    assert weight["ridge carry, shared redrawn"] == weight["ridge carry, all kept"] == pytest.approx(0.7 * 0.8 * 0.25)
    fresh = {m.label: m.move.get_proposal.fresh for m, _ in moves if m.label.startswith("ridge carry")}
    assert fresh == {"ridge carry, shared redrawn": t.ic_start - 1, "ridge carry, all kept": 0}
    assert all(isinstance(m.move.get_proposal, RidgeCarry) for m, _ in moves if m.label.startswith("ridge"))


def test_default_walkers_with_block_moves():
    """With block moves: 2·dim + 2 walkers on small problems, capped at WALKERS_CAP but never below the block
    minimum 2·(s + p) + 2; without: 2·dim + 2; an explicit count is made even and kept above the minimum."""
    from bayes_disc.inference.model.config import SamplerSettings
    from bayes_disc.inference.sampling.mixing import WALKERS_CAP, n_walkers
    block, plain = SamplerSettings(block_fraction=0.3), SamplerSettings(block_fraction=0.0)
    small = _ArrowTarget(s=10, p=12, n_flights=4)                 # the demo's sizes: dim 58
    assert n_walkers(block, small) == n_walkers(plain, small) == 2 * 58 + 2
    big = _ArrowTarget(s=10, p=12, n_flights=24)
    assert n_walkers(block, big) == WALKERS_CAP and n_walkers(plain, big) == 2 * big.dim + 2
    wide = _ArrowTarget(s=60, p=12, n_flights=24)                 # block minimum above the cap
    assert n_walkers(block, wide) == 2 * (60 + 12) + 2
    assert n_walkers(SamplerSettings(block_fraction=0.3, walkers=61), big) == 62
    assert n_walkers(SamplerSettings(block_fraction=0.3, walkers=10), big) == 2 * (10 + 12) + 2


def test_block_moves_only_when_the_walkers_cannot_span_the_space():
    from bayes_disc.inference.sampling.mixing import uses_block_moves
    assert not uses_block_moves(0.3, 118, 58) and uses_block_moves(0.3, 116, 58)
    assert not uses_block_moves(0.0, 46, 58)


def test_independence_jump_remembers_densities_without_changing_the_chain():
    """IndependenceJump (ln q of unmoved walkers remembered), mixed with DE moves that move some walkers in
    between: the same chain, bit for bit, as emcee's MHMove with the same proposal and seed; and fewer
    density evaluations."""
    from bayes_disc.inference.sampling.moves import IndependenceJump
    m, S = np.array([1.0, -0.5, 0.2]), np.array([[0.5, 0.3, 0.0], [0.3, 0.4, 0.1], [0.0, 0.1, 0.3]])
    Si = np.linalg.inv(S)

    def log_prob(x):
        d = x - m
        return -0.5 * np.einsum("ni,ij,nj->n", d, Si, d)

    class Counting(MixtureProposal):
        calls = [0]

        def log_density(self, x):
            self.calls[0] += len(x)
            return super().log_density(x)

    q = MixtureProposal.from_components([np.zeros(3), np.ones(3)], [np.eye(3), 0.5 * np.eye(3)], np.log([0.5, 0.5]))
    counting = Counting(q.means, q.chols, q.log_weights)
    chains = []
    for move in (emcee.moves.MHMove(counting), IndependenceJump(counting)):
        counting.calls[0] = 0
        sampler = emcee.EnsembleSampler(16, 3, log_prob, vectorize=True,
                                        moves=[(move, 0.7), (emcee.moves.DEMove(), 0.3)])
        sampler.random_state = np.random.RandomState(7).get_state()
        sampler.run_mcmc(np.random.default_rng(8).normal(size=(16, 3)), 400, progress=False)
        chains.append((sampler.get_chain(), counting.calls[0]))
    np.testing.assert_array_equal(chains[0][0], chains[1][0])
    assert chains[1][1] < 0.8 * chains[0][1], (chains[0][1], chains[1][1])


# ------------------------------------------------------------------------------ ridge carries
class _Banana:
    """v ~ N(0, 1); x1 | v ~ N(c v², s(v)²), s(v) = 0.3 e^{0.3 v} (the valley widens along v, so the
    carry's Jacobian |L(v′)|/|L(v)| matters); x2 | x1 ~ N(x1 / 2, 0.5²). Exact moments: E v = 0, var v = 1,
    E x1 = c, var x1 = 2c² + 0.09 e^{0.18}, E x2 = c/2."""

    c = 0.8

    def log_prob(self, x):
        x = np.atleast_2d(x)
        v, x1, x2 = x.T
        s = 0.3 * np.exp(0.3 * v)
        return -0.5 * v**2 - 0.5 * ((x1 - self.c * v**2) / s) ** 2 - np.log(s) - 0.5 * ((x2 - 0.5 * x1) / 0.5) ** 2


def _banana_ridge(shift=0.1, widen=1.3):
    """A ridge proposal along v for :class:`_Banana`, deliberately off: g 1.2 times too wide, the valley's
    floor shifted by ``shift`` in x1, its conditional covariance ``widen`` times too wide."""
    from bayes_disc.inference.sampling.proposals import RidgeProposal
    c, v = _Banana.c, np.linspace(-3.5, 3.5, 8)
    means = np.c_[c * v**2 + shift, 0.5 * (c * v**2 + shift)]
    slopes = np.c_[2 * c * v, c * v]
    chols = []
    for vk in v:
        s2 = (0.3 * np.exp(0.3 * vk)) ** 2
        chols.append(np.linalg.cholesky(widen * np.array([[s2, 0.5 * s2], [0.5 * s2, 0.25 * s2 + 0.25]])))
    return RidgeProposal(index=0, v=v, log_g=-0.5 * (v / 1.2) ** 2, s=np.full(v.size, 1.2), means=means,
                         slopes=slopes, chols=np.array(chols))


def test_ridge_mean_follows_a_bent_valley_floor_between_path_points():
    """Between path points the conditional mean is the cubic Hermite interpolant of the points with their
    slopes as tangents: on a parabolic floor x1 = c v² it is the floor itself (a linear blend of the tangent
    lines misses it by c h² a (1 − a), 0.2 here at mid-segment); beyond the end points, the end tangents."""
    ridge = _banana_ridge(shift=0.0)
    c, v = _Banana.c, np.linspace(-5.0, 5.0, 401)
    _, _, mean = ridge._segment(v)
    inside = np.abs(v) <= 3.5
    np.testing.assert_allclose(mean[inside, 0], c * v[inside] ** 2, atol=1e-12)
    np.testing.assert_allclose(mean[inside, 1], 0.5 * c * v[inside] ** 2, atol=1e-12)
    end = np.where(v > 0, 3.5, -3.5)[~inside]
    np.testing.assert_allclose(mean[~inside, 0], c * end ** 2 + 2 * c * end * (v[~inside] - end), atol=1e-12)


def test_ridge_whiten_and_place_are_inverse():
    ridge = _banana_ridge()
    x = np.random.default_rng(2).normal(size=(40, 3)) * [2.0, 1.0, 1.0]
    z, log_det = ridge.whiten(x)
    back, log_det_back = ridge.place(x[:, 0], z)
    np.testing.assert_allclose(back, x, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(log_det_back, log_det, rtol=1e-12)
    _, L = _dense_conditional(ridge, x[:, 0])
    np.testing.assert_allclose(log_det, np.log(np.diagonal(L, axis1=1, axis2=2)).sum(axis=1), rtol=1e-12)


def test_ridge_carries_leave_the_target_invariant():
    """Ridge carries (v′ from g, the walker's whitened z kept) mixed with a small Gaussian random walk (which
    moves z) recover the banana's exact moments, with a proposal whose g, valley floor and conditional
    width are all off. The acceptance ratio needs the Jacobian |L(v′)|/|L(v)|: without it, E v comes out −0.29
    and var x1 1.62 instead of 0 and 1.39 (checked with two seeds when this test was written)."""
    from bayes_disc.inference.sampling.moves import RidgeCarry
    target = _Banana()
    carry = RidgeCarry((_banana_ridge(),), np.zeros(1))
    moves = [(emcee.moves.MHMove(carry), 0.5), (emcee.moves.GaussianMove(0.05 * np.ones(3)), 0.5)]
    sampler = emcee.EnsembleSampler(64, 3, target.log_prob, vectorize=True, moves=moves)
    sampler.random_state = np.random.RandomState(7).get_state()
    p0 = np.c_[np.zeros(64), np.full(64, 0.1), np.full(64, 0.05)] + 0.1 * np.random.default_rng(8).normal(size=(64, 3))
    sampler.run_mcmc(p0, 6000, progress=False)
    x = sampler.get_chain(discard=1000, flat=True)
    c = target.c
    np.testing.assert_allclose(x.mean(axis=0), [0.0, c, c / 2], atol=0.04)
    assert x[:, 0].var() == pytest.approx(1.0, abs=0.05)
    assert x[:, 1].var() == pytest.approx(2 * c**2 + 0.09 * np.exp(0.18), rel=0.06)
    accepted = sampler.acceptance_fraction.mean()
    assert 0.2 < accepted < 0.95


def _arrow_ridge(t, shift=0.3, widen=1.6):
    """A ridge proposal along the shared θ_0 of an :class:`_ArrowTarget`, from its exact profile path with
    the path shifted by ``shift`` sds in every parameter and the local covariances ``widen`` times too wide."""
    from types import SimpleNamespace
    from bayes_disc.inference.sampling.proposals import RidgeProposal
    m, S = t.exact()
    sd = np.sqrt(np.diag(S))
    pts = [SimpleNamespace(value=m[0] + u * sd[0], theta=m + S[:, 0] / S[0, 0] * u * sd[0] + shift * sd,
                           cov=widen * S, ok=True) for u in np.arange(-4.0, 5.0)]
    for p in pts:
        p.theta[0] = p.value
    return RidgeProposal.from_path(t, SimpleNamespace(index=0, points=pts))


def test_ridge_block_conditionals_are_the_ridge_conditional_of_each_flight():
    """For an arrow-structured posterior the ridge's conditional of flight k given θ_0 and the other shared
    parameters, from the factor's blocks, equals the Gaussian conditional of its dense covariance."""
    t = _ArrowTarget(seed=4, s=3, p=2, n_flights=4)
    ridge = _arrow_ridge(t)
    x = ridge.draw(5, np.random.RandomState(2))
    blocks = [t.layout.flight_slice(k) for k in range(t.n_flights)]
    conds = ridge.block_conditionals(x, t.ic_start - 1, blocks)
    mean, L = _dense_conditional(ridge, x[:, 0])
    rest = x[:, 1:]
    s = t.ic_start - 1
    for n in range(x.shape[0]):
        C = L[n] @ L[n].T
        for (m_k, L_k), b in zip(conds, blocks):
            r = np.arange(b.start, b.stop) - 1
            gain = C[np.ix_(r, range(s))] @ np.linalg.inv(C[:s, :s])
            np.testing.assert_allclose(m_k[n], mean[n, r] + gain @ (rest[n, :s] - mean[n, :s]), atol=1e-10)
            np.testing.assert_allclose(L_k[n] @ L_k[n].T, C[np.ix_(r, r)] - gain @ C[np.ix_(range(s), r)], atol=1e-10)


def test_ridge_moves_leave_an_arrow_posterior_invariant():
    """Flight refreshes from a ridge's conditional and ridge carries, both from a ridge proposal that is off
    (shifted 0.3 sd, 1.6 times too wide), mixed with a small Gaussian random walk, recover the exact
    posterior's mean and sds. Without the refresh's Hastings factor the flights' sds come out 0.79–0.88 of
    the exact ones and their means up to 0.18 sd off (checked when this test was written)."""
    from bayes_disc.inference.sampling.moves import RidgeCarry, RidgeFlightRefresh
    t = _ArrowTarget(seed=1, s=3, p=2, n_flights=4)
    mean, cov = t.exact()
    sd = np.sqrt(np.diag(cov))
    ridge = _arrow_ridge(t)
    moves = [(RidgeFlightRefresh(t, (ridge,), np.zeros(1)), 0.4),
             (emcee.moves.MHMove(RidgeCarry((ridge,), np.zeros(1), fresh=t.ic_start - 1)), 0.3),
             (emcee.moves.GaussianMove(0.02 * sd**2), 0.3)]
    nw = 32
    sampler = emcee.EnsembleSampler(nw, t.dim, t.log_prob_blobs, vectorize=True, moves=moves, blobs_dtype=float)
    sampler.random_state = np.random.RandomState(5).get_state()
    p0 = mean + np.random.default_rng(6).normal(size=(nw, t.dim)) * sd
    sampler.run_mcmc(p0, 5000, progress=False)
    x = sampler.get_chain(discard=500, flat=True)
    assert np.max(np.abs(x.mean(axis=0) - mean) / sd) < 0.06
    np.testing.assert_allclose(x.std(axis=0), sd, rtol=0.06)
    last = sampler.get_last_sample()
    np.testing.assert_allclose(last.log_prob, t.log_prob_blobs(last.coords)[:, 0], rtol=1e-10)


def test_block_sparse_ridge_algebra_equals_the_dense_one():
    """A ridge whose factors have the arrow's block structure (shared rows dense, every flight's rows its own
    block only): the compiled loops that skip the zeros give the density, whitening and draws of the same
    factors treated as dense; and from_path with the problem's blocks keeps the dense path's factors to
    rounding on an arrow-structured posterior."""
    from bayes_disc.inference.sampling.proposals import (RidgeProposal, _block_structure, _structure_mask,
                                                         flight_blocks)
    t = _ArrowTarget(seed=3, s=3, p=2, n_flights=4)
    first, shared = _block_structure(1, t.dim, *flight_blocks(t))
    mask = _structure_mask(first, shared)
    assert mask.sum() == sum(r + 1 for r in range(shared)) + (t.dim - 1 - shared) * shared + 4 * 3
    rng = np.random.default_rng(5)
    K, d = 4, t.dim - 1
    chols = np.array([(np.tril(rng.normal(size=(d, d)), -1) + np.diag(rng.uniform(0.5, 2.0, d))) * mask for _ in range(K)])
    args = dict(index=1, v=np.sort(rng.normal(size=K)), log_g=rng.normal(size=K), s=rng.uniform(0.2, 1, K),
                means=rng.normal(size=(K, d)), slopes=rng.normal(size=(K, d)), chols=chols)
    sparse, dense = RidgeProposal(**args, first=first, shared=shared), RidgeProposal(**args)
    x = rng.normal(size=(30, t.dim))
    np.testing.assert_allclose(sparse.log_density(x), dense.log_density(x), rtol=1e-12, atol=1e-12)
    for a, b in zip(sparse.whiten(x), dense.whiten(x)):
        np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(sparse.draw(40, np.random.RandomState(2)), dense.draw(40, np.random.RandomState(2)),
                               rtol=1e-12, atol=1e-12)
    # built from a path: the same factors as the dense construction, to rounding
    from types import SimpleNamespace
    m, S = t.exact()
    sd = np.sqrt(np.diag(S))
    pts = [SimpleNamespace(value=m[1] + u * sd[1], theta=m + S[:, 1] / S[1, 1] * u * sd[1], cov=S, ok=True)
           for u in np.arange(-3.0, 4.0)]
    built = RidgeProposal.from_path(t, SimpleNamespace(index=1, points=pts), flight_blocks(t))
    plain = RidgeProposal.from_path(t, SimpleNamespace(index=1, points=pts))
    np.testing.assert_allclose(built.chols, plain.chols, atol=1e-12 * np.abs(plain.chols).max())
    assert np.all(built.chols[:, ~mask] == 0)


def test_scaled_cholesky_factors_directly_where_the_floor_cannot_bind(monkeypatch):
    """A well-conditioned covariance with scales from 1e−7 to 1 is factored as it is, without an
    eigendecomposition; a rank-deficient one gets the floored eigenvalues, the same as factoring the floored
    matrix itself."""
    rng = np.random.default_rng(11)
    n = 40
    A = rng.normal(size=(n, n))
    scales = 10.0 ** rng.uniform(-7, 0, n)
    cov = (A @ A.T / n + 0.1 * np.eye(n)) * np.outer(scales, scales)
    with monkeypatch.context() as m:
        m.setattr(np.linalg, "eigh", lambda *a, **k: pytest.fail("eigendecomposition of a well-conditioned matrix"))
        L = scaled_cholesky(cov)
    np.testing.assert_allclose(L, np.tril(L))
    np.testing.assert_allclose(L @ L.T / np.outer(scales, scales), cov / np.outer(scales, scales), atol=1e-12)
    B = rng.normal(size=(n, 3))
    low = (B @ B.T) * np.outer(scales, scales)                      # rank 3: the floor binds
    d = np.sqrt(np.diag(low))
    w, V = np.linalg.eigh(low / np.outer(d, d))
    floored = (V * np.maximum(w, EIGENVALUE_FLOOR * w.max())) @ V.T
    L = scaled_cholesky(low)
    np.testing.assert_allclose(L @ L.T / np.outer(d, d), floored, atol=1e-9)
    assert np.linalg.eigvalsh(L @ L.T / np.outer(d, d)).min() > 0.5 * EIGENVALUE_FLOOR * w.max()


def test_counted_move_counts_without_changing_the_chain():
    """A counted DE move gives the same chain as the move alone (it draws nothing of its own), counts one
    proposal per walker and step, and its acceptances are emcee's; a wrong count would break either check."""
    from bayes_disc.inference.sampling.mixing import CountedMove, add_counts, move_counts

    def log_prob(x):
        return -0.5 * np.sum(x * x / np.arange(1, 4), axis=-1)

    p0 = np.random.default_rng(1).standard_normal((12, 3))
    chains, counted = [], None
    for wrap in (False, True):
        move = emcee.moves.DEMove()
        if wrap:
            move = counted = CountedMove(move, "DE")
        sampler = emcee.EnsembleSampler(12, 3, log_prob, vectorize=True, moves=[(move, 1.0)])
        sampler.random_state = np.random.RandomState(7).get_state()
        sampler.run_mcmc(p0, 40, progress=False)
        chains.append(sampler.get_chain())
    np.testing.assert_array_equal(chains[0], chains[1])
    assert counted.proposed == 40 * 12 and counted.accepted == int(sampler.backend.accepted.sum()) > 0
    counts = move_counts([(counted, 1.0)])
    assert add_counts(counts, counts) == {"DE": [1.0, 2 * 480, 2 * counted.accepted]}
