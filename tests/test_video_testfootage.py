"""Test footage from an imaging model independent of the renderer, and ``track`` scored against its truth.

The footage (:mod:`bayes_disc.video.testfootage`) has 11-coefficient DLT cameras, blob widths of 1.3–2 px
and brightness changing by about ×2 between frames and markers, exposure smear, a bright patch, occluding
poles, read and shot noise, and a camera starting two frames late. ``track`` runs with a plain
configuration (median background, no frame offsets) and is scored against the truth: the share of marker
positions seen by ≥ 2 cameras that are labelled, identity swaps, the share of labelled points outside their
own 99.9 % covariance ellipsoid, the 95th percentile of the 3-D error, and the frame offsets found.
"""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy.stats import chi2

from bayes_disc.observation.markers import flights_from_table, read_marker_csv
from bayes_disc.video.calibration import DLTDV, camera_from_dlt, cameras_from_dlt_csv
from bayes_disc.video.cli import main
from bayes_disc.video.pipeline import CameraInput, TrackConfig, track_footage
from bayes_disc.video.testfootage import (TabulatedFlight, TestFootage, marker_positions, project,
                                          standard_test_spec)

MARKERS = ["0", "1", "2"]
Q999 = chi2.ppf(0.999, 3)


def score(xyz, cov, truth, n_cameras) -> dict:
    """Scores of tracked points xyz (F, M, 3) with covariances (F, M, 3, 3) against truth (F, M, 3), for
    the positions seen by ``n_cameras`` (F, M) cameras."""
    err = np.linalg.norm(xyz - truth, axis=2)
    ok = np.isfinite(err)
    d = np.linalg.norm(xyz[:, :, None, :] - truth[:, None, :, :], axis=3)
    nearest = np.argmin(np.where(np.isfinite(d), d, np.inf), axis=2)
    e = (xyz - truth)[ok]
    m2 = np.einsum("pi,pij,pj->p", e, np.linalg.inv(cov[ok]), e)
    return {"labelled": float(ok[n_cameras >= 2].mean()), "swaps": int(np.sum(ok & (nearest != np.arange(xyz.shape[1])))),
            "outside": float(np.mean(m2 > Q999)), "p95_mm": 1e3 * float(np.percentile(err[ok], 95)),
            "mean_m2": float(m2.mean()), "n": int(ok.sum())}


def cameras_of(spec) -> dict:
    """The calibrated cameras of a spec, decomposed from its DLT coefficients as ``track`` does."""
    return {c.name: camera_from_dlt(c.dlt, c.name, c.image_size, DLTDV, 1e-3) for c in spec.cameras}


def track_in_memory(spec, given_offsets: bool = False, **config):
    footage = TestFootage(spec)
    inputs = [CameraInput(c.name, "", (c.frame_offset + c.subframe) if given_offsets else None) for c in spec.cameras]
    cfg = TrackConfig(path=Path("in-memory.yaml"), flight=spec.name, fps=spec.fps, t0=spec.t0, markers=spec.markers,
                      cameras=cameras_of(spec), inputs=inputs, background="median", **config)
    res = track_footage(cfg, sources={c.name: footage.source(k) for k, c in enumerate(spec.cameras)}, progress=False)
    return footage, res


# ---------------------------------------------------------------------------------------------------
# the footage itself
# ---------------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def small():
    return TestFootage(standard_test_spec("small", seed=3))


def test_footage_is_deterministic_in_its_seed(small):
    again = TestFootage(standard_test_spec("small", seed=3))
    other = TestFootage(standard_test_spec("small", seed=4))
    for c in range(3):
        assert np.array_equal(small.render(c, 10), again.render(c, 10))
        assert not np.array_equal(small.render(c, 10), other.render(c, 10))
    assert small.render(2, small.frame_range(2)[1] + 1) is None


