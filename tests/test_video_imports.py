"""DLTdv and Argus point files: round trips, image conventions, import through TRACK.yaml with a
reprojection check."""
from __future__ import annotations

import numpy as np
import pytest
import yaml

from bayes_disc.observation.markers import read_marker_csv
from bayes_disc.video.calibration import ARGUS, DLTDV, write_dlt_csv
from bayes_disc.video.camera import look_at
from bayes_disc.video.errors import VideoInputError
from bayes_disc.video.imports import (Points2D, Points3D, detect_format, read_xypts, read_xyzpts,
                                      reprojection_check, write_xypts, write_xyzpts)
from bayes_disc.video.pipeline import run_track

from conftest import MARKERS



def cams():
    return [look_at("left", [7, -10, 6], [7, 0, 1.5], 1000, (1280, 1024)),
            look_at("right", [7, 10, 7], [7, 0, 1.5], 1100, (1024, 768)),
            look_at("back", [-4, -2, 5], [8, 0, 1.5], 900, (1280, 1024))]


def scene(rng, F=25):
    """Three markers moving rigidly across the volume, with gaps: xyz (F, 3, 3), uv (F, 3, C, 2)."""
    c = np.linspace([1, 0, 1.2], [12, -1, 1.8], F)
    lay = np.array(list(MARKERS.values())) @ np.diag([1, -1, -1])
    xyz = c[:, None, :] + lay[None]
    cs = cams()
    uv = np.stack([cam.project(xyz) for cam in cs], axis=2)
    gaps = rng.random(uv.shape[:3]) < 0.15
    uv[gaps] = np.nan
    return xyz, uv, cs


@pytest.mark.parametrize("fmt", ["dltdv", "argus"])
def test_point_files_round_trip(tmp_path, rng, fmt):
    xyz, uv, cs = scene(rng)
    heights = [c.height for c in cs]
    names = ["pt1", "pt2", "pt3"] if fmt == "dltdv" else ["tip", "left", "right"]
    write_xypts(tmp_path / "xy.csv", Points2D(uv, names), fmt, heights)
    write_xyzpts(tmp_path / "xyz.csv", Points3D(xyz * 1000, names), fmt)  # file in mm
    header = (tmp_path / "xy.csv").read_text().splitlines()[0].split(",")
    if fmt == "dltdv":
        assert header[:4] == ["pt1_cam1_X", "pt1_cam1_Y", "pt1_cam2_X", "pt1_cam2_Y"]
        assert (tmp_path / "xyz.csv").read_text().startswith("pt1_X,pt1_Y,pt1_Z,pt2_X")
    else:
        assert header[:4] == ["tip_cam_1_x", "tip_cam_1_y", "tip_cam_2_x", "tip_cam_2_y"]
        assert (tmp_path / "xyz.csv").read_text().startswith("tip_x,tip_y,tip_z,left_x")
    assert detect_format(tmp_path / "xy.csv") == fmt and detect_format(tmp_path / "xyz.csv") == fmt
    p2 = read_xypts(tmp_path / "xy.csv", fmt, heights)
    p3 = read_xyzpts(tmp_path / "xyz.csv", fmt, metres_per_unit=0.001)
    assert p2.names == names and p3.names == names
    assert np.array_equal(np.isnan(p2.uv), np.isnan(uv))
    assert np.nanmax(np.abs(p2.uv - uv)) < 1e-9
    assert np.nanmax(np.abs(p3.xyz - xyz)) < 1e-12
    # the files hold y-up coordinates: check one value by hand
    conv = DLTDV if fmt == "dltdv" else ARGUS
    f, p, c = np.argwhere(np.isfinite(uv[..., 0]))[0]
    raw = np.genfromtxt(tmp_path / "xy.csv", delimiter=",", skip_header=1)
    col = 2 * (3 * p + c)
    assert raw[f, col] == pytest.approx(uv[f, p, c, 0] + conv.first_pixel)
    assert raw[f, col + 1] == pytest.approx(heights[c] - 1 + conv.first_pixel - uv[f, p, c, 1])
    assert np.nanmax(reprojection_check(cs, p3.xyz, p2.uv)) < 1e-6


def test_reader_errors(tmp_path, rng):
    (tmp_path / "a.csv").write_text("pt1_cam1_X,pt1_cam1_Y,pt1_cam3_X,pt1_cam3_Y\n1,2,3,4\n")
    with pytest.raises(VideoInputError, match="not 1..3"):
        read_xypts(tmp_path / "a.csv", "dltdv", [100, 100, 100])
    (tmp_path / "b.csv").write_text("pt1_X,pt1_Y,pt1_Z\n1,2,oops\n")
    with pytest.raises(VideoInputError, match=r"b\.csv:2: column 'pt1_Z'"):
        read_xyzpts(tmp_path / "b.csv", "dltdv")
    with pytest.raises(VideoInputError, match="file not found"):
        read_xyzpts(tmp_path / "none.csv", "argus")


