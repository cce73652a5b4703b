"""The fixed-truth section of the validation page (tools/validation_fixed_truth.py): the chance that exactly
calibrated intervals meet the sd(z) criterion, and the coverages it judges against their bands."""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
from scipy import stats

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tools"))

import validation_fixed_truth as V  # noqa: E402


def test_the_pass_chance_of_independent_coefficients_is_the_chi_square_one():
    """With uncorrelated z every sd(z) is an independent √(χ²_{K−1}/(K−1)): the chance all ten land in
    1 ± 0.15 is P(0.85² (K−1) ≤ χ² ≤ 1.15² (K−1))¹⁰, which the simulation reproduces; strongly correlated pairs
    make it larger (fewer independent chances to miss)."""
    k = 50
    z = np.random.default_rng(3).standard_normal((5000, 10))[:k]
    z_indep = np.linalg.qr(z - z.mean(axis=0))[0] * np.sqrt(k - 1)     # exactly uncorrelated columns
    one = stats.chi2.cdf(1.15 ** 2 * (k - 1), k - 1) - stats.chi2.cdf(0.85 ** 2 * (k - 1), k - 1)
    assert abs(V.pass_chance(z_indep) - one ** 10) < 0.03, (V.pass_chance(z_indep), one ** 10)
    paired = z_indep.copy()
    paired[:, 1::2] = paired[:, 0::2] + 0.05 * paired[:, 1::2]
    assert V.pass_chance(paired) > V.pass_chance(z_indep) + 0.1


def test_coverages_outside_the_family_wise_band_are_named():
    """At 150 draws a 90 % coverage of 0.77 is outside the family-wise band, 0.90 and 0.85 are not."""
    names = V.COEFFICIENTS
    fig = {"coverage_50": dict.fromkeys(names, 0.5), "coverage_90": dict.fromkeys(names, 0.9)}
    assert V.coverage_judgement(fig, 150) == []
    fig["coverage_90"] = {**fig["coverage_90"], "CRp": 0.77, "CRr": 0.85}
    assert V.coverage_judgement(fig, 150) == ["CRp 90 %"]


def test_paired_figures_recover_a_posterior_narrower_than_the_laplace_approximation():
    """Least-squares optima scattering at their Laplace sd (z_LS ~ N(0, 1)) and a posterior whose mean is the
    optimum but whose sd is 0.8 of the Laplace sd: z_post = z_LS / 0.8, so the slope is 1.25 and the
    least-squares sd(z) about 1; a coefficient whose posterior equals the Laplace approximation has slope 1."""
    rng = np.random.default_rng(5)
    k, n = 400, 3
    truth = np.array([1.0, -2.0, 0.5])
    laplace_sd = np.tile([0.1, 0.2, 0.05], (k, 1))
    optima = truth + rng.standard_normal((k, n)) * laplace_sd
    z_ls = (truth - optima) / laplace_sd
    z_post = z_ls / np.array([0.8, 1.0, 1.0])
    fig = V.paired_figures(z_post, optima, laplace_sd, truth)
    assert np.allclose(fig["slope"], [1.25, 1.0, 1.0])
    assert np.allclose(fig["correlation"], 1.0)
    assert np.all(np.abs(fig["sd_z_ls"] - 1.0) < 0.1), fig["sd_z_ls"]
    wider = V.paired_figures(z_ls * 0.7 + 0.3 * rng.standard_normal((k, n)), optima, laplace_sd, truth)
    assert np.all(np.abs(wider["slope"] - 0.7) < 0.06) and np.all(wider["correlation"] < 0.95)


def test_files_sampled_with_other_sampler_settings_are_labelled_apart():
    """A file whose runs replaced the campaign's sampler settings (``sampler``) is not counted with the template's
    runs under the same prior: its label names the settings."""
    template = {"reference_surrogate": {}}
    longer = {"reference_surrogate": {}, "sampler": {"max_steps": 3000, "min_steps": 2000}}
    assert V.prior_label(template, "reference") == "reference (default)"
    assert V.prior_label(longer, "reference") == "reference (default), sampler max_steps 3000, min_steps 2000"
    assert V.prior_label({}, "reference") == V.PLAIN_SURROGATE
