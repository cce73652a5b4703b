"""`bayes-disc sample`: determinism, resume, recovery of the truth, and the paper's narrow-α finding."""
import json
from pathlib import Path

import arviz as az
import numpy as np
import pytest

from bayes_disc.cli import main
from bayes_disc.observation.synth import LaunchSpec, SynthSpec, synthesize, write_synth

from conftest import MARKERS_YAML, REPO, keep_flights

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
    # the keys of docs/outputs.md for every coefficient and the flight's σ
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
    _check_move_counts(a, runs[0], since=30)
    # one flight's posterior is close to Gaussian: its mean lies near its mode, above the typical draw
    assert a["convergence"]["log_prob_gap_at_mean"] < 0


def _check_move_counts(summary: dict, out: Path, since: int):
    """convergence.moves counts every walker's proposal after the last warm-up adaptation (step ``since``) once,
    and its acceptances are the walkers' moves in the chain files over those steps."""
    import emcee
    conv = summary["convergence"]
    moves = conv["moves"]
    assert {"independence jump", "DE, γ × 0.35", "DE snooker"} <= set(moves)
    assert sum(m["share"] for m in moves.values()) == pytest.approx(1.0, abs=1e-3)
    steps = conv["total_steps"] - since
    assert sum(m["proposals"] for m in moves.values()) == steps * conv["walkers_per_ensemble"] * conv["ensembles"]
    moved = 0
    for e in range(conv["ensembles"]):
        chain = emcee.backends.HDFBackend(str(out / f"chains/ensemble_{e}.h5"), read_only=True).get_chain()
        moved += int(np.any(chain[since + 1:] != chain[since:-1], axis=-1).sum())
        moved += int(np.any(chain[since] != chain[since - 1], axis=-1).sum())
    accepted = sum(round(m["acceptance"] * m["proposals"]) for m in moves.values() if m["proposals"])
    assert accepted == moved > 0


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
    # the moves' counts go on from the interrupted run's last check: every step after the warm-up, once
    _check_move_counts(json.loads((tmp_path / "out/summary.json").read_text()), tmp_path / "out", since=30)


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
    assert (d / "out/reports/four.html").is_file()          # the report goes with its run
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


def _importance_moments(problem, q, rng_seed: int = 1, batches: int = 9, per_batch: int = 20_000):
    """Posterior means and sds of every parameter by importance sampling from ``q`` (any proposal with
    ``draw`` and ``log_density``): weights p(θ|y)/q(θ), Pareto-smoothed (PSIS, Vehtari et al. 2024, via
    ``az.psislw``; in ~60 dimensions raw weights are heavy-tailed and their effective sample size varies
    by orders of magnitude between seeds). Fails unless the estimate is reliable by that paper's
    sample-size rule k̂ < 1 − 1/log10(S)."""
    random = np.random.RandomState(rng_seed)
    x = np.concatenate([q.draw(per_batch, random) for _ in range(batches)])
    lw = np.concatenate([problem.log_prob(xb) - q.log_density(xb) for xb in np.split(x, batches)])
    lw_smoothed, k_hat = az.psislw(lw - lw.max())
    assert k_hat < 1.0 - 1.0 / np.log10(len(x)), f"importance sampling unreliable (Pareto k̂ {float(k_hat):.2f})"
    w = np.exp(lw_smoothed - lw_smoothed.max())
    w /= w.sum()
    m = w @ x
    return m, np.sqrt(w @ (x - m) ** 2)


def _with_defensive_gaussian(q, samples: np.ndarray, inflation: float = 1.2):
    """``q`` made defensive by an equal share of a Gaussian on the samples' moments (sd × ``inflation``)."""
    from bayes_disc.inference.sampling.proposals import CompositeProposal, MixtureProposal
    gauss = MixtureProposal.from_components([samples.mean(axis=0)], [np.cov(samples.T) * inflation ** 2], [0.0])
    return CompositeProposal(q.parts + (gauss,), np.log(np.r_[0.5 * np.exp(q.log_weights), 0.5]))


class _StudentT:
    """Multivariate Student t (ν degrees of freedom, location ``mean``, scale matrix ``cov``) with the
    proposal interface ``draw(n, random)`` and ``log_density(x)`` (x: (n, d))."""

    def __init__(self, mean: np.ndarray, cov: np.ndarray, nu: float):
        self.mean, self.nu = mean, float(nu)
        self.L = np.linalg.cholesky(cov)
        self.log_det = 2.0 * float(np.sum(np.log(np.diag(self.L))))

    def draw(self, n: int, random) -> np.ndarray:
        z = random.standard_normal((n, self.mean.size))
        w = random.chisquare(self.nu, size=n) / self.nu
        return self.mean + (z @ self.L.T) / np.sqrt(w)[:, None]

    def log_density(self, x: np.ndarray) -> np.ndarray:
        from scipy.special import gammaln
        m = np.sum(np.linalg.solve(self.L, (x - self.mean).T) ** 2, axis=0)
        d, nu = self.mean.size, self.nu
        return (gammaln(0.5 * (nu + d)) - gammaln(0.5 * nu) - 0.5 * d * np.log(nu * np.pi) - 0.5 * self.log_det
                - 0.5 * (nu + d) * np.log1p(m / nu))


def _with_defensive_t(q, samples: np.ndarray, nu: float = 4.0):
    """``q`` made defensive by an equal share of a Student t (ν = 4) on the samples' moments: heavier tails
    than a Gaussian's, where the posterior's valley runs past every ridge component. On a four-flight run
    a Gaussian share (sd × 1.2, 1.5 or 2) left Pareto k̂ at 0.81 (an earlier run's: 0.809, 0.001
    inside the rule), the t share 0.72."""
    from bayes_disc.inference.sampling.proposals import CompositeProposal
    t = _StudentT(samples.mean(axis=0), np.cov(samples.T), nu)
    return CompositeProposal(q.parts + (t,), np.log(np.r_[0.5 * np.exp(q.log_weights), 0.5]))


