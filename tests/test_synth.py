"""Synthetic flights: the demo description gives the designed envelope, noise and dropout."""
import json
import shutil

import numpy as np
import pytest

from bayes_disc.cli import main
from bayes_disc.observation.config_io import ConfigError
from bayes_disc.observation.markers import load_flights
from bayes_disc.observation.synth import LaunchSpec, SynthSpec, load_synth_spec, synthesize
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
