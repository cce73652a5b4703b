"""Marker identity: labelling on the scalene triangle, ambiguity → NaN, tracking without swaps."""
from __future__ import annotations

import numpy as np
import pytest

from bayes_disc.physics import literature_coefficients, simulate
from bayes_disc.physics.frames import quat_to_matrix
from bayes_disc.video.camera import look_at
from bayes_disc.video.identity import IdentityConfig, Tracker, kabsch, label_frame, layout_distinctness

LAYOUT = np.array([[0.100, 0.000, -0.015], [-0.0308, 0.0846, -0.015], [-0.0707, -0.0778, -0.015]])


def rig():
    return [look_at("a", [7.5, -12, 7], [7.5, -0.7, 1.5], 950, (1280, 1024), dist=[-0.12, 0.05, 0, 0, 0]),
            look_at("b", [7.5, 11, 8], [7.5, -0.7, 1.5], 950, (1280, 1024)),
            look_at("c", [-4, -3, 6], [8, -0.7, 1.5], 1000, (1280, 1024), dist=[0.04, 0, 0, 0, 0])]


@pytest.fixture(scope="module")
def flight():
    """Marker positions (n, 3, 3) of a spinning throw at 120 Hz."""
    q = np.array([0.0, 1.0, 0.0, 0.0])
    y0 = np.r_[0, 0, 1.2, 13, 0, 1.5, q, 0, 0, 55.0]
    t = np.arange(0, 1.2, 1 / 120)
    tr = simulate(y0, literature_coefficients("hummel2002").as_array(), t, marker_body=LAYOUT)
    return tr.markers[0], tr.states[0]


def pose(X, yaw=0.5):
    """Markers of a flat, right-side-up disc (b3 down) centred at X, turned by ``yaw`` about z."""
    c, s = np.cos(yaw), np.sin(yaw)
    A = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]]) @ np.diag([1.0, -1.0, -1.0])
    return LAYOUT @ A.T + X


def observe(cams, X, rng, noise=0.05, drop=None, clutter=0):
    out = []
    for c, cam in enumerate(cams):
        uv = cam.project(X) + rng.normal(0, noise, (len(X), 2))
        keep = np.ones(len(X), bool) if drop is None else ~drop[c]
        uv = uv[keep]
        if clutter:
            uv = np.vstack([uv, rng.uniform([100, 100], [1180, 924], (clutter, 2))])
        out.append(uv[rng.permutation(len(uv))])
    return out


def test_labels_from_side_lengths_without_prediction(rng):
    cams = rig()
    cfg = IdentityConfig()
    for k in range(20):
        X = pose(np.array([rng.uniform(1, 14), rng.uniform(-1.5, 0.5), rng.uniform(1, 2.5)]), yaw=rng.uniform(0, 6.3))
        # tilt the disc by up to 20° about a random horizontal axis
        ax = np.r_[rng.normal(size=2), 0]
        half = np.radians(rng.uniform(-20, 20)) / 2
        R = quat_to_matrix(np.r_[np.cos(half), np.sin(half) * ax / np.linalg.norm(ax)])
        X = (X - X.mean(0)) @ R.T + X.mean(0)
        lab = label_frame(cams, observe(cams, X, rng, clutter=2), LAYOUT, cfg)
        assert np.all(lab.n_views == 3)
        assert np.abs(lab.xyz - X).max() < 3e-3


def test_two_markers_without_prediction_are_left_nan_and_with_prediction_labelled(rng):
    cams = rig()
    cfg = IdentityConfig()
    X = pose(np.array([6.0, -0.5, 1.6]))
    drop = np.zeros((3, 3), bool)
    drop[:, 2] = True  # marker 2 hidden everywhere
    lab = label_frame(cams, observe(cams, X, rng, drop=drop), LAYOUT, cfg)
    assert np.all(np.isnan(lab.xyz)) and lab.ambiguous[:2].all()
    # a prediction (as from the tracker) 1 cm off resolves the order
    pred = X + rng.normal(0, 0.006, X.shape)
    lab = label_frame(cams, observe(cams, X, rng, drop=drop), LAYOUT, cfg, pred, np.full(3, 0.01))
    assert np.abs(lab.xyz[:2] - X[:2]).max() < 3e-3 and np.isnan(lab.xyz[2]).all()


