"""Simulation-based calibration: the rank/coverage statistics, CAL.yaml validation, a campaign on Dask."""
import json
import re
from collections import Counter
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from scipy import stats

from bayes_disc.calibration import load_cal_config
from bayes_disc.calibration.stats import (binomial_band, covers, rank_bins, rank_counts, rank_uniformity_p,
                                          sbc_rank, summarize, thinned_draws)
from bayes_disc.cli import main
from bayes_disc.inference.fitting.noise_choice import TITLES as NOISE_LABELS
from bayes_disc.observation.config_io import ConfigError


# ----------------------------------------------------------------------------------- the statistics
def _conjugate_replicates(n_rep, n_draws, rng, sd_factor=1.0):
    """θ ~ N(0, 1), y | θ ~ N(θ, 1): the posterior is N(y/2, 1/2). ``sd_factor`` ≠ 1 makes it miscalibrated."""
    records = []
    for _ in range(n_rep):
        theta = rng.normal()
        y = theta + rng.normal()
        draws = y / 2 + np.sqrt(0.5) * sd_factor * rng.normal(size=n_draws)
        many = y / 2 + np.sqrt(0.5) * sd_factor * rng.normal(size=4000)
        records.append({"ranks": {"t": sbc_rank(theta, draws)}, "truth": {"t": theta},
                        "posterior": {"t": {"mean": float(many.mean()), "sd": float(many.std())}},
                        "covered": {"50": {"t": covers(theta, many, 0.5)}, "90": {"t": covers(theta, many, 0.9)}}})
    return records


def test_ranks_of_the_true_posterior_are_uniform_and_intervals_cover():
    rng = np.random.default_rng(3)
    res = summarize(_conjugate_replicates(400, 19, rng), ["t"], 19, bins=10)
    c = res["coefficients"]["t"]
    assert res["replicates"] == 400 and sum(c["rank_counts"]) == 400 and len(c["rank_counts"]) == 10
    assert c["rank_uniformity_p"] > 0.01
    for level in ("50", "90"):
        lo, hi = res["coverage_band_95"][level]
        assert lo <= c[f"coverage_{level}"] <= hi
    assert abs(c["z_sd"] - 1.0) < 3 * res["z_sd_se"]


@pytest.mark.parametrize("sd_factor, shape", [(0.5, "too narrow"), (2.0, "too wide")])
def test_a_miscalibrated_posterior_is_caught(sd_factor, shape):
    rng = np.random.default_rng(4)
    res = summarize(_conjugate_replicates(400, 19, rng, sd_factor), ["t"], 19, bins=10)
    c = res["coefficients"]["t"]
    assert c["rank_uniformity_p"] < 1e-4, shape
    lo, hi = res["coverage_band_95"]["90"]
    assert not lo <= c["coverage_90"] <= hi
    counts = np.array(c["rank_counts"])
    edges, middle = counts[[0, -1]].mean(), counts[3:7].mean()
    assert (edges > middle) if sd_factor < 1 else (edges < middle)       # ∪ when too narrow, ∩ when too wide
    assert c["z_sd"] == pytest.approx(1.0 / sd_factor, rel=0.1)          # the widths' error itself


def test_rank_and_interval_definitions():
    draws = np.array([0.1, 0.5, 0.2, 0.9])
    assert sbc_rank(0.0, draws) == 0 and sbc_rank(0.3, draws) == 2 and sbc_rank(1.0, draws) == 4
    x = np.linspace(0, 1, 1001)
    assert covers(0.5, x, 0.5) and covers(0.26, x, 0.5) and not covers(0.24, x, 0.5)
    assert covers(0.06, x, 0.9) and not covers(0.04, x, 0.9)
    np.testing.assert_array_equal(rank_counts([0, 4, 5, 9, 10, 19, 15], 19, 4), [2, 2, 1, 2])   # bins of 5 ranks
    with pytest.raises(ValueError):
        rank_counts([20], 19, 4)
    assert rank_bins(99, 100) == 20 and rank_bins(99, 30) == 5 and rank_bins(19, 3) == 2
    with pytest.raises(ValueError):
        rank_bins(19, 100, bins=3)
    lo, hi = binomial_band(100, 0.9)
    assert lo == stats.binom.ppf(0.025, 100, 0.9) / 100 and hi == stats.binom.ppf(0.975, 100, 0.9) / 100
    assert rank_uniformity_p([10, 10, 10, 10]) == pytest.approx(1.0)
    assert rank_uniformity_p([40, 0, 0, 0]) < 1e-10


