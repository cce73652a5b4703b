"""`bayes-disc sample`: determinism, resume, recovery of the truth, and the paper's narrow-α finding."""
import json
import shutil
from pathlib import Path

import arviz as az
import numpy as np
import pytest

from bayes_disc.cli import main
from bayes_disc.observation.synth import LaunchSpec, SynthSpec, synthesize, write_synth

from conftest import REPO, keep_flights

MARKERS_YAML = """markers:
  "0": [0.100, 0.000, -0.015]
  "1": [-0.0308, 0.0846, -0.015]
  "2": [-0.0707, -0.0778, -0.015]
"""


@pytest.fixture(autouse=True)
def _in_tmp(tmp_path, monkeypatch):
    """`sample` writes reports/<name>.html relative to the working directory: keep it out of the repo."""
    monkeypatch.chdir(tmp_path)


def _write_config(folder: Path, name: str, sampler: str, extra: str = "") -> Path:
    cfg = folder / "config.yaml"
    cfg.write_text(f"name: {name}\nflights:\n  - file: flights.csv\n{MARKERS_YAML}prior: potts_crowther\n"
                   f"output: out\ntruth: truth.json\n{sampler}\n{extra}")
    return cfg


def _small_data(folder: Path, seed=3):
    f = LaunchSpec(name="short", speed=12.0, launch_angle_deg=4, alpha_deg=8, spin=55, duration=0.5,
                   noise_mm=1.5, dropout=0.02)
    write_synth(synthesize(SynthSpec(name="s", flights=(f,), seed=seed)), folder / "flights.csv",
                folder / "truth.json")


SMALL_SAMPLER = ("sampler: {ensembles: 2, max_steps: 60, adapt_steps: 15, check_every: 15, min_steps: 10, "
                 "seed: 5}\nleast_squares: {starts: 1}")


def test_same_seed_same_summary_and_outputs(tmp_path):
    runs = []
    for k in range(2):
        d = tmp_path / f"r{k}"
        d.mkdir()
        _small_data(d)
        cfg = _write_config(d, "det", SMALL_SAMPLER)
        assert main(["sample", str(cfg), "--no-progress"]) == 0
        runs.append(d / "out")
    a = json.loads((runs[0] / "summary.json").read_text())
    b = json.loads((runs[1] / "summary.json").read_text())
    a.pop("config"), b.pop("config")
    for f in a["flights"]:
        a["flights"][f].pop("file"), b["flights"][f].pop("file")
    assert a == b
    # SPEC §6 keys for every coefficient and the flight's σ
    for name in ["CL0", "CLa", "CD0", "CDa", "CM0", "CMa", "CMq", "CRr", "CRp", "CNr", "sigma_short"]:
        assert set(a["parameters"][name]) >= {"mean", "sd", "q05", "q50", "q95", "r_hat", "ess_bulk"}
    assert set(a["parameters"]["CLa"]) >= {"ess_tail", "mcse_mean", "mcse_sd", "r_hat_walkers"}
    idata = az.from_netcdf(str(runs[0] / "posterior.nc"))
    assert {"posterior", "sample_stats", "prior", "observed_data", "log_likelihood",
            "posterior_predictive"} <= set(idata.groups())
    assert "CLa" in idata.posterior and list(idata.prior["sigma"].flight.values) == ["short"]
    assert idata.posterior["x"].dims == ("chain", "draw", "flight") and "ensemble" in idata.posterior.coords
    # ArviZ users: az.summary gives summary.json's ESS and MCSE, az.loo works on the run as written
    row = az.summary(idata, var_names=["sigma"], round_to="none").loc["sigma[short]"]
    assert a["parameters"]["sigma_short"]["ess_tail"] == pytest.approx(row["ess_tail"], rel=1e-9)
    loo = az.loo(idata)
    assert loo.n_data_points == a["flights"]["short"]["points"] and np.isfinite(loo.elpd_loo)


