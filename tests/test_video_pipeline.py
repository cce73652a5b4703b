"""End to end: synthetic footage → TRACK.yaml → marker tracks; the CLI; configuration errors."""
from __future__ import annotations

import argparse
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import yaml

from bayes_disc.observation.markers import read_marker_csv
from bayes_disc.video.calibration import write_camera_yaml
from bayes_disc.video.camera import look_at
from bayes_disc.video.cli import main, register
from bayes_disc.video.errors import VideoInputError
from bayes_disc.video.pipeline import CameraInput, TrackConfig, parse_track_config, track_footage
from bayes_disc.video.render import Renderer
from bayes_disc.video.scenes import standard_spec

MARKERS = {"0": [0.100, 0.000, -0.015], "1": [-0.0308, 0.0846, -0.015], "2": [-0.0707, -0.0778, -0.015]}


def evaluate(result, renderer):
    """3-D RMS error [m], identity swaps, and NaN bookkeeping against the renderer's truth."""
    X, T = result.xyz, renderer.xyz
    err = np.linalg.norm(X - T, axis=2)
    ok = np.isfinite(err)
    d = np.linalg.norm(X[:, :, None, :] - T[:, None, :, :], axis=3)
    nearest = np.argmin(np.where(np.isfinite(d), d, np.inf), axis=2)
    swaps = int(np.sum(ok & (nearest != np.arange(X.shape[1]))))
    n_cam = renderer.seen.sum(axis=0)
    return dict(rms=float(np.sqrt(np.mean(err[ok] ** 2))), max=float(err[ok].max()), swaps=swaps,
                tracked_without_two_views=int(np.sum(ok & (n_cam < 2))),
                coverage=float(ok[n_cam >= 2].mean()), ok=ok)


def track_rendered(spec, roi=True, **identity):
    r = Renderer(spec)
    cfg = TrackConfig(path=Path("in-memory.yaml"), flight=spec.flight.name, fps=spec.fps, t0=spec.t0,
                      markers=spec.markers, cameras=dict(zip(r.camera_names, r.cameras)),
                      inputs=[CameraInput(n, "", rc.frame_offset) for n, rc in zip(r.camera_names, spec.cameras)],
                      roi=roi)
    res = track_footage(cfg, sources={n: r.source(c) for c, n in enumerate(r.camera_names)}, progress=False)
    return r, res


def test_end_to_end_synthetic_footage(tmp_path):
    """3 cameras, 120 Hz, 1280×1024, a 15 m flight with distortion, motion blur, noise, saturation,
    frame offsets and dropped frames: 3-D RMS ≤ 1 mm against truth, no identity swaps, NaN gaps only."""
    spec = standard_spec(seed=11, drop_rate=0.03)
    r, res = track_rendered(spec)
    assert spec.cameras[0].camera.image_size == (1280, 1024) and spec.fps == 120
    assert r.xyz[-1, :, 0].mean() - r.xyz[0, :, 0].mean() > 15.0
    assert r.dropped.any() and (r.visible & r.recorded[:, :, None] & r.dropped[:, :, None]).any()
    m = evaluate(res, r)
    assert m["rms"] <= 1e-3, m
    assert m["swaps"] == 0
    assert m["tracked_without_two_views"] == 0
    assert m["coverage"] > 0.95
    assert res.stats["ROI detections"] > res.stats["full-frame detections"]
    # covariance is calibrated against the actual errors (χ²(3) mean 3)
    e = (res.xyz - r.xyz)[m["ok"]]
    chi2 = np.einsum("pi,pij,pj->p", e, np.linalg.inv(res.cov[m["ok"]]), e)
    assert 1.5 < chi2.mean() < 6
    # the written file is a valid marker file (docs/data-formats.md) with the extra columns
    res.write(tmp_path / "tracks.csv")
    table = read_marker_csv(tmp_path / "tracks.csv", list(MARKERS))
    assert {"reproj_rms_px", "n_views", "cov_xx", "cov_yz"} <= set(table.extra)
    assert len(table) == 3 * spec.n_frames
    assert np.array_equal(np.all(np.isfinite(table.xyz), axis=1), m["ok"].ravel())


