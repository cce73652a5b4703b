"""`bayes-disc predict`: held-out flights fitted with a run's coefficients fixed, and free.

The run folder is stood in for by a summary.json whose medians are the synthetic truth (a right model) or the
truth with CLa and CMa off by 30 % (a wrong one): the mechanics of the command do not need a sample run."""
import json

import numpy as np
import pytest

from bayes_disc.cli import main
from bayes_disc.observation.synth import LaunchSpec, SynthSpec, synthesize, write_synth
from bayes_disc.physics import COEFFICIENT_NAMES

from conftest import run_config

CONFIG = run_config("held", "least_squares: {starts: 1}", "output: out")


def _summary(folder, truth, scale=None):
    scale = scale or {}
    params = {n: {"q50": truth["coefficients"][n] * scale.get(n, 1.0)} for n in COEFFICIENT_NAMES}
    folder.mkdir()
    (folder / "summary.json").write_text(json.dumps({"parameters": params}))
    return folder


@pytest.fixture(scope="module")
def data(tmp_path_factory):
    d = tmp_path_factory.mktemp("predict")
    f = LaunchSpec(name="held", speed=12.0, launch_angle_deg=5, alpha_deg=10, spin=55, duration=0.8, noise_mm=1.5)
    write_synth(synthesize(SynthSpec(name="s", flights=(f,), seed=7)), d / "flights.csv", d / "truth.json")
    (d / "config.yaml").write_text(CONFIG)
    return d, json.loads((d / "truth.json").read_text())


@pytest.fixture(scope="module")
def fitted(data):
    """The held-out configuration's problem and its free least-squares fit θ (one start)."""
    from bayes_disc.inference.fitting.leastsq import fit_least_squares
    from bayes_disc.inference.model.config import load_config
    from bayes_disc.inference.model.data import build_problem
    problem = build_problem(load_config(data[0] / "config.yaml"))
    return problem, fit_least_squares(problem, starts=1).theta


def test_right_coefficients_predict_as_well_as_a_free_fit_and_wrong_ones_do_not(data, capsys):
    d, truth = data
    right = _summary(d / "right", truth)
    wrong = _summary(d / "wrong", truth, {"CLa": 1.3, "CMa": 1.3})
    assert main(["predict", str(d / "config.yaml"), "--from", str(right), "--output", str(d / "p_right")]) == 0
    assert main(["predict", str(d / "config.yaml"), "--from", str(wrong), "--output", str(d / "p_wrong")]) == 0
    r = json.loads((d / "p_right" / "prediction.json").read_text())["flights"]["held"]
    w = json.loads((d / "p_wrong" / "prediction.json").read_text())["flights"]["held"]
    assert r["status"] == "ok" and set(r["channels"]) == {"markers"}
    m = r["channels"]["markers"]
    assert m["unit"] == "m"
    assert m["rms_fixed"] < 1.05 * m["rms_free"]                     # the truth predicts like a free fit
    assert abs(m["rms_free"] - 1.5e-3) < 0.2e-3                        # both at the noise level
    bad = w["channels"]["markers"]
    assert bad["rms_fixed"] > 2 * bad["rms_free"]                      # wrong ones do not (measured ×2.8)
    assert "held: ok: markers RMS" in capsys.readouterr().out


def test_a_run_with_another_model_is_refused(data, capsys):
    d, truth = data
    cfg = d / "config_side.yaml"
    cfg.write_text(CONFIG + "physics: {side_force: {CY: 0.0}}\n")
    assert main(["predict", str(cfg), "--from", str(_summary(d / "plain", truth))]) == 2
    err = capsys.readouterr().err
    assert "no parameter 'CY'" in err and len(err.strip().splitlines()) == 1


def test_the_held_out_fit_keeps_the_better_of_its_two_starts(fitted):
    from bayes_disc.jobs.predict import _fit_own, fit_held_out
    problem, free = fitted
    block = problem.layout.flight_slice(0)
    poor = free.copy()
    poor[block] = problem.start_vector()[block] * 0.5             # a start far from the flight's optimum
    _, dev_poor = _fit_own(problem, poor, 0, max_nfev=3)
    _, dev_free = _fit_own(problem, free, 0, max_nfev=3)
    assert dev_free < dev_poor                                      # the two starts end apart in 3 evaluations
    best, how = fit_held_out(problem, poor, free, 0, max_nfev=3)
    _, ok = problem.residuals(best[None], 0)
    assert ok[0] and how == "free"
    assert best[block] == pytest.approx(_fit_own(problem, free, 0, max_nfev=3)[0][block])