def test_thinning_removes_the_autocorrelation():
    rng = np.random.default_rng(5)
    rho, n_chain, n_step = 0.9, 40, 2000
    x = np.empty((n_chain, n_step))
    x[:, 0] = rng.normal(size=n_chain)
    for t in range(1, n_step):
        x[:, t] = rho * x[:, t - 1] + np.sqrt(1 - rho ** 2) * rng.normal(size=n_chain)
    tau = (1 + rho) / (1 - rho)                                   # integrated autocorrelation time: 19
    kept = x[:, ::int(np.ceil(tau))]
    lag1 = np.mean([np.corrcoef(c[1:], c[:-1])[0, 1] for c in kept])
    assert lag1 == pytest.approx(rho ** 19, abs=0.04)           # 0.9 → ρ^⌈τ⌉ ≈ 0.14: nearly independent
    d = thinned_draws(x[..., None], tau, 999, rng)
    assert d.shape == (999, 1) and set(d[:, 0]) <= set(kept.ravel())
    with pytest.raises(ValueError, match="only"):
        thinned_draws(x[..., None], tau, n_chain * kept.shape[1] + 1, rng)


# ----------------------------------------------------------------------------------------- CAL.yaml
TINY = """\
name: tiny
replicates: {n}
seed: 5
template:
  sample_rate_hz: 60
  flights:
    - {{name: f1, speed: 12, launch_angle_deg: 5, alpha_deg: 8, spin: 55, duration: 0.4, noise_mm: 2}}
truth: {{draw: around, relative_sd: 0.02}}
launch_jitter: {{speed: 0.5}}
run:
  least_squares: {{starts: 1, max_nfev: 40}}
  sampler: {{ensembles: 2, max_steps: 60, check_every: 10, min_steps: 10, adapt_steps: 10, ess: 20, n_tau: 2}}
draws: 19
output: out
"""

BAD_CAL = {
    "replicates": ("replicates: 3", "replicates: 0"),
    "seeed": ("seed: 5", "seeed: 5"),
    "template.flights[0].speed": ("speed: 12,", "speed: -12,"),
    "template.flights[0].defects.ar1.rho": ("noise_mm: 2}", "noise_mm: 2, defects: {ar1: {rho: 2}}}"),
    "run.sampler.processes": ("ess: 20,", "ess: 20, processes: 2,"),
    "run.sampler.walkerz": ("ess: 20,", "ess: 20, walkerz: 4,"),
    "run.flights": ("run:\n", "run:\n  flights: [{file: x.csv}]\n"),
    "run.prior": ("run:\n", "run:\n  prior: flat\n"),
    "truth.draw": ("draw: around", "draw: posterior"),
    "truth.sd.CLa": ("relative_sd: 0.02", "relative_sd: 0.02, sd: {CLa: -1}"),
    "launch_jitter.velocity": ("speed: 0.5", "velocity: 0.5"),
    "bins": ("draws: 19", "draws: 19\nbins: 3"),
    "template": ("template:\n", "template: nope.yaml\nx_template:\n"),
}


