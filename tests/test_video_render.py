"""Synthetic footage: blob positions, occlusion of the top face, saturation, motion blur, dropped
frames, frame offsets, files on disk and the render config."""
from __future__ import annotations

import csv
from dataclasses import replace

import numpy as np
import pytest
import yaml

from bayes_disc.physics.frames import quat_to_matrix
from bayes_disc.video.camera import look_at
from bayes_disc.video.detection import ELONGATED, SATURATED, DetectionConfig, detect_full
from bayes_disc.video.errors import VideoInputError
from bayes_disc.video.render import (FlightSpec, ImagingSpec, RenderCamera, RenderSpec, Renderer,
                                     parse_render_config, run_render)


def small_spec(**imaging):
    """A 0.25 s throw seen from 4 m by 640×512 cameras: one above the disc, one level with it (the top
    face is edge-on: markers hidden) and one above with an offset of 2 frames."""
    cams = (RenderCamera(look_at("above", [1.6, -3.0, 3.5], [1.6, 0, 1.25], 700, (640, 512))),
            RenderCamera(look_at("below", [1.6, 4.0, 0.3], [1.6, 0, 1.25], 700, (640, 512))),
            RenderCamera(look_at("late", [1.6, 3.0, 3.0], [1.6, 0, 1.25], 650, (640, 512)), frame_offset=2))
    base = ImagingSpec(noise_sigma=1.5, noise_region="windows", drop_rate=0.0, peak=160)
    return RenderSpec(FlightSpec(duration=0.25), cams, imaging=replace(base, **imaging), fps=120.0, seed=3)


@pytest.fixture(scope="module")
def renderer():
    return Renderer(small_spec())


def test_blob_centroids_match_truth_and_occlusion(renderer):
    r = renderer
    assert r.visible[0].all()                    # the camera above sees every marker
    assert not r.visible[1].any()                # the camera below sees the underside: markers hidden
    errs = []
    for c in (0, 2):
        first, last = r.frame_range(c)
        for i in range(first, last + 1):
            f = i + r.spec.cameras[c].frame_offset
            b = detect_full(r.render(c, i), DetectionConfig(threshold=30))
            b = b.subset(b.usable)
            truth = r.uv[c, f][r.visible[c, f]]
            assert len(b) == len(truth)
            d = np.linalg.norm(b.uv[:, None] - truth[None], axis=2)
            errs.append(d.min(axis=0))
    assert np.sqrt(np.mean(np.concatenate(errs) ** 2)) < 0.05
    below = r.render(1, 5)
    assert below.max() < 30                      # nothing but background and noise


def test_top_face_visibility_follows_the_disc_normal(renderer):
    r = renderer
    top = -quat_to_matrix(r.states[:, 6:10])[:, :, 2]
    for c, rc in enumerate(r.spec.cameras):
        v = rc.camera.center - r.xyz[:, 0]
        elev = np.degrees(np.arcsin(np.sum(v * top, axis=1) / np.linalg.norm(v, axis=1)))
        assert np.array_equal(r.visible[c, :, 0], elev > 5.0)


def test_frame_offsets_and_dropped_frames(tmp_path):
    spec = small_spec(drop_rate=0.2)
    r = Renderer(spec)
    assert r.dropped.any()
    first, last = r.frame_range(2)
    assert (first, last) == (0, spec.n_frames - 1 - 2)
    assert not r.recorded[2, :2].any() and r.recorded[2, 2:].all()
    for c in range(3):
        for i in range(*r.frame_range(c)):
            f = i + spec.cameras[c].frame_offset
            assert (r.render(c, i) is None) == bool(r.dropped[c, f])
    sources = r.write_footage(tmp_path, "png", progress=False)
    for c, name in enumerate(r.camera_names):
        files = sorted((tmp_path / name).glob("*.png"))
        first, last = r.frame_range(c)
        n_dropped = int(r.dropped[c, first + spec.cameras[c].frame_offset:last + spec.cameras[c].frame_offset + 1].sum())
        assert len(files) == last - first + 1 - n_dropped
        assert sources[name] == f"{name}/{name}_%06d.png"


