"""Missing physics (``bayes-disc diagnose``): data explanations, candidate ranking, acceptance, words.

The statistical proofs (slow) run on synthetic data with one effect concealed from the run's model, at
a magnitude where the best base-model fit is only 1.5–3× the noise RMS (checked in each test, so the
data cannot drift into glaring effects), on data with nothing missing (false alarms) and on a flight
hit by a gust, which no term of the library describes.
"""
import json
from pathlib import Path

import numpy as np
import pytest
import yaml

from bayes_disc.cli import main
from bayes_disc.jobs.diagnose import run_diagnose
from bayes_disc.diagnostics.missing_physics import CANDIDATES, evidence, extend_theta
from bayes_disc.inference.model.config import load_config
from bayes_disc.inference.model.data import build_problem
from bayes_disc.observation.config_io import ConfigError
from bayes_disc.observation.explanations import predicted_markers
from bayes_disc.observation.synth import DEFAULT_MARKERS, LaunchSpec
from bayes_disc.physics import literature_coefficients, simulate

NOISE_MM = 1.5
#: three throws spanning α 2–27°, both spin directions, one skimming low (ground effect needs it)
FLIGHTS = [
    dict(name="a", speed=13.0, launch_angle_deg=4, alpha_deg=6, spin=60, duration=1.0, position=[0, 0, 1.0]),
    dict(name="b", speed=10.0, launch_angle_deg=10, pitch_deg=32, spin=-50, duration=0.9, position=[0, 0, 0.9]),
    dict(name="c", speed=14.0, launch_angle_deg=0, alpha_deg=2, roll_deg=-4, spin=65, duration=1.0,
         position=[0, 0, 0.45]),
]
#: concealed effects, calibrated so that the base fit's RMS is 1.7–2.2× the noise (seed 3)
CONCEALED = {
    "side_force": {"side_force": {"CY": 0.05}},
    "wind": {"wind": {"wind_x": 2.5, "wind_y": 1.5}},
    "ground_effect": {"ground_effect": {"CL_ge": 0.5, "CD_ge": 0.15}},
    "nonlinear_aero": {"nonlinear_aero": {"CL2": -2.0, "CD3": 2.0, "CM2": -0.2}},
}


def make_run(folder: Path, physics: dict, seed: int, gust: dict | None = None, markers: dict | None = None,
             nature: dict | None = None) -> Path:
    """Synthesize the three flights with ``physics`` and ``nature`` (hidden from the run's config) into
    ``folder``; returns the run's config path. ``gust`` is added to flight a; ``markers`` are the true body
    positions."""
    folder.mkdir(parents=True, exist_ok=True)
    flights = [dict(f, noise_mm=NOISE_MM, dropout=0.02) for f in FLIGHTS]
    if gust:
        flights[0]["gust"] = gust
    synth = dict(name="t", seed=seed, coefficients="hummel2002", physics=physics, flights=flights,
                 output=dict(markers="flights.csv", truth="truth.json"))
    if markers:
        synth["markers"] = markers
    if nature:
        synth["nature"] = nature
    (folder / "synth.yaml").write_text(yaml.safe_dump(synth))
    assert main(["synth", str(folder / "synth.yaml")]) == 0
    config = dict(name="t", flights=[dict(file="flights.csv")], markers=DEFAULT_MARKERS, prior="potts_crowther",
                  output="out", least_squares=dict(starts=2))
    (folder / "config.yaml").write_text(yaml.safe_dump(config))
    return folder / "config.yaml"


def diagnose(cfg_path: Path, candidates=None, learn: bool = True) -> dict:
    """``diagnose --no-sample``; ``learn=False`` skips the learned correction (tests of library formulas,
    where it is not what is tested, run faster)."""
    return run_diagnose(load_config(cfg_path), sample=False, processes=1, candidates=candidates, learn=learn)


def pooled_ratio(rms: dict) -> float:
    return float(np.sqrt(np.mean(np.square(list(rms.values())))) / NOISE_MM)


