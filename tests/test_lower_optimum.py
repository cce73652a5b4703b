"""A least-squares optimum that is not the lowest point: the profiles that reach below it, and the refit from
there before the profiles start again (bayes_disc.inference.fitting.profile.LowerOptimum, leastsq.refit_from_lower,
run.posterior_approximation), and the refit from a published coefficient set that fits better than the optimum
(joint_region.literature_tests_through_lowest)."""
import json
from dataclasses import replace

import numpy as np
import pytest

from bayes_disc.cli import main
from bayes_disc.jobs import identifiability as diag_run
from bayes_disc.inference.fitting import profile
from bayes_disc.inference.model.config import load_config
from bayes_disc.inference.model.initial import initial_state_from_data
from bayes_disc.inference.fitting.minimiser import minimise
from bayes_disc.inference.fitting.leastsq import refine_least_squares
from bayes_disc.inference.fitting.residuals import whitened_residuals
from bayes_disc.inference.model.problem import Problem
from bayes_disc.inference.fitting.profile import (LOWER_OPTIMUM_DEVIANCE, LowerOptimum, lowest_point, profile_paths,
                                                  profile_side, ridge_first)
from bayes_disc.inference.fitting.joint_region import literature_tests_through_lowest
from bayes_disc.jobs.sample import posterior_approximation
from bayes_disc.report.content import _lower_optimum_rows
from bayes_disc.observation.synth import DEFAULT_MARKERS, LaunchSpec, SynthSpec, synthesize

from conftest import REPO, keep_flights


def _cost(x, p, sigma):
    return 0.5 * float(np.sum(np.square(whitened_residuals(x, p, sigma))))


@pytest.fixture(scope="module")
def displaced():
    """Two throws; their least-squares optimum, and the same result moved to the optimum with CL0 held 3 sd
    above it (every other parameter re-optimised): a "local optimum" 9 deviance units above the lowest point,
    that every profile leaves downhill."""
    flights = (LaunchSpec(name="a", speed=13.0, launch_angle_deg=3, alpha_deg=6, spin=60, duration=0.8, noise_mm=1.0),
               LaunchSpec(name="b", speed=11.0, launch_angle_deg=8, alpha_deg=14, spin=55, duration=0.8, noise_mm=1.0))
    spec = SynthSpec(name="lower", flights=flights, seed=7)
    data = synthesize(spec)
    mb = np.array(list(DEFAULT_MARKERS.values()))
    p = Problem(flights=data.flights, marker_body=mb, disc=spec.disc, env=spec.env, prior_name="potts_crowther",
                start_states=[initial_state_from_data(f, mb) for f in data.flights])
    ls = refine_least_squares(p, minimise(p, p.start_vector(), p.nominal_noise, max_nfev=200).x)
    i = p.names.index("CL0")
    sd = np.sqrt(ls.cov[i, i])
    fit = profile._fixed_fit(p, ls.sigma, ls.theta, ls.cov, i, ls.theta[i] + 3 * sd, 100, _cost(ls.theta, p, ls.sigma))
    assert fit.ok
    x = fit.x
    return p, ls, replace(ls, theta=x, cost=_cost(x, p, ls.sigma)), i


def test_a_side_stops_at_its_first_point_below_the_optimum(displaced):
    p, ls, local, i = displaced
    down = profile_side(p, local.theta, local.sigma, local.cov, i, -1.0).points
    assert len(down) == 1 and down[0].deviance < -LOWER_OPTIMUM_DEVIANCE
    assert _cost(down[0].theta, p, local.sigma) < local.cost
    assert lowest_point(down) is down[0]
    up = profile_side(p, local.theta, local.sigma, local.cov, i, 1.0).points
    assert len(up) > 1 and lowest_point(up) is None and np.all(np.diff([q.deviance for q in up]) > 0)


