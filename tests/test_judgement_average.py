"""The posterior averaged over the judgement of outliers and label swaps (robust noise): the
mixture likelihood of a recording as given against brute-force enumeration and the Gaussian it reduces to,
σ integrated out against numerical quadrature, and the importance reweighting of a run's draws."""
from itertools import combinations, product

import numpy as np
import pytest
from scipy.integrate import quad
from scipy.special import logsumexp

from bayes_disc.observation.models import gaussian_marginal_loglik
from bayes_disc.observation.models.outliers import (OUTLIER_FRACTION, OUTLIER_WIDTH_M, SWAP_FRACTION,
                                                    log_marginal_over_scale, mixture_log_likelihood)


def _lower(rng, n, m):
    """(n, m, 3, 3) lower-triangular whitening maps with positive diagonals (per-point errors)."""
    W = np.tril(rng.normal(scale=0.2, size=(n, m, 3, 3)), -1)
    W += np.eye(3) * rng.uniform(0.5, 2.0, size=(n, m, 1, 3))
    return W


def _recording(rng, n=4, m=3, sigma=2e-3):
    pred = rng.normal(size=(n, m, 3))
    obs = pred + sigma * rng.normal(size=(n, m, 3))
    obs[1, 2] = np.nan
    obs[2, [0, 1]] = obs[2, [1, 0]]                  # a swapped frame
    obs[3, 1] += [0.0, 0.03, 0.0]                    # an outlier
    return pred, obs


def test_without_gross_errors_the_mixture_is_the_gaussian_likelihood():
    """π = π_s = 0: p(y | θ, σ) = Π |W_i| N(W_i r_i | 0, σ² I), and integrated over dσ/σ it is
    ½ Γ(N/2) (π S)^(−N/2) Π |W_i| (the sampled model's formula) — also for a peak far from the first guess."""
    rng = np.random.default_rng(1)
    pred, obs = _recording(rng, n=40)       # N = 357: the rule's truncation error grows as N falls (1e-9 at N = 33)
    W = _lower(rng, *obs.shape[:2])
    seen = np.all(np.isfinite(obs), axis=-1)
    e = np.einsum("nmij,nmj->nmi", W, pred - np.nan_to_num(obs))[seen]
    S, N = float(np.sum(e * e)), 3 * int(seen.sum())
    log_w = float(np.linalg.slogdet(W)[1][seen].sum())
    log_sigma = np.log([[1e-3, 2e-3, 0.05]])
    with np.errstate(divide="ignore"):
        got = mixture_log_likelihood(pred[None], obs, W, log_sigma, outlier_fraction=0.0, swap_fraction=0.0)
        want = log_w - 0.5 * N * np.log(2 * np.pi) - N * log_sigma - 0.5 * S * np.exp(-2 * log_sigma)
        np.testing.assert_allclose(got, want, rtol=1e-12)
        lik = lambda u, rows: mixture_log_likelihood(np.repeat(pred[None], rows.size, 0), obs, W, u,
                                                     outlier_fraction=0.0, swap_fraction=0.0)
        for centre in (0.5 * np.log(S / N), 0.5 * np.log(S / N) + 3.0):      # the second: moved back to the peak
            marginal = log_marginal_over_scale(lik, np.array([centre]), N)
            assert marginal[0] == pytest.approx(gaussian_marginal_loglik(np.array([[S]]), np.array([N]))[0] + log_w,
                                                rel=0, abs=1e-9)


def test_mixture_likelihood_equals_enumerating_every_swap_and_outlier():
    """At fixed σ, the frame-by-frame mixture equals the sum over every frame's label hypothesis and every
    point's inlier/outlier indicator of prior × density (brute force, 4 frames of 3 markers)."""
    rng = np.random.default_rng(2)
    pred, obs = _recording(rng)
    W = _lower(rng, *obs.shape[:2])
    sigma = 2.5e-3
    n, m, _ = obs.shape
    pairs = list(combinations(range(m), 2))

    def ln3(x, cov_chol_inv=None, s=None):
        if cov_chol_inv is None:
            return -1.5 * np.log(2 * np.pi * s ** 2) - 0.5 * x @ x / s ** 2
        e = cov_chol_inv @ x
        return np.linalg.slogdet(cov_chol_inv)[1] - 1.5 * np.log(2 * np.pi * sigma ** 2) - 0.5 * e @ e / sigma ** 2

    total = 0.0
    for i in range(n):
        seen = [j for j in range(m) if np.all(np.isfinite(obs[i, j]))]
        terms = []
        hyps = [(np.log1p(-SWAP_FRACTION), list(range(m)))]
        for j, l in pairs:
            if j in seen and l in seen:
                idx = list(range(m))
                idx[j], idx[l] = l, j
                hyps.append((np.log(SWAP_FRACTION / len(pairs)), idx))
        for log_prior, idx in hyps:
            for flags in product((0, 1), repeat=len(seen)):
                t = log_prior
                for a, out in zip(seen, flags):
                    r = pred[i, a] - obs[i, idx[a]]
                    t += (np.log(OUTLIER_FRACTION) + ln3(r, s=OUTLIER_WIDTH_M) if out
                          else np.log1p(-OUTLIER_FRACTION) + ln3(r, W[i, idx[a]]))
                terms.append(t)
        total += logsumexp(terms)
    got = mixture_log_likelihood(pred[None], obs, W, np.log([[sigma]]))
    assert got[0, 0] == pytest.approx(total, rel=1e-12)


def test_sigma_integrated_out_matches_quadrature():
    """log ∫ p(y | θ, σ) dσ/σ with gross errors present, two predictions, against scipy's adaptive quadrature."""
    rng = np.random.default_rng(3)
    pred, obs = _recording(rng, n=30)
    preds = np.stack([pred, pred + 1e-3 * rng.normal(size=pred.shape)])
    seen = np.all(np.isfinite(obs), axis=-1)
    N = 3 * int(seen.sum())
    lik = lambda u, rows: mixture_log_likelihood(preds[rows], obs, None, u)
    got = log_marginal_over_scale(lik, np.log([1e-3, 4e-3]), N)
    grid = np.linspace(np.log(1e-4), np.log(1e-1), 4001)
    for b in range(2):
        values = lik(grid[None], np.array([b]))[0]
        peak = grid[np.argmax(values)]
        ref = values.max()
        f = lambda u: np.exp(lik(np.array([[u]]), np.array([b]))[0, 0] - ref)
        val, err = quad(f, peak - 3.0, peak + 3.0, points=[peak], limit=200, epsabs=0, epsrel=1e-11)
        assert got[b] == pytest.approx(ref + np.log(val), abs=1e-8)


def test_weighted_quantiles_are_hazen_quantiles_and_zero_weights_drop_draws():
    from bayes_disc.inference.fitting.robust import weighted_quantiles
    rng = np.random.default_rng(4)
    x = rng.normal(size=501)
    q = np.array([0.05, 0.5, 0.95])
    np.testing.assert_allclose(weighted_quantiles(x, np.full(x.size, 1 / x.size), q),
                               np.quantile(x, q, method="hazen"), rtol=1e-12)
    w = (x > 0) / np.sum(x > 0)                              # zero weight: as if the draw were not there
    np.testing.assert_allclose(weighted_quantiles(x, w, q), np.quantile(x[x > 0], q, method="hazen"), rtol=1e-12)
