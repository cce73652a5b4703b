"""The sampler's batched autocorrelation time equals emcee's estimator computed walker by walker."""
import emcee
import numpy as np
import pytest

from bayes_disc.inference.sampling import stopping
from bayes_disc.inference.model.config import SamplerSettings
from bayes_disc.inference.sampling.chains import StoredChains
from bayes_disc.inference.sampling.mcmc_stats import rhat
from bayes_disc.inference.sampling.stopping import _tau


def tau_walker_by_walker(chain: np.ndarray, c: float = 5.0) -> np.ndarray:
    """emcee's function_1d per walker and parameter, averaged over the walkers that moved, Sokal's window."""
    n_steps, n_w, dim = chain.shape
    tau = np.empty(dim)
    for d in range(dim):
        f, used = np.zeros(n_steps), 0
        for k in range(n_w):
            if np.ptp(chain[:, k, d]) > 0:
                f += emcee.autocorr.function_1d(chain[:, k, d])
                used += 1
        if used == 0:
            tau[d] = np.inf
            continue
        taus = 2.0 * np.cumsum(f / used) - 1.0
        tau[d] = taus[emcee.autocorr.auto_window(taus, c)]
    return tau


def ar1_chain(n_steps: int, n_w: int, dim: int, rho: float, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    e = rng.standard_normal((n_steps, n_w, dim))
    x = np.empty_like(e)
    x[0] = e[0] / np.sqrt(1 - rho ** 2)
    for t in range(1, n_steps):
        x[t] = rho * x[t - 1] + e[t]
    return x


@pytest.mark.parametrize("n_steps", [37, 150, 256, 301])
def test_batched_tau_equals_emcee_walker_by_walker(n_steps):
    x = ar1_chain(n_steps, 24, 7, 0.8, n_steps)
    x[:, 3, 2] = 0.1                     # a walker stuck at a value whose mean is not exact in floating point
    x[:, 5, 2] = 1 / 3
    x[:, :, 4] = 2.0                     # no walker moved: τ undefined
    ref = tau_walker_by_walker(x)
    got = _tau(x)
    assert np.array_equal(np.isinf(got), np.isinf(ref)) and np.isinf(got[4])
    fin = np.isfinite(ref)
    np.testing.assert_allclose(got[fin], ref[fin], rtol=1e-10)


def test_batches_and_threads_do_not_change_tau(monkeypatch):
    x = ar1_chain(200, 16, 9, 0.9, 1)
    whole = _tau(x)
    monkeypatch.setattr(stopping, "TAU_BATCH_VALUES", 1)   # one parameter per batch
    np.testing.assert_allclose(_tau(x, workers=2), whole, rtol=1e-12)


def test_tau_of_ar1_near_its_theory():
    rho = 0.8                                              # integrated time (1 + ρ) / (1 − ρ) = 9
    tau = _tau(ar1_chain(2000, 32, 3, rho, 2))
    np.testing.assert_allclose(tau, (1 + rho) / (1 - rho), rtol=0.15)


def _write_chain(path, chain: np.ndarray) -> None:
    """One ensemble's steps (n_steps, n_walkers, dim) in an emcee HDF5 chain file."""
    from emcee.state import State
    n_steps, n_w, dim = chain.shape
    backend = emcee.backends.HDFBackend(str(path))
    backend.reset(n_w, dim)
    backend.grow(n_steps, None)
    random = np.random.RandomState(0)
    for t in range(n_steps):
        backend.save_step(State(chain[t], log_prob=np.zeros(n_w), random_state=random.get_state()),
                          np.ones(n_w, bool))


def test_check_on_stored_chains_reads_blocks_and_gives_the_in_memory_verdict(tmp_path, monkeypatch):
    """The convergence check on chain files (read a block of parameters at a time) gives the verdict of the
    same steps held in memory in one block; walkers that stop moving (repeated values: rank ties) included."""
    n_ens, n_steps, n_w, dim = 3, 140, 12, 23
    chains = np.stack([ar1_chain(n_steps, n_w, dim, 0.7 + 0.05 * e, seed=e) for e in range(n_ens)])
    chains[1, 60:, 3, :5] = chains[1, 59, 3, :5]                  # a stuck walker: ties in the ranks
    chains[2, :, :, 7] += 0.3                                       # an ensemble off in one parameter
    paths = [tmp_path / f"ensemble_{e}.h5" for e in range(n_ens)]
    for p, c in zip(paths, chains):
        _write_chain(p, c)
    settings = SamplerSettings(ess=100, min_steps=0, processes=2)
    coef = np.array([0, 2, 7, 11])
    whole = stopping.convergence(chains[:, 20:], settings, coef, first_step=20)
    reads = []
    block = StoredChains.block

    def spy(self, skip, cols):
        out = block(self, skip, cols)
        reads.append(out.shape[-1])
        return out

    monkeypatch.setattr(stopping, "CHECK_VALUES", n_ens * (n_steps - 20) * n_w * 4)   # blocks of 4 parameters
    monkeypatch.setattr(StoredChains, "block", spy)
    stored = stopping.convergence(StoredChains(paths, start=20), settings, coef, first_step=20)
    assert max(reads) == 4 and sum(reads) == 2 * dim                 # two passes, never the whole chain
    assert whole["rhat_max"] > 1.01                                  # the offset ensemble is seen
    for key in ("burn", "n_over_tau", "rhat_max", "rhat_max_coef", "ess_min_coef", "converged"):
        assert stored[key] == pytest.approx(whole[key], rel=1e-12), key
    np.testing.assert_allclose(stored["tau"], whole["tau"], rtol=1e-12)
    # the coefficients' R-hat alone: the largest of theirs after the burn-in, below every parameter's largest here
    rh = rhat(chains[:, whole["burn"]:], layout="ensembles")
    assert whole["rhat_max"] == pytest.approx(rh.max(), rel=1e-12)
    assert whole["rhat_max_coef"] == pytest.approx(rh[coef].max(), rel=1e-12) and rh[coef].max() < rh.max()
