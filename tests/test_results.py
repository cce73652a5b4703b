"""posterior.nc for ArviZ users: flight dimension, ensemble/walker coordinates, pointwise log-likelihood
(az.loo, az.compare), posterior predictive; summary.json statistics equal ArviZ's.

The InferenceData is built exactly as `bayes-disc sample` builds it (:func:`build_inference_data`,
:func:`build_summary`) from short chains of draws around the synthetic truth, with σ drawn from its exact
conditional: a real sample run takes minutes, these mechanics do not need one."""
import json
from pathlib import Path

import arviz as az
import h5py
import numpy as np
import pytest

from bayes_disc.inference.model.config import load_config
from bayes_disc.inference.model.data import build_problem
from bayes_disc.inference.sampling.mcmc_stats import rhat
from bayes_disc.inference.results.idata import build_inference_data, pointwise_log_likelihood
from bayes_disc.inference.results.summary import build_summary, summarize, summary_names
from bayes_disc.inference.results.compare import compare_runs
from bayes_disc.inference.results.draws import ensemble_view, posterior_draws
from bayes_disc.inference.results.posterior_file import load_posterior, write_posterior, writing_posterior
from bayes_disc.inference.sampling.chains import Chains
from bayes_disc.inference.model.truth import truth_theta

from conftest import run_config, write_two_flights

N_ENS, N_STEPS, N_W = 2, 12, 6


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    d = tmp_path_factory.mktemp("results")
    write_two_flights(d, 0.3)
    return d


def _run(folder: Path, name: str, extra: str = "", seed: int = 0):
    """(problem, chains, idata, summary) of a short fake run around the truth, written to out_<name>/."""
    cfg_path = folder / f"{name}.yaml"
    cfg_path.write_text(run_config(name, "prior: potts_crowther", f"output: out_{name}", extra))
    problem = build_problem(load_config(cfg_path))
    rng = np.random.default_rng(seed)
    theta0 = truth_theta(problem, json.loads((folder / "truth.json").read_text()))
    scale = 1e-3 * problem.prior_sd
    chain = theta0 + scale * rng.standard_normal((N_ENS, N_STEPS, N_W, problem.dim))
    flat = chain.reshape(-1, problem.dim)
    ss = problem.sum_squares(flat)
    assert np.all(np.isfinite(ss))
    sigma = problem.draw_sigma(ss, rng).reshape(N_ENS, N_STEPS, N_W, -1)
    lp = problem.log_prob(flat).reshape(N_ENS, N_STEPS, N_W)
    chains = Chains(chain=chain, log_prob=lp, sigma=sigma, acceptance=np.full((N_ENS, N_W), 0.3), burn=0,
                    total_steps=N_STEPS, tau=np.ones((N_ENS, problem.dim)), converged=False, reason="test")
    idata = build_inference_data(problem, chains, np.random.default_rng(seed), n_prior=50,
                                 n_log_likelihood=N_ENS * N_W * 6, n_predictive=N_ENS * N_W * 2)
    summary = build_summary(problem, chains, idata, {}, {"name": name})
    out = folder / f"out_{name}"
    out.mkdir(exist_ok=True)
    write_posterior(idata, out / "posterior.nc")
    (out / "summary.json").write_text(json.dumps(summary))
    return problem, chains, idata, summary


@pytest.fixture(scope="module")
def base(folder):
    return _run(folder, "base")


@pytest.fixture(scope="module")
def side(folder):
    return _run(folder, "side", "physics: {side_force: {CY: 0.0}}", seed=1)


def test_posterior_file_reads_back_as_written(base, folder):
    """write_posterior's filters are lossless: every group, variable, coordinate and attribute comes back."""
    idata = base[2]
    back = load_posterior(folder / "out_base" / "posterior.nc")
    assert sorted(back.groups()) == sorted(set(idata.groups()))
    for g in idata.groups():
        a, b = getattr(idata, g), getattr(back, g)
        assert sorted(a.variables) == sorted(b.variables), g
        for name in a.variables:
            np.testing.assert_array_equal(a[name].values, b[name].values, err_msg=f"{g}/{name}")
        assert a.attrs.keys() <= b.attrs.keys(), g
    with h5py.File(folder / "out_base" / "posterior.nc", "r") as f:
        lp = f["sample_stats/lp"]
        assert lp.compression == "gzip" and lp.shuffle