def test_single_view_markers_stay_nan(rng):
    cams = rig()
    X = pose(np.array([8.0, -0.6, 1.7]))
    seps = [np.min(np.linalg.norm(c.project(X)[:, None] - c.project(X)[None], axis=2)[np.triu_indices(3, 1)])
            for c in cams]
    assert min(seps) > 4  # no marker hides behind another in any view
    drop = np.zeros((3, 3), bool)
    drop[1:, 1] = True  # marker 1 only in camera a
    # without a prediction the two triangulated markers cannot be told apart (one side length)
    lab = label_frame(cams, observe(cams, X, rng, drop=drop), LAYOUT, IdentityConfig())
    assert np.isnan(lab.xyz).all()
    # with one, they are labelled and the single-view marker stays NaN
    pred = X + rng.normal(0, 0.005, X.shape)
    lab = label_frame(cams, observe(cams, X, rng, drop=drop), LAYOUT, IdentityConfig(), pred, np.full(3, 0.01))
    assert np.isnan(lab.xyz[1]).all() and lab.n_views[1] == 0
    assert np.abs(lab.xyz[[0, 2]] - X[[0, 2]]).max() < 3e-3


def test_tracking_a_spinning_disc_without_swaps(rng, flight):
    """Random per-camera dropouts (15 %) and clutter blobs: no identity swaps; a marker is NaN only
    where fewer than two cameras saw it or its identity could not be told."""
    X, _ = flight
    cams = rig()
    cfg = IdentityConfig()
    trk = Tracker(LAYOUT, cfg)
    out = np.full_like(X, np.nan)
    n_seen = np.zeros(X.shape[:2], int)
    for f in range(len(X)):
        drop = rng.random((3, 3)) < 0.15
        n_seen[f] = 3 - drop.sum(0)
        pred, s = trk.predict(f)
        lab = label_frame(cams, observe(cams, X[f], rng, drop=drop, clutter=1), LAYOUT, cfg, pred, s)
        trk.update(f, lab.xyz)
        out[f] = lab.xyz
    ok = np.all(np.isfinite(out), axis=2)
    assert not np.any(ok & (n_seen < 2))
    d = np.linalg.norm(out[:, :, None, :] - X[:, None, :, :], axis=3)
    nearest = np.argmin(np.where(np.isfinite(d), d, np.inf), axis=2)
    assert np.sum(ok & (nearest != np.arange(3))) == 0           # no swaps
    assert np.nanmax(np.linalg.norm(out - X, axis=2)) < 5e-3
    assert ok[n_seen >= 2].mean() > 0.97                          # almost everything seen twice is labelled


def test_tracker_prediction_follows_the_spin(flight):
    X, states = flight
    cfg = IdentityConfig()
    trk = Tracker(LAYOUT, cfg)
    errs = []
    for f in range(len(X) - 1):
        trk.update(f, X[f])
        if f >= 1:
            pred, s = trk.predict(f + 1)
            errs.append(np.abs(pred - X[f + 1]).max())
    # spin moves a marker 4.6 cm per frame; the rigid constant-velocity prediction is within 2 mm
    assert max(errs) < 2e-3
    assert np.linalg.norm(X[1] - X[0], axis=1).max() > 0.1


def test_kabsch_recovers_pose(rng):
    A = np.linalg.qr(rng.normal(size=(3, 3)))[0]
    A *= np.sign(np.linalg.det(A))
    c = rng.normal(size=3)
    R, t, rms = kabsch(LAYOUT, LAYOUT @ A.T + c)
    assert np.allclose(R, A) and np.allclose(t, c) and rms < 1e-12


def test_layout_distinctness_and_an_isosceles_layout(rng):
    """The side lengths identify the markers only for a scalene layout: an isosceles triangle leaves its
    two base markers unlabelled in every frame without a prediction, and its distinctness is 0."""
    d = np.linalg.norm(LAYOUT[:, None] - LAYOUT[None], axis=2)
    sides = np.array([d[0, 1], d[0, 2], d[1, 2]])
    # for a triangle the closest relabelling swaps two markers: two sides exchange
    expected = np.sqrt(2) * np.min(np.abs(sides[:, None] - sides[None, :])[np.triu_indices(3, 1)])
    assert layout_distinctness(LAYOUT) == pytest.approx(expected, rel=1e-12)
    assert layout_distinctness(LAYOUT) > IdentityConfig().side_sigma_m * 3
    iso = np.array([[0.100, 0.0, -0.015], [-0.05, 0.07, -0.015], [-0.05, -0.07, -0.015]])  # |01| = |02|
    square = np.array([[0.1, 0, 0], [0, 0.1, 0], [-0.1, 0, 0], [0, -0.1, 0]])
    assert layout_distinctness(iso) < 1e-12 and layout_distinctness(square) < 1e-12
    assert layout_distinctness(square + rng.normal(0, 0.02, square.shape)) > 1e-3
    cams = rig()
    X = iso @ np.diag([1.0, -1.0, -1.0]) + np.array([7.0, -0.5, 1.6])  # right side up
    lab = label_frame(cams, observe(cams, X, rng), iso, IdentityConfig())
    assert np.abs(lab.xyz[0] - X[0]).max() < 3e-3                      # the apex is unique
    assert np.isnan(lab.xyz[1:]).all() and lab.ambiguous[1:].all()    # the base markers never are