def test_resume_continues_without_losing_samples(tmp_path):
    _small_data(tmp_path)
    cfg = _write_config(tmp_path, "res", SMALL_SAMPLER.replace("max_steps: 60", "max_steps: 45"))
    assert main(["sample", str(cfg), "--no-progress"]) == 0
    import emcee
    first = emcee.backends.HDFBackend(str(tmp_path / "out/chains/ensemble_0.h5"), read_only=True).get_chain()
    cfg.write_text(cfg.read_text().replace("max_steps: 45", "max_steps: 75"))
    assert main(["sample", str(cfg), "--no-progress", "--resume"]) == 0
    second = emcee.backends.HDFBackend(str(tmp_path / "out/chains/ensemble_0.h5"), read_only=True).get_chain()
    assert second.shape[0] == 75
    np.testing.assert_array_equal(second[:45], first)


# ---------------------------------------------------------------------------------------------- slow
def _demo_like(folder: Path, seed: int, names=None):
    """Four flights like the demo (Hummel 2002 coefficients, 1–3 mm noise per flight, 2 % dropped)."""
    text = (REPO / "runs/demo/synth.yaml").read_text().replace("seed: 2002", f"seed: {seed}")
    (folder / "synth.yaml").write_text(text)
    assert main(["synth", str(folder / "synth.yaml")]) == 0
    if names is not None:
        keep_flights(folder / "flights.csv", names)


# The noise draw of the shipped demo. Coverage is a property of one data set: on another draw (seed 11)
# the truths of CM0 and CMq (one weakly identified valley) lie at the 98-99 % tail of the posterior,
# where the sampler, an importance-sampling estimate and a Laplace marginal along the CMq profile path
# all put them. test_sampler_agrees_with_importance_sampling checks the sampler itself.
DATA_SEED = 2002


@pytest.fixture(scope="module")
def four_flights_run(tmp_path_factory):
    d = tmp_path_factory.mktemp("four")
    _demo_like(d, seed=DATA_SEED)
    cfg = _write_config(d, "four", "sampler: {seed: 2}")
    mp = pytest.MonkeyPatch()
    mp.chdir(d)
    try:
        assert main(["sample", str(cfg), "--no-progress"]) == 0
    finally:
        mp.undo()
    assert (d / "reports/four.html").is_file()
    return d


@pytest.fixture(scope="module")
def four_flights(four_flights_run):
    d = four_flights_run
    return json.loads((d / "out/summary.json").read_text()), json.loads((d / "truth.json").read_text())


@pytest.mark.slow
@pytest.mark.xdist_group("four_flights")     # one worker samples the shared run
def test_recovery_four_flights_noise_and_convergence(four_flights):
    summary, truth = four_flights
    p = summary["parameters"]
    for f, t in truth["flights"].items():
        assert p[f"sigma_{f}"]["q50"] == pytest.approx(t["noise_m"], rel=0.15)
    assert summary["convergence"]["r_hat_max"] < 1.01
    assert summary["convergence"]["converged"]


@pytest.mark.slow
@pytest.mark.xdist_group("four_flights")     # one worker samples the shared run
def test_recovery_four_flights_every_coefficient_covered(four_flights):
    summary, truth = four_flights
    p = summary["parameters"]
    for name, value in truth["coefficients"].items():
        assert p[name]["q025"] <= value <= p[name]["q975"], (name, value, p[name])


@pytest.mark.slow
def test_single_narrow_flight_is_much_less_informative(four_flights, tmp_path):
    summary4, _ = four_flights
    _demo_like(tmp_path, seed=DATA_SEED, names={"fffl10"})
    cfg = _write_config(tmp_path, "narrow", "sampler: {seed: 2}")
    assert main(["sample", str(cfg), "--no-progress"]) == 0
    summary1 = json.loads((tmp_path / "out/summary.json").read_text())
    for name in ("CLa", "CDa", "CMa"):
        ratio = summary1["parameters"][name]["sd"] / summary4["parameters"][name]["sd"]
        assert ratio > 3.0, (name, ratio)