def test_posterior_written_beside_the_summary_in_a_child_process(base, folder, tmp_path):
    """writing_posterior: the child writes the same file as the foreground writer while the body runs;
    a failed child is an error, and the body's own error comes first."""
    problem, _, idata, summary = base
    with writing_posterior(idata, tmp_path / "posterior.nc", background=True):
        params = summarize(idata, summary_names(problem), threads=2)
    assert params == summary["parameters"]                      # threads: the same records as one thread
    back, ref = load_posterior(tmp_path / "posterior.nc"), load_posterior(folder / "out_base" / "posterior.nc")
    assert sorted(back.groups()) == sorted(ref.groups())
    for g in ref.groups():
        for name in getattr(ref, g).variables:
            np.testing.assert_array_equal(getattr(back, g)[name].values, getattr(ref, g)[name].values)
    with pytest.raises(RuntimeError, match="writing the posterior failed in its child process"):
        with writing_posterior(idata, tmp_path / "no" / "such" / "folder.nc", background=True):
            pass
    with pytest.raises(KeyError, match="body"):
        with writing_posterior(idata, tmp_path / "no" / "such" / "folder.nc", background=True):
            raise KeyError("body")


def test_posterior_has_flight_dimension_and_ensemble_walker_coords(base, folder):
    problem, chains, idata, summary = base
    post = load_posterior(folder / "out_base" / "posterior.nc").posterior
    assert list(post["flight"].values) == ["a", "b"]
    for n in ("x", "vz", "th1", "wz", "sigma"):
        assert post[n].dims == ("chain", "draw", "flight")
    assert post["sigma"].attrs["units"] == "m" and post["vx"].attrs["units"] == "m/s"
    assert not any(v.startswith("sigma_") or v.endswith("_a") for v in post.data_vars)
    np.testing.assert_array_equal(post["ensemble"].values, np.repeat(np.arange(N_ENS), N_W))
    np.testing.assert_array_equal(post["walker"].values, np.tile(np.arange(N_W), N_ENS))
    # chain c = walker w of ensemble e holds exactly that walker's steps
    k = problem.names.index("vz_b")
    np.testing.assert_array_equal(post["vz"].sel(flight="b").values[N_W + 2], chains.chain[1, :, 2, k])
    np.testing.assert_array_equal(posterior_draws(post, "sigma_a")[3], chains.sigma[0, :, 3, 0])
    # summary.json keeps the flat names of docs/outputs.md, read back from the flight dimension
    for n in problem.names + problem.sigma_names:
        assert summary["parameters"][n]["mean"] == pytest.approx(posterior_draws(post, n).mean(), rel=1e-12)


def test_summary_statistics_are_arviz_summary_and_r_hat_across_ensembles(base):
    problem, chains, idata, summary = base
    table = az.summary(idata, round_to="none")
    p = summary["parameters"]
    for name, label in (("CLa", "CLa"), ("wz_a", "wz[a]"), ("sigma_b", "sigma[b]")):
        row = table.loc[label]
        for key in ("ess_bulk", "ess_tail", "mcse_sd"):
            assert p[name][key] == pytest.approx(row[key], rel=1e-12), (name, key)
        # mcse_mean's ESS is computed on the raw draws, which loses digits for a spin far from 0 with a small
        # sd (demo, fffl10: wz ≈ −65 rad/s, sd 0.007 rad/s): there ArviZ's own value moves by 9e-8 (relative)
        # when the draws are shifted by a constant, which leaves it mathematically unchanged, and
        # summary.json's equals ArviZ's on the centred draws (asserted below to 1e-12)
        assert p[name]["mcse_mean"] == pytest.approx(row["mcse_mean"], rel=1e-6), name
        x = posterior_draws(idata.posterior, name)
        centred = az.summary(az.convert_to_dataset({"v": x - x.mean()}), kind="diagnostics", round_to="none")
        assert p[name]["mcse_mean"] == pytest.approx(float(centred.loc["v", "mcse_mean"]), rel=1e-12), name
        assert p[name]["r_hat_walkers"] == pytest.approx(row["r_hat"], rel=1e-12)
    # r_hat: the sampler's statistic across ensembles, reproducible from posterior.nc alone
    theta_rh = rhat(chains.chain, layout="ensembles")
    across = az.rhat(ensemble_view(idata.posterior))
    for i, name in enumerate(problem.names):
        assert p[name]["r_hat"] == pytest.approx(theta_rh[i], rel=1e-12)
    assert p["CMq"]["r_hat"] == pytest.approx(float(across["CMq"]), rel=1e-12)
    assert p["x_b"]["r_hat"] == pytest.approx(float(across["x"].sel(flight="b")), rel=1e-12)
    assert summary["convergence"]["r_hat_max"] == max(v["r_hat"] for v in p.values())


def test_pointwise_log_likelihood_sums_to_the_conditional_likelihood(base):
    problem, chains, idata, _ = base
    theta = chains.chain[0, :3, 0]
    sigma = chains.sigma[0, :3, 0]
    ll, _ = pointwise_log_likelihood(problem, theta, sigma)
    ss = problem.sum_squares(theta)
    start = 0
    for k, f in enumerate(problem.flights):
        n_points = int(f.observed.sum())
        n = 3 * n_points
        expected = -0.5 * n * np.log(2 * np.pi * sigma[:, k] ** 2) - ss[:, k] / (2 * sigma[:, k] ** 2)
        np.testing.assert_allclose(ll[:, start: start + n_points].sum(axis=1), expected, rtol=1e-10)
        start += n_points
    assert start == ll.shape[1]
    # the stored group: every observed point of both flights, labelled, float32 copies of the same values
    g = idata.log_likelihood
    assert g["markers"].sizes["point"] == ll.shape[1]
    assert sorted(set(g["point_flight"].values)) == ["a", "b"]
    assert g["markers"].dtype == np.float32 and np.all(np.isfinite(g["markers"].values))