def test_a_side_counts_the_work_of_every_fit_a_failed_one_included(displaced, monkeypatch):
    """A side's ``njev``/``nfev`` (profiles.json's ``jacobians``/``evaluations``) add up every fit on it, the
    failed fit that ends it included; so do a path's, over both sides."""
    p, ls, _, i = displaced
    fits = []
    real_fit = profile._fixed_fit
    monkeypatch.setattr(profile, "_fixed_fit", lambda *a, **k: fits.append(real_fit(*a, **k)) or fits[-1])
    side = profile_side(p, ls.theta, ls.sigma, ls.cov, i, 1.0)
    assert len(fits) == len(side.points) >= 2 and all(f.ok for f in fits)
    assert (side.njev, side.nfev) == (sum(f.njev for f in fits), sum(f.nfev for f in fits))
    fits.clear()
    starved = profile_side(p, ls.theta, ls.sigma, ls.cov, i, 1.0, max_nfev=1)     # its first fit runs out
    assert starved.points == [] and len(fits) == 1 and not fits[0].ok
    assert starved.njev == fits[0].njev >= 1 and starved.nfev == fits[0].nfev >= 2
    fits.clear()
    path = profile.profile_path(p, ls.theta, ls.sigma, ls.cov, i)
    assert len(fits) == len(path.points) - 1
    assert (path.njev, path.nfev) == (sum(f.njev for f in fits), sum(f.nfev for f in fits))


def test_the_profiles_stop_on_the_same_side_whatever_the_workers(displaced):
    """With ``stop_on_lower`` the first side in ridge-first order that reaches below the optimum is reported,
    in one process as in two; without it the paths come back with those points."""
    p, _, local, _ = displaced
    idx = range(p.n_coef)
    found = []
    for processes in (1, 2):
        with pytest.raises(LowerOptimum) as info:
            profile_paths(p, local.theta, local.sigma, local.cov, idx, processes=processes, stop_on_lower=True)
        found.append(info.value)
    assert found[0].name == found[1].name == p.names[ridge_first(local.cov, idx)[0]]
    assert found[0].point.deviance == found[1].point.deviance < -LOWER_OPTIMUM_DEVIANCE
    paths = profile_paths(p, local.theta, local.sigma, local.cov, [0, 1], processes=1)
    assert all(lowest_point(path.points) is not None for path in paths)


def test_ridge_first_puts_the_correlated_parameters_first():
    """Variance inflation Σ_ii (Σ⁻¹)_ii, scale-free: the pair correlated at 0.99 before the free one, whatever
    the scales."""
    corr = np.array([[1.0, 0.0, 0.1], [0.0, 1.0, 0.99], [0.1, 0.99, 1.0]])
    scale = np.array([1e-5, 3.0, 1e2])
    cov = corr * np.outer(scale, scale)
    order = ridge_first(cov, [0, 1, 2])
    assert set(order[:2]) == {1, 2} and order[2] == 0
    # a held parameter (zero row and column, as refine_least_squares(free=...) leaves it) comes last
    held = np.zeros((4, 4))
    held[:3, :3] = cov
    assert ridge_first(held, [3, 0, 1, 2])[2:] == [0, 3]


def test_the_least_squares_are_refitted_from_the_lower_point(displaced, tmp_path):
    """posterior_approximation: the profiles find the lower point, the least squares are refitted from it (to the
    lowest optimum), the files rewritten, and the profiles go through the new optimum."""
    p, ls, local, _ = displaced
    _, new = posterior_approximation(p, local, 1, tmp_path)
    assert len(new.lower_optima) == 1
    found = new.lower_optima[0]
    assert found["profile"] in p.names[: p.n_coef] and found["deviance"] < -LOWER_OPTIMUM_DEVIANCE
    assert found["earlier_cost"] == pytest.approx(_cost(local.theta, p, new.sigma))
    assert new.cost < found["earlier_cost"] - 4.0          # CL0 3 sd off: ≈ 9/2 above the lowest point
    sd = np.sqrt(np.diag(ls.cov))
    assert np.max(np.abs(new.theta - ls.theta) / sd) < 0.01
    saved = json.loads((tmp_path / "least_squares.json").read_text())
    assert saved["lower_optima"] == json.loads(json.dumps(new.lower_optima))
    assert np.array_equal(np.load(tmp_path / "least_squares_theta.npy"), new.theta)
    profiles = json.loads((tmp_path / "profiles.json").read_text())
    assert min(min(r["deviance"]) for r in profiles.values()) > -LOWER_OPTIMUM_DEVIANCE
    # the paths' work: at least one Jacobian (its covariance) and one evaluation per point
    for r in profiles.values():
        assert r["jacobians"] >= len(r["t"]) - 1 and r["evaluations"] >= len(r["t"]) - 1