@pytest.mark.slow
@pytest.mark.xdist_group("four_flights")     # one worker samples the shared run
def test_sampler_agrees_with_importance_sampling(four_flights_run, four_flights):
    """The MCMC posterior of every coefficient matches an importance-sampling estimate of the same
    posterior: means within 0.25 sd, sds within 20 %. Proposal (any proposal gives a consistent estimate):
    the run's ridge-aware independence proposal, made defensive by an equal share of a Gaussian on the
    MCMC samples' moments (sd × 1.2); weights p(θ|y)/q(θ). Two different estimators: a sampler that
    misses part of the valley the ridge proposals cover fails it.

    In 58 dimensions the raw weights are heavy-tailed: their effective sample size from the same 120 000
    draws ranged from 2 to 720 over runs and seeds (Pareto k̂ 0.70–0.81), so raw weights made this test
    pass or fail by chance. The weights are therefore Pareto-smoothed (PSIS, Vehtari et al. 2024, via
    ``az.psislw``), and the estimate is used only when it is reliable by that paper's sample-size rule
    k̂ < 1 − 1/log10(S) (0.81 for S = 180 000 draws)."""
    import emcee
    from bayes_disc.inference.config import load_config
    from bayes_disc.inference.data import build_problem
    from bayes_disc.inference.proposals import CompositeProposal, MixtureProposal
    d = four_flights_run
    summary, _ = four_flights
    problem = build_problem(load_config(d / "config.yaml"))
    q = CompositeProposal.load(d / "out/chains/independence.npz")
    chains = [emcee.backends.HDFBackend(str(p), read_only=True).get_chain()[-300:].reshape(-1, problem.dim)
              for p in sorted((d / "out/chains").glob("ensemble_*.h5"))]
    post = np.concatenate(chains)
    gauss = MixtureProposal.from_components([post.mean(axis=0)], [np.cov(post.T) * 1.2 ** 2], [0.0])
    q = CompositeProposal(q.parts + (gauss,), np.log(np.r_[0.5 * np.exp(q.log_weights), 0.5]))
    random = np.random.RandomState(1)
    x = np.concatenate([q.draw(20_000, random) for _ in range(9)])
    lw = np.concatenate([problem.log_prob(xb) - q.log_density(xb) for xb in np.split(x, 9)])
    lw_smoothed, k_hat = az.psislw(lw - lw.max())
    assert k_hat < 1.0 - 1.0 / np.log10(len(x)), f"importance sampling unreliable (Pareto k̂ {float(k_hat):.2f})"
    w = np.exp(lw_smoothed - lw_smoothed.max())
    w /= w.sum()
    for i, name in enumerate(summary["coefficients"]):
        m = w @ x[:, i]
        sd = np.sqrt(w @ (x[:, i] - m) ** 2)
        post_i = summary["parameters"][name]
        assert abs(m - post_i["mean"]) < 0.25 * post_i["sd"], (name, m, post_i["mean"], post_i["sd"])
        assert sd == pytest.approx(post_i["sd"], rel=0.2), (name, sd, post_i["sd"])


@pytest.mark.slow
@pytest.mark.xdist_group("four_flights")     # one worker samples the shared run
def test_identifiability_verdicts_agree_with_the_posterior(four_flights_run):
    """`identifiability --profiles` on the sampled run: the fast verdicts (least squares, Fisher
    information, profiles) equal the verdicts from the posterior samples' widths, coefficient by coefficient."""
    d = four_flights_run
    assert main(["identifiability", str(d / "config.yaml"), "--profiles", "--no-design"]) == 0
    r = json.loads((d / "out/identifiability.json").read_text())
    assert r["posterior"]["agreement"] == {n: True for n in r["coefficients"]}, (
        {n: (r[n]["verdict"], r["posterior"]["verdicts"][n]["verdict"]) for n in r["coefficients"]})
