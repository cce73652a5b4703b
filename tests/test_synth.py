"""Synthetic flights: the demo description gives the designed envelope, noise and dropout."""
import json
import shutil

import numpy as np
import pytest

from bayes_disc.cli import main
from bayes_disc.observation.config_io import ConfigError
from bayes_disc.observation.markers import load_flights
from dataclasses import replace

from bayes_disc.observation.synth_defects import Defects
from bayes_disc.observation.synth import LaunchSpec, SynthSpec, synthesize
from bayes_disc.observation.synth_config import load_synth_spec
from bayes_disc.physics import simulate

from conftest import REPO


def test_demo_envelope_like_the_paper():
    spec, _, _ = load_synth_spec(REPO / "runs/demo/synth.yaml")
    truth = synthesize(spec).truth
    spans = {k: v["alpha_range_deg"][1] - v["alpha_range_deg"][0] for k, v in truth["flights"].items()}
    narrow = sorted(spans.values())[:2]
    assert all(4.0 <= s <= 7.0 for s in narrow), spans
    lo = min(v["alpha_range_deg"][0] for v in truth["flights"].values())
    hi = max(v["alpha_range_deg"][1] for v in truth["flights"].values())
    assert lo < 3.0 and hi > 28.0


def test_noise_dropout_and_truth_reproduce_the_flight():
    f = LaunchSpec(name="a", speed=12.0, launch_angle_deg=5, alpha_deg=6, spin=55, duration=1.5,
                   noise_mm=2.5, dropout=0.1)
    spec = SynthSpec(name="t", flights=(f,), seed=7)
    res = synthesize(spec)
    obs = res.flights[0]
    y0 = np.concatenate([v for k, v in res.truth["flights"]["a"]["initial_state"].items() if k != "t"])
    clean = simulate(y0, spec.coefficients.as_array(), obs.times,
                     marker_body=np.array(list(spec.markers.values()))).markers[0]
    resid = (obs.positions - clean)[obs.observed]
    assert resid.std() == pytest.approx(2.5e-3, rel=0.1)
    assert abs(resid.mean()) < 3e-4
    assert 1 - obs.observed.mean() == pytest.approx(0.1, abs=0.03)
    # same seed → same data; another seed → other noise
    again = synthesize(spec).flights[0].positions
    np.testing.assert_array_equal(again, obs.positions)
    other = synthesize(SynthSpec(name="t", flights=(f,), seed=8)).flights[0].positions
    assert not np.array_equal(np.isnan(other), np.isnan(obs.positions)) or np.nanmax(np.abs(other - obs.positions)) > 0


def test_cli_synth_writes_valid_files(tmp_path):
    shutil.copy(REPO / "runs/demo/synth.yaml", tmp_path / "synth.yaml")
    assert main(["synth", str(tmp_path / "synth.yaml")]) == 0
    truth = json.loads((tmp_path / "truth.json").read_text())
    flights = load_flights(tmp_path / "flights.csv", list(truth["markers"]))
    assert [f.name for f in flights] == list(truth["flights"])


def test_concealed_term_is_in_the_data_not_the_base_model():
    f = LaunchSpec(name="a", speed=12.0, alpha_deg=5, spin=60, duration=1.0, noise_mm=0.0)
    base = synthesize(SynthSpec(name="b", flights=(f,))).flights[0].positions
    side = synthesize(SynthSpec(name="s", flights=(f,), physics={"side_force": {"CY": 0.4}})).flights[0].positions
    assert np.abs(side - base)[..., 1].max() > 0.01


BAD_SYNTH = {
    "flights[0].speed": ("speed: 9.0,", "sped: 9.0,"),            # misspelt: the required key is missing
    "flights[1].spinn": ("spin: -65,", "spin: -65, spinn: 3,"),    # unknown key
    "coefficients": ("coefficients: hummel2002", "coefficients: nope"),
    "sample_rate_hz": ("sample_rate_hz: 120", "sample_rate_hz: -5"),
}


@pytest.mark.parametrize("key", sorted(BAD_SYNTH))
def test_bad_synth_config_names_the_key(tmp_path, key):
    old, new = BAD_SYNTH[key]
    p = tmp_path / "s.yaml"
    p.write_text((REPO / "runs/demo/synth.yaml").read_text().replace(old, new, 1))
    with pytest.raises(ConfigError) as e:
        load_synth_spec(p)
    assert f"key '{key}'" in str(e.value), str(e.value)


