"""``diagnose`` on inertial throws: residual series of the logger, per-channel RMS, and the candidate
ranking on synthetic throws (independent synthesizer, :mod:`bayes_disc.observation.inertial_synth`) with a
concealed side force and with nothing missing."""
import numpy as np
import pytest

from bayes_disc.diagnostics.diagnosis_words import rms_text
from bayes_disc.diagnostics.missing_physics import (CANDIDATES, ModelFit, applicable_candidates, diagnose, model_fit,
                                                    structured)
from bayes_disc.diagnostics.mismatch import onset_unavailable, term_signature
from bayes_disc.diagnostics.residuals import peak_window
from bayes_disc.inference.model.inertial import InertialThrow, level_start, own_start, search_starts
from bayes_disc.inference.fitting.leastsq import LeastSquaresResult, fit_least_squares, noise_text, refine_least_squares
from bayes_disc.inference.model.problem import Problem
from bayes_disc.observation.inertial_synth import LoggerSpec, synthetic_log
from bayes_disc.observation.models.inertial import SERIES, InertialMeasurements
from bayes_disc.observation.registry import split_extensions
from bayes_disc.observation.synth import LaunchSpec
from bayes_disc.physics import Disc, Environment, get_terms, literature_coefficients

COEF = literature_coefficients("hummel2002")
SPEC = LoggerSpec()                      # noise: gyro 0.005 (z) / 0.05 (x, y) rad/s, acc 0.05 m/s²
CY = 0.08
#: two throws, spins of both signs
LAUNCHES = [LaunchSpec(name="a", speed=13.0, launch_angle_deg=5, alpha_deg=8, spin=55, roll_deg=3, duration=1.5),
            LaunchSpec(name="b", speed=12.0, launch_angle_deg=10, alpha_deg=15, spin=-50, roll_deg=-5, duration=1.5)]
PERIOD0 = 0.0125                         # nominal period given to the model (the logger's is 12.2 ms)


def throws(cy: float, seed: int):
    """Synthetic logs of LAUNCHES with a side force CY (0: none)."""
    rng = np.random.default_rng(seed)
    terms, ext = (get_terms(["side_force"]), np.array([cy, 1.0])) if cy else ((), None)
    return [synthetic_log(ls.name, ls.initial_state(), COEF, ls.duration, SPEC, rng, terms=terms, extension=ext)
            for ls in LAUNCHES]


def builder(logs, starts=None):
    """``build(ids)`` of the diagnosis for these logs (starts: data-derived by default, as the run does)."""
    models = [(InertialMeasurements(g, Environment().g, period=PERIOD0),) for g in logs]
    th = [InertialThrow(g, "synth", "ok", "synthetic") for g in logs]
    own = [own_start(m[0], t) for m, t in zip(models, th)]

    def make(ids, st):
        terms, expl = split_extensions(ids)
        return Problem(flights=list(logs), marker_body=np.zeros((1, 3)), disc=Disc(), env=Environment(),
                       prior_name="potts_crowther", terms=terms, explanations=expl, start_states=list(st),
                       observations=models, own_start=own)
    if starts is None:
        p = make((), [level_start(t) for t in th])
        starts = [search_starts(p, k) for k in range(len(logs))]
    return lambda ids: make(tuple(ids), starts)


def true_theta(p: Problem, cy: float | None) -> np.ndarray:
    """θ of the synthesizer's truth in problem p (CY set when p has the side force)."""
    theta = p.start_vector()
    theta[: p.n_coef] = COEF.as_array()
    shared = {"imu_offset_x": SPEC.offset[0], "imu_offset_y": SPEC.offset[1], "imu_offset_z": SPEC.offset[2],
              "imu_lpf_tau": SPEC.lpf_tau, "imu_tilt_1": 0.0, "imu_tilt_2": 0.0}
    for n, v in shared.items():
        theta[p.layout.index(n)] = v
    if cy is not None:
        theta[p.layout.index("CY")] = cy
    for k, ls in enumerate(LAUNCHES):
        y0 = ls.initial_state()
        theta[p.ic_slice(k)] = p.state_to_ic(y0, k)
        theta[p.layout.index(f"imu_period_{ls.name}")] = SPEC.period
        for a in "xyz":
            theta[p.layout.index(f"gyro_bias_{a}_{ls.name}")] = 0.0
            theta[p.layout.index(f"acc_bias_{a}_{ls.name}")] = 0.0
    return theta


def fit_at(p: Problem, theta: np.ndarray, sigma: np.ndarray, ids=()) -> ModelFit:
    """A ModelFit at a given θ (no optimisation); the settled filter state is set from the first rows."""
    ls = LeastSquaresResult(theta=theta, sigma=sigma, cov=np.eye(p.dim), cost=0.0, condition_number=1.0,
                            start_costs=[], nfev=0, message="", names=p.names, flight_names=[f.name for f in p.flights],
                            sigma_names=list(p.sigma_names), sigma_units=list(p.noise_units))
    return model_fit(p, ls, ids)


