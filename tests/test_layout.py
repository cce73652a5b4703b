"""The parameter layout, the unit registry and the observation-model contract."""
import numpy as np
import pytest
from scipy.special import gammaln

from bayes_disc.inference.model.initial import initial_state_from_data
from bayes_disc.inference.model.layout import IC_NAMES, ParameterLayout
from bayes_disc.inference.model.problem import Problem
from bayes_disc.observation.markers import FlightObservation
from bayes_disc.observation.models import MarkerPositions, ObservationModel
from bayes_disc.observation.registry import (DATA_EXPLANATION, LEARNED, MODEL_EXTENSIONS, OBSERVATION_MODEL, PHYSICS_TERM,
                                             UNITS, split_extensions, unit)
from bayes_disc.observation.synth import DEFAULT_MARKERS, LaunchSpec, SynthSpec, synthesize
from bayes_disc.physics import COEFFICIENT_NAMES, TERMS, Disc, Environment

MB = np.array(list(DEFAULT_MARKERS.values()))


@pytest.fixture(scope="module")
def data():
    flights = (LaunchSpec(name="a", speed=13.0, launch_angle_deg=3, alpha_deg=6, spin=60, duration=0.4,
                          noise_mm=1.0, dropout=0.05),
               LaunchSpec(name="b", speed=11.0, launch_angle_deg=8, alpha_deg=14, spin=-55, duration=0.3,
                          noise_mm=2.0, dropout=0.0))
    return synthesize(SynthSpec(name="t", flights=flights, seed=2)).flights


def _problem(flights, **kw):
    starts = [initial_state_from_data(f, MB) for f in flights]
    return Problem(flights=list(flights), marker_body=MB, disc=Disc(), env=Environment(), prior_name="weak",
                   start_states=starts, **kw)


def test_layout_names_slices_and_units_agree():
    terms, expl = split_extensions(["wind", "side_force", "time_offset"])
    ep = tuple(p for e in expl for p in e.parameters_for(("0", "1", "2")))
    own = ((), (unit("side_force").obj.parameters[0],))     # flight b carries one own parameter
    L = ParameterLayout(terms=terms, explanation_parameters=ep, flight_names=("a", "b"), flight_parameters=own)
    names, units = L.names, L.units
    assert len(names) == len(units) == L.dim == 10 + 7 + 2 + 12 + 13
    assert names[:10] == list(COEFFICIENT_NAMES)
    assert names[L.term_slice] == ["wind_x", "wind_y", "wind_z", "shear_x", "shear_y", "CY", "n_Y"]
    assert names[L.explanation_slice] == ["dt_1", "dt_2"]
    assert names[L.ic_slice(1)] == [f"{n}_b" for n in IC_NAMES]
    assert names[L.own_slice(1)] == ["CY_b"] and L.own_slice(0).stop == L.own_slice(0).start
    assert units[L.index("vx_a")] == "m/s" and units[L.index("dt_2")] == "s" and units[L.index("CMq")] == "s/rad"
    cols = L.flight_columns(1)
    assert [names[c] for c in cols[-13:]] == [f"{n}_b" for n in IC_NAMES] + ["CY_b"]
    assert not any(names[c].endswith("_a") for c in cols)
    with pytest.raises(KeyError, match="no parameter 'nope'"):
        L.index("nope")


def test_transfer_and_kernel_extension():
    small = ParameterLayout(terms=split_extensions(["side_force"])[0], flight_names=("a",))
    big = ParameterLayout(terms=split_extensions(["wind", "side_force"])[0], flight_names=("a",))
    theta = np.arange(small.dim, dtype=float)
    out = big.transfer(theta, small, np.full(big.dim, -1.0))
    for j, n in enumerate(big.names):
        assert out[j] == (theta[small.index(n)] if n in small.names else -1.0)
    ext = small.kernel_extension(theta[None], tuple(TERMS.values()))
    flat = [p for t in TERMS.values() for p in t.parameters]
    for j, p in enumerate(flat):
        assert ext[0, j] == (theta[small.index(p.name)] if p.name in ("CY", "n_Y") else p.off_value)
    with pytest.raises(ValueError, match="lacks the model's terms"):
        big.kernel_extension(out[None], split_extensions(["side_force"])[0])