def test_footage_has_what_it_promises(small):
    """Widths within 1.3–2 px and varying; brightness varying about ×2 over frames and markers; smear;
    partial and full occlusions by the poles; a bright patch; the third camera starting two frames late."""
    spec = small.spec
    vis = small.visible
    s = small.sigma_px[vis]
    assert s.min() >= 1.3 and s.max() <= 2.0 and s.max() - s.min() > 0.4
    flux = np.where(vis, small.flux, np.nan)
    assert np.nanmax(flux) / np.nanmin(flux) > 2.0                               # over frames and markers
    assert max(np.nanmax(flux[c]) / np.nanmin(flux[c]) for c in range(3)) > 1.5  # one camera alone
    smear = np.linalg.norm(small.uv_sub[:, :, -1] - small.uv_sub[:, :, 0], axis=-1)[vis]
    assert np.nanmax(smear) > 1.0
    occluded = vis & (small.unoccluded < 0.95)
    assert occluded[0].any() and occluded[1].any() and not occluded[2].any()
    assert np.any(vis & (small.unoccluded > 0.05) & (small.unoccluded < 0.95))   # partly hidden blobs too
    assert spec.cameras[0].patch is not None and small.scene(0).max() > 50 + spec.pedestal_dn
    assert not small.recorded[2, :2].any() and small.recorded[2, 2:].all() and small.recorded[:2].all()
    assert np.sum(small.seen.sum(axis=0) >= 2) > 0.9 * small.seen[0].size


def test_dlt_cameras_read_back_with_the_tracker_conventions(small, tmp_path):
    """The generator projects with its own DLT code in DLTdv pixels and mm; the tracker's DLT reader
    (bottom-left origin, first pixel 1, units mm) must give the same OpenCV pixels."""
    spec = small.spec
    path = tmp_path / "dlt.csv"
    path.write_text("\n".join(",".join(repr(float(c.dlt[k])) for c in spec.cameras) for k in range(11)) + "\n")
    cams = cameras_from_dlt_csv(path, [c.name for c in spec.cameras], {c.name: c.image_size for c in spec.cameras},
                                DLTDV, 1e-3)
    for c, tc in enumerate(spec.cameras):
        mine, front = project(tc, small.xyz)
        assert front.all()
        assert np.abs(cams[tc.name].project(small.xyz) - mine).max() < 1e-6


def test_exposure_start_stamps_shift_the_truth_by_half_an_exposure():
    a = standard_test_spec("small")
    b = standard_test_spec("small", timestamps="exposure-start")
    assert np.allclose(TestFootage(b).times - TestFootage(a).times, 0.5 * a.exposure_s)


# ---------------------------------------------------------------------------------------------------
# tracking it
# ---------------------------------------------------------------------------------------------------
def test_plain_config_on_test_footage_files(tmp_path):
    """Command line end to end on the small footage: ``test-footage`` writes files, ``track`` reads its plain
    track.yaml (DLT calibration in mm, no frame offsets). ≥ 97 % of the positions seen by ≥ 2 cameras are
    labelled, no swaps, ≤ 1 % of points outside their 99.9 % ellipsoid, p95 error ≤ 1.5 mm, and the frame
    offsets are found exactly."""
    folder = tmp_path / "footage"
    assert main(["test-footage", str(folder), "--size", "small", "-q"]) == 0
    assert main(["track", str(folder / "track.yaml"), "-q"]) == 0
    truth = read_marker_csv(folder / "truth.csv", MARKERS)
    got = read_marker_csv(folder / "tracks.csv", MARKERS)
    assert np.array_equal(got.t, truth.t) and np.array_equal(got.marker, truth.marker)
    obs = flights_from_table(got, MARKERS)[0]
    T = truth.xyz.reshape(-1, 3, 3)
    n_cam = truth.extra["n_cameras"].astype(int).reshape(-1, 3)
    s = score(obs.positions, obs.cov, T, n_cam)
    assert s["labelled"] >= 0.97, s
    assert s["swaps"] == 0, s
    assert s["outside"] <= 0.01, s
    assert s["p95_mm"] <= 1.5, s
    info = json.loads((folder / "truth.json").read_text())
    meta = json.loads((folder / "tracks.json").read_text())
    for name, cam in info["cameras"].items():
        assert meta["cameras"][name]["frame_offset"] == cam["frame_offset"], (name, meta["cameras"][name])
        assert abs(meta["cameras"][name]["subframe"] - cam["subframe"]) < 0.05
    assert meta["cameras"]["camC"]["source"] == "estimated" and meta["cameras"]["camC"]["frame_offset"] == 2
    flags = got.extra["flag"]
    assert set(flags[np.all(np.isfinite(got.xyz), axis=1)]) and all(isinstance(f, str) and f for f in flags)