def _settle_filter(p: Problem, theta: np.ndarray) -> np.ndarray:
    """The synthesizer starts the filter settled (y0 = its input at release): set lpf_state to it."""
    from bayes_disc.diagnostics.residuals import channel_runs
    from bayes_disc.observation.models.inertial import sensor_rotation, sensor_signals
    theta = theta.copy()
    for k, ls in enumerate(LAUNCHES):
        (c, tr, extra, _, _), = channel_runs(p, theta, k)
        par = c.split(extra)
        x = sensor_signals(np.ascontiguousarray(tr.states), c.h, c.g, np.ascontiguousarray(par["r_s"]),
                           np.ascontiguousarray(sensor_rotation(par["tilt"])))
        y0 = x[0, 0, 3:]                                   # C f_B at release: the settled filter's state
        for a, v in zip("xyz", y0):
            theta[p.layout.index(f"lpf_state_{a}_{ls.name}")] = v
    return theta


NOISE = np.array([SPEC.gyro_noise[0], SPEC.gyro_noise[1], SPEC.acc_noise[0], SPEC.acc_noise[1]])


def test_inertial_residual_series_white_at_the_truth_and_structured_without_the_side_force():
    """At the synthesizer's parameters the six sensor series of both throws are white with RMS at the noise;
    with the side force switched off (same θ otherwise) the accelerometer series are structured. RMS per
    channel (gyro, acc) with units; the onset search is declined for inertial flights with a reason."""
    logs = throws(CY, seed=3)
    build = builder(logs, starts=[ls.initial_state() for ls in LAUNCHES])
    p = build(("side_force",))
    theta = _settle_filter(p, true_theta(p, CY))
    sigma = np.tile(NOISE, 2)
    truth = fit_at(p, theta, sigma, ("side_force",))
    assert set(truth.localisation) == {"a", "b"}
    for per in truth.localisation.values():
        assert set(per) == set(SERIES)
        for name, d in per.items():
            assert d["unit"] == ("rad/s" if name.startswith("gyro") else "m/s²")
            assert 0.8 < d["noise_ratio"] < 1.2, (name, d["noise_ratio"])
    assert structured(truth) == {"a": [], "b": []}
    rms = truth.rms
    assert set(rms["a"]) == {"gyro", "acc"} and rms["a"]["acc"]["unit"] == "m/s²"
    assert abs(rms["a"]["acc"]["rms"] / SPEC.acc_noise[0] - 1) < 0.15
    assert truth.rms_mm == {}                                   # no markers: no mm entry
    assert "gyro" in rms_text(rms) and "m/s²" in rms_text(rms)
    off = theta.copy()
    off[p.layout.index("CY")] = 0.0
    wrong = fit_at(p, off, sigma, ("side_force",))
    bad = structured(wrong)
    assert all(any(s.startswith("acc_") for s in bad[f]) for f in ("a", "b")), bad
    t0, t1 = peak_window(wrong.residuals[0], sigma)
    assert 0.0 <= t0 <= t1 <= wrong.residuals[0].parts[0].times[-1]
    # the term's signature: it changes the accelerometer in the disc plane (x, y) by more than its noise per
    # sample (the filter, τ 0.15 s, passes a tenth of a force turning with the spin at ~9 Hz)
    sig = term_signature(truth, ["CY"])
    assert set(sig[0]["series"]) == set(SERIES)
    assert max(np.sqrt(np.mean(sig[0]["series"][n] ** 2)) for n in ("acc_x", "acc_y")) > SPEC.acc_noise[1]
    assert np.sqrt(np.mean(sig[0]["series"]["acc_z"] ** 2)) < np.sqrt(np.mean(sig[0]["series"]["acc_x"] ** 2))
    assert "not searched" in onset_unavailable(p, 0)
    # marker explanations are no candidates without markers
    keep, skipped = applicable_candidates(p, CANDIDATES)
    assert set(skipped) == {"marker_geometry", "time_offset"} and "side_force" in keep


def diagnose_logs(logs):
    """The diagnosis of these logs as ``diagnose`` makes it: least squares from data-derived starts (two
    starts, 100 evaluations), then every applicable candidate in one process."""
    build = builder(logs)
    p = build(())
    ls = fit_least_squares(p, starts=2, max_nfev=100, seed=0)
    base = model_fit(p, ls, ())
    cands, _ = applicable_candidates(p, CANDIDATES)
    return diagnose(base, build, processes=1, max_nfev=100, candidates=cands)


