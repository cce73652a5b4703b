"""Camera synchronisation from the footage: integer frame offsets from epipolar consistency, a first guess
of sub-frame delays from the blobs' own tracks, the configuration's offsets kept as given."""
from __future__ import annotations

import numpy as np
import pytest

from bayes_disc.video.calibration import DLTDV, camera_from_dlt
from bayes_disc.video.sync import (coarse_subframe, epipolar_distances, estimate_frame_offsets, moved_blobs,
                                   typical_motion)
from bayes_disc.video.testfootage import marker_positions, project, standard_test_spec


def blobs_of(spec, offsets, delays=(0.0, 0.0, 0.0), frames=60, clutter=0, rng=None):
    """Per camera {camera frame: projected marker positions} of the test flight: camera c's frame i shows
    reference frame i + offsets[c] + delays[c]; ``clutter`` random blobs per frame."""
    out = []
    for c, cam in enumerate(spec.cameras):
        found = {}
        for i in range(frames):
            t = (i + offsets[c] + delays[c]) / spec.fps
            if t < 0:
                continue
            uv, front = project(cam, marker_positions(spec, [t])[0][0])
            if clutter:
                uv = np.vstack([uv, rng.uniform([50, 50], [600, 450], (clutter, 2))])
            found[i] = uv
        out.append(found)
    return out


@pytest.fixture(scope="module")
def rig():
    spec = standard_test_spec("small")
    cams = [camera_from_dlt(c.dlt, c.name, c.image_size, DLTDV, 1e-3) for c in spec.cameras]
    return spec, cams, [c.name for c in spec.cameras]


def test_epipolar_distance_is_zero_for_the_same_point(rig):
    spec, cams, _ = rig
    X = marker_positions(spec, [0.1])[0][0]
    d = epipolar_distances(cams[0], cams[1], cams[0].project(X), cams[1].project(X))
    assert np.all(np.diag(d) < 1e-6) and np.all(d[~np.eye(3, dtype=bool)] > 0.05)


@pytest.mark.parametrize("offsets", [(0, 0, 2), (0, 3, -2), (4, 1, 0)])
def test_integer_offsets_are_found(rig, rng, offsets):
    """All three offsets unknown: found relative to the first camera (its offset is the reference, 0),
    with a clutter blob in every frame."""
    spec, cams, names = rig
    blobs = blobs_of(spec, offsets, clutter=1, rng=rng)
    res = estimate_frame_offsets(cams, names, blobs, {})
    rel = {n: k - offsets[0] for n, k in zip(names, offsets)}
    assert res.offsets == rel, (res.offsets, rel)
    assert res.source == {"camA": "reference", "camB": "estimated", "camC": "estimated"}
    for n in ("camB", "camC"):
        best, second = res.cost[n]
        assert second - best > 0.2                               # a clear minimum (clutter raises both)
    assert all("estimated from the footage" in m for m in res.messages)


def test_a_given_offset_is_kept_and_the_others_follow_it(rig):
    spec, cams, names = rig
    blobs = blobs_of(spec, (0, 3, -2))
    res = estimate_frame_offsets(cams, names, blobs, {"camB": 5})
    assert res.offsets == {"camA": 2, "camB": 5, "camC": 0} and res.source["camB"] == "config"


def test_no_overlap_is_an_error(rig):
    spec, cams, names = rig
    blobs = blobs_of(spec, (0, 0, 0), frames=10)
    blobs[2] = {i + 500: u for i, u in blobs[2].items()}
    with pytest.raises(ValueError, match="camC: no frames overlap"):
        estimate_frame_offsets(cams, names, blobs, {}, max_offset=5)


def test_sub_frame_delays_first_guess(rig):
    """Blobs moved along their own tracks: a delay of 0.3 frame is found on a 0.05 grid."""
    spec, cams, names = rig
    blobs = blobs_of(spec, (0, 0, 2), delays=(0.0, 0.3, -0.2))
    moved = moved_blobs(blobs[1], 0.3)
    exact = blobs_of(spec, (0, 0, 2))[1]
    err = [np.min(np.linalg.norm(moved[i][:, None] - exact[i][None], axis=2), axis=1) for i in range(2, 58)]
    assert np.percentile(np.concatenate(err), 95) < 0.2           # px, where the blob moved ~3 px
    assert typical_motion(blobs) > 5
    guess = coarse_subframe(cams, names, blobs, {"camA": 0, "camB": 0, "camC": 2}, [1, 2], 1.5)
    assert guess[1] == pytest.approx(0.3, abs=0.051) and guess[2] == pytest.approx(-0.2, abs=0.051)