# -- data explanations ------------------------------------------------------------------------------------

def _one_flight():
    y0 = LaunchSpec(name="x", speed=13.0, alpha_deg=6, spin=60).initial_state()
    times = np.arange(121) / 120.0
    mb = np.array(list(DEFAULT_MARKERS.values()))
    return y0, times, mb


def test_marker_offsets_equal_a_simulation_with_moved_markers():
    y0, times, mb = _one_flight()
    coef = literature_coefficients("hummel2002").as_array()
    delta = np.array([[0.003, -0.002, 0.001], [0.0, 0.004, 0.0], [-0.002, 0.0, -0.003]])
    moved = simulate(y0, coef, times, marker_body=mb + delta).markers
    tr = simulate(y0, coef, times, marker_body=mb)
    pred = predicted_markers(tr.states, mb, delta[None], None)
    assert np.max(np.abs(pred - moved)) < 1e-12
    assert np.max(np.abs(pred - tr.markers)) > 1e-3


def test_timing_offsets_equal_a_simulation_at_shifted_times():
    """m_j(t + δ_j) from the rigid-body advance (explanations.py) against the simulator run at t + δ_j."""
    y0, times, mb = _one_flight()
    coef = literature_coefficients("hummel2002").as_array()
    dt = np.array([0.0, 0.001, -0.0015])
    tr = simulate(y0, coef, times[1:-1], t0=0.0, marker_body=mb)
    pred = predicted_markers(tr.states, mb, None, dt[None], times[1:-1])
    for j, d in enumerate(dt):
        exact = simulate(y0, coef, times[1:-1] + d, t0=0.0, marker_body=mb).markers[0, :, j]
        assert np.max(np.abs(pred[0, :, j] - exact)) < 1e-6, j
    # a millisecond moves a rim marker (spin 60 rad/s, 13 m/s) by about a centimetre
    assert np.max(np.abs(pred[0, :, 1] - tr.markers[0, :, 1])) > 5e-3


def test_config_accepts_every_candidate_and_rejects_unknown_terms(tmp_path):
    cfg_path = make_run(tmp_path, {}, seed=1)
    text = cfg_path.read_text()
    for cid in CANDIDATES:
        cfg_path.write_text(text + f"physics: {{{cid}: {{}}}}\n")
        problem = build_problem(load_config(cfg_path))
        assert problem.model_ids == [cid]
        assert problem.n_ext >= 1
    cfg_path.write_text(text + "physics: {magnus: {}}\n")
    with pytest.raises(ConfigError, match="physics.magnus"):
        load_config(cfg_path)


def test_evidence_charges_for_parameters(tmp_path):
    """ΔBIC = Σ n_f ln(S_base/S_cand) − k ln N; extend_theta keeps every shared value."""
    cfg = load_config(make_run(tmp_path, {}, seed=1))
    base_p = build_problem(cfg)
    cand_p = build_problem(cfg, terms_override=["wind"])
    theta = base_p.prior_mean + 0.01
    x = extend_theta(theta, base_p, cand_p)
    assert np.array_equal(x[:10], theta[:10]) and np.array_equal(x[cand_p.ic_start:], theta[base_p.ic_start:])
    k = cand_p.n_ext                                  # wind: three components and two shears
    assert k == 5 and np.array_equal(x[10:10 + k], np.zeros(k))

    class Fit:
        def __init__(self, problem, ss):
            self.problem, self.ss = problem, np.asarray(ss, float)
    n = base_p.n_coords
    same = evidence(Fit(base_p, [1.0, 2.0, 3.0]), Fit(cand_p, [1.0, 2.0, 3.0]))
    assert same == pytest.approx(-k * np.log(n.sum()))
    better = evidence(Fit(base_p, [1.0, 2.0, 3.0]), Fit(cand_p, [0.5, 2.0, 3.0]))
    assert better == pytest.approx(n[0] * np.log(2.0) - k * np.log(n.sum()))


