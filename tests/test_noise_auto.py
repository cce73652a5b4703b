"""``noise: {model: auto}``, the default: each marker flight's noise model chosen by evidence at the least
squares — AR(1) on AR(1) data, white on white data, per-point on data whose stated errors vary, robust on
data with gross errors and swapped labels — stated in the log, summary.json and the report; explicit
settings respected; ``sample`` and ``diagnose`` make the same choice; inertial channels untouched."""
import json
import logging

import numpy as np
import pytest

from bayes_disc.inference.fitting.leastsq import fit_least_squares
from bayes_disc.inference.fitting.noise_choice import (NOISE_CHOICE, NOISE_EVIDENCE, choose_noise, run_settings,
                                                       with_saved_choice)
from bayes_disc.inference.model.config import load_config
from bayes_disc.inference.model.data import build_problem
from bayes_disc.observation.models.noise import AR1Noise, RobustNoise, WhiteNoise
from bayes_disc.observation.synth import LaunchSpec, SynthSpec, synthesize, write_synth
from bayes_disc.observation.synth_defects import Defects

from conftest import run_config

#: four short throws (speed m/s, launch angle °, α °, spin rad/s)
THROWS = ((13.0, 4, 7, 60), (11.0, 8, 13, -55), (14.0, 2, 3, 65), (12.0, 6, 10, 58))
#: sampling kept short: these tests check the choice and where it is stated, not the posterior
SHORT = "sampler: {ensembles: 2, max_steps: 30, adapt_steps: 10, check_every: 10, min_steps: 10, seed: 5}"


def write_flights(folder, defects: Defects, seed: int, n: int = 4, duration: float = 0.5, noise_mm: float = 1.5,
                  *lines: str):
    """``n`` synthetic flights f1… with ``defects`` (flights.csv, truth.json) and a run configuration with
    ``lines`` (config.yaml) in ``folder``; returns the configuration's path."""
    folder.mkdir(parents=True, exist_ok=True)
    flights = tuple(LaunchSpec(name=f"f{i + 1}", speed=s, launch_angle_deg=g, alpha_deg=a, spin=w, duration=duration,
                               noise_mm=noise_mm, defects=defects) for i, (s, g, a, w) in enumerate(THROWS[:n]))
    write_synth(synthesize(SynthSpec(name="auto", flights=flights, seed=seed)), folder / "flights.csv",
                folder / "truth.json")
    path = folder / "config.yaml"
    path.write_text(run_config("auto", "output: out", "least_squares: {starts: 1}", *lines))
    return path


def least_squares_choice(path):
    """The configuration, its problem as built, and the choice at its least squares (as `sample` makes it)."""
    cfg = load_config(path)
    problem = build_problem(cfg)
    ls = fit_least_squares(problem, starts=cfg.least_squares.starts, max_nfev=cfg.least_squares.max_nfev,
                           seed=cfg.sampler.seed)
    return cfg, problem, choose_noise(problem, ls, run_settings(cfg, problem), max_nfev=cfg.least_squares.max_nfev)


def run_logged(path):
    """``sample`` without its report; returns (summary, log messages)."""
    from bayes_disc.jobs.sample import run_sample
    records = []
    handler = logging.Handler()
    handler.emit = lambda rec: records.append(rec.getMessage())
    handler.setLevel(logging.INFO)
    logger = logging.getLogger("bayes_disc")
    level = logger.level
    logger.addHandler(handler)
    logger.setLevel(logging.INFO)
    try:
        summary = run_sample(load_config(path), progress=False)
    finally:
        logger.removeHandler(handler)
        logger.setLevel(level)
    return summary, records


@pytest.fixture(scope="module")
def ar1_run(tmp_path_factory):
    """Four flights with AR(1) marker noise ρ = 0.85 and a default configuration, sampled briefly."""
    path = write_flights(tmp_path_factory.mktemp("ar1"), Defects(ar1_rho=0.85), 21, 4, 0.5, 1.5, SHORT)
    summary, log = run_logged(path)
    return path, summary, log