@pytest.mark.slow
@pytest.mark.parametrize("cy, expected", [(CY, "side_force"), (0.0, None)])
def test_diagnose_inertial_throws(cy, expected):
    """Least squares from data-derived starts, then every applicable candidate: a concealed side force is
    named and the refit's residuals are white; with nothing missing the verdict is adequate."""
    d = diagnose_logs(throws(cy, seed=3))
    if expected is None:
        assert d.verdict == "adequate", [(c.id, c.delta_bic, c.status) for r in d.rounds for c in r]
    else:
        assert d.verdict == "missing_physics"
        assert d.accepted[0].id == expected, [(c.id, c.delta_bic, c.status) for r in d.rounds for c in r]
        assert not any(d.unexplained.values())
        for f, per in d.final.rms.items():
            assert abs(per["acc"]["rms"] / SPEC.acc_noise[0] - 1) < 0.2, (f, per)


def test_inertial_problem_survives_pickling_into_worker_processes():
    """Candidate fits run in worker processes (the Problem is pickled): an inertial throw must keep its
    inertial initial conditions there (regression: the kind was tested by identity and was lost)."""
    import pickle
    logs = throws(0.0, seed=4)
    p = builder(logs, starts=[ls.initial_state() for ls in LAUNCHES])(())
    q = pickle.loads(pickle.dumps(p))
    theta = p.start_vector()[None]
    r, ok = p.residuals(theta, 0)
    r2, ok2 = q.residuals(theta, 0)
    assert ok[0] and ok2[0] and np.array_equal(r, r2)


def test_least_squares_output_reports_every_noise_group_in_its_own_unit():
    """An inertial fit has four noise groups per throw (gyro and accelerometer, axial and transverse): its
    least-squares output names each with its unit and lists no marker RMS. (Before, ``rms_mm`` paired the
    flights with the first groups' σ, so a gyro σ in rad/s was shown as millimetres of the wrong throw.)"""
    p = builder(throws(0.0, seed=3))(())
    sigma = 0.01 * (1.0 + np.arange(p.n_groups))
    ls = LeastSquaresResult(theta=p.start_vector(), sigma=sigma, cov=np.eye(p.dim), cost=0.0, condition_number=1.0,
                            start_costs=[], nfev=0, message="", names=p.names, flight_names=[f.name for f in p.flights],
                            sigma_names=list(p.sigma_names), sigma_units=list(p.noise_units))
    out = ls.to_dict()
    assert out["rms_mm"] == {}
    assert list(out["noise"]) == p.sigma_names and len(p.sigma_names) == 4 * len(LAUNCHES)
    for name, s in zip(p.sigma_names, sigma):
        assert out["noise"][name] == {"value": s, "unit": "rad/s" if "gyro" in name else "m/s²"}
    text = noise_text(out["noise"])
    assert "mm" not in text and text.count("rad/s") == 2 * len(LAUNCHES) and text.count("m/s²") == 2 * len(LAUNCHES)


def test_least_squares_noise_counts_are_the_residuals_behind_each_sigma():
    """Each noise group's ``n`` in the least-squares output is the number of residuals its σ is the RMS of:
    n σ² is the group's summed squared residuals at the optimum, so two fits of the same data compare by
    Σ n ln(σ₁/σ₂)."""
    p = builder(throws(0.0, seed=3))(())
    ls = refine_least_squares(p, p.start_vector(), max_nfev=2, rounds=1)
    noise = ls.to_dict()["noise"]
    n = np.array([noise[name]["n"] for name in p.sigma_names])
    sigma = np.array([noise[name]["value"] for name in p.sigma_names])
    assert np.all(n > 0)
    np.testing.assert_allclose(n * sigma ** 2, p.sum_squares(ls.theta[None])[0], rtol=1e-9)


def _nutation_logs(nutation, seed=3):
    """LAUNCHES' logs with the logger's transverse gyro carrying a randomly forced nutation (None: none)."""
    from dataclasses import replace
    rng = np.random.default_rng(seed)
    spec = replace(SPEC, nutation=nutation)
    return [synthetic_log(ls.name, ls.initial_state(), COEF, ls.duration, spec, rng) for ls in LAUNCHES]


@pytest.mark.parametrize("nutation", [None, (0.3, 2.0, 0.85)])
def test_random_nutation_check_at_the_truth(nutation):
    """diagnose's check on the residuals at the synthesizer's θ: a concealed random nutation (six times the
    white noise) is found with its turning rate and size; white noise gives none."""
    from bayes_disc.diagnostics.random_nutation import random_nutation
    logs = _nutation_logs(nutation)
    p = builder(logs, starts=[ls.initial_state() for ls in LAUNCHES])(())
    rec = random_nutation(p, _settle_filter(p, true_theta(p, None)))
    assert set(rec["throws"]) == {"a", "b"}
    if nutation is None:
        assert not rec["found"] and "not a randomly forced nutation" in rec["words"], rec
        return
    assert rec["found"] and rec["evidence"] > 100 and "gyro_noise: nutation" in rec["words"]
    assert abs(rec["kappa"] - nutation[2]) < 0.03
    for r in rec["throws"].values():
        assert abs(r["nutation_rms"] / nutation[0] - 1) < 0.35
        assert abs(r["white_sigma"] / SPEC.gyro_noise[1] - 1) < 0.25
