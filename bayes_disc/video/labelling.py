"""The frame-by-frame pass of ``track``: detection, labelling and tracking, collecting each marker's views.

For every reference frame f and camera c, the camera's frame i = f − k_c (k_c: the integer part of its
frame offset) is read, blobs are detected (full frame, or in windows around the predicted marker pixels
once the tracker has a prediction), blobs that are not usable (merged, cut by the border) are set aside
with their reason, the markers are labelled and triangulated (:mod:`.identity`) and the tracker is
updated. The blob each marker was labelled with in each camera — its centroid, covariance and width —
is kept for the second pass (:mod:`.refine`).

When some camera's frame offset must be estimated, every frame of every camera is first detected in
full (:func:`detect_all`); the labelling pass then reuses those detections.

**Backwards.** Before the tracker has a prediction (the first frames, or after a gap) a marker whose
identity the layout alone cannot settle — a disc seen obliquely by only two cameras — is left unlabelled.
Once the pass is over, the frames are walked again from the last to the first with a second tracker fed
the labels found, so that it predicts backwards in time; a frame with a marker left ambiguous is labelled
again with that prediction (the same candidates, costs and ambiguity rule) and the new labels are kept
where they label more markers and keep every marker the forward pass labelled where it was.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .detection import Blobs, detect_full, detect_roi
from .errors import VideoInputError
from .identity import Tracker, label_frame
from .refine import Views
from .sync import centre_velocity, moved_blobs


@dataclass
class FramePass:
    """Result of :func:`label_frames`: reference frames (F,), the labelled views, ambiguous (F, M): a
    marker left unlabelled because its identity was not certain, counts for the report, and per camera
    the pooled shot-noise statistics of its usable blobs (C, 2) (:class:`.detection.Blobs`)."""

    frames: np.ndarray
    views: Views
    ambiguous: np.ndarray
    stats: dict = field(default_factory=dict)
    shot_stats: np.ndarray = None


def median_background(src, first: int, last: int, n: int):
    """Median of ``n`` frames spread over ``first`` … ``last`` (float32), or None with fewer than 3."""
    idx = np.unique(np.linspace(first, last, n).round().astype(int))
    frames = [f for f in (src.get(i) for i in idx) if f is not None]
    if len(frames) < 3:
        return None
    return np.median(np.stack(frames), axis=0).astype(np.float32)


def backgrounds_of(cfg, srcs) -> list:
    """Each camera's background image (``background: median``) or None."""
    out = [None] * len(srcs)
    if cfg.background == "median":
        for c, s in enumerate(srcs):
            a, b = s.frame_range()
            out[c] = median_background(s, a, b, cfg.background_frames)
    return out


def _check_size(img, cam, i: int) -> None:
    if img.shape[:2] != (cam.height, cam.width):
        raise VideoInputError(f"camera {cam.name}: frame {i} is {img.shape[1]}×{img.shape[0]} px but the "
                              f"calibration says {cam.width}×{cam.height}")


def detect_all(cfg, cams: list, srcs: list, backgrounds: list, progress: bool = False) -> list:
    """Full-frame detection of every frame of every camera: per camera {camera frame: Blobs}."""
    from tqdm import tqdm

    out = []
    total = sum(s.frame_range()[1] - s.frame_range()[0] + 1 for s in srcs)
    with tqdm(total=total, desc=f"detect {cfg.flight}", unit="frame", disable=not progress) as bar:
        for cam, src, bg in zip(cams, srcs, backgrounds):
            a, b = src.frame_range()
            found = {}
            for i in range(a, b + 1):
                img = src.get(i)
                bar.update(1)
                if img is None:
                    continue
                _check_size(img, cam, i)
                found[i] = detect_full(img, cfg.detection, bg)
            out.append(found)
    return out


def frame_span(cfg, srcs: list, offsets: list) -> np.ndarray:
    """Reference frames to process: the config's ``frames`` or all that any camera has."""
    if cfg.frames is not None:
        f0, f1 = cfg.frames
    else:
        ranges = [(s.frame_range()[0] + k, s.frame_range()[1] + k) for s, k in zip(srcs, offsets)]
        f0, f1 = min(r[0] for r in ranges), max(r[1] for r in ranges)
    return np.arange(f0, f1 + 1)