def _kept_samples(out: Path, dim: int, last: int = 300) -> np.ndarray:
    import emcee
    return np.concatenate([emcee.backends.HDFBackend(str(p), read_only=True).get_chain()[-last:].reshape(-1, dim)
                           for p in sorted((out / "chains").glob("ensemble_*.h5"))])


@pytest.mark.slow
@pytest.mark.xdist_group("four_flights")     # one worker samples the shared run
def test_sampler_agrees_with_importance_sampling(four_flights_run, four_flights):
    """The MCMC posterior of every coefficient matches an importance-sampling estimate of the same
    posterior: means within 0.25 sd, sds within 20 %. Proposal (any proposal gives a consistent estimate):
    the run's ridge-aware independence proposal, made defensive by an equal share of a Student t (ν = 4) on
    the MCMC samples' moments (:func:`_with_defensive_t`). Two different estimators: a sampler that misses part of the valley
    the ridge proposals cover fails it (the weights: :func:`_importance_moments`)."""
    from bayes_disc.inference.model.config import load_config
    from bayes_disc.inference.model.data import build_problem
    from bayes_disc.inference.sampling.proposals import CompositeProposal
    d = four_flights_run
    summary, _ = four_flights
    problem = build_problem(load_config(d / "config.yaml"))
    if (d / "out/ic_reference.json").is_file():      # the run's initial conditions' reference prior
        from bayes_disc.inference.model.priors import surrogate_from_dict
        problem = problem.with_ic_reference(surrogate_from_dict(json.loads((d / "out/ic_reference.json").read_text())))
    q = _with_defensive_t(CompositeProposal.load(d / "out/chains/independence.npz"), _kept_samples(d / "out", problem.dim))
    mean, sd = _importance_moments(problem, q)
    for i, name in enumerate(summary["coefficients"]):
        post_i = summary["parameters"][name]
        assert abs(mean[i] - post_i["mean"]) < 0.25 * post_i["sd"], (name, mean[i], post_i["mean"], post_i["sd"])
        assert sd[i] == pytest.approx(post_i["sd"], rel=0.2), (name, sd[i], post_i["sd"])


@pytest.mark.slow
def test_ar1_posterior_is_as_wide_as_importance_sampling_says(tmp_path):
    """Four flights with AR(1) marker noise ρ = 0.85 (the first data set of the AR(1) calibration campaign,
    runs/calibration/four_flights_ar1.yaml), fitted with ``noise: {model: ar1}`` and the default sampler: every
    coefficient's posterior sd within 10 % of an importance-sampling estimate (proposal: the Laplace
    approximation at the least-squares optimum, sd × 1.05, and the run's independence proposal, made
    defensive by a Gaussian on the MCMC moments; :func:`_importance_moments`).

    The sampler as it was (a 0.3 share of independence and pCN moves, the rest differential evolution)
    stopped by its rule with intervals 5–19 % too narrow here (CRp 0.81, CRr 0.83, CMa 0.90 of an
    importance-sampling estimate with the Laplace proposal alone): in ~60 dimensions an ensemble that has
    contracted re-expands under DE moves only over thousands of steps (on an exact Gaussian with this
    posterior's covariance, DE alone held an ensemble started at 0.83 of the sd at 0.78 for 2000 steps), and
    R-hat, ESS and τ cannot see a contraction that every ensemble shares. It was part of the AR(1)
    campaign's too-narrow intervals (README)."""
    from bayes_disc.api import sample
    from bayes_disc.calibration.config import load_cal_config
    from bayes_disc.calibration.replicate import replicate_data, replicate_run
    from bayes_disc.inference.model.config import config_from_mapping
    from bayes_disc.inference.model.data import build_problem
    from bayes_disc.inference.sampling.proposals import CompositeProposal, MixtureProposal
    cal = load_cal_config(REPO / "runs/calibration/four_flights_ar1.yaml")
    result, _, _, seed = replicate_data(cal, 0)
    write_synth(result, tmp_path / "markers.csv", tmp_path / "truth.json")
    run = replicate_run(cal, result, seed)
    sample(run, base_dir=tmp_path, progress=False)
    out = tmp_path / "run"
    summary = json.loads((out / "summary.json").read_text())
    assert summary["convergence"]["converged"]
    problem = build_problem(config_from_mapping(run, tmp_path / "config.yaml"))
    laplace = MixtureProposal.from_components([np.load(out / "least_squares_theta.npy")],
                                              [np.load(out / "least_squares_cov.npy") * 1.05 ** 2], [0.0])
    q = CompositeProposal.load(out / "chains/independence.npz")
    q = CompositeProposal((laplace,) + q.parts, np.log(np.r_[0.5, 0.5 * np.exp(q.log_weights)]))
    mean, sd = _importance_moments(problem, _with_defensive_gaussian(q, _kept_samples(out, problem.dim)))
    ratios = {name: summary["parameters"][name]["sd"] / sd[i] for i, name in enumerate(summary["coefficients"])}
    for i, name in enumerate(summary["coefficients"]):
        post_i = summary["parameters"][name]
        assert abs(mean[i] - post_i["mean"]) < 0.25 * post_i["sd"], (name, mean[i], post_i["mean"], post_i["sd"])
    assert all(0.9 < r < 1.1 for r in ratios.values()), ratios


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
