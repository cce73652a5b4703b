"""N-view triangulation (linear DLT + Gauss–Newton) and its covariance."""
from __future__ import annotations

import numpy as np

from bayes_disc.video.camera import look_at
from bayes_disc.video.triangulation import triangulate, triangulate_linear


def rig():
    return [look_at("a", [7.5, -12, 7], [7.5, -0.7, 1.5], 950, (1280, 1024), dist=[-0.12, 0.05, 5e-4, -3e-4, -0.01]),
            look_at("b", [7.5, 11, 8], [7.5, -0.7, 1.5], 950, (1280, 1024), dist=[-0.10, 0.03, 0, 0, 0]),
            look_at("c", [-4, -3, 6], [8, -0.7, 1.5], 1000, (1280, 1024), dist=[0.04, 0, 0, 0, 0]),
            look_at("d", [16, 3, 4], [7, -0.5, 1.5], 900, (1280, 1024), dist=[-0.05, 0.01, 0, 0, 0])]


def test_exact_projections_are_recovered_with_any_subset_of_views(rng):
    cams = rig()
    X = rng.uniform([0, -2, 0.5], [15, 1, 3], (500, 3))
    uv = np.stack([c.project(X) for c in cams], axis=1)
    mask = rng.random(uv.shape[:2]) < 0.3
    uv[mask] = np.nan
    n = np.sum(~mask, axis=1)
    tr = triangulate(cams, uv)
    ok = n >= 2
    assert np.array_equal(tr.n_views, np.where(ok, n, 0))
    assert np.abs(tr.xyz[ok] - X[ok]).max() < 1e-9
    assert np.all(np.isnan(tr.xyz[~ok])) and np.all(np.isnan(tr.rms_px[~ok]))
    assert np.nanmax(tr.rms_px) < 1e-9
    # the linear step alone is biased by ignoring the pixel metric, but close
    lin = triangulate_linear(cams, uv)
    assert np.abs(lin[ok] - X[ok]).max() < 1e-6


def test_gauss_newton_beats_linear_and_covariance_is_calibrated(rng):
    """With pixel noise σ: refined points are closer than linear ones, and the Mahalanobis distances
    e' Σ⁻¹ e follow χ²(3) (mean 3)."""
    cams = rig()[:3]
    sigma = 0.2
    X = rng.uniform([0, -2, 0.5], [15, 1, 3], (3000, 3))
    uv = np.stack([c.project(X) for c in cams], axis=1) + rng.normal(0, sigma, (3000, 3, 2))
    tr = triangulate(cams, uv, pixel_sigma=sigma)
    e = tr.xyz - X
    chi2 = np.einsum("pi,pij,pj->p", e, np.linalg.inv(tr.cov), e)
    assert abs(chi2.mean() - 3) < 0.15
    assert abs(np.mean(chi2 < 7.815) - 0.95) < 0.015  # 95 % quantile of χ²(3)
    # residual RMS: E[n·rms²] = (2n − 3) σ²
    assert abs(np.mean(3 * tr.rms_px ** 2) / (3 * sigma ** 2) - 1) < 0.05
    lin = triangulate_linear(cams, uv)
    assert np.mean(np.sum(e ** 2, 1)) <= np.mean(np.sum((lin - X) ** 2, 1))


def test_point_behind_a_camera_is_not_triangulated_from_it():
    cams = rig()[:2]
    X = np.array([[7.5, -0.5, 1.5]])
    uv = np.stack([c.project(X) for c in cams], axis=1)
    tr = triangulate(cams, uv)
    assert np.allclose(tr.xyz, X)
    one = uv.copy()
    one[:, 1] = np.nan
    assert np.all(np.isnan(triangulate(cams, one).xyz))