def test_reach_is_where_a_term_acts_beyond_the_launch(tmp_path):
    """A ground effect acts in the low flight c (0.45 m) and not in a and b (about 1 m), beyond what their
    launch absorbs; a wind acts in every flight."""
    from bayes_disc.diagnostics.missing_physics import REACH_SD, ModelFit, reach
    from bayes_disc.inference.fitting.leastsq import LeastSquaresResult
    cfg = load_config(make_run(tmp_path, {}, seed=1))

    def fit_of(problem, theta):
        ls = LeastSquaresResult(theta=theta, sigma=np.full(problem.n_groups, NOISE_MM * 1e-3), cov=np.eye(theta.size),
                                cost=0.0, condition_number=1.0, start_costs=[], nfev=0, message="",
                                names=list(problem.names), flight_names=[], sigma_names=list(problem.sigma_names),
                                sigma_units=list(problem.noise_units))
        return ModelFit((), problem, ls, np.ones(problem.n_groups))
    base_p = build_problem(cfg)
    base = fit_of(base_p, base_p.start_vector())
    found = {}
    for term, values in (("ground_effect", {"CL_ge": 0.5, "CD_ge": 0.15}), ("wind", {"wind_x": 1.0, "wind_y": 1.0})):
        p = build_problem(cfg, terms_override=[term])
        x = extend_theta(base.ls.theta, base_p, p)
        for name, v in values.items():
            x[p.names.index(name)] = v
        found[term] = reach(fit_of(p, x), base)
    ge = found["ground_effect"]
    assert ge[2] > 100 * REACH_SD and max(ge[0], ge[1]) < REACH_SD, ge
    assert np.all(found["wind"] > 10 * REACH_SD), found["wind"]
    # switched off, the term does not act anywhere
    assert np.allclose(reach(base, base), 0.0)


# -- end to end ---------------------------------------------------------------------------------------

def test_diagnose_names_a_concealed_side_force(tmp_path, capsys):
    """The command on data with a concealed side force: the file of docs/outputs.md, words, the right term, the gain."""
    cfg = make_run(tmp_path, CONCEALED["side_force"], seed=3)
    assert main(["diagnose", str(cfg), "--no-sample", "--processes", "2"]) == 0   # forked candidate fits
    out = capsys.readouterr().out
    result = json.loads((tmp_path / "out" / "diagnosis.json").read_text())
    assert {"verdict", "effects", "rms_before_mm", "rms_after_mm"} <= set(result)
    assert result["verdict"] == "missing_physics"
    top = result["effects"][0]
    assert {"id", "evidence", "estimate", "where"} <= set(top)
    assert top["id"] == "side_force"
    assert 1.5 < pooled_ratio(result["rms_before_mm"]) < 3.0
    assert all(abs(v / NOISE_MM - 1) < 0.15 for v in result["rms_after_mm"].values())
    cy = top["estimate"]["CY"]
    assert cy["q025"] < 0.05 < cy["q975"]
    assert top["fingerprint"]["sign_follows_spin"] is True
    assert "side force" in out and "sign follows spin" in out
    assert (tmp_path / "out" / "diagnosis_residuals.npz").is_file()


def test_diagnose_finds_nothing_missing_in_correct_data(tmp_path):
    result = diagnose(make_run(tmp_path, {}, seed=5))
    assert result["verdict"] == "adequate", result["words"]
    assert result["effects"] == [] and result["unexplained"] == []
    assert result["rms_after_mm"] == result["rms_before_mm"]
    assert result["lines"] is None               # white residuals: no sinusoid holds 30 % of any series


