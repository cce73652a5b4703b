"""Correlated noise is not missing physics: `diagnose` tells them apart."""
import json
from dataclasses import replace

from bayes_disc.cli import main
from bayes_disc.diagnostics.residuals import flight_residuals, ljung_box
from bayes_disc.observation.synth_defects import Defects
from bayes_disc.observation.synth import LaunchSpec, SynthSpec, synthesize, write_synth

from conftest import run_config
from test_noise import _fit, _problem, clean, with_ar1_noise  # noqa: F401 (clean: a fixture)


def test_residual_series_of_ar1_noise_are_its_innovations(clean):
    """Diagnostics judge whiteness on what the noise model does not explain: with AR(1) noise ρ = 0.85 in
    the data, the marker residual series (translations and the attitude series, whose marker combinations
    turn with the spin) are white under the AR(1) model at its fit, and structured under white noise."""
    noisy = with_ar1_noise(clean)
    p_ar, p_white = _problem(noisy, noise_model="ar1"), _problem(noisy)
    ls_ar, ls_white = _fit(p_ar), _fit(p_white)
    level = 1e-3 / 9                                     # the diagnosis' Bonferroni level for nine series
    p_values = {kind: {name: ljung_box(x)[1] for name, x in flight_residuals(p, ls.theta)[0].series.items()}
                for kind, p, ls in (("ar1", p_ar, ls_ar), ("white", p_white, ls_white))}
    assert min(p_values["ar1"].values()) > level, p_values["ar1"]
    assert p_values["white"]["roll"] < level and p_values["white"]["along"] < level, p_values["white"]


def test_diagnose_says_noise_correlated_not_missing_physics(tmp_path, monkeypatch):
    """Two flights with AR(1) marker noise ρ = 0.85 at 120 Hz and nothing missing from the model: the white
    diagnosis leaves structure no term explains; with AR(1) noise the model is adequate, ρ is recovered."""
    monkeypatch.chdir(tmp_path)
    ar = Defects(ar1_rho=0.85)
    flights = (LaunchSpec(name="a", speed=13.0, launch_angle_deg=4, alpha_deg=7, spin=60, duration=0.5, noise_mm=1.5,
                          defects=ar),
               LaunchSpec(name="b", speed=11.0, launch_angle_deg=8, alpha_deg=13, spin=-55, duration=0.5,
                          noise_mm=1.5, defects=ar))
    write_synth(synthesize(SynthSpec(name="c", flights=flights, seed=21)), tmp_path / "flights.csv",
                tmp_path / "truth.json")
    (tmp_path / "config.yaml").write_text(run_config("corr", "output: out\nleast_squares: {starts: 1}"))
    assert main(["diagnose", str(tmp_path / "config.yaml"), "--no-sample", "--processes", "1", "--no-progress"]) == 0
    d = json.loads((tmp_path / "out" / "diagnosis.json").read_text())
    assert d["noise"]["model"] == "ar1" and d["noise"]["evidence"] > 10, d["noise"]
    assert set(d["noise"]["rho"]) == {"a", "b"}
    assert all(0.7 < r < 0.95 for r in d["noise"]["rho"].values()), d["noise"]["rho"]
    assert d["verdict"] == "adequate" and d["effects"] == [], (d["verdict"], d["words"])
    assert "Noise correlated in time" in d["words"] and "no missing physics" in d["words"]


def _laplace_run(problem, ls, folder, seed: int):
    """posterior.nc of draws from N(θ̂, Σ/100), Σ the least-squares covariance (2 ensembles × 40 steps × 8
    walkers; σ drawn from its exact conditional), written to ``folder``: a cloud with the posterior's shape,
    narrowed because one half-second flight leaves the coefficients so loose that N(θ̂, Σ) reaches where the
    model is far from linear (and out of the prior's support)."""
    import numpy as np

    from bayes_disc.inference.results.idata import build_inference_data
    from bayes_disc.inference.sampling.chains import Chains
    rng = np.random.default_rng(seed)
    n_ens, n_steps, n_w = 2, 40, 8
    flat = rng.multivariate_normal(ls.theta, ls.cov / 100, size=n_ens * n_steps * n_w)
    lp = problem.log_prob(flat)
    assert np.all(np.isfinite(lp))
    sigma = problem.draw_sigma(problem.sum_squares(flat), rng, flat)
    shape = (n_ens, n_steps, n_w)
    chains = Chains(chain=flat.reshape(*shape, -1), log_prob=lp.reshape(shape), sigma=sigma.reshape(*shape, -1),
                    acceptance=np.full((n_ens, n_w), 0.3), burn=0, total_steps=n_steps,
                    tau=np.ones((n_ens, problem.dim)), converged=False, reason="test")
    idata = build_inference_data(problem, chains, rng, n_prior=20, n_log_likelihood=n_ens * n_steps * n_w,
                                 n_predictive=n_ens * n_w)
    folder.mkdir(parents=True)
    idata.to_netcdf(str(folder / "posterior.nc"))


def test_loo_prefers_the_ar1_noise_model_on_correlated_noise_and_not_on_white(clean, tmp_path):
    """Model choice between noise models by PSIS-LOO (az.compare through `bd.compare`): the same points fitted
    with white and with AR(1) noise. With AR(1) noise ρ = 0.85 in the data the AR(1) model has the higher
    expected log predictive density by many standard errors; with white noise the two are not told apart
    (ρ ≈ 0 adds nothing)."""
    import numpy as np

    import bayes_disc as bd
    rng = np.random.default_rng(5)
    white_data = replace(clean, positions=clean.positions + 2e-3 * rng.normal(size=clean.positions.shape))
    for kind, flight in (("correlated", with_ar1_noise(clean)), ("white", white_data)):
        for model in ("gaussian", "ar1"):
            p = _problem(flight, noise_model=model) if model == "ar1" else _problem(flight)
            _laplace_run(p, _fit(p), tmp_path / kind / model, seed=3)
        table = bd.compare({m: tmp_path / kind / m for m in ("gaussian", "ar1")})
        if kind == "correlated":
            assert table.index[0] == "ar1", table
            assert table.loc["gaussian", "elpd_diff"] > 10 * table.loc["gaussian", "dse"], table
        else:
            other = table.index[1]
            assert table.loc[other, "elpd_diff"] < 2 * table.loc[other, "dse"] + 1.0, table