def test_subframe_delays_are_estimated_and_applied():
    """Cameras exposed 0.3 and −0.2 frames off the first one (and the third two frames late): the total
    offsets are found to 0.05 frame, and the tracks meet the same scores."""
    spec = standard_test_spec("small", seed=2, subframes=(0.0, 0.3, -0.2))
    footage, res = track_in_memory(spec)
    for c in spec.cameras:
        m = res.meta["cameras"][c.name]
        assert m["frame_offset"] == c.frame_offset and abs(m["subframe"] - c.subframe) < 0.05, (c.name, m)
    s = score(res.xyz, res.cov, footage.xyz, footage.seen.sum(axis=0))
    assert s["labelled"] >= 0.97 and s["swaps"] == 0 and s["outside"] <= 0.01 and s["p95_mm"] <= 1.5, s


def test_given_offsets_are_used_as_given():
    spec = standard_test_spec("small", seed=5)
    footage, res = track_in_memory(spec, given_offsets=True)
    assert {n: m["source"] for n, m in res.meta["cameras"].items()} == {"camA": "config", "camB": "config",
                                                                        "camC": "config"}
    assert res.stats["ROI detections"] > 0                     # no full-frame pass over every frame
    s = score(res.xyz, res.cov, footage.xyz, footage.seen.sum(axis=0))
    assert s["labelled"] >= 0.97 and s["swaps"] == 0 and s["outside"] <= 0.01 and s["p95_mm"] <= 1.5, s


def test_timestamp_convention_is_applied():
    """Frames stamped at the start of a 4 ms exposure: with ``exposure-start`` the rows are stamped at the
    middle (+ 2 ms) and match the truth; taking the stamps for the middle puts every point half an
    exposure (≈ 2.6 cm at 13 m/s) away from where the disc was at the stamped time."""
    spec = standard_test_spec("small", seed=6, timestamps="exposure-start", exposure_s=0.004)
    footage, right = track_in_memory(spec, given_offsets=True, timestamps="exposure-start", exposure_s=0.004)
    assert np.allclose(right.times, footage.times) and np.allclose(right.times - right.frames / spec.fps, 0.002)
    s = score(right.xyz, right.cov, footage.xyz, footage.seen.sum(axis=0))
    assert s["labelled"] >= 0.97 and s["outside"] <= 0.01 and s["p95_mm"] <= 1.5, s
    _, wrong = track_in_memory(spec, given_offsets=True)
    assert np.allclose(wrong.times, footage.times - 0.002)
    from bayes_disc.video.testfootage import marker_positions
    at_stamp = marker_positions(spec, wrong.times)[0]
    err = np.linalg.norm(wrong.xyz - at_stamp, axis=2)
    assert np.nanmedian(err) > 0.01


@pytest.mark.slow
@pytest.mark.parametrize("subframes", [(0.0, 0.0, 0.0), (0.0, 0.3, -0.2)])
def test_full_size_footage(subframes):
    """1280×1024 px, 151 frames, plain configuration: the same scores, offsets found."""
    spec = standard_test_spec("full", seed=1, subframes=subframes)
    footage, res = track_in_memory(spec)
    s = score(res.xyz, res.cov, footage.xyz, footage.seen.sum(axis=0))
    assert s["labelled"] >= 0.97 and s["swaps"] == 0 and s["outside"] <= 0.01 and s["p95_mm"] <= 1.5, s
    for c in spec.cameras:
        m = res.meta["cameras"][c.name]
        assert m["frame_offset"] == c.frame_offset and abs(m["subframe"] - c.subframe) < 0.05, (c.name, m)


