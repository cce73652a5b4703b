"""Least squares on many flights: starts fitted on the most informative flights, the others joined
to the best start, and the step-length correction of fits started next to an optimum
(bayes_disc.inference.fitting.leastsq: informative_flights, join_flights; .minimiser: step_length)."""
import numpy as np
import pytest

from bayes_disc.inference.fitting import leastsq
from bayes_disc.inference.fitting.arrow import ArrowJacobian
from bayes_disc.inference.model.initial import initial_state_from_data
from bayes_disc.inference.fitting.minimiser import MU_NEAR, STEP_LENGTH_BOUNDS, minimise, step_length
from bayes_disc.inference.fitting.residuals import jacobian_blocks
from bayes_disc.inference.fitting.leastsq import REFINE_DECREMENT, fit_least_squares, informative_flights, _rms
from bayes_disc.inference.model.problem import Problem
from bayes_disc.observation.synth import DEFAULT_MARKERS, LaunchSpec, SynthSpec, synthesize


def _problem(flights, seed):
    spec = SynthSpec(name="campaign", flights=flights, seed=seed)
    data = synthesize(spec)
    mb = np.array(list(DEFAULT_MARKERS.values()))
    return Problem(flights=data.flights, marker_body=mb, disc=spec.disc, env=spec.env, prior_name="potts_crowther",
                   start_states=[initial_state_from_data(f, mb) for f in data.flights])


@pytest.fixture(scope="module")
def six_flights():
    """Six short throws over a range of angle of attack (3°–16°) and speed."""
    kinds = [(13.0, 3, 4, 60), (11.0, 8, 14, 55), (12.0, 5, 9, 58), (14.0, 2, 6, 62), (10.5, 9, 16, 50),
             (12.5, 4, 11, 57)]
    flights = tuple(LaunchSpec(name=f"f{i}", speed=v, launch_angle_deg=g, alpha_deg=a, spin=w, duration=0.8,
                               noise_mm=1.0) for i, (v, g, a, w) in enumerate(kinds))
    return _problem(flights, seed=11)


def _random_arrow(rng, s=4, own=(3, 3, 3), rows=(30, 30, 30)):
    n = s + sum(own)
    shared = np.arange(s)
    parts, j = [], s
    for p in own:
        parts.append(np.arange(j, j + p))
        j += p
    blocks = tuple(rng.normal(size=(m, s + p)) for m, p in zip(rows, own))
    return ArrowJacobian(shared=shared, own=tuple(parts), blocks=blocks, prior=rng.uniform(0.1, 1.0, size=n))


def test_block_schur_complements_sum_to_the_shared_information():
    """Σ_k S_k + P_s² is the Schur complement of the whole arrow (every block's own unknowns marginalised)."""
    J = _random_arrow(np.random.default_rng(2))
    total = sum(J.block_schur()) + np.diag(J.prior[J.shared] ** 2)
    np.testing.assert_allclose(total, J.information().schur(), rtol=1e-10, atol=1e-10)


def test_informative_flights_are_complementary():
    """Two flights that pin down the same shared direction are not both chosen while another flight informs a
    direction neither sees: the greedy D-optimal choice, not the largest information."""
    rng = np.random.default_rng(3)
    s, own, m = 2, 2, 40
    t = np.linspace(0, 1, m)
    strong = np.c_[10 * t, 0 * t, rng.normal(size=(m, own))]        # shared direction 0, strongly
    weak = np.c_[0 * t, 1 * t, rng.normal(size=(m, own))]           # shared direction 1, weakly
    J = ArrowJacobian(shared=np.arange(s), own=(np.arange(2, 4), np.arange(4, 6), np.arange(6, 8)),
                      blocks=(strong, strong.copy(), weak), prior=np.full(8, 0.1))
    assert informative_flights(J, 2) in ([0, 2], [1, 2])
    assert informative_flights(J, 3) == [0, 1, 2]


@pytest.mark.parametrize("curvature_ratio", [0.5, 2.0, 3.0])
def test_step_length_is_the_minimum_of_the_parabola(curvature_ratio):
    """Along a step δ whose true curvature is c times the model's, f(α) = f0 + α s + ½ c α² |s|: the factor
    is 1/c exactly; none near 1; the longest where the cost falls at least linearly."""
    f0, slope = 10.0, -2.0
    f = lambda a: f0 + a * slope + 0.5 * curvature_ratio * a * a * (-slope)  # noqa: E731
    assert step_length(f0, f(1.0), slope) == pytest.approx(1.0 / curvature_ratio)
    assert step_length(f0, f0 + slope + 0.5 * 1.1 * (-slope), slope) is None
    assert step_length(f0, f0 + 1.2 * slope, slope) == STEP_LENGTH_BOUNDS[1]
    assert step_length(f0, f0 - 1.0, +1.0) is None                  # not a descent step


def test_step_length_corrections_reach_the_same_optimum(six_flights):
    """From a start's optimum, refits with new noise scales (the refinement) with and without the correction
    end at the same optimum: within the refinement's decrement of each other, and θ within 0.02 sd."""
    p = six_flights
    start = minimise(p, p.start_vector(), p.nominal_noise, max_nfev=200, dtol=0.1)
    sigma = _rms(p, start.x)
    plain = minimise(p, start.x, sigma, max_nfev=200, xtol=1e-12, ftol=1e-12, mu0=MU_NEAR, dtol=REFINE_DECREMENT)
    corrected = minimise(p, start.x, sigma, max_nfev=200, xtol=1e-12, ftol=1e-12, mu0=MU_NEAR, dtol=REFINE_DECREMENT,
                         line_search=True)
    assert plain.status > 0 and corrected.status > 0
    assert abs(plain.cost - corrected.cost) < 20 * REFINE_DECREMENT
    cov = jacobian_blocks(plain.x, p, sigma).information().inverse()
    assert np.max(np.abs(plain.x - corrected.x) / np.sqrt(np.diag(cov))) < 0.02


def test_a_flight_subset_is_the_same_model(six_flights):
    """The problem of some flights (in any order) predicts those flights exactly as the whole problem does,
    at θ mapped by name."""
    p = six_flights
    part = p.select_flights([4, 1])
    x = p.start_vector() + 0.01 * p.prior_sd * np.random.default_rng(0).standard_normal(p.dim)
    z = part.layout.transfer(x, p.layout, part.start_vector())
    for j, k in enumerate([4, 1]):
        np.testing.assert_array_equal(part.noise_residuals(z[None], j)[0], p.noise_residuals(x[None], k)[0])
    assert [f.name for f in part.flights] == ["f4", "f1"]


def test_starts_on_informative_flights_reach_the_optimum_of_starts_on_all(six_flights, monkeypatch):
    """Six flights: starts fitted on four of them and the other two joined (the default above START_FLIGHTS
    flights) reach the optimum of the same starts fitted on all six: cost within 10⁻³, θ within 0.01 sd."""
    p = six_flights
    staged = fit_least_squares(p, starts=4)
    assert len(staged.start_flights) == leastsq.START_FLIGHTS < p.n_flights
    monkeypatch.setattr(leastsq, "START_FLIGHTS", p.n_flights)
    every = fit_least_squares(p, starts=4)
    assert every.start_flights == []
    assert staged.cost == pytest.approx(every.cost, abs=1e-3)
    sd = np.sqrt(np.diag(every.cov))
    assert np.max(np.abs(staged.theta - every.theta) / sd) < 0.01
    np.testing.assert_allclose(staged.sigma, every.sigma, rtol=1e-4)