def test_identifiability_profiles_refit_a_least_squares_that_stopped_short(tmp_path, monkeypatch):
    """``identifiability --profiles`` given a least-squares result away from the optimum (CL0 held 3 sd off, as
    a fit that stopped short would leave it): its profiles reach below, the least squares are refitted, and the
    Fisher analysis, verdicts and least_squares.json are those of the refitted optimum."""
    (tmp_path / "synth.yaml").write_text((REPO / "runs/demo/synth.yaml").read_text())
    assert main(["synth", str(tmp_path / "synth.yaml")]) == 0
    keep_flights(tmp_path / "flights.csv", {"bsfl5", "fffl10"})
    (tmp_path / "config.yaml").write_text((REPO / "runs/demo/config.yaml").read_text().replace("truth: truth.json", ""))
    real = diag_run.fit_least_squares
    held = {}

    def stopped_short(problem, **kwargs):
        ls = real(problem, **kwargs)
        i = problem.names.index("CL0")
        x = profile._fixed_fit(problem, ls.sigma, ls.theta, ls.cov, i, ls.theta[i] + 3 * np.sqrt(ls.cov[i, i]), 100,
                               _cost(ls.theta, problem, ls.sigma)).x
        held.update(lowest=ls, off=x)
        return replace(ls, theta=x, cost=_cost(x, problem, ls.sigma))
    monkeypatch.setattr(diag_run, "fit_least_squares", stopped_short)
    r = diag_run.run_identifiability(load_config(tmp_path / "config.yaml"), profiles=True, design=False)
    assert len(r["least_squares"]["lower_optima"]) == 1
    saved = json.loads((tmp_path / "out/least_squares.json").read_text())
    assert saved["lower_optima"] == r["least_squares"]["lower_optima"]
    theta = np.array([saved["parameters"][n]["value"] for n in held["lowest"].names])
    sd = np.sqrt(np.diag(held["lowest"].cov))
    assert np.max(np.abs(theta - held["lowest"].theta) / sd) < 0.01           # back at the optimum
    assert np.max(np.abs(held["off"] - held["lowest"].theta) / sd) > 2.5        # from 3 sd off
    assert min(min(p["deviance"]) for p in r["profiles"].values()) > -LOWER_OPTIMUM_DEVIANCE
    cl0 = r["coefficients"]["CL0"]
    assert cl0["value"] == pytest.approx(held["lowest"].theta[0], abs=0.01 * sd[0])


def test_a_published_set_below_the_optimum_refits_the_least_squares(displaced):
    """A coefficient set whose values held together fit better than the optimum (here the lowest optimum's own
    coefficients, tested against the displaced one) has the least squares refitted from its conditional optimum;
    its test is then against the new optimum, and a set above the optimum changes nothing."""
    p, ls, local, _ = displaced
    best = dict(zip(p.names[:p.n_coef], map(float, ls.theta[:p.n_coef])))
    seen = []
    tests, new = literature_tests_through_lowest(p, local, 200, sets={"best": best},
                                                 on_refit=lambda key, test, fit: seen.append((key, test.deviance)))
    assert len(seen) == 1 and seen[0][0] == "best" and seen[0][1] < -LOWER_OPTIMUM_DEVIANCE
    assert len(new.lower_optima) == 1 and new.lower_optima[0]["joint_test"] == "best"
    assert new.cost < new.lower_optima[0]["earlier_cost"] - 4.0
    sd = np.sqrt(np.diag(ls.cov))
    assert np.max(np.abs(new.theta - ls.theta) / sd) < 0.01
    assert not tests["best"].below_optimum and abs(tests["best"].deviance) < 0.1
    rows = dict(_lower_optimum_rows(new.to_dict()))
    assert "the best values held together fitted better" in rows["refit 1 from a lower point"]
    again, same = literature_tests_through_lowest(p, ls, 200, sets={"best": best})
    assert same is ls and not again["best"].below_optimum