@pytest.mark.parametrize("key", sorted(BAD_CAL))
def test_bad_cal_yaml_names_file_and_key(tmp_path, key, capsys):
    old, new = BAD_CAL[key]
    text = TINY.format(n=3)
    assert old in text
    p = tmp_path / "cal.yaml"
    p.write_text(text.replace(old, new, 1))
    if key == "template":
        with pytest.raises(ConfigError) as e:
            load_cal_config(p)
        assert "key 'template'" in str(e.value) and "not found" in str(e.value)
        return
    with pytest.raises(ConfigError) as e:
        load_cal_config(p)
    assert f"{p}: key '{key}'" in str(e.value), str(e.value)
    assert main(["calibrate", str(p)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and f"key '{key}'" in err[0]


def test_good_cal_yaml_reads(tmp_path):
    p = tmp_path / "cal.yaml"
    p.write_text(TINY.format(n=3))
    cal = load_cal_config(p)
    assert cal.replicates == 3 and cal.draws == 19 and cal.output == tmp_path / "out"
    assert cal.run["sampler"]["processes"] == 1 and cal.truth.draw == "around"
    assert cal.truth.sd["CLa"] == pytest.approx(0.02 * abs(cal.truth.values["CLa"]))
    assert cal.template.flights[0].duration == 0.4



def test_truths_drawn_from_an_around_prior_are_the_fits_prior():
    """Exact SBC: with ``truth.draw: prior`` the campaign draws from the prior the fit will use, also when
    that prior is an ``around`` prior given under ``run.prior``; the shipped four_flights_white campaign is of this kind."""
    from bayes_disc.inference.model.priors import coefficient_prior
    from bayes_disc.physics import literature_coefficients
    cal = load_cal_config(Path(__file__).parents[1] / "runs/calibration/four_flights_white.yaml")
    assert cal.truth.draw == "prior"
    hh = literature_coefficients("hummel2002").as_dict()
    assert cal.truth.values == pytest.approx(hh)
    assert cal.truth.sd == pytest.approx({k: 0.1 * abs(v) for k, v in hh.items()})
    from bayes_disc.inference.model.config import config_from_mapping
    run = config_from_mapping({**cal.run, "name": "r", "flights": [{"file": "four_flights_white.yaml"}],
                               "markers": {"0": [0.1, 0, 0], "1": [0, 0.1, 0], "2": [-0.1, 0, 0]}},
                              Path(__file__).parents[1] / "runs/calibration/four_flights_white.yaml")
    cp = coefficient_prior(run.prior)
    assert cp.mean == pytest.approx(cal.truth.values) and cp.sd == pytest.approx(cal.truth.sd)

# ------------------------------------------------------------------------------- a campaign on Dask
def test_tiny_campaign_on_two_workers_resumes_without_redoing(tmp_path, capsys):
    """Two replicates; three asked for with --summary-only: nothing runs and the two are summarised; then three
    with replicate 0 deleted: only 0 and 2 run again; the keys of docs/outputs.md."""
    p = tmp_path / "cal.yaml"
    p.write_text(TINY.format(n=2))
    assert main(["calibrate", str(p), "--workers", "2", "--no-progress"]) == 0
    out = tmp_path / "out"
    files = sorted((out / "replicates").glob("replicate_*.json"))
    assert [f.name for f in files] == ["replicate_00000.json", "replicate_00001.json"]
    first = {f.name: f.stat().st_mtime_ns for f in files}
    rec1 = json.loads(files[1].read_text())
    # the run's sampler settings are recorded, the configured ones and the defaults
    assert rec1["sampler"]["max_steps"] == 60 and rec1["sampler"]["independence_fraction"] == 0.8
    assert set(rec1["noise"]) == {"f1"} and rec1["noise"]["f1"] in NOISE_LABELS    # noise: auto, the default
    # three asked for, two finished: --summary-only runs nothing and summarises those two
    p.write_text(TINY.format(n=3))
    assert main(["calibrate", str(p), "--workers", "2", "--no-progress", "--summary-only"]) == 0
    summary = json.loads((out / "calibration.json").read_text())
    assert (summary["replicates"], summary["requested"]) == (2, 3)
    assert sorted(f.name for f in (out / "replicates").glob("replicate_*.json")) == [f.name for f in files]
    files[0].unlink()
    capsys.readouterr()
    assert main(["calibrate", str(p), "--workers", "2", "--no-progress"]) == 0
    err = capsys.readouterr().err
    assert "1 of 3 replicates already done, 2 to run" in err
    assert sorted(int(i) for i in re.findall(r"replicate (\d+) finished", err)) == [0, 2]
    files = sorted((out / "replicates").glob("replicate_*.json"))
    assert len(files) == 3
    assert (out / "replicates/replicate_00001.json").stat().st_mtime_ns == first["replicate_00001.json"]
    assert json.loads((out / "replicates/replicate_00001.json").read_text()) == rec1
    cal = json.loads((out / "calibration.json").read_text())
    assert cal["replicates"] == 3 and not cal["failed"]
    assert sum(cal["noise_chosen"].values()) == 3 and set(cal["noise_chosen"]) <= set(NOISE_LABELS)
    assert cal["noise_chosen"] == dict(Counter(json.loads(f.read_text())["noise"]["f1"] for f in files))
    for name in ("CL0", "CLa", "CD0", "CDa", "CM0", "CMa", "CMq", "CRr", "CRp", "CNr"):
        c = cal["coefficients"][name]
        assert set(c) >= {"coverage_50", "coverage_90", "rank_uniformity_p"}
        assert 0 <= c["coverage_50"] <= c["coverage_90"] <= 1 and sum(c["rank_counts"]) == 3
    recs = [json.loads(f.read_text()) for f in files]
    assert [r["index"] for r in recs] == [0, 1, 2] and all(r["status"] == "ok" for r in recs)
    # ranks and coverage of the records agree (a rank at an end is outside the 50 % interval's draws)
    assert cal["coefficients"]["CLa"]["coverage_90"] == np.mean([r["covered"]["90"]["CLa"] for r in recs])
    assert len({r["truth"]["CLa"] for r in recs}) == 3                  # different truths
    html = (out / "calibration.html").read_text()
    assert html.count("<img src=\"data:image/png;base64,") == 2
    # another campaign in the same folder is refused, naming the output key
    p.write_text(TINY.format(n=3).replace("seed: 5", "seed: 6"))
    with pytest.raises(ConfigError, match="key 'output'.*differs in seed"):
        from bayes_disc.calibration import run_campaign
        run_campaign(load_cal_config(p), progress=False)


# --------------------------------------------------------------------------------- documented keys
def _cal_keys(tmp_path, truth: dict) -> dict:
    """{documented key form: default} of every CAL.yaml key the reader asks for (template given as a file
    and the run block's own validation switched off: their keys belong to other pages)."""
    from test_docs import REQUIRED
    from bayes_disc.calibration import config as cal_config
    from bayes_disc.observation import config_io
    (tmp_path / "s.yaml").write_text("name: s\nflights:\n  - {speed: 10}\n")
    cal = tmp_path / "cal.yaml"
    data = {"name": "k", "replicates": 2, "template": "s.yaml", "truth": truth, "launch_jitter": {"speed": 1.0},
            "run": {}, "draws": 19}
    import yaml
    cal.write_text(yaml.safe_dump(data))
    seen = {}
    original = config_io.Section.raw

    def recording(self, name, default=None, required=False):
        if str(self.path) == str(cal):
            seen.setdefault(self.key(name), REQUIRED if required else default)
        return original(self, name, default, required)

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(config_io.Section, "raw", recording)
        # the run block is the run configuration's (documented there); only its prior is used here
        mp.setattr(cal_config, "config_from_mapping", lambda *a, **k: SimpleNamespace(prior="potts_crowther"))
        load_cal_config(cal)
    out = {}
    for k, v in seen.items():
        k = re.sub(r"^launch_jitter\.\w+$", "launch_jitter.<launch value>", k)
        k = re.sub(r"^truth\.(sd|values)\.\w+$", r"truth.\1.<coefficient>", k)
        out[k] = v
    return out


def test_every_cal_key_is_documented_with_its_default(tmp_path):
    from test_docs import REPO, default_matches, documented_rows, leaves
    for d in ("a", "b"):
        (tmp_path / d).mkdir()
    keys = _cal_keys(tmp_path / "a", {"draw": "prior"})
    keys.update(_cal_keys(tmp_path / "b", {"draw": "around", "values": {"CLa": 3.0}}))
    assert {"replicates", "truth.max_redraws", "truth.sd.<coefficient>", "launch_jitter.<launch value>"} <= set(keys)
    rows = documented_rows((REPO / "docs/calibration.md").read_text())
    missing = sorted(k for k in leaves(keys) if k not in rows)
    assert not missing, f"CAL.yaml keys not documented in docs/calibration.md: {missing}"
    stale = sorted(k for k in rows if k not in keys)
    assert not stale, f"docs/calibration.md documents keys CAL.yaml does not accept: {stale}"
    checked = {k: (rows[k], keys[k]) for k in leaves(keys)
               if not k.endswith("<coefficient>") and not default_matches(rows[k], keys[k])}
    assert not checked, f"documented default differs from the code (doc cell, code default): {checked}"


def test_a_campaign_recorded_before_the_template_had_nature_still_resumes(tmp_path):
    """runs/calibration/out_ar1_f03 (then out_ar1) was recorded before SynthSpec gained ``nature``: its key (template repr without
    the field) is accepted while the template has no nature, and refused once it has one."""
    from dataclasses import replace

    from bayes_disc.calibration.campaign import CAMPAIGN_FILE, check_campaign
    cal = load_cal_config(Path(__file__).parents[1] / "runs/calibration/four_flights_ar1.yaml")
    cal = replace(cal, output=tmp_path)
    old = {**cal.key(), "template": repr(cal.template).replace(", nature={}", "")}
    assert old != cal.key() and cal.earlier_keys() == [old]
    (tmp_path / CAMPAIGN_FILE).write_text(json.dumps(old))
    check_campaign(cal)                                              # resumes
    natured = replace(cal, template=replace(cal.template, nature={"wind_power_shear": {"wref_x": 1.0}}))
    assert natured.earlier_keys() == []
    with pytest.raises(ConfigError, match="another campaign"):
        check_campaign(natured)


def test_replicate_problem_is_what_the_replicates_fit_builds():
    """The problem of a campaign replicate, for checks that do not sample: the campaign's run settings (AR(1)
    noise, two least-squares starts), the replicate's flights and truth; at θ̃ (bayes_disc.inference.model.truth)
    the effective residuals over σ have mean square 1 − ρ² (the innovations, scaled by |W|^(−1/n))."""
    from bayes_disc.calibration.replicate import replicate_data, replicate_problem
    from bayes_disc.inference.fitting.residuals import flight_residuals
    from bayes_disc.inference.model.truth import truth_theta
    repo = Path(__file__).resolve().parents[1]
    cal = load_cal_config(repo / "runs/calibration/four_flights_ar1.yaml")
    problem, cfg, result, truth = replicate_problem(cal, 3)
    assert truth == replicate_data(cal, 3)[1]
    assert cfg.least_squares.starts == 2
    assert [f.name for f in problem.flights] == [f.name for f in cal.template.flights]
    assert all(f"rho_{f.name}" in problem.names for f in problem.flights)
    theta = truth_theta(problem, result.truth)
    sigma = np.array([result.truth["flights"][f.name]["noise_m"] for f in problem.flights])
    ms = [np.mean(r ** 2) for r in flight_residuals(theta, problem, sigma)]
    assert np.allclose(ms, 1 - 0.85 ** 2, atol=0.06), ms        # ~900 residuals a flight: sd ≈ 0.013


def test_outside_probability_and_familywise_band_match_simulated_campaigns():
    """Simulated campaigns of K = 20 calibrated coverage counts (N = 100, levels 0.5 and 0.9): the fraction of
    counts outside their own 95 % band equals Σ outside_probability / K, and the fraction of campaigns with
    every count inside the family-wise band is ≥ 95 % (and the family-wise band is wider than the single one)."""
    from bayes_disc.calibration.stats import familywise_mass, outside_probability
    rng = np.random.default_rng(11)
    n, campaigns = 100, 20_000
    levels = np.repeat([0.5, 0.9], 10)
    counts = rng.binomial(n, levels, size=(campaigns, levels.size)) / n
    single = np.array([binomial_band(n, p) for p in levels])
    family = np.array([binomial_band(n, p, familywise_mass(levels.size)) for p in levels])
    outside = (counts < single[:, 0]) | (counts > single[:, 1])
    expected = np.mean([outside_probability(n, p) for p in levels])
    assert outside.mean() == pytest.approx(expected, abs=4 * np.sqrt(expected / outside.size))
    assert 0 < expected <= 0.05
    all_inside = np.all((counts >= family[:, 0]) & (counts <= family[:, 1]), axis=1).mean()
    assert all_inside >= 0.95 - 3 * np.sqrt(0.05 * 0.95 / campaigns)
    assert np.all(family[:, 0] <= single[:, 0]) and np.all(family[:, 1] >= single[:, 1])
    res = summarize(_conjugate_replicates(100, 19, rng), ["t"], 19, bins=10)
    assert res["coverage_outside_expected"] == pytest.approx(outside_probability(100, 0.5) + outside_probability(100, 0.9))
    assert res["coverage_band_familywise_95"]["90"] == list(binomial_band(100, 0.9, familywise_mass(2)))


def test_calibration_page_counts_coverages_outside_their_bands(tmp_path):
    """The page says how many coverages fall outside their own band and which are inside the family-wise one:
    a 90 % coverage of 0.83 at N = 100 (band 0.84–0.95, family-wise 0.80–0.98 for K = 4) is 'NO', 'yes'."""
    from bayes_disc.report.calibration import build_calibration_page
    rng = np.random.default_rng(12)
    recs = _conjugate_replicates(100, 19, rng)
    for r in recs:                                     # a second coefficient, a copy of the first
        for key in ("ranks", "truth", "posterior"):
            r[key]["u"] = r[key]["t"]
        for lv in ("50", "90"):
            r["covered"][lv]["u"] = r["covered"][lv]["t"]
    res = summarize(recs, ["t", "u"], 19, bins=10)
    res["coefficients"]["u"]["coverage_90"] = 0.83
    for lv in ("50", "90"):
        res["coefficients"]["t"][f"coverage_{lv}"] = float(lv) / 100
    res["coefficients"]["u"]["coverage_50"] = 0.5
    html = build_calibration_page(res, tmp_path / "c.html").read_text()
    assert "1 of the 4 coverages fall outside their own 95 % band" in html
    row = re.search(r"<tr><td>u</td>(.*?)</tr>", html).group(1)
    cells = re.findall(r"<td>(.*?)</td>", row)
    assert cells[:6] == ["0.5", "yes", "yes", "0.83", "NO", "yes"], cells