def test_posterior_predictive_has_observed_dims_and_the_drawn_noise(base):
    problem, chains, idata, _ = base
    pp, obs = idata.posterior_predictive, idata.observed_data
    assert set(pp.data_vars) == set(obs.data_vars)
    for k, f in enumerate(problem.flights):
        key = f"markers_{f.name}"
        assert pp[key].dims[2:] == obs[key].dims and pp[key].shape[2:] == obs[key].shape
        y = pp[key].values[:, :, f.observed]
        r = y - f.positions[f.observed]
        # predictive − observed = (model error ≈ noise at the truth) + fresh noise: RMS ≈ √2 σ
        ratio = np.sqrt(np.mean(r ** 2)) / np.median(chains.sigma[..., k])
        assert 1.2 < ratio < 1.65, (f.name, ratio)


def test_loo_and_compare_on_two_runs(base, side, folder):
    loo_base = az.loo(load_posterior(folder / "out_base" / "posterior.nc"))
    loo_side = az.loo(load_posterior(folder / "out_side" / "posterior.nc"))
    n_points = base[2].log_likelihood.sizes["point"]
    assert loo_base.n_data_points == n_points and np.isfinite(loo_base.elpd_loo)
    table = compare_runs([folder / "out_base", folder / "out_side"])
    assert list(table.index) != [] and set(table.index) == {"out_base", "out_side"}
    assert table.loc["out_base", "elpd_loo"] == pytest.approx(loo_base.elpd_loo)
    assert table.loc["out_side", "elpd_loo"] == pytest.approx(loo_side.elpd_loo)
    assert table["rank"].min() == 0 and table["weight"].sum() == pytest.approx(1.0)


def test_compare_command_prints_the_table_and_writes_json(base, side, folder, tmp_path, capsys):
    import json

    import bayes_disc as bd
    from bayes_disc.cli import main
    out = tmp_path / "cmp" / "comparison.json"
    assert main(["compare", str(folder / "out_base"), str(folder / "out_side"), "--output", str(out)]) == 0
    text = capsys.readouterr().out
    assert "elpd_loo" in text and "out_base" in text and "out_side" in text and "below" in text
    record = json.loads(out.read_text())
    table = bd.compare([folder / "out_base", folder / "out_side"])
    assert list(record["comparison"]) == list(table.index)
    for label, row in record["comparison"].items():
        assert row["elpd_loo"] == pytest.approx(table.loc[label, "elpd_loo"])
        assert row["pareto_k_high"] == table.loc[label, "pareto_k_high"] >= 0
    assert sum(r["weight"] for r in record["comparison"].values()) == pytest.approx(1.0)
    # one run, or a folder that is not a run: one line on stderr, exit status 2
    assert main(["compare", str(folder / "out_base")]) == 2
    assert "at least two" in capsys.readouterr().err
    assert main(["compare", str(folder / "out_base"), str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "posterior.nc" in err


def test_compare_refuses_runs_of_different_observations(base, folder, tmp_path):
    idata = load_posterior(folder / "out_base" / "posterior.nc")
    ll = idata.log_likelihood
    idata.log_likelihood = ll.assign_coords(point_time=("point", ll["point_time"].values + 0.01))
    (tmp_path / "other").mkdir()
    idata.to_netcdf(str(tmp_path / "other" / "posterior.nc"))
    with pytest.raises(ValueError, match="observed marker points differ"):
        compare_runs({"base": folder / "out_base", "other": tmp_path / "other"})
    with pytest.raises(ValueError, match="at least two"):
        compare_runs([folder / "out_base"])


def test_reader_handles_the_older_layout_and_names_missing_parameters(base):
    import xarray as xr
    post = base[2].posterior
    old = xr.Dataset({"CLa": post["CLa"], "sigma_a": post["sigma"].sel(flight="a", drop=True),
                      "x_b": post["x"].sel(flight="b", drop=True)}).drop_vars(["ensemble", "walker"])
    np.testing.assert_array_equal(posterior_draws(old, "sigma_a"), posterior_draws(post, "sigma_a"))
    np.testing.assert_array_equal(posterior_draws(old, "x_b"), posterior_draws(post, "x_b"))
    with pytest.raises(KeyError, match="sigma_c"):
        posterior_draws(post, "sigma_c")
    with pytest.raises(KeyError, match="ensemble"):
        ensemble_view(old)
