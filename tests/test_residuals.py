"""Locating a mismatch: residual whiteness and direction (bayes_disc.diagnostics.residuals)."""
import numpy as np

from bayes_disc.inference.fitting.leastsq import fit_least_squares
from bayes_disc.inference.model.problem import Problem
from bayes_disc.inference.model.initial import initial_state_from_data
from bayes_disc.diagnostics.residuals import DIRECTIONS, ROTATIONS, localise, ljung_box, structured_windows
from bayes_disc.observation.synth import DEFAULT_MARKERS, LaunchSpec, SynthSpec, synthesize


def test_ljung_box_separates_white_noise_from_a_trend():
    rng = np.random.default_rng(0)
    white = rng.normal(size=240)
    q, p = ljung_box(white)
    assert p > 0.01
    _, p_trend = ljung_box(white + 0.02 * np.arange(240))
    assert p_trend < 1e-6


def test_structured_windows_find_a_bump():
    t = np.arange(240) / 120.0
    x = np.random.default_rng(1).normal(size=240)
    assert structured_windows(x, np.ones(240), t) == []
    x[100:140] += 3.0
    (w,) = structured_windows(x, np.ones(240), t)
    assert 0.75 < w[0] < 0.9 and 1.1 < w[1] < 1.25


def _fit_base(physics):
    flights = (LaunchSpec(name="a", speed=13.0, launch_angle_deg=3, alpha_deg=6, spin=60, duration=1.2,
                          noise_mm=1.0, dropout=0.02),
               LaunchSpec(name="b", speed=11.0, launch_angle_deg=8, alpha_deg=14, spin=55, duration=1.0,
                          noise_mm=1.0, dropout=0.02))
    data = synthesize(SynthSpec(name="c", flights=flights, physics=physics, seed=4))
    mb = np.array(list(DEFAULT_MARKERS.values()))
    starts = [initial_state_from_data(f, mb) for f in data.flights]
    problem = Problem(flights=data.flights, marker_body=mb, disc=SynthSpec(name="x", flights=()).disc,
                      env=SynthSpec(name="x", flights=()).env, prior_name="weak", start_states=starts)
    ls = fit_least_squares(problem, starts=2)
    return problem, ls


def test_no_missing_physics_leaves_white_residuals():
    problem, ls = _fit_base({})
    loc = localise(problem, ls.theta, ls.sigma)
    assert all(set(per) == set(DIRECTIONS) | set(ROTATIONS) for per in loc.values())
    p = [d["ljung_box_p"] for per in loc.values() for d in per.values()]
    assert min(p) > 1e-4, p
    assert all(abs(per[n]["rms_mm"] - 1.0 / np.sqrt(3)) < 0.25 for per in loc.values() for n in DIRECTIONS)
    # attitude residuals: pure noise, so their RMS is what the markers' noise predicts
    ratios = [per[n]["noise_ratio"] for per in loc.values() for n in DIRECTIONS + ROTATIONS]
    assert all(0.8 < r < 1.2 for r in ratios), ratios
