"""Honest per-point uncertainty: each blob's centroid covariance, the gain measured on the blobs, weighted
triangulation, views holding two markers, outlying views, and the layout and time checks."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import chi2

from bayes_disc.video.camera import look_at
from bayes_disc.video.consistency import CheckConfig, check_points
from bayes_disc.video.detection import MERGED, DetectionConfig, detect_full
from bayes_disc.video.psf import spots
from bayes_disc.video.refine import Views, drop_overlaps, refine, shot_noise
from bayes_disc.video.testfootage import marker_positions, standard_test_spec
from bayes_disc.video.triangulation import triangulate

LAYOUT = np.array([[0.100, 0.000, -0.015], [-0.0308, 0.0846, -0.015], [-0.0707, -0.0778, -0.015]])


def noisy_blob_frame(rng, truth, shape=(96, 96), read=2.0, gain=5.0, pedestal=8.0):
    """Frame with blobs (u, v, σ, flux) [px, DN], Gaussian read noise and shot noise of ``gain`` e⁻/DN, 8 bit."""
    img = np.full(shape, pedestal)
    for u, v, s, f in truth:
        img += spots(shape, (0, 0), [u], [v], [s], [f])
    img += rng.normal(0, 1, shape) * np.sqrt(read ** 2 + img / gain)
    return np.clip(np.rint(img), 0, 255).astype(np.uint8)


@pytest.fixture(scope="module")
def blob_sample():
    """400 isolated blobs of σ 1.2–2 px and flux 600–3000 DN with read noise 2 DN and gain 5 e⁻/DN."""
    rng = np.random.default_rng(21)
    out = []
    for _ in range(100):
        truth = [(24 + 48 * (k % 2) + rng.uniform(-2, 2), 24 + 48 * (k // 2) + rng.uniform(-2, 2), rng.uniform(1.2, 2.0),
                  rng.uniform(600, 3000)) for k in range(4)]
        out.append((truth, noisy_blob_frame(rng, truth)))
    return out


def _matched(blobs, truth):
    d = np.linalg.norm(blobs.uv[:, None] - np.array([t[:2] for t in truth])[None], axis=2)
    return np.argmin(d, axis=0)


def test_blob_covariance_with_the_gain_describes_the_centroid_error(blob_sample):
    """With the gain given, eᵀ C⁻¹ e of the centroid errors follows χ²(2): mean ≈ 2, tail at 99.9 % rare."""
    cfg = DetectionConfig(threshold=20, gain=5.0)
    m2 = []
    for truth, img in blob_sample:
        b = detect_full(img, cfg, np.full(img.shape, 8.0, np.float32))
        j = _matched(b, truth)
        for k, t in enumerate(truth):
            e = b.uv[j[k]] - t[:2]
            m2.append(e @ np.linalg.solve(b.cov[j[k]], e))
    m2 = np.array(m2)
    assert 1.5 < m2.mean() < 2.6, m2.mean()
    assert np.mean(m2 > chi2.ppf(0.999, 2)) < 0.01


def test_shot_noise_is_measured_on_the_blobs(blob_sample):
    """Without a gain, the blobs' scatter about a fitted Gaussian gives 1/gain to within 30 %; the read-noise
    covariance alone is too small (its χ² mean above the band about 2), with the measured shot noise it is not."""
    cfg = DetectionConfig(threshold=20)
    stats = np.zeros(2)
    m2_read, m2_all = [], []
    found = []
    for truth, img in blob_sample:
        b = detect_full(img, cfg, np.full(img.shape, 8.0, np.float32))
        stats += b.shot_stats.sum(axis=0)
        found.append((truth, b))
    alpha = shot_noise(stats[None])[0]
    assert 1 / alpha == pytest.approx(5.0, rel=0.3)
    for truth, b in found:
        j = _matched(b, truth)
        for k, t in enumerate(truth):
            e = b.uv[j[k]] - t[:2]
            m2_read.append(e @ np.linalg.solve(b.cov[j[k]], e))
            m2_all.append(e @ np.linalg.solve(b.cov[j[k]] + alpha * b.cov_shot[j[k]], e))
    assert np.mean(m2_read) > 2.6 and 1.5 < np.mean(m2_all) < 2.6


def test_a_bright_single_marker_is_not_merged():
    """Markers of one disc seen at different angles differ ×2–3 in brightness and size: none is merged."""
    rng = np.random.default_rng(3)
    truth = [(30.0, 30.0, 1.3, 900), (70.0, 35.0, 1.9, 2900), (50.0, 70.0, 1.5, 1200)]
    img = noisy_blob_frame(rng, truth)
    b = detect_full(img, DetectionConfig(threshold=20), np.full(img.shape, 8.0, np.float32))
    assert len(b) == 3 and b.usable.all() and not np.any(b.flags & MERGED)
    assert b.flux.max() / b.flux.min() > 2.5 and b.area.max() / b.area.min() > 2


def rig():
    return [look_at("a", [7.5, -10, 9.3], [7.5, 0, 1.4], 1000, (1280, 1024)),
            look_at("b", [7.0, 9.5, 9.8], [7.5, 0, 1.4], 970, (1280, 1024)),
            look_at("c", [5.0, -5, 13.3], [9.0, 0, 1.3], 860, (1280, 1024))]


def test_weighted_triangulation_covariance_is_calibrated(rng):
    """Views with their own pixel covariances (σ from 0.02 to 0.5 px, anisotropic): eᵀ Σ⁻¹ e ~ χ²(3)."""
    cams = rig()
    X = rng.uniform([2, -1, 0.5], [13, 1, 2.5], (3000, 3))
    sig = rng.uniform(0.02, 0.5, (3000, 3, 2))
    rho = rng.uniform(-0.6, 0.6, (3000, 3))
    cov = np.zeros((3000, 3, 2, 2))
    cov[..., 0, 0], cov[..., 1, 1] = sig[..., 0] ** 2, sig[..., 1] ** 2
    cov[..., 0, 1] = cov[..., 1, 0] = rho * sig[..., 0] * sig[..., 1]
    noise = np.einsum("pcij,pcj->pci", np.linalg.cholesky(cov), rng.normal(size=(3000, 3, 2)))
    uv = np.stack([c.project(X) for c in cams], axis=1) + noise
    tri = triangulate(cams, uv, uv_cov=cov)
    e = tri.xyz - X
    m2 = np.einsum("pi,pij,pj->p", e, np.linalg.inv(tri.cov), e)
    assert abs(m2.mean() - 3) < 0.15
    assert abs(tri.chi2.mean() - 3) < 0.15                     # 2n − 3 = 3 degrees of freedom
    assert np.allclose(tri.leverage.sum(axis=1), 3.0)          # the fit takes 3 of the 6 residual dimensions
    iso = triangulate(cams, uv, pixel_sigma=0.3)
    assert np.mean(np.sum(e ** 2, 1)) < np.mean(np.sum((iso.xyz - X) ** 2, 1))


def views_of(cams, X, rng, sigma=0.05):
    """Views (F, M, C) of points X (F, M, 3) with blob covariance σ² I and that noise."""
    F, M = X.shape[:2]
    v = Views.empty(F, M, len(cams))
    for c, cam in enumerate(cams):
        v.uv[:, :, c] = cam.project(X.reshape(-1, 3)).reshape(F, M, 2) + rng.normal(0, sigma, (F, M, 2))
        v.cov[:, :, c] = sigma ** 2 * np.eye(2)
        v.width[:, :, c] = 1.5
    return v


def test_camera_noise_is_fitted_to_the_residuals(rng):
    """Blobs say 0.05 px, one camera is really 0.25 px off (calibration, lens): that camera gets σ_c ≈ 0.24 px
    and the points' covariances become honest; the others get ≈ 0."""
    cams = rig()
    X = rng.uniform([2, -1, 0.5], [13, 1, 2.5], (400, 1, 3))
    v = views_of(cams, X, rng)
    v.uv[:, :, 1] += rng.normal(0, 0.24, (400, 1, 2))
    ref = refine(cams, v, ["a", "b", "c"])
    assert ref.noise.sigma[1] == pytest.approx(0.245, rel=0.2)
    assert ref.noise.sigma[0] < 0.03 and ref.noise.sigma[2] < 0.03
    e = ref.tri.xyz - X[:, 0]
    m2 = np.einsum("pi,pij,pj->p", e, np.linalg.inv(ref.tri.cov), e)
    assert 2.3 < m2.mean() < 3.7 and np.mean(m2 > chi2.ppf(0.999, 3)) < 0.01
    tri0 = refine(cams, v, ["a", "b", "c"], calibrate=False).tri
    m0 = np.einsum("pi,pij,pj->p", e, np.linalg.inv(tri0.cov), tri0.xyz - X[:, 0])
    assert m0.mean() > 6                                        # without the fit the covariance is too tight


