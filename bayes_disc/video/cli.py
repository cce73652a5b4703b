"""Command-line subcommands ``track`` and ``render`` (registered into the main ``bayes-disc`` parser).

``bayes-disc track TRACK.yaml [-o OUT.csv] [--quiet]`` — footage or imported points → marker
file (docs/data-formats.md).
``bayes-disc render RENDER.yaml [-o FOLDER] [--quiet]`` — synthetic footage, camera file and truth.
``bayes-disc test-footage FOLDER [--size small|full] [--seed N] [--flight MARKERS.csv] ...`` — footage of a
known flight (analytic, or a simulated one given as a dense marker file) made by an imaging model
independent of ``render`` (DLT cameras, varying blobs, smear, occlusions, offsets), with a plain
``track.yaml`` and the truth, for checking a tracking setup.

Bad input raises :class:`~.errors.VideoInputError`; the main CLI prints it and exits with status 2.
``python -m bayes_disc.video ...`` runs the same subcommands on their own.
"""
from __future__ import annotations

import argparse
import sys

import numpy as np


def _track(args) -> int:
    from .pipeline import run_track

    result = run_track(args.config, output=args.output, progress=not args.quiet)
    if not args.quiet:
        print(result.summary(), file=sys.stderr)
    seen = np.all(np.isfinite(result.xyz), axis=2)
    if not seen.any():
        print(f"{args.config}: no marker was tracked in any frame (check detection.threshold, the "
              "calibration and the camera sources)", file=sys.stderr)
        return 1
    return 0


def _render(args) -> int:
    from .render import run_render

    info = run_render(args.config, output_dir=args.output, progress=not args.quiet)
    if not args.quiet:
        cams = ", ".join(f"{k} ({v['dropped_frames']} dropped)" for k, v in info["cameras"].items())
        print(f"rendered flight {info['flight']}: {info['n_frames']} frames at {info['fps']:g} Hz; cameras {cams}",
              file=sys.stderr)
    return 0


def _test_footage(args) -> int:
    from .testfootage import standard_test_spec, tabulated_flight_from_markers, write_test_footage

    given = {}
    if args.flight is not None:
        flight = tabulated_flight_from_markers(args.flight, args.flight_name)
        fps = 120.0
        # frame 0 a frame after the table starts and the last a frame before it ends: exposure smear and
        # sub-frame delays stay inside the table
        t0 = float(flight.times[0]) + 1.0 / fps
        given = dict(flight=flight, t0=t0, n_frames=int(np.floor((flight.times[-1] - t0) * fps + 1e-9)),
                     name=args.flight_name or "test_flight")
    spec = standard_test_spec(args.size, seed=args.seed, frame_offsets=tuple(args.frame_offsets),
                              subframes=tuple(args.subframes), timestamps=args.timestamps, **given)
    info = write_test_footage(spec, args.folder, progress=not args.quiet)
    if not args.quiet:
        offs = ", ".join(f"{n} {c['frame_offset']}{c['subframe']:+.2f}" for n, c in info["cameras"].items())
        print(f"wrote test footage of flight {info['flight']} ({info['n_frames']} frames, frame offsets {offs}) "
              f"into {args.folder}: run bayes-disc track {args.folder}/track.yaml and compare with truth.csv",
              file=sys.stderr)
    return 0


def register(subparsers) -> None:
    """Add the ``track`` and ``render`` subcommands to an argparse subparsers object."""
    p = subparsers.add_parser("track", help="footage (or DLTdv/Argus points) + calibration → marker CSV "
                                            "(docs/data-formats.md)",
                              description="Detect, label and triangulate disc markers from multi-camera footage "
                                          "(see bayes_disc/video/README.md for TRACK.yaml).")
    p.add_argument("config", help="TRACK.yaml")
    p.add_argument("-o", "--output", help="marker file to write (default: the config's 'output')")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress bar or summary")
    p.set_defaults(func=_track)
    r = subparsers.add_parser("render", help="synthetic multi-camera footage of a simulated flight, with truth",
                              description="Render synthetic marker footage (pinhole cameras with distortion, "
                                          "blur, noise, saturation, occlusion, dropped frames) and its ground truth.")
    r.add_argument("config", help="RENDER.yaml")
    r.add_argument("-o", "--output", help="output folder (default: the config's output.folder)")
    r.add_argument("-q", "--quiet", action="store_true", help="no progress bar or summary")
    r.set_defaults(func=_render)
    t = subparsers.add_parser("test-footage", help="footage of a known flight from an independent imaging model, "
                                                   "with a plain track.yaml and the truth",
                              description="Write three cameras' image sequences of a known flight (DLT cameras, "
                                          "blob widths and brightness varying between frames and markers, exposure "
                                          "smear, a bright patch, occluding poles, read and shot noise, a camera "
                                          "starting late), their DLT calibration, a plain track.yaml and truth.csv / "
                                          "truth_2d.csv / truth.json (see bayes_disc/video/README.md).")
    t.add_argument("folder", help="output folder")
    t.add_argument("--size", choices=("small", "full"), default="full",
                   help="full: 1280×1024 px, 151 frames; small: 640×512 px, 48 frames (default: full)")
    t.add_argument("--seed", type=int, default=1, help="random seed (default 1)")
    t.add_argument("--frame-offsets", type=int, nargs=3, default=[0, 0, 2], metavar="K",
                   help="integer frame offset of each of the three cameras (default 0 0 2)")
    t.add_argument("--subframes", type=float, nargs=3, default=[0.0, 0.0, 0.0], metavar="D",
                   help="sub-frame delay of each camera in frames, |D| ≤ 0.5 (default 0 0 0)")
    t.add_argument("--timestamps", choices=("mid-exposure", "exposure-start"), default="mid-exposure",
                   help="what a frame's time stamp marks (default mid-exposure)")
    t.add_argument("--flight", metavar="MARKERS.csv",
                   help="film this flight instead of the analytic one: a marker file sampled densely and without "
                        "noise or gaps (bayes-disc synth with sample_rate_hz: 2400, noise_mm: 0, dropout: 0), markers "
                        "0, 1, 2 at the default layout")
    t.add_argument("--flight-name", metavar="NAME", help="which flight of --flight's file (needed if it holds several)")
    t.add_argument("-q", "--quiet", action="store_true", help="no progress bar or summary")
    t.set_defaults(func=_test_footage)


def main(argv=None) -> int:
    """Stand-alone entry point (``python -m bayes_disc.video``)."""
    from .errors import VideoInputError

    parser = argparse.ArgumentParser(prog="bayes-disc")
    sub = parser.add_subparsers(dest="command", required=True)
    register(sub)
    args = parser.parse_args(argv)
    try:
        return args.func(args)
    except VideoInputError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
