"""The vectorised convergence statistics equal ArviZ's rank-normalised R-hat and bulk ESS."""
import warnings

import arviz as az
import numpy as np
import pytest

from bayes_disc.inference.sampling.mcmc_stats import SUMMARY_COLUMNS, ess, rhat, summary_diagnostics


def arviz(x: np.ndarray, what: str) -> np.ndarray:
    """ArviZ on x (p, chains, draws), one variable per parameter."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ds = az.convert_to_dataset({f"v{i}": x[i] for i in range(x.shape[0])})
        res = az.rhat(ds, method="rank") if what == "rhat" else az.ess(ds, method="bulk")
    return np.array([float(res[f"v{i}"]) for i in range(x.shape[0])])


def chains(p: int, m: int, n: int, seed: int) -> np.ndarray:
    """AR(1) chains with different autocorrelations, a shifted chain, ties and a constant parameter."""
    rng = np.random.default_rng(seed)
    rho = np.linspace(0.0, 0.95, p)[:, None]
    x = np.empty((p, m, n))
    x[:, :, 0] = rng.standard_normal((p, m))
    for t in range(1, n):
        x[:, :, t] = rho * x[:, :, t - 1] + np.sqrt(1 - rho ** 2) * rng.standard_normal((p, m))
    x[1, 0] += 2.0                                  # one chain off: R-hat > 1
    x[2] = np.round(x[2], 1)                        # ties: average ranks
    x[3] = 1.5                                      # constant
    return x


@pytest.mark.parametrize("m,n", [(4, 10), (4, 301), (16, 64), (1, 50), (3, 5)])
def test_rank_rhat_and_bulk_ess_equal_arviz(m, n):
    x = chains(6, m, n, m * 1000 + n)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")             # constant parameter: 0/0 in R-hat, as in ArviZ
        rh = rhat(x)
    np.testing.assert_allclose(rh, arviz(x, "rhat"), rtol=1e-10, equal_nan=True)
    np.testing.assert_allclose(ess(x), arviz(x, "ess"), rtol=1e-10, equal_nan=True)
    if m > 1:
        assert rh[1] > 1.05 and np.isnan(rh[3])
    assert ess(x)[3] == (n // 2) * 2 * m       # constant: every draw counts


def test_non_finite_draws_give_nan_like_arviz():
    x = chains(5, 4, 40, 7)
    x[0, 1, 5] = np.nan
    assert np.isnan(rhat(x)[0]) and np.isnan(ess(x)[0])
    assert np.isfinite(rhat(x)[[1, 2, 4]]).all() and np.isfinite(ess(x)[1:]).all()


def test_ensemble_layout():
    """rhat(layout="ensembles"): ensembles are chains (walkers pooled step-major); ess(layout="walkers"):
    every walker a chain."""
    rng = np.random.default_rng(3)
    c = rng.standard_normal((3, 20, 8, 2)).cumsum(axis=1) * 0.1 + rng.standard_normal((3, 20, 8, 2))
    pooled = np.moveaxis(c.reshape(3, 160, 2), 2, 0)
    per_walker = np.moveaxis(np.moveaxis(c, 2, 1).reshape(24, 20, 2), 2, 0)
    np.testing.assert_allclose(rhat(c, layout="ensembles"), arviz(pooled, "rhat"), rtol=1e-10)
    np.testing.assert_allclose(ess(c, layout="walkers"), arviz(per_walker, "ess"), rtol=1e-10)


@pytest.mark.parametrize("m,n", [(4, 10), (4, 301), (16, 64), (1, 50), (3, 5)])
def test_summary_diagnostics_equal_arviz_summary(m, n):
    x = chains(6, m, n, m * 7 + n)
    x[4] = np.exp(x[4])                             # skewed: mean and median, 5 % and 95 % tails differ
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ours = summary_diagnostics(x)
        ds = az.convert_to_dataset({f"v{i}": x[i] for i in range(x.shape[0])})
        ref = az.summary(ds, kind="diagnostics", round_to="none")
    assert tuple(ref.columns) == SUMMARY_COLUMNS
    for col in SUMMARY_COLUMNS:
        np.testing.assert_allclose(ours[col], ref[col].to_numpy(float), rtol=1e-10, equal_nan=True, err_msg=col)
    if m > 1:
        assert ours["r_hat"][1] > 1.05
    assert np.isnan(ours["r_hat"]).all() if m == 1 else np.isfinite(ours["r_hat"][[0, 1, 2, 4, 5]]).all()


def test_summary_diagnostics_nan_for_non_finite_draws():
    x = chains(4, 3, 30, 11)
    x[0, 2, 7] = np.inf
    out = summary_diagnostics(x)
    assert all(np.isnan(out[c][0]) for c in SUMMARY_COLUMNS)
    assert all(np.isfinite(out[c][[1, 2]]).all() for c in SUMMARY_COLUMNS)


def sampler_like(n_ens: int, n_steps: int, n_w: int, dim: int, seed: int) -> np.ndarray:
    """Ensemble chains (n_ens, n_steps, n_w, dim) whose walkers repeat their position when a proposal is
    rejected (80 % of steps), two walkers stuck at the same value (a tie across runs), and a coarse
    parameter whose runs tie with each other."""
    rng = np.random.default_rng(seed)
    x = rng.standard_normal((n_ens, n_steps, n_w, dim)).cumsum(axis=1) * 0.2
    for t in range(1, n_steps):
        held = rng.random((n_ens, n_w)) < 0.8
        x[:, t][held] = x[:, t - 1][held]
    x[0, :, 1, 0] = x[1, :, 2, 0] = 0.25
    x[..., 1] = np.round(x[..., 1], 1)
    return x


@pytest.mark.parametrize("n_steps,n_w", [(40, 6), (41, 6), (41, 5)])
def test_run_length_ranks_equal_sorting_every_draw(n_steps, n_w):
    """The ranks found from runs of repeated draws (diagnostics_mcmc._z_and_median) are those of sorting
    every draw, bit for bit, and so are R-hat across ensembles and bulk ESS (even and odd draw counts)."""
    from bayes_disc.inference.sampling import mcmc_stats as dm
    c = sampler_like(3, n_steps, n_w, 4, n_steps * n_w)
    per_walker = np.moveaxis(np.moveaxis(c, 2, 1).reshape(3 * n_w, n_steps, 4), 2, 0)
    z, median = dm._z_and_median(per_walker)
    np.testing.assert_array_equal(z, dm._z_scale_sorted(per_walker))
    np.testing.assert_array_equal(median, np.median(per_walker.reshape(4, -1), axis=1))
    pooled = dm._split(np.moveaxis(c.reshape(3, n_steps * n_w, 4), 2, 0))
    folded = np.abs(pooled - np.median(pooled.reshape(4, -1), axis=1)[:, None, None])
    sorted_rhat = np.maximum(dm._psrf(dm._z_scale_sorted(pooled)), dm._psrf(dm._z_scale_sorted(folded)))
    np.testing.assert_array_equal(rhat(c, layout="ensembles"), sorted_rhat)
    np.testing.assert_array_equal(ess(c, layout="walkers"),
                                  dm._effective_draws(dm._z_scale_sorted(dm._split(per_walker))))
    np.testing.assert_allclose(rhat(c, layout="ensembles"), arviz(np.moveaxis(c.reshape(3, -1, 4), 2, 0), "rhat"),
                               rtol=1e-10)
