"""Profile intervals: quantiles of the normalised profile likelihood along a coefficient's path."""
import numpy as np
import pytest
from scipy.stats import norm

from bayes_disc.inference.fitting.profile_interval import profile_cdf, profile_interval, signed_root


def _path(t, deviance, centre=0.2, sd=0.05):
    t = np.asarray(t, float)
    return {"value": (centre + sd * t).tolist(), "t": t.tolist(), "deviance": list(deviance)}


def test_a_gaussian_profile_gives_the_laplace_interval_even_beyond_its_points():
    t = np.array([-2.0, -1.0, 0.0, 1.0, 2.0])              # the 5 % and 95 % points lie beyond the path's ends
    q = profile_interval(_path(t, t * t))
    for key, p in (("q05", 0.05), ("q25", 0.25), ("q50", 0.5), ("q75", 0.75), ("q95", 0.95)):
        assert q[key] == pytest.approx(0.2 + 0.05 * norm.ppf(p), abs=1e-4 * 0.05), key


def test_a_flat_topped_profile_gives_its_exact_wider_quantiles():
    """D = (|t| − 1)² beyond |t| = 1, zero inside: mass 2 on the flat top and √(2π)/2 in each tail, so the 95 %
    point is t = 1 + x with √(2π)(1 − Φ(x)) = 0.05 (2 + √(2π))."""
    t = np.linspace(-4, 4, 33)
    D = np.maximum(np.abs(t) - 1, 0) ** 2
    x = norm.isf(0.05 * (2 + np.sqrt(2 * np.pi)) / np.sqrt(2 * np.pi))
    q = profile_interval(_path(t, D))
    assert q["q95"] == pytest.approx(0.2 + 0.05 * (1 + x), abs=1e-3 * 0.05)
    assert q["q05"] == pytest.approx(0.2 - 0.05 * (1 + x), abs=1e-3 * 0.05)
    assert q["q95"] - q["q05"] > 2 * 1.6449 * 0.05                  # wider than the Laplace interval


def test_the_cdf_and_signed_root_follow_a_skewed_profile():
    """Steeper on the right: less mass there, the median left of the optimum; the CDF at a value is the
    quantile the interval inverts."""
    t = np.linspace(-3, 3, 13)
    D = np.where(t > 0, 4 * t * t, t * t)
    path = _path(t, D)
    q = profile_interval(path)
    assert q["q50"] < 0.2
    assert profile_cdf(path, q["q95"])[0] == pytest.approx(0.95, abs=1e-4)
    assert profile_cdf(path, 0.2)[0] == pytest.approx(2 / 3, abs=2e-3)      # Gaussian halves of sd 1 and 1/2
    assert signed_root(path, [0.2 + 0.05 * 5])[0] == pytest.approx(6 + 2, abs=1e-9)  # r = 6 at t = 3, slope 1/sd


def test_a_point_below_the_optimum_recentres_the_profile():
    t = np.array([-2.0, -1.0, 0.0, 1.0, 2.0, 3.0])
    D = (t - 1) ** 2 - 1                                     # the lowest point at t = 1, one unit below the optimum
    q = profile_interval(_path(t, D))
    assert q["q50"] == pytest.approx(0.2 + 0.05, abs=1e-4 * 0.05)


def test_a_path_without_its_optimum_is_refused():
    with pytest.raises(ValueError, match="optimum"):
        profile_interval(_path([1.0, 2.0], [1.0, 4.0]))


def test_the_result_table_of_the_log_shows_the_profile_interval_beside_the_credible_one():
    from bayes_disc.inference.results.summary import format_table
    record = {"q50": 0.19, "q05": 0.185, "q95": 0.195, "r_hat": 1.001, "ess_bulk": 900.0}
    summary = {"literature": {"potts_crowther": {}, "hummel2002": {}}, "coefficients": ["CL0", "CY"],
               "parameters": {"CL0": record, "CY": record}}
    plain = format_table(summary).splitlines()
    assert "profile" not in plain[0]
    summary["profile_intervals"] = {"CL0": {"q05": 0.1812, "q25": 0.0, "q50": 0.19, "q75": 0.0, "q95": 0.1987}}
    lines = format_table(summary).splitlines()
    assert "profile q05" in lines[0] and "profile q95" in lines[0]
    assert lines[1].split()[:6] == ["CL0", "0.19", "0.185", "0.195", "0.1812", "0.1987"]
    assert lines[2].split()[:4] == ["CY", "0.19", "0.185", "0.195"] and len(lines[2]) == len(lines[1])


def test_the_run_summary_names_a_path_that_gives_no_interval(caplog):
    from bayes_disc.jobs.sample import profile_intervals
    t = [-1.0, 0.0, 1.0]
    paths = {"CL0": _path(t, [1.0, 0.0, 1.0]), "CMq": _path([0.0], [0.0])}
    with caplog.at_level("WARNING", logger="bayes_disc"):
        out = profile_intervals(paths)
    assert list(out) == ["CL0"] and "no profile interval for CMq" in caplog.text
