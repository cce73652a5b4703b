"""Joint statements from the profile likelihood (bayes_disc.inference.fitting.joint_region): the deviance W of
held coefficient values against the least-squares quadratic form where the likelihood is near Gaussian, the
joint region's verdict, and the published sets' tests."""
import numpy as np
import pytest
from scipy import stats

from bayes_disc.inference.fitting.joint_region import JointTest, literature_tests, profile_deviance


def test_the_deviance_is_zero_at_the_optimum_and_the_quadratic_form_near_it(two_flights):
    """At the optimum's own values W = 0; one coefficient held m least-squares sds away gives W ≈ m² where the
    profile is near Gaussian (CL0, CRp), and all ten held at a point of Mahalanobis distance² d² give W ≈ d²
    (the least-squares covariance's Schur complement is the profile's curvature)."""
    problem, ls = two_flights
    names = list(problem.names[:problem.n_coef])
    at_optimum = profile_deviance(problem, ls, dict(zip(names, ls.theta[:10])))
    assert at_optimum.converged and at_optimum.deviance < 1e-3
    sd = np.sqrt(np.diag(ls.cov))
    for name in ("CL0", "CRp"):
        k = names.index(name)
        for m in (0.5, 1.0, 2.0):
            t = profile_deviance(problem, ls, {name: ls.theta[k] + m * sd[k]})
            assert t.converged and t.dof == 1
            assert abs(t.deviance - m * m) < 0.05 * m * m + 1e-3, (name, m, t.deviance)
    L = np.linalg.cholesky(ls.cov[:10, :10])
    z = 0.5 * np.random.default_rng(0).standard_normal(10)
    t = profile_deviance(problem, ls, dict(zip(names, ls.theta[:10] + L @ z)))
    assert t.dof == 10 and abs(t.deviance - z @ z) < 0.1 * (z @ z), (t.deviance, z @ z)


def test_the_joint_region_verdict():
    edge = stats.chi2.ppf(0.9, 10)
    inside, outside = JointTest({f"c{i}": 0.0 for i in range(10)}, edge - 0.01, True), \
        JointTest({f"c{i}": 0.0 for i in range(10)}, edge + 0.01, True)
    assert inside.inside and not outside.inside
    assert abs(inside.p_value - 0.1) < 1e-3 and outside.p_value < 0.1
    assert JointTest({"CL0": 0.2}, 3.0, False).to_dict() == {
        "values": {"CL0": 0.2}, "deviance": 3.0, "dof": 1, "p_value": float(stats.chi2.sf(3.0, 1)),
        "inside_90": False, "converged": False, "below_optimum": False}
    # a fit that went below the optimum is named, not counted as W = 0; round-off below it is not
    assert JointTest({"CL0": 0.2}, -2.5, True).below_optimum
    assert not JointTest({"CL0": 0.2}, -0.01, True).below_optimum


def test_the_first_screen_words_of_the_joint_tests():
    """Inside, outside, an upper bound, and a set that fits better than the reported optimum."""
    from bayes_disc.report.answer import literature_test_note
    tests = {"hummel2002": JointTest({f"c{i}": 0.0 for i in range(10)}, 9.56, True).to_dict(),
             "potts_crowther": JointTest({f"c{i}": 0.0 for i in range(6)}, 5322.0, False).to_dict()}
    text = literature_test_note({"literature_tests": tests})
    assert "its 10 values together: W = 9.56, inside the data's joint 90 % region (p = 0.48)" in text
    assert ("its 6 values together: W = 5322 (an upper bound: its fit stopped at its budget), outside the data's "
            "joint 90 % region (p &lt; 0.001)") in text
    tests["hummel2002"] = JointTest({f"c{i}": 0.0 for i in range(10)}, -3.0, True).to_dict()
    text = literature_test_note({"literature_tests": tests})
    assert "a lower cost than the least-squares optimum (W = -3)" in text and "inside" not in text.split(";")[0]
    assert literature_test_note({}) == ""


def test_the_published_sets_are_tested_on_the_values_they_give(two_flights):
    """Hummel & Hubbard give all ten coefficients, Potts & Crowther six; a name the model does not have is
    refused."""
    problem, ls = two_flights
    tests = literature_tests(problem, ls)
    assert tests["hummel2002"].dof == 10 and tests["potts_crowther"].dof == 6
    assert set(tests["potts_crowther"].values) == {"CL0", "CLa", "CD0", "CDa", "CM0", "CMa"}
    assert all(t.converged and t.deviance >= 0 for t in tests.values())
    with pytest.raises(ValueError, match="CXx"):
        profile_deviance(problem, ls, {"CXx": 1.0})
