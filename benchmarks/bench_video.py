"""Detection speed of the video front end: frames per second per camera, full frame vs ROI mode.

Frames are rendered in memory (the demo rig: 3 cameras, 1280×1024, 8-bit, noise over the whole frame
unless ``--noise-region windows``) and detection is timed alone (no decoding, no identity or
triangulation). ROI mode searches windows around predicted marker positions, here the true positions
plus 1 px of prediction error. Each figure is the median over ``--repeats`` passes over the frames.

    PYTHONPATH=. python3 benchmarks/bench_video.py [--frames 60] [--repeats 5] [--json]
"""
from __future__ import annotations

import argparse
import json
import platform
import statistics
import time

import cv2
import numpy as np

from bayes_disc.video.detection import DetectionConfig, detect_full, detect_roi
from bayes_disc.video.render import Renderer
from bayes_disc.video.scenes import standard_spec

#: target: detection frames per second per camera in ROI mode
TARGET_ROI_FPS = 500.0


def _fps(fn, frames, repeats):
    rates = []
    for _ in range(repeats):
        t = time.perf_counter()
        for k, img in enumerate(frames):
            fn(k, img)
        rates.append(len(frames) / (time.perf_counter() - t))
    return statistics.median(rates), min(rates), max(rates)


def run(n_frames: int = 60, repeats: int = 5, noise_region: str = "full", seed: int = 0) -> dict:
    spec = standard_spec(seed=seed, noise_region=noise_region, noise_sigma=2.0, drop_rate=0.0)
    r = Renderer(spec)
    cfg = DetectionConfig()
    rng = np.random.default_rng(seed)
    out = {"config": {"frames_per_camera": n_frames, "repeats": repeats, "noise_region": noise_region,
                      "image_size": list(spec.cameras[0].camera.image_size), "threshold": cfg.threshold,
                      "roi_radius": cfg.roi_radius, "opencv": cv2.__version__, "opencv_threads": cv2.getNumThreads(),
                      "python": platform.python_version(), "machine": platform.machine()},
           "cameras": {}}
    for c, name in enumerate(r.camera_names):
        first, last = r.frame_range(c)
        mid = (first + last) // 2
        idx = [i for i in range(mid - n_frames // 2, mid - n_frames // 2 + n_frames) if first <= i <= last]
        frames, centres = [], []
        for i in idx:
            img = r.render(c, i)
            if img is None:
                continue
            f = i + spec.cameras[c].frame_offset
            frames.append(img)
            centres.append(r.uv[c, f][r.visible[c, f]] + rng.normal(0, 1.0, (int(r.visible[c, f].sum()), 2)))
        n_blobs = np.mean([len(detect_full(img, cfg)) for img in frames])
        full = _fps(lambda k, img: detect_full(img, cfg), frames, repeats)
        roi = _fps(lambda k, img: detect_roi(img, centres[k], cfg), frames, repeats)
        out["cameras"][name] = {"frames": len(frames), "blobs_per_frame": round(float(n_blobs), 2),
                                "full_frame_fps": {"median": round(full[0], 1), "min": round(full[1], 1), "max": round(full[2], 1)},
                                "roi_fps": {"median": round(roi[0], 1), "min": round(roi[1], 1), "max": round(roi[2], 1)}}
    slowest = min(v["roi_fps"]["median"] for v in out["cameras"].values())
    out["roi_target"] = {"fps": TARGET_ROI_FPS, "slowest_camera_median_fps": slowest, "met": slowest >= TARGET_ROI_FPS}
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=60, help="frames per camera (default 60)")
    ap.add_argument("--repeats", type=int, default=5, help="timed passes; the median is reported (default 5)")
    ap.add_argument("--noise-region", choices=("full", "windows"), default="full")
    ap.add_argument("--json", action="store_true", help="print JSON instead of a table")
    args = ap.parse_args(argv)
    res = run(args.frames, args.repeats, args.noise_region)
    if args.json:
        print(json.dumps(res, indent=2))
        return 0
    cfg = res["config"]
    print(f"detection speed, {cfg['image_size'][0]}×{cfg['image_size'][1]} px, noise {cfg['noise_region']}, "
          f"{cfg['frames_per_camera']} frames × {cfg['repeats']} repeats (median), OpenCV {cfg['opencv']}")
    print(f"{'camera':8s} {'blobs':>6s} {'full-frame fps':>15s} {'ROI fps':>10s}")
    for name, v in res["cameras"].items():
        print(f"{name:8s} {v['blobs_per_frame']:6.1f} {v['full_frame_fps']['median']:15.1f} {v['roi_fps']['median']:10.1f}")
    t = res["roi_target"]
    print(f"ROI target ≥ {t['fps']:g} frames/s per camera: {'met' if t['met'] else 'NOT met'} "
          f"(slowest camera {t['slowest_camera_median_fps']:.1f})")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