def test_saturation_and_motion_blur():
    r = Renderer(small_spec(peak=900, noise_sigma=0.0))
    img = r.render(0, 10)
    assert img.max() == 255
    b = detect_full(img, DetectionConfig(threshold=30))
    assert len(b) == 3 and np.all(b.flags & SATURATED)
    assert np.linalg.norm(b.uv[:, None] - r.uv[0, 10][None], axis=2).min(axis=0).max() < 0.1
    # a 4 ms exposure smears each marker along its image motion
    r = Renderer(small_spec(exposure_s=0.004, blur_samples=9, noise_sigma=0.0))
    b = detect_full(r.render(0, 10), DetectionConfig(threshold=15, max_elongation=1.5))
    assert len(b) == 3 and np.all(b.flags & ELONGATED) and not np.any(b.flags & SATURATED)
    motion = r.uv_sub[0, 10, -1] - r.uv_sub[0, 10, 0]
    assert np.all(np.linalg.norm(motion, axis=1) > 3)
    d = np.linalg.norm(b.uv[:, None] - r.uv[0, 10][None], axis=2).min(axis=0)
    assert d.max() < 0.1  # the blurred blob's centroid is the mean position over the exposure


def test_write_truth_files(tmp_path, renderer):
    renderer.write_truth(tmp_path / "truth.csv")
    renderer.write_truth_2d(tmp_path / "truth_2d.csv")
    rows = list(csv.DictReader(open(tmp_path / "truth.csv")))
    assert len(rows) == renderer.spec.n_frames * 3
    assert {int(r["n_cameras"]) for r in rows} <= {0, 1, 2}
    rows2 = list(csv.DictReader(open(tmp_path / "truth_2d.csv")))
    late = [r for r in rows2 if r["camera"] == "late"]
    assert all(int(r["camera_frame"]) == int(r["frame"]) - 2 for r in late)
    assert all(r["recorded"] == "0" for r in late if int(r["frame"]) < 2)


def test_render_config(tmp_path):
    cfg = {"seed": 1, "fps": 100, "flight": {"name": "x", "duration": 0.1, "attitude_deg": {"pitch": 5}},
           "cameras": {"a": {"position": [1, -3, 3], "look_at": [0.6, 0, 1.2], "focal_px": 600,
                             "image_size": [320, 256], "dist": [-0.1, 0.01, 0, 0, 0]},
                       "b": {"position": [1, 3, 3], "look_at": [0.6, 0, 1.2], "focal_px": 600,
                             "image_size": [320, 256], "frame_offset": 1}},
           "imaging": {"noise_region": "windows"}, "output": {"folder": "out", "footage": "avi"}}
    (tmp_path / "r.yaml").write_text(yaml.safe_dump(cfg))
    spec, out = parse_render_config(tmp_path / "r.yaml")
    assert spec.n_frames == 11 and out.folder == tmp_path / "out" and out.footage_format == "avi"
    info = run_render(tmp_path / "r.yaml", progress=False)
    assert (tmp_path / "out" / "footage" / "a.avi").is_file() and (tmp_path / "out" / "cameras.yaml").is_file()
    assert info["cameras"]["b"]["frame_offset"] == 1
    cfg["imaging"]["noise_regoin"] = "full"
    (tmp_path / "bad.yaml").write_text(yaml.safe_dump(cfg))
    with pytest.raises(VideoInputError, match=r"'imaging\.noise_regoin': unknown key"):
        parse_render_config(tmp_path / "bad.yaml")
    del cfg["imaging"]["noise_regoin"]
    cfg["cameras"]["a"]["dist"] = [0.1, 0.2, 0.3]
    (tmp_path / "bad.yaml").write_text(yaml.safe_dump(cfg))
    with pytest.raises(VideoInputError, match=r"cameras\.a.*distortion"):
        parse_render_config(tmp_path / "bad.yaml")