# ------------------------------------------------------------------------------------------- defects
def test_defects_off_leave_the_demo_output_byte_identical(tmp_path):
    """An explicit block with every defect off writes the same bytes as no block, and without ``defects:``
    the demo synth is the committed data: the same rows (dropout) and the same noise draws (values within
    1 µm; the committed file was written by an earlier integrator, which differs by ~1e-7 m, while other
    noise draws would differ by millimetres)."""
    text = (REPO / "runs/demo/synth.yaml").read_text()
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    (tmp_path / "a/synth.yaml").write_text(text)
    (tmp_path / "b/synth.yaml").write_text(text + "defects: {outliers: {fraction: 0.0}, swaps: {frames: 0}, "
                                                  "ar1: {rho: 0.0}}\n")
    for d in ("a", "b"):
        assert main(["synth", str(tmp_path / d / "synth.yaml")]) == 0
    assert (tmp_path / "a/flights.csv").read_bytes() == (tmp_path / "b/flights.csv").read_bytes()
    assert (tmp_path / "a/truth.json").read_bytes() == (tmp_path / "b/truth.json").read_bytes()
    new = (tmp_path / "a/flights.csv").read_text().splitlines()
    old = (REPO / "runs/demo/flights.csv").read_text().splitlines()
    assert new[0] == old[0] and len(new) == len(old)
    a = np.array([[float(v) for v in r.split(",")[3:]] for r in new[1:]])
    b = np.array([[float(v) for v in r.split(",")[3:]] for r in old[1:]])
    assert [r.split(",")[:3] for r in new[1:]] == [r.split(",")[:3] for r in old[1:]]
    np.testing.assert_allclose(a, b, rtol=0, atol=1e-6)
    assert "defects" not in json.loads((tmp_path / "a/truth.json").read_text())["flights"]["bsfl5"]


def _defect_run(defects, noise_mm=2.0, dropout=0.05, duration=2.0, seed=11):
    f = LaunchSpec(name="a", speed=12.0, alpha_deg=6, spin=55, duration=duration, noise_mm=noise_mm,
                   dropout=dropout, defects=defects)
    spec = SynthSpec(name="t", flights=(f,), seed=seed)
    clean = replace(spec, flights=(replace(f, noise_mm=0.0, dropout=0.0, defects=Defects()),))
    return synthesize(spec), synthesize(clean).flights[0].positions


def test_ar1_noise_has_the_flight_sd_and_lag_one_correlation():
    res, clean = _defect_run(Defects(ar1_rho=0.85), dropout=0.0, duration=4.0)
    e = (res.flights[0].positions - clean) / 2e-3
    assert e.std() == pytest.approx(1.0, abs=0.2)
    r1 = np.mean([np.corrcoef(e[1:, k, a], e[:-1, k, a])[0, 1] for k in range(3) for a in range(3)])
    assert r1 == pytest.approx(0.85, abs=0.05)
    white, clean = _defect_run(Defects(), dropout=0.0, duration=4.0)
    w = (white.flights[0].positions - clean) / 2e-3
    assert abs(np.mean([np.corrcoef(w[1:, k, 0], w[:-1, k, 0])[0, 1] for k in range(3)])) < 0.1
    # the same white draws underlie both: the dropout pattern of a seed does not change
    assert np.array_equal(white.flights[0].observed, res.flights[0].observed)


