"""Compare tracked markers with the rendering's ground truth (run by make_demo.sh).

    python check_tracks.py [tracks.csv] [truth.csv] [--max-rms-mm 1.0]

Prints the 3-D RMS and maximum error [mm] over the tracked points, identity swaps (a tracked point
nearer to another marker's true position than to its own), the fraction of NaN points, points tracked
where fewer than two cameras saw the marker (must be 0: gaps are never filled) and the mean
Mahalanobis distance eᵀ Σ⁻¹ e of the errors under the file's covariance (3 when calibrated).
Exit status 1 if the RMS exceeds ``--max-rms-mm``, a swap occurs or a point is tracked from < 2 views.
"""
from __future__ import annotations

import argparse
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from bayes_disc.observation.markers import read_marker_csv

COV = (("cov_xx", 0, 0), ("cov_xy", 0, 1), ("cov_xz", 0, 2), ("cov_yy", 1, 1), ("cov_yz", 1, 2), ("cov_zz", 2, 2))


@dataclass
class TrackErrors:
    """rms_mm, max_mm: 3-D error over tracked points [mm]; swaps; nan_fraction of all points;
    nan_with_two_views: NaN points that ≥ 2 cameras saw; tracked_without_two_views; chi2_mean."""

    n_points: int
    rms_mm: float
    max_mm: float
    swaps: int
    nan_fraction: float
    nan_with_two_views: int
    tracked_without_two_views: int
    chi2_mean: float


def compare(tracks, truth) -> TrackErrors:
    """Errors of a tracks table against a truth table (same rows: frame-major, markers in order)."""
    if not (np.array_equal(tracks.t, truth.t) and np.array_equal(tracks.marker, truth.marker)):
        raise ValueError("tracks and truth do not have the same rows (t, marker)")
    markers = list(dict.fromkeys(truth.marker))
    M = len(markers)
    X, T = tracks.xyz.reshape(-1, M, 3), truth.xyz.reshape(-1, M, 3)
    err = np.linalg.norm(X - T, axis=2)
    ok = np.isfinite(err)
    d = np.linalg.norm(X[:, :, None, :] - T[:, None, :, :], axis=3)
    nearest = np.argmin(np.where(np.isfinite(d), d, np.inf), axis=2)
    n_cam = np.asarray(truth.extra["n_cameras"], float).reshape(-1, M)
    e = (X - T).reshape(-1, 3)[ok.ravel()]
    chi2 = np.full(1, np.nan)
    if len(e) and all(name in tracks.extra for name, _, _ in COV):
        cov = np.zeros((len(tracks.t), 3, 3))
        for name, i, j in COV:
            cov[:, i, j] = cov[:, j, i] = np.asarray(tracks.extra[name], float)
        chi2 = np.einsum("pi,pij,pj->p", e, np.linalg.inv(cov[ok.ravel()]), e)
    return TrackErrors(n_points=int(ok.size), rms_mm=float(1e3 * np.sqrt(np.mean(err[ok] ** 2))) if ok.any() else np.nan,
                       max_mm=float(1e3 * err[ok].max()) if ok.any() else np.nan,
                       swaps=int(np.sum(ok & (nearest != np.arange(M)))), nan_fraction=float(np.mean(~ok)),
                       nan_with_two_views=int(np.sum(~ok & (n_cam >= 2))),
                       tracked_without_two_views=int(np.sum(ok & (n_cam < 2))), chi2_mean=float(np.mean(chi2)))


def main(argv=None) -> int:
    here = Path(__file__).resolve().parent
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("tracks", nargs="?", default=str(here / "tracks.csv"))
    ap.add_argument("truth", nargs="?", default=str(here / "truth.csv"))
    ap.add_argument("--max-rms-mm", type=float, default=1.0)
    args = ap.parse_args(argv)
    truth = read_marker_csv(args.truth)
    r = compare(read_marker_csv(args.tracks, list(dict.fromkeys(truth.marker))), truth)
    print(f"{args.tracks}: 3-D error RMS {r.rms_mm:.3f} mm, max {r.max_mm:.3f} mm; identity swaps {r.swaps}; "
          f"NaN {100 * r.nan_fraction:.2f} % of {r.n_points} points ({r.nan_with_two_views} seen by ≥ 2 cameras); "
          f"tracked from < 2 cameras {r.tracked_without_two_views}; mean eᵀΣ⁻¹e {r.chi2_mean:.2f} (3 if calibrated)")
    bad = not (r.rms_mm <= args.max_rms_mm) or r.swaps or r.tracked_without_two_views
    if bad:
        print(f"check failed (RMS limit {args.max_rms_mm} mm, no swaps, no point from < 2 cameras)", file=sys.stderr)
    return 1 if bad else 0


if __name__ == "__main__":
    raise SystemExit(main())
