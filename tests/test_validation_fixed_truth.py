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