def test_registry_knows_every_unit_once_and_rejects_unknown_ids():
    kinds = {u.kind for u in UNITS.values()}
    assert kinds == {PHYSICS_TERM, DATA_EXPLANATION, OBSERVATION_MODEL, LEARNED}
    assert set(MODEL_EXTENSIONS) == {"side_force", "wind", "ground_effect", "nonlinear_aero", "spin_lift",
                                     "roll_spin_coupling", "inertia_ratio", "rate_coupling", "rate_damping",
                                     "disc_asymmetry", "marker_geometry", "time_offset"}
    assert unit("markers").kind == OBSERVATION_MODEL
    with pytest.raises(KeyError, match="known: "):
        unit("magic")
    with pytest.raises(KeyError, match="unknown physics term or data explanation or learned correction 'markers'"):
        split_extensions(["markers"])
    assert unit("marker_geometry").parameter_names(("p", "q", "r"))[:3] == ("marker_b1_p", "marker_b2_p",
                                                                            "marker_b3_p")


def test_problem_is_complete_when_constructed(data):
    p = _problem(data)
    assert p.rates == [p.flight_rate(s) for s in p.start_states]
    assert p.term_start.shape == (0,) and p.dim == 10 + 24
    with pytest.raises(ValueError, match="start states"):
        Problem(flights=list(data), marker_body=MB, disc=Disc(), env=Environment(), prior_name="weak",
                start_states=[])
    with pytest.raises(ValueError, match="extension parameters"):
        _problem(data, terms=split_extensions(["side_force"])[0], term_start=np.zeros(3))


def test_marker_likelihood_is_the_analytic_marginal(data):
    """Σ_f [log Γ(n_f/2) − log 2 − (n_f/2) log(π S_f)] with S_f the flight's summed squared residuals."""
    p = _problem(data)
    theta = np.repeat(p.prior_mean[None], 3, axis=0)
    theta[1, 0] += 0.05
    theta[2, 4] -= 0.01
    expected = np.zeros(3)
    for k, f in enumerate(data):
        markers, ok = p.predict(theta, k)
        r = (markers[:, f.observed] - f.positions[f.observed][None]).reshape(3, -1)
        n, S = r.shape[1], np.sum(r * r, axis=1)
        expected += gammaln(n / 2) - np.log(2) - 0.5 * n * np.log(np.pi * S)
    assert np.allclose(p.log_likelihood(theta), expected, rtol=1e-12)
    assert p.sigma_names == ["sigma_a", "sigma_b"] and list(p.n_coords) == [3 * f.n_points for f in data]


def test_several_observation_models_on_one_flight_sum(data):
    """One flight recorded by two marker systems (markers 0 | markers 1, 2), each with its own noise
    scale: the log-likelihood is the sum of the two one-system problems', and each has its σ."""
    f = data[0]
    keep0 = f.positions.copy()
    keep0[:, 1:] = np.nan
    keep12 = f.positions.copy()
    keep12[:, 0] = np.nan
    f0 = FlightObservation(f.name, f.source, f.times, f.marker_ids, keep0)
    f12 = FlightObservation(f.name, f.source, f.times, f.marker_ids, keep12)

    class SecondSystem(MarkerPositions):
        id = "markers_second"

        @property
        def noise_names(self):
            return (f"sigma2_{self.flight}",)

    start = initial_state_from_data(f, MB)
    both = Problem(flights=[f], marker_body=MB, disc=Disc(), env=Environment(), prior_name="weak",
                   start_states=[start], observations=[(MarkerPositions(f0, MB), SecondSystem(f12, MB))])
    one = Problem(flights=[f0], marker_body=MB, disc=Disc(), env=Environment(), prior_name="weak",
                  start_states=[start])
    two = Problem(flights=[f12], marker_body=MB, disc=Disc(), env=Environment(), prior_name="weak",
                  start_states=[start])
    theta = np.repeat(one.prior_mean[None], 2, axis=0)
    theta[1, 1] += 0.3
    assert both.sigma_names == ["sigma_a", "sigma2_a"]
    assert np.allclose(both.log_likelihood(theta), one.log_likelihood(theta) + two.log_likelihood(theta))
    ss = both.sum_squares(theta)
    assert np.allclose(ss, np.column_stack([one.sum_squares(theta), two.sum_squares(theta)]))
    r, _ = both.residuals(theta, 0)
    assert r.shape[1] == both.residual_groups(0).size == int(both.n_coords.sum())
    sig = both.draw_sigma(np.tile(ss[:1], (4000, 1)), np.random.default_rng(0))
    assert sig.shape == (4000, 2)
    assert np.allclose(np.median(sig ** 2, axis=0), ss[0] / both.n_coords, rtol=0.05)


def test_observation_model_contract_is_abstract():
    with pytest.raises(TypeError):
        ObservationModel()
