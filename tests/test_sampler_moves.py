"""The sampler's Metropolis–Hastings proposals: the ridge-aware Gaussian mixture and its exactness."""
import emcee
import numpy as np
import pytest
from scipy.stats import multivariate_normal

from bayes_disc.inference.proposals import MixtureProposal, Proposal


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


@pytest.mark.parametrize("kind", ["mixture", "pcn"])
def test_moves_leave_the_target_invariant(kind):
    """An emcee run with only that move on a correlated Gaussian target whose shape differs from the
    proposal's recovers the target's mean and covariance (a wrong acceptance ratio biases them)."""
    m = np.array([1.0, -0.5])
    S = np.array([[0.5, 0.3], [0.3, 0.4]])
    Si = np.linalg.inv(S)

    def log_prob(x):
        d = x - m
        return -0.5 * np.einsum("ni,ij,nj->n", d, Si, d)

    if kind == "mixture":
        move = MixtureProposal.from_components([np.zeros(2), np.array([1.5, 0.0])], [np.eye(2), 0.5 * np.eye(2)],
                                               np.log([0.5, 0.5]))
    else:
        move = Proposal.from_cov(np.zeros(2), np.eye(2)).with_rho(0.8)
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
    from bayes_disc.inference.proposals import RidgeProposal
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


def test_composite_independence_move_leaves_the_target_invariant(tmp_path):
    from bayes_disc.inference.proposals import CompositeProposal
    target = _Target()
    laplace = MixtureProposal.from_components([target.m + 0.5], [np.eye(3)], [0.0])
    comp = CompositeProposal((laplace, _ridge(target)), np.log([0.3, 0.7]))
    comp.save(tmp_path / "q.npz")
    loaded = CompositeProposal.load(tmp_path / "q.npz")
    x = np.random.default_rng(1).normal(size=(20, 3))
    np.testing.assert_allclose(loaded.log_density(x), comp.log_density(x))
    sampler = emcee.EnsembleSampler(32, 3, target.log_prob, vectorize=True, moves=[emcee.moves.MHMove(loaded)])
    sampler.random_state = np.random.RandomState(3).get_state()
    sampler.run_mcmc(np.random.default_rng(4).normal(size=(32, 3)), 2000, progress=False)
    x = sampler.get_chain(discard=200, flat=True)
    np.testing.assert_allclose(x.mean(axis=0), target.m, atol=0.03)
    np.testing.assert_allclose(np.cov(x.T), target.S, atol=0.03)


def test_reweighting_moves_weight_to_the_part_that_explains_the_samples():
    from bayes_disc.inference.proposals import CompositeProposal
    a = MixtureProposal.from_components([np.zeros(2)], [np.eye(2)], [0.0])
    b = MixtureProposal.from_components([np.full(2, 6.0)], [np.eye(2)], [0.0])
    comp = CompositeProposal((a, b), np.log([0.8, 0.2]))
    samples = b.draw(3000, np.random.RandomState(0))
    w = np.exp(comp.reweighted(samples, floor=0.02).log_weights)
    assert w[1] > 0.95 and w[0] == pytest.approx(0.02 / 1.02, rel=0.05)
