"""Camera model, 11-parameter DLT (round trip, residuals, decomposition) and camera-file formats."""
from __future__ import annotations

import cv2
import numpy as np
import pytest

from bayes_disc.video.calibration import (ARGUS, DLTDV, OPENCV, ImageConvention, camera_from_dlt,
                                          cameras_from_dlt_csv, coefficients_to_matrix, decompose_projection,
                                          dlt_calibrate, dlt_from_camera, project_dlt, read_anipose_toml,
                                          read_camera_yaml, read_dlt_csv, refine_camera, write_anipose_toml,
                                          write_camera_yaml, write_dlt_csv)
from bayes_disc.video.camera import Camera, look_at
from bayes_disc.video.errors import VideoInputError


def random_camera(rng, name="cam", dist=(), skew=0.0):
    """A camera 8–15 m from a 16 × 6 × 3 m volume, looking at it, with random intrinsics."""
    target = rng.uniform([4, -1, 0.8], [11, 1, 2.0])
    az = rng.uniform(0, 2 * np.pi)
    r = rng.uniform(8, 15)
    pos = target + np.array([r * np.cos(az), r * np.sin(az), rng.uniform(2, 7)])
    return look_at(name, pos, target, rng.uniform(700, 1600), (1280, 1024), dist=dist, skew=skew,
                   aspect=rng.uniform(0.97, 1.03), principal_point=(rng.uniform(600, 680), rng.uniform(480, 540)))


def volume_points(rng, n):
    return rng.uniform([0, -2, 0.5], [15, 2, 3.0], (n, 3))


def test_projection_matches_opencv_and_undistortion_inverts(rng):
    cam = random_camera(rng, dist=[-0.15, 0.08, 0.001, -0.0007, -0.02, 0.01, 0.002, 0.001])
    X = volume_points(rng, 200)
    uv = cam.project(X)
    rvec = cv2.Rodrigues(cam.R)[0]
    ref = cv2.projectPoints(X, rvec, cam.t, cam.K, cam.dist)[0][:, 0]
    assert np.abs(uv - ref).max() < 1e-8
    Xc = cam.to_camera(X)
    assert np.abs(cam.undistort_pixels(uv) - Xc[:, :2] / Xc[:, 2:]).max() < 1e-12
    # analytic Jacobian against central differences
    _, J = cam.project_jacobian(X)
    h = 1e-6
    Jn = np.stack([(cam.project(X + h * e) - cam.project(X - h * e)) / (2 * h) for e in np.eye(3)], axis=-1)
    assert np.abs(J - Jn).max() < 1e-5 * np.abs(J).max()


def test_points_behind_camera_project_to_nan(rng):
    cam = random_camera(rng)
    behind = cam.center - 3 * cam.R[2]  # 3 m behind along the optical axis
    assert np.all(np.isnan(cam.project(behind[None])))


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_dlt_round_trip(seed):
    """DLT from exact projections recovers the projection matrix and K, R, t (with skew, non-square px)."""
    rng = np.random.default_rng(seed)
    cam = random_camera(rng, skew=rng.uniform(-2, 2))
    X = volume_points(rng, 10)
    res = dlt_calibrate(X, cam.project(X), name="c", image_size=cam.image_size)
    assert res.rms_px < 1e-8
    assert np.nanmax(res.loo_px) < 1e-7
    L_true = cam.dlt_coefficients()
    assert np.allclose(res.coefficients, L_true, rtol=1e-7, atol=1e-10)
    assert np.allclose(res.camera.K, cam.K, rtol=1e-7, atol=1e-6)
    assert np.allclose(res.camera.R, cam.R, atol=1e-9)
    assert np.allclose(res.camera.t, cam.t, atol=1e-8)
    assert np.allclose(res.camera.center, cam.center, atol=1e-7)
    # and back: the decomposition reprojects new points exactly
    Y = volume_points(rng, 50)
    assert np.abs(res.camera.project(Y) - cam.project(Y)).max() < 1e-7