@pytest.mark.xdist_group("ar1_run")     # one worker samples the shared run
def test_ar1_noise_is_chosen_for_every_flight_and_stated(ar1_run):
    """AR(1) data, default configuration: every flight gets AR(1) noise by evidence (ΔBIC over white above
    the threshold, ρ̂ near 0.85), sampled with ρ_f; summary.json's ``noise_choice``, noise_choice.json, one log
    line per flight and the report's first screen say so."""
    from bayes_disc.report.answer import noise_choice_html
    path, summary, log = ar1_run
    choice = summary["noise_choice"]
    assert set(choice) == {"f1", "f2", "f3", "f4"}
    for f, r in choice.items():
        assert r["label"] == "ar1" and r["by"] == "evidence" and r["chosen"] == {"model": "ar1", "per_point": "false"}
        assert r["setting"] == {"model": "auto", "per_point": "auto"}
        assert r["reference"] == "white" and r["delta_bic"]["white"] == 0.0
        assert r["delta_bic"]["ar1"] > NOISE_EVIDENCE, r
        assert 0.6 < r["rho"]["ar1"] < 0.95, r
        assert r["outliers"] == 0 and r["swaps"] == 0
        assert summary["noise"][f]["model"] == "ar1" and f"rho_{f}" in summary["parameters"]
        assert sum(m.startswith(f"noise choice: {f}: AR(1) noise chosen") for m in log) == 1, log
    out = path.parent / "out"
    assert json.loads((out / NOISE_CHOICE).read_text()) == choice
    html = noise_choice_html(summary)
    assert all(f"<td>{f}</td><td>AR(1), ρ̂ = " in html for f in choice), html
    assert "over white noise" in html


@pytest.mark.xdist_group("ar1_run")     # one worker samples the shared run
def test_a_resumed_or_reported_run_rebuilds_the_chosen_models(ar1_run):
    """The configuration alone builds white noise; with the run's saved choice the problem is the one sampled
    (its chains' run key matches, as resuming and the report need)."""
    from bayes_disc.jobs.sample import check_same_run
    from bayes_disc.observation.config_io import ConfigError
    path, summary, _ = ar1_run
    cfg, out = load_config(path), path.parent / "out"
    built = build_problem(cfg)
    assert all(type(ch[0].noise) is WhiteNoise for ch in built.channels)
    with pytest.raises(ConfigError, match="rho_f1"):
        check_same_run(cfg, built, out)
    chosen = with_saved_choice(built, out)
    assert all(isinstance(ch[0].noise, AR1Noise) for ch in chosen.channels)
    check_same_run(cfg, chosen, out)


def test_white_noise_keeps_white(tmp_path):
    """White data: no candidate earns ΔBIC > 10 over white noise (the AR(1) candidate pays ln n for ρ), the
    flights keep white noise and the problem and least squares are the ones given."""
    cfg, problem, choice = least_squares_choice(write_flights(tmp_path, Defects(), 22))
    for f, r in choice.records.items():
        assert r["label"] == "white" and r["by"] == "evidence", r
        assert r["delta_bic"]["ar1"] < NOISE_EVIDENCE and "per_point" not in r["delta_bic"], r
        assert "no sigma_m" in r["not_tried"]["per_point"]
        assert "white noise kept" in r["text"]
    assert choice.problem is problem and all(type(ch[0].noise) is WhiteNoise for ch in choice.problem.channels)


def test_stated_errors_that_vary_are_used(tmp_path):
    """Two flights whose noise is 5× larger over 30 % of their samples, with a truthful sigma_m column: the
    per-point model wins by evidence; a flight with ``per_point: false`` is not offered it, and the many
    points its white fit leaves far out do not make it robust (the noise varies; it is not gross errors)."""
    d = Defects(sigma_fraction=0.3, sigma_factor=5.0, per_point_sigma=True)
    path = write_flights(tmp_path, d, 23, 2, 0.5, 1.5, "flight_options: {f2: {noise: {per_point: false}}}")
    cfg, problem, choice = least_squares_choice(path)
    r1, r2 = choice.records["f1"], choice.records["f2"]
    assert r1["label"] == "per_point" and r1["delta_bic"]["per_point"] > NOISE_EVIDENCE, r1
    assert r1["chosen"] == {"model": "gaussian", "per_point": "true"}
    assert choice.problem.channels[0][0].noise.points.source == "sigma_m"
    assert "per_point" not in r2["delta_bic"] and r2["not_tried"]["per_point"] == "per_point: false", r2
    assert r2["label"] != "robust" and r2["outliers"] > 0.02 * problem.flights[1].n_points, r2
    assert "noise more likely varies" in r2["not_robust"] and "not robust:" in r2["text"]
    assert choice.problem.channels[1][0].noise.points is None


