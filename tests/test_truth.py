"""θ at the truth of a synthetic data set (bayes_disc.inference.model.truth)."""
import numpy as np

from bayes_disc.inference.fitting.residuals import flight_residuals
from bayes_disc.inference.model.problem import Problem
from bayes_disc.inference.model.truth import truth_theta
from bayes_disc.observation.models import MarkerPositions
from bayes_disc.observation.synth_defects import Defects
from bayes_disc.observation.synth import LaunchSpec, SynthSpec, synthesize
from bayes_disc.physics import Disc, Environment
from bayes_disc.inference.model.initial import initial_state_from_data

MB = np.array([[0.100, 0.000, -0.015], [-0.0308, 0.0846, -0.015], [-0.0707, -0.0778, -0.015]])


def _problem(result, noise_model: str):
    flights = result.flights
    obs = [(MarkerPositions(f, MB, noise_model=noise_model),) for f in flights]
    return Problem(flights=flights, marker_body=MB, disc=Disc(), env=Environment(), prior_name="weak",
                   start_states=[initial_state_from_data(f, MB) for f in flights], observations=obs)


def test_residuals_at_the_truth_are_the_noise_and_rho_is_set():
    """At θ̃ the whitened residuals of AR(1) data are the synthesis' innovations: unit variance and white
    (lag-1 correlation ≈ 0); ρ is the truth's, and the coefficients are the truth's. A wrong initial state or
    ρ would leave the flight's motion or the noise's correlation in them."""
    ar = Defects(ar1_rho=0.85)
    spec = SynthSpec(name="t", seed=3, flights=(
        LaunchSpec(name="a", speed=13.0, launch_angle_deg=4, alpha_deg=7, spin=60, duration=0.6, noise_mm=2.0, defects=ar),
        LaunchSpec(name="b", speed=10.0, launch_angle_deg=9, alpha_deg=12, spin=-50, duration=0.6, noise_mm=1.0,
                   defects=ar)))
    result = synthesize(spec)
    problem = _problem(result, "ar1")
    theta = truth_theta(problem, result.truth)
    assert [theta[problem.names.index(n)] for n in ("rho_a", "rho_b")] == [0.85, 0.85]
    assert np.allclose(theta[: problem.n_coef], spec.coefficients.as_array())
    for k, f in enumerate(problem.flights):
        c = problem.channels[k][0]
        r = c.residuals(problem.channel_predictions(theta[None], k)[0][0][1])
        e = c.noise.whiten(r, np.array([[0.85]]))[0].reshape(-1, 3) / {"a": 2e-3, "b": 1e-3}[f.name]
        n = e.size                                       # 5-σ bounds of a mean square and a lag-1 correlation
        assert abs(np.mean(e ** 2) - 1.0) < 5 * np.sqrt(2 / n), (f.name, np.mean(e ** 2))
        prev = c.noise.previous
        has = prev >= 0
        lag1 = np.mean(e[has] * e[prev[has]])
        assert abs(lag1) < 5 / np.sqrt(n), (f.name, lag1)
    # white noise model: the same θ̃ less ρ; the raw residuals' RMS is the noise sd
    white = _problem(result, "gaussian")
    theta_w = truth_theta(white, result.truth)
    rms = [np.sqrt(np.mean(r ** 2)) for r in flight_residuals(theta_w, white, np.ones(white.n_groups))]
    assert np.allclose(rms, [2e-3, 1e-3], rtol=0.2), rms         # AR(1): ~60 effective samples per series