def test_a_view_holding_two_markers_is_left_out(rng):
    """Marker 2 lies on camera b's line of sight through marker 1, so both fall on one blob there (marker 2
    has no blob of its own in b): marker 1's view in b is dropped with the reason, nothing else."""
    cams = rig()
    X = (LAYOUT @ np.diag([1.0, -1.0, -1.0]) + [7.5, -0.2, 1.5])[None]
    ray = cams[1].center - X[0, 1]
    X[0, 2] = X[0, 1] + 0.15 * ray / np.linalg.norm(ray)
    v = views_of(cams, X, rng, 0.02)
    v.uv[0, 2, 1] = v.cov[0, 2, 1] = np.nan                     # one blob for both in b ...
    v.uv[0, 1, 1] += 0.3                                        # ... centred between them
    seps = [np.linalg.norm(cams[1].project(X[0, 0]) - cams[1].project(X[0, k])) for k in (1, 2)]
    assert min(seps) > 5 * 1.5                                  # marker 0 is clear of them
    n = drop_overlaps(cams, v, X, ["a", "b", "c"])
    assert n == 1 and not np.isfinite(v.uv[0, 1, 1]).any()
    assert v.notes[0, 1] == ["b: overlap with marker 2"]
    assert np.isfinite(v.uv[0, 1, [0, 2]]).all() and np.isfinite(v.uv[0, 0]).all()


