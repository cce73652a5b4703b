"""The sampler's chain store (bayes_disc.inference.sampling.backend): a round of steps written at once gives the file
emcee's own backend writes step by step."""
import emcee
import h5py
import numpy as np
import pytest

from bayes_disc.inference.sampling.backend import RoundBackend

NW, DIM, G = 12, 3, 2


def _log_prob_blobs(x):
    """Gaussian log-density with two blobs per walker, in the sampler's layout (log p, S_1, S_2)."""
    return np.column_stack([-0.5 * np.sum(x * x, axis=1), np.sum(x, axis=1), np.sum(x * x, axis=1)])


def _run(backend, rounds=(7, 5)):
    """Two rounds as the sampler advances them: a seeded start, then a resume from the file."""
    start = np.random.default_rng(3).normal(size=(NW, DIM))
    for k, n in enumerate(rounds):
        s = emcee.EnsembleSampler(NW, DIM, _log_prob_blobs, vectorize=True, backend=backend, blobs_dtype=float)
        if k == 0:
            s.random_state = np.random.RandomState(11).get_state()
            s.run_mcmc(start, n, progress=False)
        else:
            s.run_mcmc(None, n, progress=False)
        if isinstance(backend, RoundBackend):
            backend.flush()


def _contents(path):
    with h5py.File(path, "r") as f:
        g = f["mcmc"]
        data = {k: g[k][...] for k in g}
        attrs = {k: g.attrs[k] for k in g.attrs}
    return data, attrs


def test_a_round_written_at_once_is_the_file_emcee_writes_step_by_step(tmp_path):
    _run(emcee.backends.HDFBackend(str(tmp_path / "emcee.h5")))
    _run(RoundBackend(str(tmp_path / "round.h5")))
    (d0, a0), (d1, a1) = _contents(tmp_path / "emcee.h5"), _contents(tmp_path / "round.h5")
    assert sorted(d0) == sorted(d1) == ["accepted", "blobs", "chain", "log_prob"]
    for k in d0:
        assert d0[k].dtype == d1[k].dtype and d0[k].shape == d1[k].shape
        np.testing.assert_array_equal(d0[k], d1[k])
    assert sorted(a0) == sorted(a1)
    for k in a0:
        np.testing.assert_array_equal(a0[k], a1[k])
    assert a1["iteration"] == 12


def test_buffered_steps_count_and_are_written_by_flush(tmp_path):
    path = str(tmp_path / "round.h5")
    backend = RoundBackend(path)
    s = emcee.EnsembleSampler(NW, DIM, _log_prob_blobs, vectorize=True, backend=backend, blobs_dtype=float)
    s.run_mcmc(np.random.default_rng(0).normal(size=(NW, DIM)), 4, progress=False)
    assert backend.iteration == 4
    assert emcee.backends.HDFBackend(path, read_only=True).iteration == 0      # nothing written yet
    last = backend.random_state
    backend.flush()
    other = emcee.backends.HDFBackend(path, read_only=True)
    assert other.iteration == 4 and backend.iteration == 4
    assert other.random_state[1].tolist() == last[1].tolist()
    np.testing.assert_array_equal(other.get_chain()[-1], s.get_last_sample().coords)


def test_steps_done_before_an_interruption_are_kept(tmp_path):
    calls = {"n": 0}

    def failing(x):
        calls["n"] += 1
        if calls["n"] > 6:
            raise KeyboardInterrupt
        return _log_prob_blobs(x)

    backend = RoundBackend(str(tmp_path / "round.h5"))
    s = emcee.EnsembleSampler(NW, DIM, failing, vectorize=True, backend=backend, blobs_dtype=float)
    with pytest.raises(KeyboardInterrupt):
        try:
            s.run_mcmc(np.random.default_rng(0).normal(size=(NW, DIM)), 10, progress=False)
        finally:
            backend.flush()
    written = emcee.backends.HDFBackend(str(tmp_path / "round.h5"), read_only=True)
    assert 0 < written.iteration < 10
    assert np.all(np.isfinite(written.get_chain()))