@pytest.mark.slow
@pytest.mark.parametrize("roi", [True, False])
def test_end_to_end_full_frame_noise(roi):
    """Noise over the whole 1280×1024 frame (σ = 2 DN), with and without ROI mode."""
    spec = standard_spec(seed=5, noise_region="full", noise_sigma=2.0, drop_rate=0.02)
    r, res = track_rendered(spec, roi=roi)
    m = evaluate(res, r)
    assert m["rms"] <= 1e-3 and m["swaps"] == 0 and m["tracked_without_two_views"] == 0 and m["coverage"] > 0.95


def small_render_config(folder: Path, footage="png") -> Path:
    cfg = {
        "seed": 4, "fps": 120,
        "flight": {"name": "short", "position": [0, 0, 1.2], "velocity": [12, 0, 1.0],
                   "attitude_deg": {"pitch": 5}, "omega_body": [0, 0, 50], "duration": 0.3},
        "markers": MARKERS,
        "cameras": {
            "A": {"position": [2.0, -5.0, 4.0], "look_at": [2.0, 0, 1.3], "focal_px": 560, "image_size": [640, 512],
                  "dist": [-0.1, 0.02, 0, 0, 0]},
            "B": {"position": [2.0, 5.0, 4.5], "look_at": [2.0, 0, 1.3], "focal_px": 560, "image_size": [640, 512],
                  "frame_offset": 1},
            "C": {"position": [-2.5, -1.0, 3.5], "look_at": [2.5, 0, 1.3], "focal_px": 520, "image_size": [640, 512]}},
        "imaging": {"noise_region": "windows", "drop_rate": 0.03, "peak": 170},
        "output": {"folder": ".", "footage": footage},
    }
    path = folder / "render.yaml"
    path.write_text(yaml.safe_dump(cfg))
    return path


def small_track_config(folder: Path, sources: dict, **changes) -> Path:
    cfg = {"flight": "short", "fps": 120, "markers": MARKERS,
           "calibration": {"format": "bayes-disc", "file": "cameras.yaml"},
           "cameras": {k: dict(v) for k, v in sources.items()}, "output": "tracks.csv"}
    cfg.update(changes)
    path = folder / "track.yaml"
    path.write_text(yaml.safe_dump(cfg))
    return path


@pytest.mark.parametrize("footage", ["png", "avi"])
def test_cli_render_then_track(tmp_path, footage):
    assert main(["render", str(small_render_config(tmp_path, footage)), "-q"]) == 0
    assert (tmp_path / "cameras.yaml").is_file() and (tmp_path / "truth.csv").is_file()
    ext = {"png": "A/A_%06d.png", "avi": "A.avi"}[footage]
    assert (tmp_path / "footage" / (ext % 0 if "%" in ext else ext)).exists()
    src = {"png": lambda n: f"footage/{n}/{n}_%06d.png", "avi": lambda n: f"footage/{n}.avi"}[footage]
    cams = {"A": {"source": src("A")}, "B": {"source": src("B"), "frame_offset": 1}, "C": {"source": src("C")}}
    frames = {"frames": [0, 36]}  # a video starts at camera frame 0, so say where the flight is
    assert main(["track", str(small_track_config(tmp_path, cams, **frames)), "-q"]) == 0
    got = read_marker_csv(tmp_path / "tracks.csv", list(MARKERS))
    truth = read_marker_csv(tmp_path / "truth.csv", list(MARKERS))
    assert np.array_equal(got.t, truth.t) and np.array_equal(got.marker, truth.marker)
    ok = np.all(np.isfinite(got.xyz), axis=1)
    n_cam = truth.extra["n_cameras"].astype(int)
    assert not np.any(ok & (n_cam < 2))
    assert ok[n_cam >= 2].mean() > 0.9
    err = np.linalg.norm(got.xyz[ok] - truth.xyz[ok], axis=1)
    assert np.sqrt(np.mean(err ** 2)) < 1e-3 and err.max() < 3e-3