def test_dlt_minimum_six_points_and_residual_statistics(rng):
    cam = random_camera(rng)
    X = volume_points(rng, 6)
    res = dlt_calibrate(X, cam.project(X))
    assert res.rms_px < 1e-7
    assert np.all(np.isnan(res.loo_px))  # leave-one-out needs ≥ 7 points
    # with pixel noise: in-sample residuals shrink by the fit, leave-one-out residuals do not
    sigma = 0.3
    X = volume_points(rng, 40)
    errs_in, errs_loo = [], []
    for _ in range(20):
        uv = cam.project(X) + rng.normal(0, sigma, (40, 2))
        r = dlt_calibrate(X, uv)
        errs_in.append(r.rms_px)
        errs_loo.append(np.sqrt(np.mean(r.loo_px ** 2)))
    expected_in = sigma * np.sqrt(2 * (80 - 11) / 80)      # E|r|² = σ²·2·(2n − 11)/(2n) per point
    assert abs(np.sqrt(np.mean(np.square(errs_in))) - expected_in) < 0.1 * expected_in
    assert np.mean(errs_loo) > np.mean(errs_in)
    assert "leave-one-out" in r.report()


def test_leave_one_out_residual_exposes_a_misdigitised_point(rng):
    """A control point digitised 4 px off: the fit partly absorbs it (smaller in-sample residual), its
    leave-one-out residual shows the whole error and is the largest of all points."""
    cam = random_camera(rng)
    X = volume_points(rng, 20)
    uv = cam.project(X) + rng.normal(0, 0.1, (20, 2))
    uv[5] += [4.0 * np.cos(1.0), 4.0 * np.sin(1.0)]
    r = dlt_calibrate(X, uv)
    res = np.linalg.norm(r.residuals, axis=1)
    assert np.argmax(r.loo_px) == 5 and r.loo_px[5] > 3.5
    assert res[5] < r.loo_px[5]
    assert np.median(np.delete(r.loo_px, 5)) < 1.0


def test_dlt_rejects_bad_control_points(rng):
    cam = random_camera(rng)
    X = volume_points(rng, 5)
    with pytest.raises(VideoInputError, match="at least 6"):
        dlt_calibrate(X, cam.project(X), name="c5")
    Xp = volume_points(rng, 12)
    Xp[:, 2] = 1.0  # all on one plane
    with pytest.raises(VideoInputError, match="coplanar"):
        dlt_calibrate(Xp, cam.project(Xp), name="flat")


def test_decomposition_handles_sign_and_scale(rng):
    cam = random_camera(rng, skew=1.0)
    for scale in (3.7, -0.02):
        K, R, t = decompose_projection(scale * cam.P)
        assert np.allclose(K, cam.K, rtol=1e-9) and np.allclose(R, cam.R, atol=1e-12) and np.allclose(t, cam.t)


def test_dlt_refinement_adds_distortion(rng):
    cam = random_camera(rng, dist=[-0.2, 0.1, 0, 0, 0])
    X = volume_points(rng, 60)
    uv = cam.project(X)
    lin = dlt_calibrate(X, uv)
    assert lin.rms_px > 0.5  # a pinhole cannot fit the distortion
    ref = refine_camera(lin.camera, X, uv, ("k1", "k2"))
    assert np.sqrt(np.mean(np.sum((ref.project(X) - uv) ** 2, axis=1))) < 1e-3
    assert abs(ref.dist[0] + 0.2) < 2e-3


def test_image_conventions():
    H = 1024
    uv = np.array([[0.0, 0.0], [1279.0, 1023.0], [10.25, 700.5]])
    d = DLTDV.from_opencv(uv, H)
    assert np.allclose(d, [[1, 1024], [1280, 1], [11.25, 323.5]])      # MATLAB 1-based, y up
    a = ARGUS.from_opencv(uv, H)
    assert np.allclose(a, [[0, 1023], [1279, 0], [10.25, 322.5]])      # 0-based, y up
    for conv in (DLTDV, ARGUS, OPENCV, ImageConvention("top-left", 1.0)):
        assert np.allclose(conv.to_opencv(conv.from_opencv(uv, H), H), uv)


@pytest.mark.parametrize("conv,units", [(DLTDV, 1.0), (DLTDV, 0.001), (ARGUS, 0.01), (OPENCV, 1.0)])
def test_dlt_csv_round_trip(tmp_path, rng, conv, units):
    cams = [random_camera(rng, name=f"c{i}", skew=0.5) for i in range(3)]
    path = tmp_path / "coefs.csv"
    write_dlt_csv(path, cams, conv, units)
    L = read_dlt_csv(path)
    assert L.shape == (3, 11)
    # the file's coefficients map file-unit points to file-convention pixels
    X = volume_points(rng, 30)
    for cam, coef in zip(cams, L):
        assert np.allclose(project_dlt(coef, X / units), conv.from_opencv(cam.project(X), cam.height), atol=1e-6)
    back = cameras_from_dlt_csv(path, ["c0", "c1", "c2"], {c.name: c.image_size for c in cams}, conv, units)
    for cam in cams:
        assert np.abs(back[cam.name].project(X) - cam.project(X)).max() < 1e-6
        assert np.allclose(back[cam.name].center, cam.center, atol=1e-6)