def test_gross_errors_and_swaps_choose_robust_and_are_stated(tmp_path):
    """Two flights with 1 % of their points gross errors (2–6 cm) and two swapped frames each: the judgement
    at the white fit finds them, the flights get robust noise, and `sample` removes them before sampling
    and says so (summary.json, flagged.json, the log)."""
    d = Defects(outlier_fraction=0.01, swap_frames=2)
    summary, log = run_logged(write_flights(tmp_path, d, 24, 2, 0.5, 1.5, SHORT))
    truth = json.loads((tmp_path / "truth.json").read_text())
    flags = json.loads((tmp_path / "out" / "flagged.json").read_text())
    for f in ("f1", "f2"):
        r = summary["noise_choice"][f]
        injected = truth["flights"][f]["defects"]
        assert r["label"] == "robust" and r["by"] == "gross errors", r
        assert r["outliers"] >= 1 and r["swaps"] >= 1, r
        assert r["outliers"] + r["swaps"] <= len(injected["outliers"]["points"]) + len(injected["swaps"]["frames"]) + 1
        assert summary["noise"][f]["model"] == "robust"
        assert {(round(w["t"], 6), tuple(w["markers"])) for w in flags[f]["swaps"]} == \
            {(round(s["t"], 6), tuple(s["markers"])) for s in injected["swaps"]["frames"]}
        assert any(m.startswith(f"noise choice: {f}: robust noise chosen") for m in log)
    assert summary["flagged"]["swaps"] == 4


def test_an_explicit_model_is_respected(tmp_path):
    """AR(1) data with ``noise: {model: gaussian}``: nothing is judged or refitted, white noise as configured;
    a flight's own ``flight_options`` setting overrides ``auto`` the same way."""
    path = write_flights(tmp_path, Defects(ar1_rho=0.85), 21, 2, 0.5, 1.5, "noise: {model: gaussian}")
    cfg, problem, choice = least_squares_choice(path)
    assert choice.problem is problem
    for r in choice.records.values():       # (the synthetic AR(1) data carry a sigma_m column, all alike)
        assert r["by"] == "configuration" and "delta_bic" not in r and "outliers" not in r, r
        assert r["chosen"] == r["setting"] == {"model": "gaussian", "per_point": "auto"}
        assert r["text"].endswith("as configured") and "white noise" in r["text"], r
    path.write_text(run_config("auto", "output: out", "least_squares: {starts: 1}",
                               "flight_options: {f2: {noise: {model: gaussian}}}"))
    cfg, problem, choice = least_squares_choice(path)
    assert choice.records["f1"]["label"] == "ar1" and choice.records["f2"]["by"] == "configuration"
    assert isinstance(choice.problem.channels[0][0].noise, AR1Noise)
    assert type(choice.problem.channels[1][0].noise) is WhiteNoise and "rho_f2" not in choice.problem.names
    assert choice.settings() == {"f1": {"model": "ar1", "per_point": "false"}}


def test_sample_and_diagnose_make_the_same_choice(tmp_path):
    """`diagnose` calls the same chooser at the same least squares as `sample`: its ``noise.choice`` equals the
    sample job's noise_choice.json."""
    from bayes_disc.diagnostics.diagnosis import analyse
    from bayes_disc.jobs.sample import _least_squares, _noise_choice
    path = write_flights(tmp_path, Defects(ar1_rho=0.85), 25, 2, 0.4, 1.5)
    cfg = load_config(path)
    out = tmp_path / "out"
    out.mkdir()
    ls, ls_dict = _least_squares(build_problem(cfg), cfg, out)
    _noise_choice(build_problem(cfg), ls, ls_dict, cfg, out)
    sampled = json.loads((out / NOISE_CHOICE).read_text())
    analysis = analyse(cfg, processes=1, candidates=["side_force"])
    assert json.loads(json.dumps(analysis.noise["choice"])) == sampled
    assert {r["label"] for r in sampled.values()} == {"ar1"}