def test_track_config_errors(tmp_path, capsys):
    cams = [look_at(n, [2, y, 4], [2, 0, 1.3], 560, (640, 512)) for n, y in (("A", -5), ("B", 5))]
    write_camera_yaml(tmp_path / "cameras.yaml", cams)
    (tmp_path / "A").mkdir()
    (tmp_path / "A" / "x_000001.png").write_bytes(b"")
    good = {"A": {"source": "A/x_%06d.png"}, "B": {"source": "A/x_%06d.png"}}
    cases = [
        ({"detection": {"treshold": 3}}, r"key 'detection\.treshold': unknown key"),
        ({"colour": "red"}, r"key 'colour': unknown key"),
        ({"calibration": {"format": "bayes-disc", "file": "nope.yaml"}}, r"key 'calibration\.file': file not found"),
        ({"cameras": {"A": {"source": "A/x_%06d.png"}, "Z": {"source": "A/x_%06d.png"}}},
         r"key 'cameras\.Z': camera 'Z' is not in the calibration"),
        ({"fps": -5}, r"key 'fps': must be positive"),
        ({"markers": {"0": [0, 0, 0], "1": [0.1, 0, 0]}}, r"key 'markers'"),
        # isosceles to within 1 mm: the side lengths cannot tell markers 1 and 2 apart
        ({"markers": {"0": [0.1, 0, -0.015], "1": [-0.05, 0.07, -0.015], "2": [-0.0495, -0.0707, -0.015]}},
         r"key 'markers': the layout is \(nearly\) symmetric"),
        ({"triangulation": {"pixel_sigma": "big"}}, r"key 'triangulation\.pixel_sigma'"),
        ({"calibration": {"format": "opencv-xml", "file": "cameras.yaml"}}, r"key 'calibration\.format'"),
        ({"timestamps": {"convention": "exposure-start"}}, r"key 'timestamps\.exposure_s': is required"),
        ({"timestamps": {"convention": "end"}}, r"key 'timestamps\.convention'"),
        ({"sync": {"max_offset": 0}}, r"key 'sync\.max_offset'"),
        ({"checks": {"action": "ignore"}}, r"key 'checks\.action'"),
        ({"cameras": {"A": {"source": "A/x_%06d.png", "frame_offset": "late"}, "B": {"source": "A/x_%06d.png"}}},
         r"key 'cameras\.A\.frame_offset'"),
    ]
    for change, message in cases:
        path = small_track_config(tmp_path, good, **change)
        with pytest.raises(VideoInputError, match=message):
            parse_track_config(path)
    # through the stand-alone CLI: one line on stderr, exit 2
    path = small_track_config(tmp_path, good, detection={"treshold": 3})
    assert main(["track", str(path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "detection.treshold" in err[0] and str(path) in err[0]
    (tmp_path / "broken.yaml").write_text("flight: [unclosed\n")
    with pytest.raises(VideoInputError, match="not valid YAML"):
        parse_track_config(tmp_path / "broken.yaml")
    with pytest.raises(VideoInputError, match="file not found"):
        parse_track_config(tmp_path / "absent.yaml")


def test_frame_offsets_timestamps_and_checks_in_the_track_config(tmp_path):
    """A camera without ``frame_offset`` has it estimated (None), a fraction is a sub-frame delay; the
    timestamp convention sets the time from a frame's stamp to the middle of its exposure."""
    cams = [look_at(n, [2, y, 4], [2, 0, 1.3], 560, (640, 512)) for n, y in (("A", -5), ("B", 5))]
    write_camera_yaml(tmp_path / "cameras.yaml", cams)
    (tmp_path / "A").mkdir()
    (tmp_path / "A" / "x_000001.png").write_bytes(b"")
    sources = {"A": {"source": "A/x_%06d.png"}, "B": {"source": "A/x_%06d.png", "frame_offset": 2.25}}
    cfg = parse_track_config(small_track_config(tmp_path, sources))
    assert [i.frame_offset for i in cfg.inputs] == [None, 2.25]
    assert cfg.timestamps == "mid-exposure" and cfg.time_shift == 0.0
    assert cfg.sync.max_offset == 10 and cfg.sync.tau_px is None and cfg.sync.subframe
    assert cfg.checks.action == "inflate" and cfg.pixel_sigma is None
    assert cfg.detection.merge_flux_ratio is None and cfg.detection.gain is None
    cfg = parse_track_config(small_track_config(
        tmp_path, sources, timestamps={"convention": "exposure-start", "exposure_s": 0.002},
        sync={"max_offset": 4, "tau_px": 2.5, "subframe": False}, checks={"action": "drop", "layout_sigma_m": 0.0005},
        detection={"gain": 4.0, "merge_flux_ratio": 1.6}))
    assert cfg.time_shift == pytest.approx(0.001)
    assert (cfg.sync.max_offset, cfg.sync.tau_px, cfg.sync.subframe) == (4, 2.5, False)
    assert cfg.checks.action == "drop" and cfg.checks.layout_sigma_m == 0.0005
    assert cfg.detection.gain == 4.0 and cfg.detection.merge_flux_ratio == 1.6


def test_register_adds_subcommands():
    parser = argparse.ArgumentParser(prog="bayes-disc")
    sub = parser.add_subparsers(dest="command", required=True)
    register(sub)
    a = parser.parse_args(["track", "T.yaml", "-o", "x.csv"])
    assert a.config == "T.yaml" and a.output == "x.csv" and callable(a.func)
    b = parser.parse_args(["render", "R.yaml"])
    assert b.config == "R.yaml" and callable(b.func) and b.func is not a.func
    c = parser.parse_args(["test-footage", "out", "--size", "small", "--frame-offsets", "0", "1", "3"])
    assert c.folder == "out" and c.frame_offsets == [0, 1, 3] and c.size == "small" and callable(c.func)


def test_control_point_calibration_in_track_config(tmp_path, rng):
    """calibration.format control-points: per-camera DLT from surveyed points (here exact projections
    of a known camera plus 0.1 px noise), with the residual report."""
    true = {"A": look_at("A", [2, -5, 4], [2, 0, 1.3], 560, (640, 512)),
            "B": look_at("B", [2, 5, 4.5], [2, 0, 1.3], 560, (640, 512))}
    pts = rng.uniform([0, -1, 0], [4, 1, 2.5], (12, 3))
    lines = ["point,x,y,z"] + [f"p{i},{x},{y},{z}" for i, (x, y, z) in enumerate(pts)]
    (tmp_path / "control.csv").write_text("\n".join(lines) + "\n")
    for name, cam in true.items():
        uv = cam.project(pts) + rng.normal(0, 0.1, (12, 2))
        rows = ["point,u,v"] + [f"p{i},{u},{v}" for i, (u, v) in enumerate(uv) if i != 3 or name == "A"]
        (tmp_path / f"{name}.csv").write_text("\n".join(rows) + "\n")
    calib = {"format": "control-points", "points": "control.csv", "image_points": {"A": "A.csv", "B": "B.csv"},
             "image_size": [640, 512], "write": "calibrated.yaml"}
    path = small_track_config(tmp_path, {"A": {"source": "A"}, "B": {"source": "A"}}, calibration=calib)
    cfg = parse_track_config(path)
    for name, cam in true.items():
        assert np.linalg.norm(cfg.cameras[name].center - cam.center) < 0.05
        assert np.abs(cfg.cameras[name].project(pts) - cam.project(pts)).max() < 0.5
    assert "leave-one-out" in cfg.calibration_report and "11 control points" in cfg.calibration_report
    assert (tmp_path / "calibrated.yaml").is_file()


def test_image_sequence_specs_and_median_background(tmp_path):
    """Sources as printf pattern, glob or folder give the same frames (numbered from the file names);
    ``background: median`` removes a static light that would otherwise be detected in every frame."""
    from bayes_disc.video.footage import ArrayFrames, ImageSequence, open_source
    import cv2

    assert main(["render", str(small_render_config(tmp_path)), "-q"]) == 0
    a = open_source("footage/A/A_%06d.png", tmp_path)
    b = open_source("footage/A/*.png", tmp_path)
    c = open_source("footage/A", tmp_path)
    assert isinstance(a, ImageSequence) and a.files == b.files == c.files
    i = a.first + 5
    assert np.array_equal(a.get(i), c.get(i)) and a.get(10_000) is None
    with pytest.raises(VideoInputError, match="no image files"):
        open_source("footage/A/*.tif", tmp_path)

    lamp = np.zeros((512, 640), np.uint8)
    lamp[400:430, 50:120] = 150
    spec_path = small_track_config(tmp_path, {n: {"source": f"footage/{n}/{n}_%06d.png", **({"frame_offset": 1} if n == "B" else {})}
                                              for n in "ABC"})
    cfg = parse_track_config(spec_path)
    truth = read_marker_csv(tmp_path / "truth.csv", list(MARKERS))
    results = {}
    for bg in ("none", "median"):
        srcs = {}
        for inp in cfg.inputs:
            seq = open_source(inp.source, tmp_path)
            srcs[inp.name] = ArrayFrames(lambda k, seq=seq: None if seq.get(k) is None else cv2.add(seq.get(k), lamp),
                                         seq.first, seq.last)
        results[bg] = track_footage(replace(cfg, background=bg, roi=False), sources=srcs, progress=False)
    assert results["none"].stats["blobs"] - results["median"].stats["blobs"] >= 3 * 30  # a lamp per frame and camera
    for res in results.values():
        got = res.xyz.reshape(-1, 3)
        ok = np.all(np.isfinite(got), axis=1)
        assert ok.mean() > 0.8
        assert np.sqrt(np.mean(np.sum((got[ok] - truth.xyz[ok]) ** 2, axis=1))) < 1e-3


def test_committed_video_demo_tracks_match_truth():
    """runs/video_demo/tracks.csv (made by make_demo.sh from the rendered footage) against truth.csv:
    3-D RMS ≤ 1 mm, no identity swaps, no point from fewer than two cameras, ≥ 98 % of the rest tracked."""
    demo = Path(__file__).resolve().parents[1] / "runs" / "video_demo"
    truth = read_marker_csv(demo / "truth.csv", list(MARKERS))
    got = read_marker_csv(demo / "tracks.csv", list(MARKERS))
    assert np.array_equal(got.t, truth.t) and np.array_equal(got.marker, truth.marker)
    X, T = got.xyz.reshape(-1, 3, 3), truth.xyz.reshape(-1, 3, 3)
    assert T[-1, :, 0].mean() - T[0, :, 0].mean() > 15.0
    err = np.linalg.norm(X - T, axis=2)
    ok = np.isfinite(err)
    d = np.linalg.norm(X[:, :, None, :] - T[:, None, :, :], axis=3)
    nearest = np.argmin(np.where(np.isfinite(d), d, np.inf), axis=2)
    n_cam = truth.extra["n_cameras"].astype(int).reshape(-1, 3)
    assert np.sqrt(np.mean(err[ok] ** 2)) <= 1e-3
    assert np.sum(ok & (nearest != np.arange(3))) == 0
    assert not np.any(ok & (n_cam < 2))
    assert ok[n_cam >= 2].mean() >= 0.98
    # the demo's TRACK.yaml reads (footage is not needed to parse it) with the frame offsets of the rendering
    from bayes_disc.video.render import parse_render_config

    cfg = parse_track_config(demo / "track.yaml")
    spec, _ = parse_render_config(demo / "render.yaml")
    assert {i.name: i.frame_offset for i in cfg.inputs} == {rc.camera.name: rc.frame_offset for rc in spec.cameras}
    assert cfg.output == demo / "tracks.csv"