def test_dlt_csv_errors(tmp_path, rng):
    p = tmp_path / "bad.csv"
    p.write_text("1,2\n" * 10)
    with pytest.raises(VideoInputError, match="11 rows"):
        read_dlt_csv(p)
    write_dlt_csv(p, [random_camera(rng, name="a")], DLTDV)
    with pytest.raises(VideoInputError, match="1 camera column"):
        cameras_from_dlt_csv(p, ["a", "b"], {"a": (1280, 1024), "b": (1280, 1024)})


def test_anipose_toml_round_trip_and_reader(tmp_path, rng):
    cams = {f"c{i}": random_camera(rng, name=f"c{i}", dist=[-0.1 * i, 0.01, 0.001, 0, 0.0]) for i in range(3)}
    path = tmp_path / "calibration.toml"
    write_anipose_toml(path, cams, metres_per_unit=0.001)
    back = read_anipose_toml(path, metres_per_unit=0.001)
    X = volume_points(rng, 30)
    assert list(back) == list(cams)
    for name, cam in cams.items():
        assert np.abs(back[name].project(X) - cam.project(X)).max() < 1e-6
    # a file as aniposelib writes it (translation in mm)
    text = """[cam_0]
name = "A"
size = [ 1280, 1024,]
matrix = [ [ 1000.0, 0.0, 640.0,], [ 0.0, 1000.0, 512.0,], [ 0.0, 0.0, 1.0,],]
distortions = [ -0.1, 0.02, 0.0, 0.0, 0.0,]
rotation = [ 0.1, -0.2, 0.05,]
translation = [ 100.0, -50.0, 8000.0,]

[metadata]
adjusted = true
error = 0.4
"""
    (tmp_path / "a.toml").write_text(text)
    a = read_anipose_toml(tmp_path / "a.toml", metres_per_unit=0.001)["A"]
    ref = cv2.projectPoints(X, np.array([0.1, -0.2, 0.05]), np.array([0.1, -0.05, 8.0]), a.K, a.dist)[0][:, 0]
    assert np.abs(a.project(X) - ref).max() < 1e-8
    (tmp_path / "b.toml").write_text(text.replace('name = "A"', 'name = "A"\nfisheye = true'))
    with pytest.raises(VideoInputError, match="fisheye"):
        read_anipose_toml(tmp_path / "b.toml")


def test_camera_yaml_round_trip_and_errors(tmp_path, rng):
    cams = [random_camera(rng, name=f"c{i}", dist=[0.01 * i, 0, 0, 0, 0]) for i in range(2)]
    write_camera_yaml(tmp_path / "cams.yaml", cams)
    back = read_camera_yaml(tmp_path / "cams.yaml")
    for c in cams:
        assert np.allclose(back[c.name].P, c.P) and np.allclose(back[c.name].dist, c.dist)
    text = (tmp_path / "cams.yaml").read_text()
    (tmp_path / "bad.yaml").write_text(text.replace("dist:", "distortion:", 1))
    with pytest.raises(VideoInputError, match=r"cameras\.c0\.distortion.*unknown key"):
        read_camera_yaml(tmp_path / "bad.yaml")
    with pytest.raises(VideoInputError, match="file not found"):
        read_camera_yaml(tmp_path / "missing.yaml")


def test_camera_validation():
    with pytest.raises(ValueError, match="rotation"):
        Camera("x", np.eye(3), np.diag([1, 1, -1.0]), np.zeros(3))
    with pytest.raises(ValueError, match="distortion"):
        Camera("x", np.eye(3), np.eye(3), np.zeros(3), dist=[0.1, 0.2, 0.3])


def test_camera_from_dlt_matches_coefficients(rng):
    cam = random_camera(rng)
    L = dlt_from_camera(cam, DLTDV, 1.0)
    P = coefficients_to_matrix(L)
    assert P[2, 3] == 1.0
    back = camera_from_dlt(L, "x", cam.image_size, DLTDV, 1.0)
    assert np.allclose(back.R, cam.R, atol=1e-9)