def test_inertial_channels_are_left_alone():
    """A flight seen by markers and an inertial logger: replacing its marker noise keeps the logger's channel
    (the same object) and the start of its own parameters; a run of inertial throws has no choice to make."""
    from bayes_disc.inference.model.problem import Problem
    from bayes_disc.observation.inertial_synth import LoggerSpec, synthetic_log
    from bayes_disc.observation.models import MarkerPositions
    from bayes_disc.observation.models.inertial import InertialMeasurements
    from bayes_disc.observation.synth import DEFAULT_MARKERS
    from bayes_disc.physics import Disc, Environment, literature_coefficients
    from bayes_disc.inference.model.initial import initial_state_from_data
    launch = LaunchSpec(name="a", speed=12.0, launch_angle_deg=4, alpha_deg=8, spin=55, duration=0.3)
    flight = synthesize(SynthSpec(name="s", flights=(launch,), seed=3)).flights[0]
    log = synthetic_log("a", launch.initial_state(), literature_coefficients("hummel2002"), 0.3, LoggerSpec(),
                        np.random.default_rng(0))
    mb = np.array(list(DEFAULT_MARKERS.values()))
    imu = InertialMeasurements(log, Environment().g, period=0.0125)
    both = Problem(flights=[flight], marker_body=mb, disc=Disc(), env=Environment(), prior_name="weak",
                   start_states=[initial_state_from_data(flight, mb)],
                   observations=[(MarkerPositions(flight, mb), imu)])
    ar = both.with_marker_noise({"a": ("ar1", "false")})
    assert ar.channels[0][1] is imu and isinstance(ar.channels[0][0].noise, AR1Noise)
    x0, x1 = both.start_vector(), ar.start_vector()
    own = [n for n in both.names if n.endswith("_a") and n not in ar.names[:ar.ic_start]]
    assert "rho_a" in ar.names and "rho_a" not in both.names
    for n in own:
        assert x1[ar.names.index(n)] == x0[both.names.index(n)], n
    with pytest.raises(ValueError, match="no marker recording"):
        Problem(flights=[log], marker_body=mb, disc=Disc(), env=Environment(), prior_name="weak",
                start_states=[launch.initial_state()], observations=[(imu,)]).with_marker_noise({"a": ("ar1", "false")})
    only = Problem(flights=[log], marker_body=mb, disc=Disc(), env=Environment(), prior_name="weak",
                   start_states=[launch.initial_state()], observations=[(imu,)])
    sentinel = object()
    choice = choose_noise(only, sentinel, {})
    assert choice.records == {} and choice.problem is only and choice.ls is sentinel


def _truth_distance(folder, summary) -> float:
    """Squared Mahalanobis distance of the ten true coefficients from the posterior (mean and covariance of
    the draws in ``folder/out/posterior.nc``): χ²₁₀ distributed when the posterior is calibrated."""
    import arviz as az
    truth = json.loads((folder / "truth.json").read_text())["coefficients"]
    post = az.from_netcdf(str(folder / "out" / "posterior.nc")).posterior
    names = summary["coefficients"]
    draws = np.column_stack([post[n].values.ravel() for n in names])
    gap = np.array([truth[n] for n in names]) - draws.mean(axis=0)
    return float(gap @ np.linalg.solve(np.cov(draws.T), gap))


@pytest.mark.slow
def test_default_configuration_covers_the_truth_on_ar1_data_where_white_noise_does_not(tmp_path):
    """Four data sets of four flights with AR(1) marker noise ρ = 0.85, each sampled (short chains) with the
    default configuration and with ``noise: {model: gaussian}``: the default chooses AR(1) for every flight,
    puts the true coefficients closer to its posterior (joint Mahalanobis distance) in every data set, and
    inside the posterior's joint 90 % region in more of them — in at least half; white noise, whose intervals
    ignore the correlation, does so in fewer."""
    from scipy.stats import chi2
    from bayes_disc.jobs.sample import run_sample
    limit = chi2.ppf(0.9, 10)
    inside = {"auto": 0, "gaussian": 0}
    for seed in (40, 41, 42, 43):
        distance = {}
        for model in ("auto", "gaussian"):
            folder = tmp_path / f"{seed}_{model}"
            sampler = f"sampler: {{ensembles: 2, max_steps: 300, min_steps: 100, check_every: 50, seed: {seed}}}"
            path = write_flights(folder, Defects(ar1_rho=0.85), seed, 4, 0.5, 1.5, sampler, "prior: weak",
                                 f"noise: {{model: {model}}}")
            summary = run_sample(load_config(path), progress=False)
            chosen = {(r["by"], r["chosen"]["model"]) for r in summary["noise_choice"].values()}
            assert chosen == ({("evidence", "ar1")} if model == "auto" else {("configuration", "gaussian")}), chosen
            distance[model] = _truth_distance(folder, summary)
            inside[model] += distance[model] <= limit
        assert distance["auto"] < distance["gaussian"], (seed, distance)
    assert inside["auto"] >= 2 and inside["auto"] > inside["gaussian"], inside