# ---------------------------------------------------------------------------------------------------
# footage of simulated flights: tracked, then sampled against the coefficients they were simulated with
# ---------------------------------------------------------------------------------------------------
def test_markers_ambiguous_before_the_tracker_predicts_are_labelled_backwards(monkeypatch):
    """On the small footage the third camera starts two frames late: in the first frames two cameras see
    the tilted disc and the layout alone leaves markers ambiguous. The backward pass labels them — every
    position seen by two cameras labelled, no swap — where the forward pass alone leaves them out."""
    import bayes_disc.video.labelling as labelling
    spec = standard_test_spec("small", seed=1)
    footage, res = track_in_memory(spec)
    s = score(res.xyz, res.cov, footage.xyz, footage.seen.sum(axis=0))
    assert res.stats["labels found backwards"] > 0 and res.stats["ambiguous labels left NaN"] == 0, res.stats
    assert s["labelled"] == 1.0 and s["swaps"] == 0, s
    monkeypatch.setattr(labelling, "_label_backwards", lambda *args: {})
    _, forward = track_in_memory(spec)
    assert forward.stats["ambiguous labels left NaN"] > 0, forward.stats


def test_tabulated_flight_follows_the_path_between_its_samples():
    """The analytic flight tabulated at 2400 Hz: between the samples (smear, sub-frame delays) the spline
    stays within 10⁻⁷ m and the top-face normal within 10⁻⁶ of the analytic ones; times outside the table
    are refused."""
    spec = standard_test_spec("full")
    table_t = np.arange(3121) / 2400.0
    flight = TabulatedFlight(table_t + spec.t0, marker_positions(spec, table_t + spec.t0)[0])
    tab = standard_test_spec("full", flight=flight, n_frames=150)
    t = spec.t0 + np.linspace(0.001, 1.29, 997)
    (X, n), (Xt, nt) = marker_positions(spec, t), marker_positions(tab, t)
    assert np.max(np.abs(Xt - X)) < 1e-7 and np.max(np.abs(nt - n)) < 1e-6
    with pytest.raises(ValueError, match="outside its table"):
        marker_positions(tab, [spec.t0 + 1.31])
    with pytest.raises(ValueError, match="strictly increasing"):
        TabulatedFlight(table_t[::-1], flight.xyz)


def test_test_footage_films_a_synthesized_flight(tmp_path):
    """``test-footage --flight`` films a flight written by ``synth`` (2400 Hz, no noise): truth.csv holds
    the file's positions at the frame times; a file with gaps, or sampled too sparsely for the spline, is
    refused with its reason (exit 2)."""
    import yaml
    from bayes_disc.cli import main as cli
    launch = dict(name="f", speed=11.0, launch_angle_deg=5, alpha_deg=6, spin=50, duration=0.3)
    for rate, noise, dropout, name in ((2400, 0.0, 0.0, "dense"), (2400, 1.0, 0.1, "gaps"), (120, 0.0, 0.0, "sparse")):
        synth = {"name": name, "seed": 3, "sample_rate_hz": rate, "coefficients": "hummel2002",
                 "flights": [dict(launch, noise_mm=noise, dropout=dropout)],
                 "output": {"markers": f"{name}.csv", "truth": f"{name}.json"}}
        (tmp_path / f"{name}.yaml").write_text(yaml.safe_dump(synth))
        assert cli(["synth", str(tmp_path / f"{name}.yaml")]) == 0
    folder = tmp_path / "film"
    assert main(["test-footage", str(folder), "--size", "small", "--flight", str(tmp_path / "dense.csv"), "-q"]) == 0
    dense = flights_from_table(read_marker_csv(tmp_path / "dense.csv", MARKERS), MARKERS)[0]
    truth = flights_from_table(read_marker_csv(folder / "truth.csv", MARKERS), MARKERS)[0]
    rows = np.round(truth.times * 2400).astype(int)
    assert truth.times[0] == pytest.approx(1 / 120) and truth.times[-1] <= 0.3 - 1 / 120 + 1e-9
    np.testing.assert_allclose(truth.positions, dense.positions[rows], atol=1e-6)   # the file's 6 decimals
    for bad, why in (("gaps", "missing positions"), ("sparse", "higher sample_rate_hz")):
        r = subprocess.run([sys.executable, "-m", "bayes_disc", "test-footage", str(tmp_path / bad), "--size", "small",
                            "--flight", str(tmp_path / f"{bad}.csv"), "-q"], capture_output=True, text=True)
        assert r.returncode == 2 and why in r.stderr, (bad, r.returncode, r.stderr)