def test_outliers_and_swaps_are_injected_and_listed():
    d = Defects(outlier_fraction=0.02, outlier_size_m=(0.02, 0.06), swap_frames=3)
    res, clean = _defect_run(d, noise_mm=0.0)
    obs, truth = res.flights[0], res.truth["flights"]["a"]["defects"]
    err = np.linalg.norm(obs.positions - clean, axis=-1)
    listed = truth["outliers"]["points"]
    assert len(listed) == round(0.02 * obs.n_points)
    ids = list(obs.marker_ids)
    for p in listed:
        i = int(np.argmin(np.abs(obs.times - p["t"])))
        assert 0.02 <= np.linalg.norm(p["offset_m"]) <= 0.06
        assert err[i, ids.index(p["marker"])] == pytest.approx(np.linalg.norm(p["offset_m"]), abs=0.1)
    swaps = truth["swaps"]["frames"]
    assert len(swaps) == 3
    for s in swaps:
        i = int(np.argmin(np.abs(obs.times - s["t"])))
        a, b = (ids.index(m) for m in s["markers"])
        hit = {(round(p["t"], 9), p["marker"]) for p in listed}
        if (round(s["t"], 9), ids[a]) not in hit and (round(s["t"], 9), ids[b]) not in hit:
            np.testing.assert_allclose(obs.positions[i, a], clean[i, b], atol=1e-12)
            np.testing.assert_allclose(obs.positions[i, b], clean[i, a], atol=1e-12)
    bad = {(round(p["t"], 9), p["marker"]) for p in listed}
    bad |= {(round(s["t"], 9), m) for s in swaps for m in s["markers"]}
    rest = [err[i, k] for i, t in enumerate(obs.times) for k, m in enumerate(ids)
            if (round(t, 9), m) not in bad and obs.observed[i, k]]
    assert max(rest) < 1e-12                          # nothing else moved (noise 0)


def test_per_point_sigma_is_written_truthfully(tmp_path):
    d = Defects(sigma_fraction=0.3, sigma_factor=10.0, per_point_sigma=True)
    res, clean = _defect_run(d, dropout=0.0, duration=4.0)
    obs = res.flights[0]
    hi = obs.sigma > 2.5e-3
    assert hi.mean() == pytest.approx(0.3, abs=0.01)
    np.testing.assert_allclose(np.unique(obs.sigma), [2e-3, 2e-2])
    z = (obs.positions - clean) / obs.sigma[..., None]
    assert z[hi].std() == pytest.approx(1.0, abs=0.1) and z[~hi].std() == pytest.approx(1.0, abs=0.1)
    p = tmp_path / "s.yaml"
    p.write_text("name: s\nflights:\n  - {name: a, speed: 12, alpha_deg: 6, duration: 0.3}\n"
                 "  - {name: b, speed: 12, alpha_deg: 6, duration: 0.3, defects: {sigma_m: {fraction: 0.5, "
                 "factor: 10}}}\n")
    assert main(["synth", str(p)]) == 0
    back = load_flights(tmp_path / "s_markers.csv", ["0", "1", "2"])
    np.testing.assert_allclose(back[0].sigma, 2e-3)                   # the flight without: its own σ
    assert np.nanmax(back[1].sigma) == pytest.approx(2e-2)


BAD_DEFECTS = {
    "defects.outlier": "defects: {outlier: {fraction: 0.01}}",
    "defects.ar1.rho": "defects: {ar1: {rho: 1.0}}",
    "defects.outliers.size_m": "defects: {outliers: {fraction: 0.01, size_m: [0.06, 0.02]}}",
    "flights[0].defects.swaps.frames": None,
}


@pytest.mark.parametrize("key", sorted(BAD_DEFECTS))
def test_bad_defects_name_the_key(tmp_path, key):
    text = (REPO / "runs/demo/synth.yaml").read_text()
    if BAD_DEFECTS[key] is None:
        text = text.replace("dropout: 0.02}", "dropout: 0.02, defects: {swaps: {frames: -1}}}", 1)
    else:
        text += BAD_DEFECTS[key] + "\n"
    p = tmp_path / "s.yaml"
    p.write_text(text)
    with pytest.raises(ConfigError) as e:
        load_synth_spec(p)
    assert f"key '{key}'" in str(e.value), str(e.value)


def test_a_gust_moves_the_flight_only_from_its_start():
    """A gust (wind during a window of one flight) with no wind term in the data: the flight is the same as
    without it before the gust and departs after."""
    f = LaunchSpec(name="g", speed=12.0, alpha_deg=6, spin=60, duration=0.6, noise_mm=0.0)
    calm = synthesize(SynthSpec(name="s", flights=(f,))).flights[0].positions
    gusty = synthesize(SynthSpec(name="s", flights=(replace(f, gust=(0.2, 0.4, 0.0, 4.0, 0.0)),))).flights[0]
    t = gusty.times
    diff = np.nanmax(np.abs(gusty.positions - calm), axis=(1, 2))
    assert np.all(diff[t < 0.2] < 1e-9) and diff[-1] > 5e-3