def test_diagnose_bad_config_is_one_line_error(tmp_path, capsys):
    (tmp_path / "c.yaml").write_text("name: x\nflights:\n  - file: missing.csv\n")
    assert main(["diagnose", str(tmp_path / "c.yaml"), "--no-sample"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "missing.csv" in err


# -- statistical proofs (slow) ------------------------------------------------------------------------

@pytest.mark.slow
@pytest.mark.parametrize("effect", ["wind", "ground_effect", "nonlinear_aero"])
def test_concealed_effect_is_ranked_first_and_refit_reaches_the_noise(tmp_path, effect):
    result = diagnose(make_run(tmp_path, CONCEALED[effect], seed=3), learn=False)
    ratio = pooled_ratio(result["rms_before_mm"])
    assert 1.5 < ratio < 3.0, f"calibration drifted: base fit {ratio:.2f}× noise"
    assert result["verdict"] == "missing_physics"
    assert result["effects"][0]["id"] == effect, result["words"]
    assert result["candidates"][0]["id"] == effect
    assert all(abs(v / NOISE_MM - 1) < 0.15 for v in result["rms_after_mm"].values()), result["rms_after_mm"]
    truth = CONCEALED[effect][effect]
    for name, value in truth.items():
        est = result["effects"][0]["estimate"][name]
        assert abs(est["value"] - value) < 4 * est["sd"] + 0.02 * abs(value), (name, est, value)


@pytest.mark.slow
def test_no_false_alarms_over_ten_seeds(tmp_path):
    verdicts = [diagnose(make_run(tmp_path / str(seed), {}, seed=100 + seed))["verdict"] for seed in range(10)]
    assert verdicts.count("adequate") >= 9, verdicts


@pytest.mark.slow
def test_gust_is_located_and_reported_unexplained(tmp_path):
    """A 4 m/s side gust hits flight a from 0.35 to 0.6 s: no library term may claim it, nor correlated noise."""
    gust = {"t_start": 0.35, "t_end": 0.6, "wind": [0.0, 4.0, 0.0]}
    result = diagnose(make_run(tmp_path, {}, seed=3, gust=gust))
    assert result["verdict"] == "missing_physics"
    assert result["effects"] == [], result["words"]
    (u,) = result["unexplained"]
    assert u["flight"] == "a"
    assert 0.2 < u["model_follows_until_s"] < 0.6
    assert "Unexplained: flight a" in result["words"]
    assert all(abs(v / NOISE_MM - 1) < 0.15 for f, v in result["rms_before_mm"].items() if f != "a")
    # correlated noise is tried and absorbs part of the gust (ρ → 1), but whitens nothing: not the explanation
    assert result["noise"]["model"] == "white" and result["noise"]["ar1_explains"] is False, result["noise"]
    # nor is the gust a smooth function of height, α and spin: the learned correction leaves it structured
    # and names no family
    ld = result["learned_discrepancy"]
    assert not ld["selected"] or (not ld["white"] and ld["family"] is None), ld


@pytest.mark.slow
def test_wrong_marker_geometry_is_named(tmp_path):
    """The markers sit 3 mm off their configured body positions: a data explanation, not physics."""
    true = {k: list(v) for k, v in DEFAULT_MARKERS.items()}
    true["1"] = [true["1"][0] + 0.003, true["1"][1] - 0.002, true["1"][2]]
    result = diagnose(make_run(tmp_path, {}, seed=3, markers=true), learn=False)
    assert result["effects"][0]["id"] == "marker_geometry", result["words"]
    assert all(abs(v / NOISE_MM - 1) < 0.15 for v in result["rms_after_mm"].values())
    est = result["effects"][0]["estimate"]
    assert abs(est["marker_b1_1"]["value"] - 0.003) < 4 * est["marker_b1_1"]["sd"] + 2e-4


@pytest.mark.slow
def test_unsynchronised_markers_are_named(tmp_path):
    """Marker 1 recorded 0.3 ms late (synth's time_offset): a data explanation, not physics."""
    result = diagnose(make_run(tmp_path, {"time_offset": {"dt_1": 0.0003}}, seed=3), learn=False)
    assert result["effects"][0]["id"] == "time_offset", result["words"]
    assert all(abs(v / NOISE_MM - 1) < 0.15 for v in result["rms_after_mm"].values())
    est = result["effects"][0]["estimate"]["dt_1"]
    assert est["q025"] < 0.0003 < est["q975"], est
