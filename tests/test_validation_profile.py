"""The profile-interval section of the validation page (tools/validation_profile.py): which coverages and
sd(z) it judges outside their bands, and its verdict from the committed kind of file."""
from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
from scipy import stats

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tools"))

import validation_profile as V  # noqa: E402


def _quantiles(k: int, widen: float = 1.0, seed: int = 0) -> np.ndarray:
    """(k, 10) truth quantiles of intervals whose width is the truth's scatter divided by ``widen`` (1: exact)."""
    z = np.random.default_rng(seed).standard_normal((k, 10))
    return stats.norm.cdf(widen * z)


def test_calibrated_quantiles_pass_and_narrow_intervals_are_named():
    u = _quantiles(150)
    assert V.sd_z_misses(u) == [] and V.coverage_misses(u) == []
    narrow = u.copy()
    narrow[:, 7:9] = _quantiles(150, widen=1.3, seed=1)[:, 7:9]     # CRr and CRp a quarter too narrow
    assert V.sd_z_misses(narrow) == ["CRr", "CRp"]
    assert set(V.coverage_misses(narrow)) <= {"CRr 50 %", "CRr 90 %", "CRp 50 %", "CRp 90 %"}


def test_deviance_figures_judge_the_joint_region():
    """χ²₁₀ deviances at the truth: mean inside its band, about 90 % below 15.99; deviances a fifth too large
    (joint regions too small) leave the band."""
    w = stats.chi2.rvs(10, size=150, random_state=np.random.default_rng(4))
    mean, (lo, hi), share = V.deviance_figures(w)
    assert lo <= mean <= hi and abs(lo - 10 + 2 * np.sqrt(20 / 150)) < 1e-12
    assert abs(share - 0.9) < 0.06
    mean, (lo, hi), share = V.deviance_figures(1.2 * w)
    assert mean > hi and share < 0.85


def test_the_section_judges_each_file_and_pairs_the_posterior(tmp_path, monkeypatch):
    """A calibrated design passes, a design with too-narrow roll intervals fails, and so does one whose joint
    deviance at the truth is too large; the posterior's figures of the same draws appear beside the profile's
    when a posterior file holds them."""
    names = V.COEFFICIENTS
    flights = [{"speed": 8.0, "alpha_deg": 30.0}, {"speed": 17.0, "alpha_deg": 5.0, "p": 2.0, "q": -2.0}]
    good, bad, joint_bad = _quantiles(150, seed=2), _quantiles(150, seed=3), _quantiles(150, seed=8)
    bad[:, 7] = stats.norm.cdf(1.4 * stats.norm.ppf(bad[:, 7]))
    w = stats.chi2.rvs(10, size=150, random_state=np.random.default_rng(6))
    for i, (u, dev) in enumerate(((good, w), (bad, w), (joint_bad, 1.3 * w))):
        (tmp_path / f"d{i}.json").write_text(json.dumps({
            "campaign": "c", "replicate": i, "draws": 150, "flights": flights, "quantile": u.tolist(),
            "deviance": dev.tolist(),
            "coverage_90": dict(zip(names, np.mean(np.abs(u - 0.5) < 0.45, axis=0).tolist())),
            "command": f"python benchmarks/bench_profile_coverage.py c.yaml --replicate {i} --draws 150"}))
    post = tmp_path / "posterior"
    post.mkdir()
    (post / "p.json").write_text(json.dumps({"campaign": "c", "replicate": 0, "reference_surrogate": {},
                                             "per_draw": {"reference": {"quantile": bad.tolist()}}}))
    monkeypatch.setattr(V, "FOLDER", tmp_path)
    monkeypatch.setattr(V, "POSTERIOR_FOLDER", post)
    text = "\n".join(V.section_profile_intervals())
    assert "| 0 | 150 | none | none | 9" in text                     # exact intervals pass about 92 % of the time
    assert "| 1 | 150 | CRr |" in text
    assert "| 2 | 150 | none | none |" in text
    assert "| 0 | posterior (same draws) |" in text and "| 1 | posterior (same draws) |" not in text
    assert "the criteria hold on 1 of 3 designs" in text and "do not cover as they claim" in text
    assert "8.0 m/s α 30°" in text and "p, q +2.0, −2.0 rad/s" in text