def test_an_outlying_view_is_left_out(rng):
    cams = rig()
    X = rng.uniform([2, -1, 0.5], [13, 1, 2.5], (50, 1, 3))
    v = views_of(cams, X, rng, 0.05)
    v.uv[7, 0, 2] += [1.5, -1.0]                                 # a 1.8 px error: a deblending gone wrong
    ref = refine(cams, v, ["a", "b", "c"], calibrate=False)
    assert not np.isfinite(ref.views.uv[7, 0, 2]).any() and "c: outlier" in ref.views.notes[7, 0][0]
    assert sum(len(n) for n in ref.views.notes.ravel()) == 1
    assert np.linalg.norm(ref.tri.xyz[7] - X[7, 0]) < 2e-3


@pytest.fixture(scope="module")
def clean_track():
    """Markers of the test flight over 60 frames with 1 mm noise and its covariance."""
    spec = standard_test_spec("small")
    X = marker_positions(spec, np.arange(60) / 120.0)[0]
    rng = np.random.default_rng(8)
    cov = np.broadcast_to(1e-6 * np.eye(3), X.shape[:2] + (3, 3)).copy()
    return spec, X, X + rng.normal(0, 1e-3, X.shape), cov


def test_checks_leave_a_clean_track_alone(clean_track):
    spec, _, Xn, cov = clean_track
    res = check_points(Xn, cov, spec.layout, CheckConfig())
    assert np.sum(res.flag != "") <= 1                         # false alarms are rare (level 10⁻⁴ per point)


@pytest.mark.parametrize("action", ["inflate", "drop"])
def test_a_point_off_by_a_centimetre_is_flagged(clean_track, action):
    """A point 1 cm off with a 1 mm covariance is flagged by its neighbours in time; inflated, its ellipsoid
    then holds the truth."""
    spec, X, Xn, cov = clean_track
    bad = Xn.copy()
    bad[30, 1] += [0.006, -0.006, 0.005]
    res = check_points(bad, cov, spec.layout, CheckConfig(action=action))
    assert "time" in res.flag[30, 1]
    assert np.sum(res.flag != "") <= 2
    C = cov[30, 1] + res.inflation[30, 1]
    e = bad[30, 1] - X[30, 1]
    assert e @ np.linalg.solve(cov[30, 1], e) > 50 and e @ np.linalg.solve(C, e) < chi2.ppf(0.999, 3)


def test_a_point_off_the_layout_is_the_culprit(clean_track):
    """Marker 1 pushed 1.5 cm out from the disc's centre in a frame: its two sides are too long, the third
    is fine, so marker 1 (and only it) is flagged by the layout, even without neighbours in time."""
    spec, X, Xn, cov = clean_track
    frame = Xn[20:21].copy()
    out = frame[0, 1] - frame[0].mean(axis=0)
    frame[0, 1] += 0.015 * out / np.linalg.norm(out)
    res = check_points(frame, cov[20:21], spec.layout, CheckConfig())
    assert list(res.flag[0]) == ["", "layout", ""]
