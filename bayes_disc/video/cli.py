"""Command-line subcommands ``track`` and ``render`` (registered into the main ``bayes-disc`` parser).

``bayes-disc track TRACK.yaml [-o OUT.csv] [--quiet]`` — footage or imported points → marker
file (docs/data-formats.md).
``bayes-disc render RENDER.yaml [-o FOLDER] [--quiet]`` — synthetic footage, camera file and truth.

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