def _blobs(cfg, cam, src, i: int, pred, background, cached, counts: dict):
    """A camera's blobs in its frame i (None when the frame is missing)."""
    if cached is not None:
        return cached.get(i)
    img = src.get(i)
    if img is None:
        return None
    _check_size(img, cam, i)
    r = cfg.detection.roi_radius
    if cfg.roi and pred is not None:
        ctr = cam.project(pred[np.all(np.isfinite(pred), axis=1)])
        ctr = ctr[np.all(np.isfinite(ctr), axis=1) & cam.in_image(ctr, margin=-r)]
        counts["ROI detections"] += 1
        return detect_roi(img, ctr, cfg.detection, background) if len(ctr) else Blobs()
    counts["full-frame detections"] += 1
    return detect_full(img, cfg.detection, background)


def _to_reference_instant(uv: np.ndarray, cam, tracker: Tracker, f: int, delay: float, pred) -> np.ndarray:
    """Blob centroids uv (n, 2) of a camera exposed ``delay`` frames after reference frame f, moved to
    the instant f by the image motion of the nearest predicted marker (the tracker's prediction at f and
    f + delay); blobs farther than 20 px from every prediction, and all without a prediction, stay."""
    if pred is None or len(uv) == 0 or abs(delay) < 1e-6:
        return uv
    later, _ = tracker.predict(f + delay)
    if later is None:
        return uv
    p0, p1 = cam.project(pred), cam.project(later)
    ok = np.all(np.isfinite(p0), axis=1) & np.all(np.isfinite(p1), axis=1)
    if not ok.any():
        return uv
    d = np.linalg.norm(uv[:, None, :] - p1[None, ok, :], axis=2)
    j = np.argmin(d, axis=1)
    near = d[np.arange(len(uv)), j] < 20.0
    out = uv.copy()
    out[near] += (p0[ok] - p1[ok])[j[near]]
    return out


def _moved(uv, cam, tracker, f: int, delay: float, pred, cached, i: int) -> np.ndarray:
    """A delayed camera's blobs moved to the reference instant: by the tracker's prediction when there is
    one, else (acquisition) along each blob's own track through the neighbouring frames
    (:func:`.sync.moved_blobs`)."""
    if abs(delay) < 1e-6 or len(uv) == 0:
        return uv
    if pred is not None:
        return _to_reference_instant(uv, cam, tracker, f, delay, pred)
    if cached is None:
        return uv
    near = {k: cached[k].uv[cached[k].usable] for k in (i - 1, i, i + 1) if k in cached}
    if i not in near or len(near[i]) != len(uv):
        return uv - delay * centre_velocity(near, i)
    return moved_blobs(near, delay)[i]