#: the demo's four launches (runs/demo/synth.yaml), simulated without noise at 2400 Hz
DEMO_LAUNCHES = [
    dict(name="bsfl5", speed=9.0, launch_angle_deg=12, pitch_deg=32, roll_deg=4, spin=50, duration=0.9),
    dict(name="fffl10", speed=14.0, launch_angle_deg=2, alpha_deg=7, roll_deg=-3, spin=-65, duration=1.0),
    dict(name="fffl14", speed=15.0, launch_angle_deg=1, alpha_deg=1, roll_deg=-5, spin=-60, duration=1.0),
    dict(name="ffsl5", speed=8.0, launch_angle_deg=12, pitch_deg=30, roll_deg=-2, spin=-45, duration=0.8),
]


@pytest.mark.slow
def test_sample_on_tracks_of_simulated_flights_covers_the_truth(tmp_path):
    """The demo's four flights simulated with Hummel & Hubbard's coefficients, filmed as test footage
    (full size, a camera two frames late, offsets not given), tracked with a plain configuration and sampled
    with a default one: no identity swap and ≤ 1 % of the points outside their own 99.9 % ellipsoid in every
    flight (what the per-point likelihood relies on), and the true coefficients inside the posterior's joint
    99.9 % region (squared Mahalanobis distance under χ²₁₀)."""
    import yaml
    from bayes_disc.inference.model.config import load_config
    from bayes_disc.jobs.sample import run_sample
    from bayes_disc.observation.synth import synthesize
    from bayes_disc.observation.synth_config import synth_spec_from_mapping
    from bayes_disc.physics import literature_coefficients
    spec, _, _ = synth_spec_from_mapping({"name": "filmed", "seed": 7, "sample_rate_hz": 2400, "coefficients": "hummel2002",
                                          "flights": [dict(f, noise_mm=0.0, dropout=0.0) for f in DEMO_LAUNCHES]},
                                         tmp_path / "synth.yaml")
    sim = synthesize(spec)
    files = []
    for k, f in enumerate(sim.flights):
        frames = int(round(f.times[-1] * 120)) - 1            # frame 0 at 1/120 s: smear and delays stay in the table
        film = standard_test_spec("full", seed=20 + k, flight=TabulatedFlight(f.times, f.positions), name=f.name,
                                  n_frames=frames, t0=1 / 120)
        footage, res = track_in_memory(film)
        s = score(res.xyz, res.cov, footage.xyz, footage.seen.sum(axis=0))
        assert s["swaps"] == 0 and s["outside"] <= 0.01, (f.name, s)
        res.write(tmp_path / f"{f.name}.csv")
        files.append({"file": f"{f.name}.csv"})
    config = {"name": "filmed", "flights": files, "markers": {m: list(v) for m, v in spec.markers.items()},
              "output": "out"}
    (tmp_path / "config.yaml").write_text(yaml.safe_dump(config))
    summary = run_sample(load_config(tmp_path / "config.yaml"), progress=False)
    assert summary["convergence"]["converged"], summary["convergence"]
    import arviz as az
    truth = literature_coefficients("hummel2002").as_dict()
    post = az.from_netcdf(str(tmp_path / "out" / "posterior.nc")).posterior
    names = list(truth)
    draws = np.column_stack([post[n].values.ravel() for n in names])
    gap = np.array([truth[n] for n in names]) - draws.mean(axis=0)
    d2 = float(gap @ np.linalg.solve(np.cov(draws.T), gap))
    assert d2 < chi2.ppf(0.999, len(names)), (d2, dict(zip(names, gap / draws.std(axis=0))))