def test_a_throw_the_run_cannot_fly_is_failed_with_the_simulator_s_reason(data):
    d, truth = data
    diverging = {n: 1.0 for n in COEFFICIENT_NAMES}
    diverging.update({"CMq": 1e3, "CRp": -1e2})            # C_Mq, C_Rp ≈ +1 s/rad: the wobble grows
    run = _summary(d / "diverging", truth, diverging)
    assert main(["predict", str(d / "config.yaml"), "--from", str(run), "--output", str(d / "p_div")]) == 0
    held = json.loads((d / "p_div" / "prediction.json").read_text())["flights"]["held"]
    assert held["status"] == "failed" and held["channels"] == {}
    assert "nor reached from the free fit by continuation (the continuation got " in held["reason"]
    assert held["reason"].endswith(": angular or aerodynamic rate above the integrator's rated envelope")


def test_a_throw_neither_start_flies_is_reached_by_continuation(fitted, monkeypatch):
    """Both starts stood in for as unflyable (deviance inf): the fixed fit comes from the continuation, which
    follows the block from the free fit (λ = 0) to the run's shared values (λ = 1)."""
    import bayes_disc.jobs.predict as predict
    problem, free = fitted
    run = free.copy()
    for i, n in enumerate(COEFFICIENT_NAMES):                   # a run whose coefficients are 20 % off the fit's
        run[i] = free[i] * (1.2 if n in ("CLa", "CMa") else 1.0)
    calls, real = [], predict._fit_own

    def two_failed_starts(problem, x, k, max_nfev):
        calls.append(x[: problem.ic_start].copy())
        return (x, float("inf")) if len(calls) <= 2 else real(problem, x, k, max_nfev)
    monkeypatch.setattr(predict, "_fit_own", two_failed_starts)
    best, how = predict.fit_held_out(problem, run, free, 0, max_nfev=5)
    assert how == "continuation"
    assert best[: problem.ic_start] == pytest.approx(run[: problem.ic_start])        # at the run's values
    _, ok = problem.residuals(best[None], 0)
    assert ok[0]
    lams = [float(np.linalg.norm(c - free[: problem.ic_start]) / np.linalg.norm(run[: problem.ic_start]
                                                                                   - free[: problem.ic_start]))
            for c in calls[2:]]
    assert lams == pytest.approx(np.arange(1, 9) * predict.CONTINUATION_STEP)     # eight steps, none halved


def test_the_release_states_of_a_run_s_flights_are_read_by_kind():
    from bayes_disc.inference.model.layout import FULL_IC, INERTIAL_IC
    from bayes_disc.jobs.predict import run_release_states
    params = {"CL0": 0.2}
    params.update({f"{n}_t1": float(i) for i, n in enumerate(INERTIAL_IC.names)})
    params.update({f"{n}_t2": 1.0 for n in INERTIAL_IC.names[:-1]})              # one missing: not a state
    params.update({f"{n}_m": 2.0 for n in FULL_IC.names})
    got = run_release_states(params, INERTIAL_IC)
    assert list(got) == ["t1"] and got["t1"] == pytest.approx(np.arange(INERTIAL_IC.size))
    assert list(run_release_states(params, FULL_IC)) == ["m"]


def test_a_run_flight_s_release_state_is_a_start_of_the_held_out_fit(fitted, monkeypatch):
    """Own and free starts stood in for as unflyable: the fit comes from the run flight's release state (its
    initial conditions in the flight's block, the free fit's other entries), before any continuation."""
    import bayes_disc.jobs.predict as predict
    problem, free = fitted
    ics = problem.layout.ic_slice(0)
    release = free[ics] * 1.01
    starts, real = [], predict._fit_own

    def own_and_free_fail(problem, x, k, max_nfev):
        starts.append(x.copy())
        return (x, float("inf")) if len(starts) <= 2 else real(problem, x, k, max_nfev)
    monkeypatch.setattr(predict, "_fit_own", own_and_free_fail)
    best, how = predict.fit_held_out(problem, free, free, 0, max_nfev=5, release_states={"other": release})
    assert how == "run flight other" and len(starts) == 3                       # no continuation needed
    assert starts[2][ics] == pytest.approx(release)
    own = problem.layout.own_slice(0)
    assert starts[2][own] == pytest.approx(free[own])
    _, ok = problem.residuals(best[None], 0)
    assert ok[0]