def label_frames(cfg, cams: list, srcs: list, offsets: list, backgrounds: list, cached=None,
                 progress: bool = True, delays=None) -> FramePass:
    """Detect, label and track over the reference frames (module docstring). offsets: integer frame
    offset per camera; cached: per camera {camera frame: Blobs} from :func:`detect_all`, or None; delays:
    sub-frame delay per camera [frames] — the blobs of a delayed camera are moved to the reference instant
    for labelling (:func:`_to_reference_instant`), while the views kept are the blobs as measured (the
    second pass shifts them by interpolation)."""
    from tqdm import tqdm

    frames = frame_span(cfg, srcs, offsets)
    F, M, C = len(frames), len(cfg.markers), len(cams)
    views = Views.empty(F, M, C)
    labels, kept = [], {}                     # per frame its labels; the blobs of frames with ambiguity
    tracker = Tracker(cfg.layout, cfg.identity)
    counts = {"ROI detections": 0,
              "full-frame detections": 0 if cached is None else sum(len(d) for d in cached)}
    missing = [0] * C
    n_blobs, unusable = 0, {"merged": 0, "edge": 0}
    shot = np.zeros((C, 2))
    for k, f in enumerate(tqdm(frames, desc=f"track {cfg.flight}", unit="frame", disable=not progress)):
        pred, psig = tracker.predict(int(f))
        usable = []
        for c in range(C):
            blobs = _blobs(cfg, cams[c], srcs[c], int(f - offsets[c]), pred, backgrounds[c],
                           None if cached is None else cached[c], counts)
            if blobs is None:
                missing[c] += 1
                blobs = Blobs()
            n_blobs += len(blobs)
            for key, v in blobs.reasons().items():
                unusable[key] += v
            usable.append(blobs.subset(blobs.usable))
            shot[c] += usable[-1].shot_stats.sum(axis=0)
        moved = [u.uv if delays is None else _moved(u.uv, cams[c], tracker, int(f), delays[c], pred,
                                                    None if cached is None else cached[c], int(f - offsets[c]))
                 for c, u in enumerate(usable)]
        lab = label_frame(cams, moved, cfg.layout, cfg.identity, pred, psig, blob_cov=[u.cov for u in usable])
        tracker.update(int(f), lab.xyz)
        labels.append(lab)
        if lab.ambiguous.any():
            kept[k] = (moved, usable)
        _keep_views(views, k, lab, usable)
    relabelled = _label_backwards(cfg, cams, frames, labels, kept)
    for k in relabelled:
        _keep_views(views, k, labels[k], kept[k][1])
    ambiguous = np.array([lab.ambiguous for lab in labels]).reshape(F, M)
    stats = {"frames missing per camera": dict(zip([c.name for c in cams], missing)), **counts, "blobs": n_blobs,
             "blobs left out (merged)": unusable["merged"], "blobs left out (cut by the frame border)": unusable["edge"],
             "ambiguous labels left NaN": int(ambiguous.sum()),
             "labels found backwards": int(sum(relabelled.values()))}
    return FramePass(frames, views, ambiguous, stats, shot)


def _keep_views(views: Views, k: int, lab, usable: list) -> None:
    """Store frame k's labelled views (the blob each marker was labelled with in each camera)."""
    views.uv[k], views.cov[k], views.width[k], views.cov_shot[k] = np.nan, np.nan, np.nan, 0.0
    for m, c in zip(*np.nonzero(lab.views >= 0)):
        j = lab.views[m, c]
        views.uv[k, m, c] = usable[c].uv[j]
        views.cov[k, m, c] = usable[c].cov[j]
        views.width[k, m, c] = usable[c].width[j]
        views.cov_shot[k, m, c] = usable[c].cov_shot[j]


def _label_backwards(cfg, cams: list, frames: np.ndarray, labels: list, kept: dict) -> dict:
    """Label again, with a tracker running from the last frame to the first, the frames whose labels left
    a marker ambiguous (module docstring); ``labels`` (F,) FrameLabels are replaced in place, ``kept``
    {k: (moved centroids, usable blobs)} holds those frames' blobs. Returns {k: markers labelled anew}."""
    back = Tracker(cfg.layout, cfg.identity)          # fed frames −f: its "ahead" runs back in time
    found = {}
    for k in range(len(frames) - 1, -1, -1):
        f = int(frames[k])
        if k in kept:
            pred, psig = back.predict(-f)
            if pred is not None:
                moved, usable = kept[k]
                lab = label_frame(cams, moved, cfg.layout, cfg.identity, pred, psig, blob_cov=[u.cov for u in usable])
                before = np.isfinite(labels[k].xyz[:, 0])
                gain = int(np.sum(np.isfinite(lab.xyz[:, 0]))) - int(before.sum())
                agree = np.all(np.linalg.norm(lab.xyz[before] - labels[k].xyz[before], axis=1)
                               <= cfg.identity.swap_distance_m)      # NaN (now unlabelled) compares False
                if gain > 0 and agree:
                    labels[k] = lab
                    found[k] = gain
        back.update(-f, labels[k].xyz)
    return found