def _write_import_case(tmp_path, rng, fmt, origin=None):
    xyz, uv, cs = scene(rng)
    heights = [c.height for c in cs]
    names = ["pt1", "pt2", "pt3"]
    write_xypts(tmp_path / "t-xypts.csv", Points2D(uv, names), fmt, heights)
    write_xyzpts(tmp_path / "t-xyzpts.csv", Points3D(xyz * 1000, names), fmt)
    conv = DLTDV if fmt == "dltdv" else ARGUS
    write_dlt_csv(tmp_path / "coefs.csv", cs, conv, metres_per_unit=0.001)  # an easyWand-style file in mm
    imp = {"format": fmt, "xypts": "t-xypts.csv", "xyzpts": "t-xyzpts.csv", "units": "mm",
           "first_pixel": conv.first_pixel, "cameras": [c.name for c in cs],
           "points": {"pt1": "0", "pt2": "1", "pt3": "2"}}
    if origin is not None:
        imp["origin"] = origin
    cfg = {"flight": "imported", "fps": 250, "markers": MARKERS,
           "calibration": {"format": "dlt-csv", "file": "coefs.csv", "cameras": [c.name for c in cs],
                           "image_size": {c.name: list(c.image_size) for c in cs}, "units": "mm",
                           "origin": conv.origin, "first_pixel": conv.first_pixel},
           "import": imp, "output": "out.csv"}
    (tmp_path / "track.yaml").write_text(yaml.safe_dump(cfg))
    return xyz, uv


@pytest.mark.parametrize("fmt", ["dltdv", "argus"])
def test_import_through_track_config(tmp_path, rng, fmt):
    xyz, uv = _write_import_case(tmp_path, rng, fmt)
    res = run_track(tmp_path / "track.yaml", progress=False)
    assert max(res.stats["reprojection check RMS px"].values()) < 1e-4
    table = read_marker_csv(tmp_path / "out.csv", list(MARKERS))
    assert np.allclose(np.unique(table.t), np.arange(len(xyz)) / 250)
    got = table.xyz.reshape(len(xyz), 3, 3)
    n = np.sum(np.isfinite(uv[..., 0]), axis=2)
    assert np.array_equal(np.all(np.isfinite(got), axis=2), n >= 2)  # gaps where < 2 views stay NaN
    assert np.nanmax(np.abs(got - xyz)) < 1e-6
    assert np.array_equal(table.extra["n_views"].reshape(len(xyz), 3), np.where(n >= 2, n, 0))


def test_import_with_wrong_origin_fails_the_reprojection_check(tmp_path, rng):
    _write_import_case(tmp_path, rng, "dltdv", origin="top-left")
    with pytest.raises(VideoInputError, match="reproject"):
        run_track(tmp_path / "track.yaml", progress=False)


def test_import_of_3d_points_alone(tmp_path, rng):
    xyz, _ = _write_import_case(tmp_path, rng, "argus")
    cfg = yaml.safe_load((tmp_path / "track.yaml").read_text())
    del cfg["import"]["xypts"]
    cfg["import"]["points"] = {"pt2": "1", "pt1": "0", "pt3": "2"}
    (tmp_path / "track.yaml").write_text(yaml.safe_dump(cfg))
    run_track(tmp_path / "track.yaml", progress=False)
    table = read_marker_csv(tmp_path / "out.csv", list(MARKERS))
    assert np.nanmax(np.abs(table.xyz.reshape(len(xyz), 3, 3) - xyz)) < 1e-9  # 9 decimals in the file


def test_import_config_errors(tmp_path, rng):
    _write_import_case(tmp_path, rng, "dltdv")
    cfg = yaml.safe_load((tmp_path / "track.yaml").read_text())
    cfg["import"]["points"] = {"pt9": "0"}
    (tmp_path / "track.yaml").write_text(yaml.safe_dump(cfg))
    with pytest.raises(VideoInputError, match="'pt9'"):
        run_track(tmp_path / "track.yaml", progress=False)
    cfg["import"]["points"] = {"pt1": "0"}
    cfg["import"]["cameras"] = ["left", "nope", "back"]
    (tmp_path / "track.yaml").write_text(yaml.safe_dump(cfg))
    with pytest.raises(VideoInputError, match="'nope' is not in the calibration"):
        run_track(tmp_path / "track.yaml", progress=False)
