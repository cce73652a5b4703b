"""Marker detection: threshold, connected components and intensity-weighted centroids.

For a grey frame I (DN; uint8, uint16 or float) and an optional background image B:

1. pixels with I − B > ``threshold`` form a binary mask; connected components (8-connectivity,
   ``cv2.connectedComponentsWithStats``) with ``min_area`` ≤ area ≤ ``max_area`` px are blobs;
2. each blob's centroid is measured on a window = its bounding box grown by ``pad`` px: the local
   background b (median of the window's border ring, other blobs excluded) and noise σ_b (1.4826 × MAD)
   are subtracted, pixels of other blobs (grown by ``mask_dilation`` px) get zero weight, and

       w = max(I − B − b − k σ_b, 0),   (u, v) = Σ w·(x, y) / Σ w

   with k = ``noise_floor_sigma`` (pixel centres at integer coordinates, OpenCV convention). The
   centroid's covariance propagates the pixel noise through these weights,
   C = Σ_(w>0) (x − c)(x − c)ᵀ var / (Σ w)², var = σ_b² + (DN step)²/12 + (I − B − b)/g: a wide, faint
   or smeared blob has a larger one than a small bright one. The shot-noise term needs the gain g
   (e⁻/DN): given as ``gain``, it is included; otherwise its part per unit 1/g is kept apart
   (``Blobs.cov_shot``) and each isolated blob reports how its pixels scatter about a fitted Gaussian
   (``Blobs.shot_stats``): pooled over a camera's blobs, var(r) = σ_b² + m/g gives 1/g (a photon
   transfer measured on the markers themselves; the tracker does this per camera);
3. flags (bit mask):

   - ``SATURATED``: a pixel at or above the saturation level (the centroid stays usable: clipping is
     symmetric about the centre);
   - ``ELONGATED``: ratio of the principal axes of the weighted second moments > ``max_elongation``
     (motion blur; usable);
   - ``CROWDED``: another blob reached into the window and was masked. Its tail can still bias the
     centroid by up to a few tenths of a pixel, so with ``deblend`` the centroids of a group of
     crowded blobs are refined by a joint least-squares fit of pixel-integrated Gaussians
     (:mod:`.deblend`), whose covariance (plus the square of a quarter of the correction) replaces the
     centroid's. A single component with two or more separate intensity peaks (two
     markers touching in the image) is split by the same fit into crowded blobs;
   - ``MERGED``: a multi-peak component that could not be split, or (only when ``expected_area`` is
     given) a blob larger than ``merge_area_ratio`` (default 2) × that area; optionally (when
     ``merge_flux_ratio`` or ``merge_area_ratio`` is set) a blob whose flux or area exceeds that ratio ×
     the median of the frame's other blobs. Not usable. The relative tests are off by default: a marker
     seen face-on is easily twice as bright as its neighbours, and two markers in one blob are found
     better from the geometry, once they are labelled (:mod:`.consistency`);
   - ``EDGE``: the blob touches the frame border; its centroid is biased. Not usable.

Two modes. Full frame: a coarse pass marks ``tile``×``tile`` tiles that hold any mask pixel and the
components are labelled only in the bounding boxes of clusters of active tiles (fast for the sparse
images of marker footage). ROI: only windows of half-size ``roi_radius`` around predicted pixel
positions are searched; a blob cut by a window border makes that window grow until it is whole.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np

from .deblend import deblend_groups, fit_spots, min_separation, peaks, spot_jacobian

SATURATED = 1
ELONGATED = 2
MERGED = 4
EDGE = 8
CROWDED = 16
FLAG_NAMES = {SATURATED: "saturated", ELONGATED: "elongated", MERGED: "merged", EDGE: "edge", CROWDED: "crowded"}


@dataclass(frozen=True)
class DetectionConfig:
    """Detection settings (pixel units; intensities in DN of the frame).

    merge_flux_ratio, merge_area_ratio: when set, a blob brighter (larger) than this × the median of the
    frame's other blobs is flagged ``MERGED``; off by default, because markers whose brightness changes
    with the view angle differ by ×2 or more while each is one marker (the tracker instead drops a view in
    which two labelled markers fall on one blob, see :mod:`.consistency`). gain: e⁻ per DN, for the shot
    noise of a centroid's covariance (None: only the background noise measured around the blob).
    """

    threshold: float = 30.0
    min_area: int = 2
    max_area: int = 5000
    pad: int = 3
    mask_dilation: int = 2
    noise_floor_sigma: float = 2.0
    saturation: float | None = None  # default: the dtype's maximum (255 for uint8)
    max_elongation: float = 2.0
    merge_flux_ratio: float | None = None
    merge_area_ratio: float | None = None
    expected_area: float | None = None
    roi_radius: int = 16
    tile: int = 8
    deblend: bool = True
    gain: float | None = None

    def __post_init__(self):
        if self.threshold <= 0:
            raise ValueError("detection.threshold must be positive")
        if self.min_area < 1 or self.max_area < self.min_area:
            raise ValueError("detection: need 1 ≤ min_area ≤ max_area")
        if self.pad < 1 or self.roi_radius < 2 or self.tile < 2:
            raise ValueError("detection: pad ≥ 1, roi_radius ≥ 2 and tile ≥ 2 are required")
        if self.gain is not None and self.gain <= 0:
            raise ValueError("detection.gain must be positive")


_FIELDS = ("uv", "area", "flux", "peak", "elongation", "flags", "cov", "width", "cov_shot", "shot_stats")


@dataclass
class Blobs:
    """Blobs of one frame: uv (n, 2) centroids [px]; area (n,) [px]; flux (n,) background-subtracted
    sum [DN]; peak (n,) brightest raw pixel [DN]; elongation (n,) ≥ 1; flags (n,) bit mask; cov (n, 2, 2)
    covariance of the centroid [px²] from the noise around the blob (or from the deblending fit); width
    (n,) RMS width along the blob's major axis [px]; cov_shot (n, 2, 2) the shot-noise part of the
    centroid covariance per unit 1/gain [px² DN] (zero when the gain is given: then it is in ``cov``);
    shot_stats (n, 2): (Σ m (r² − σ_b² − 1/12), Σ m²) over the pixels of a Gaussian fitted to an isolated
    blob (m: the model [DN], r: the residual [DN]) — summed over many blobs, their ratio estimates 1/gain
    [DN per e⁻] (zeros when not measured)."""

    uv: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    area: np.ndarray = field(default_factory=lambda: np.zeros(0, int))
    flux: np.ndarray = field(default_factory=lambda: np.zeros(0))
    peak: np.ndarray = field(default_factory=lambda: np.zeros(0))
    elongation: np.ndarray = field(default_factory=lambda: np.zeros(0))
    flags: np.ndarray = field(default_factory=lambda: np.zeros(0, int))
    cov: np.ndarray = field(default_factory=lambda: np.zeros((0, 2, 2)))
    width: np.ndarray = field(default_factory=lambda: np.zeros(0))
    cov_shot: np.ndarray = field(default_factory=lambda: np.zeros((0, 2, 2)))
    shot_stats: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))

    def __len__(self) -> int:
        return len(self.uv)

    @property
    def usable(self) -> np.ndarray:
        """True for blobs whose centroid can be trusted (not merged, not cut by the frame border)."""
        return (self.flags & (MERGED | EDGE)) == 0

    def subset(self, keep) -> "Blobs":
        return Blobs(*(getattr(self, f)[keep] for f in _FIELDS))

    @staticmethod
    def concat(parts: list) -> "Blobs":
        if not parts:
            return Blobs()
        return Blobs(*(np.concatenate([getattr(p, f) for p in parts]) for f in _FIELDS))

    def reasons(self) -> dict:
        """Counts of the blobs that are not usable, by reason (``merged``, ``edge``)."""
        return {"merged": int(np.sum(self.flags & MERGED > 0)), "edge": int(np.sum((self.flags & EDGE > 0)
                                                                                  & (self.flags & MERGED == 0)))}


def _as_gray(frame) -> np.ndarray:
    f = np.asarray(frame)
    if f.ndim == 3:
        if f.shape[2] == 1:
            return f[..., 0]
        return cv2.cvtColor(f, cv2.COLOR_BGR2GRAY)
    if f.ndim != 2:
        raise ValueError(f"frame must be 2-D (grey) or 3-D (colour), got shape {f.shape}")
    return f


def _saturation_level(frame: np.ndarray, cfg: DetectionConfig) -> float:
    if cfg.saturation is not None:
        return float(cfg.saturation)
    if np.issubdtype(frame.dtype, np.integer):
        return float(np.iinfo(frame.dtype).max)
    return np.inf


def _quantum(frame: np.ndarray) -> float:
    """The DN step of a frame: 1 for integer frames, 0 for float frames."""
    return 1.0 if np.issubdtype(frame.dtype, np.integer) else 0.0


def _signal(region: np.ndarray, background: np.ndarray | None) -> np.ndarray:
    r = region.astype(np.float32)
    if background is not None:
        r = r - background.astype(np.float32)
    return r


def _threshold_mask(signal: np.ndarray, thr: float) -> np.ndarray:
    return (signal > thr).view(np.uint8) if signal.dtype == np.bool_ else (signal > thr).astype(np.uint8)


_KERNELS: dict = {}


def _kernel(r: int) -> np.ndarray:
    if r not in _KERNELS:
        _KERNELS[r] = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * r + 1, 2 * r + 1))
    return _KERNELS[r]


def _window(signal, labels, k: int, box, pad: int, dd: int):
    """Centroid window of component k (bounding box ``box`` = x0, y0, w, h in the region): the window
    (x0, y0, x1, y1), its own-pixel mask, the mask of other components grown by ``dd`` px, and the labels
    of those neighbours."""
    H, W = signal.shape
    x0, y0, w, h = box
    wx0, wy0 = max(x0 - pad, 0), max(y0 - pad, 0)
    wx1, wy1 = min(x0 + w + pad, W), min(y0 + h + pad, H)
    own = labels[wy0:wy1, wx0:wx1] == k
    # other components in or near the window (up to dd px outside), grown by dd
    ex0, ey0, ex1, ey1 = max(wx0 - dd, 0), max(wy0 - dd, 0), min(wx1 + dd, W), min(wy1 + dd, H)
    Lb = labels[ey0:ey1, ex0:ex1]
    ob = (Lb != 0) & (Lb != k)
    neighbours = set()
    others = np.zeros(own.shape, bool)
    if ob.any():
        grown = cv2.dilate(ob.view(np.uint8), _kernel(dd)).astype(bool) if dd > 0 else ob
        others = grown[wy0 - ey0:wy1 - ey0, wx0 - ex0:wx1 - ex0] & ~own
        if others.any():
            neighbours = set(np.unique(Lb[ob]).tolist())
    return (wx0, wy0, wx1, wy1), own, others, neighbours


def _moments(S: np.ndarray, own, others, window, cfg: DetectionConfig, quantum: float):
    """Weighted centroid of a window (see the module docstring) and its covariance.

    Returns None when no pixel has weight, else (cx, cy, total weight, elongation, major-axis RMS width
    [px], background b, RMS width σ̄ [px], covariance (2, 2) [px²], shot-noise covariance per unit 1/gain
    (2, 2) [px² DN]). The covariance propagates the noise of the weighted pixels: C = Σ_(w>0) (x − c)(x − c)ᵀ
    var / W², var = σ_b² + quantum²/12 (+ signal/gain with a gain), σ_b the noise of the window's border
    ring (1.4826 × MAD); without a gain the shot-noise part Σ_(w>0) (x − c)(x − c)ᵀ signal / W² is returned
    apart, for the gain to be measured later (:mod:`.refine`)."""
    wx0, wy0, wx1, wy1 = window
    ring = np.zeros(S.shape, bool)
    ring[0, :] = ring[-1, :] = ring[:, 0] = ring[:, -1] = True
    ring &= ~own & ~others
    if ring.sum() >= 4:
        vals = S[ring]
        b = _median(vals)
        sig = 1.4826 * _median(np.abs(vals - b))
    else:
        b, sig = 0.0, 0.0
    wgt = S - (b + cfg.noise_floor_sigma * sig)
    wgt[others] = 0
    np.maximum(wgt, 0, out=wgt)
    tot = float(wgt.sum())
    if tot <= 0:
        return None
    ys = np.arange(wy0, wy1, dtype=np.float64)
    xs = np.arange(wx0, wx1, dtype=np.float64)
    wx_ = wgt.sum(axis=0, dtype=np.float64)
    wy_ = wgt.sum(axis=1, dtype=np.float64)
    cx = float(wx_ @ xs) / tot
    cy = float(wy_ @ ys) / tot
    dx, dy = xs - cx, ys - cy
    sxx = float(wx_ @ (dx * dx)) / tot
    syy = float(wy_ @ (dy * dy)) / tot
    sxy = float(dy @ wgt.astype(np.float64) @ dx) / tot
    tr, det = sxx + syy, sxx * syy - sxy * sxy
    disc = max(tr * tr / 4 - det, 0.0) ** 0.5
    l1, l2 = tr / 2 + disc, max(tr / 2 - disc, 1e-12)
    on = (wgt > 0).astype(np.float64)
    var = on * (sig * sig + quantum * quantum / 12.0)
    shot = on * np.maximum(S - b, 0)
    cov = _spread(var, dx, dy, tot)
    cov_shot = _spread(shot, dx, dy, tot)
    if cfg.gain is not None:
        cov, cov_shot = cov + cov_shot / cfg.gain, np.zeros((2, 2))
    return (cx, cy, tot, float(np.sqrt(l1 / l2)), float(np.sqrt(l1)), b, float(np.sqrt(max(tr / 2 - 1 / 12, 0.09))),
            cov, cov_shot)


def _spread(var: np.ndarray, dx: np.ndarray, dy: np.ndarray, tot: float) -> np.ndarray:
    """Σ var (x − c)(x − c)ᵀ / tot² over a window (rows y, columns x) [px² × units of var]."""
    xy = float(dy @ var @ dx)
    return np.array([[float(var.sum(axis=0) @ (dx * dx)), xy], [xy, float(var.sum(axis=1) @ (dy * dy))]]) / (tot * tot)


def _split(S, b, own, labels_w, origin, tot, peaks_found):
    """Split one component with two or more intensity peaks (window coordinates) by a joint fit of as many
    spots on its window S (top-left pixel ``origin`` in the frame); None when that fails."""
    valid = ~((labels_w != 0) & ~own)
    u0 = np.array([p[0] + origin[0] for p in peaks_found], float)
    v0 = np.array([p[1] + origin[1] for p in peaks_found], float)
    n = len(peaks_found)
    fit = fit_spots(S.astype(np.float64) - b, valid, origin, u0, v0, np.full(n, 1.0), np.full(n, max(tot, 1.0) / n), 2.0)
    if fit is None or min_separation(fit[0], fit[1]) < 1.0:
        return None
    return fit


def _measure(signal: np.ndarray, raw: np.ndarray, labels: np.ndarray, stats: np.ndarray, x_off: int, y_off: int,
             frame_shape, cfg: DetectionConfig, sat: float, region_is_frame_edge, quantum: float = 1.0) -> tuple[Blobs, list]:
    """Centroids of the components of ``labels`` inside one region (offset x_off, y_off in the frame).

    Returns the blobs and, for each, whether it touches the region border where the region is not the
    frame border (then the caller must grow the region). ``quantum``: the frame's DN step (0 for float
    frames), for the quantisation noise of the covariance."""
    H, W = signal.shape
    fh, fw = frame_shape
    rows, info, cut = [], [], []  # info per blob: label (−1 after a split), window, background, σ, neighbours
    for k in range(1, len(stats)):
        x0, y0, w, h, area = (int(v) for v in stats[k])
        if area < cfg.min_area or area > cfg.max_area:
            continue
        touches = (x0 == 0 and not region_is_frame_edge[0]) or (y0 == 0 and not region_is_frame_edge[1]) or \
                  (x0 + w == W and not region_is_frame_edge[2]) or (y0 + h == H and not region_is_frame_edge[3])
        window, own, others, neighbours = _window(signal, labels, k, (x0, y0, w, h), cfg.pad, cfg.mask_dilation)
        wx0, wy0, wx1, wy1 = window
        S = signal[wy0:wy1, wx0:wx1]
        mom = _moments(S, own, others, window, cfg, quantum)
        if mom is None:
            continue
        cx, cy, tot, elong, width, b, sbar, cov, cov_shot = mom
        peak_raw = float(raw[wy0:wy1, wx0:wx1][own].max())
        flags = SATURATED if peak_raw >= sat else 0
        gx0, gy0 = x0 + x_off, y0 + y_off
        if gx0 == 0 or gy0 == 0 or gx0 + w == fw or gy0 + h == fh:
            flags |= EDGE
        if others.any():
            flags |= CROWDED
        # two markers ≥ 3 px apart make a blob elongated (ratio ≥ 1.25 for σ ≤ 2 px): only then look for peaks
        found = peaks(S - b, own) if elong > 1.15 else [None]
        if len(found) >= 2:
            fit = None
            if cfg.deblend and len(found) <= 4 and not flags & EDGE:
                fit = _split(S, b, own, labels[wy0:wy1, wx0:wx1], (wx0 + x_off, wy0 + y_off), tot, found)
            if fit is not None:  # two or more markers in one component, split by a joint fit
                for j in range(len(found)):
                    rows.append(((fit[0][j], fit[1][j]), area, float(fit[3][j]), peak_raw, 1.0, flags | CROWDED,
                                 fit[4][j], float(fit[2][j]), cov_shot / len(found), np.zeros(2)))
                    info.append((-1, window, b, float(fit[2][j]), set()))
                    cut.append(touches)
                continue
            flags |= MERGED
        if elong > cfg.max_elongation:
            flags |= ELONGATED
        if cfg.expected_area is not None and area > (cfg.merge_area_ratio or 2.0) * cfg.expected_area:
            flags |= MERGED
        stats_ = np.zeros(2)
        if cfg.gain is None and flags == 0:
            stats_ = _shot_stats(S, b, own, others, window, (x_off, y_off), (cx, cy, sbar, tot), quantum)
        rows.append(((cx + x_off, cy + y_off), area, tot, peak_raw, elong, flags, cov, width, cov_shot, stats_))
        info.append((k, window, b, sbar, neighbours))
        cut.append(touches)
    blobs = _blobs_from_rows(rows)
    if cfg.deblend and any(i[4] for i in info):
        deblend_groups(signal, labels, blobs.uv, blobs.cov, info, x_off, y_off)
    return blobs, cut


def _blobs_from_rows(rows: list) -> Blobs:
    if not rows:
        return Blobs()
    uv, area, flux, peak, el, flags, cov, width, cov_shot, shot = zip(*rows)
    return Blobs(np.array(uv, float).reshape(-1, 2), np.array(area, int), np.array(flux, float), np.array(peak, float),
                 np.array(el, float), np.array(flags, int), np.array(cov, float).reshape(-1, 2, 2),
                 np.array(width, float), np.array(cov_shot, float).reshape(-1, 2, 2), np.array(shot, float).reshape(-1, 2))


def _shot_stats(S, b: float, own, others, window, offset, start, quantum: float) -> np.ndarray:
    """(Σ m (r² − (1 − h)(σ_b² + quantum²/12)), Σ (1 − h) m²) of a round Gaussian fitted to an isolated blob's
    window (m: model, r: residual [DN], h: the fit's leverage of each pixel, which takes that share of the
    pixel's noise out of its residual); zeros when the fit fails. start: (cx, cy, σ, flux), region pixels.
    Summed over many blobs, the ratio is 1/gain, since E[r²] = (1 − h)(σ_b² + m/g)."""
    wx0, wy0 = window[0], window[1]
    ring = np.zeros(S.shape, bool)
    ring[0, :] = ring[-1, :] = ring[:, 0] = ring[:, -1] = True
    ring &= ~own & ~others
    if ring.sum() < 8:
        return np.zeros(2)
    data = S.astype(np.float64) - b
    origin = (wx0 + offset[0], wy0 + offset[1])
    cx, cy, sbar, tot = start
    valid = ~others
    fit = fit_spots(data, valid, origin, np.array([cx + offset[0]]), np.array([cy + offset[1]]),
                    np.array([max(sbar, 0.5)]), np.array([max(tot, 1.0)]), 1.5)
    if fit is None:
        return np.zeros(2)
    model, J = spot_jacobian(data.shape, valid, origin, fit[0], fit[1], fit[2], fit[3])
    lev = np.einsum("pi,ij,pj->p", J, np.linalg.pinv(J.T @ J), J)
    vals = data[ring]
    s2 = (1.4826 * _median(np.abs(vals - _median(vals)))) ** 2 + quantum * quantum / 12.0
    r2 = (data[valid] - model) ** 2
    keep = 1.0 - np.clip(lev, 0.0, 1.0)
    return np.array([float(np.sum(model * (r2 - keep * s2))), float(np.sum(keep * model * model))])


def flag_bright(blobs: Blobs, cfg: DetectionConfig) -> Blobs:
    """Flag blobs much brighter or larger than the frame's other blobs as ``MERGED`` (in place), when
    ``merge_flux_ratio`` or ``merge_area_ratio`` is set (both are off by default)."""
    n = len(blobs)
    if n < 2 or (cfg.merge_flux_ratio is None and cfg.merge_area_ratio is None):
        return blobs
    for i in range(n):
        others = np.arange(n) != i
        f_ref = _median(blobs.flux[others])
        a_ref = _median(blobs.area[others].astype(float))
        if cfg.merge_flux_ratio is not None and f_ref > 0 and blobs.flux[i] > cfg.merge_flux_ratio * f_ref:
            blobs.flags[i] |= MERGED
        if cfg.merge_area_ratio is not None and blobs.area[i] > cfg.merge_area_ratio * a_ref:
            blobs.flags[i] |= MERGED
    return blobs


def _median(a: np.ndarray) -> float:
    a = np.sort(a, axis=None)
    n = a.size
    return 0.5 * float(a[(n - 1) // 2] + a[n // 2])


class _LazySignal:
    """Frame minus background, computed per region on demand (avoids converting the whole frame)."""

    def __init__(self, frame, background):
        self.frame, self.background = frame, background

    def __getitem__(self, idx):
        return _signal(self.frame[idx], None if self.background is None else self.background[idx])


def detect_full(frame, cfg: DetectionConfig = DetectionConfig(), background=None) -> Blobs:
    """Detect blobs in a whole frame (coarse tile pass, then components in the active areas)."""
    g = _as_gray(frame)
    sat = _saturation_level(g, cfg)
    fh, fw = g.shape
    if background is None and g.dtype == np.uint8:
        _, mask = cv2.threshold(g, min(cfg.threshold, 255), 255, cv2.THRESH_BINARY)
    else:
        sig = g.astype(np.float32) - (0 if background is None else background.astype(np.float32))
        mask = (sig > cfg.threshold).astype(np.uint8) * 255
    t = cfg.tile
    ph, pw = -fh % t, -fw % t
    if ph or pw:
        mask = cv2.copyMakeBorder(mask, 0, ph, 0, pw, cv2.BORDER_CONSTANT, value=0)
    coarse = cv2.resize(mask, (mask.shape[1] // t, mask.shape[0] // t), interpolation=cv2.INTER_AREA)
    if not coarse.any():
        return Blobs()
    coarse = (coarse > 0).astype(np.uint8)
    n, _, cstats, _ = cv2.connectedComponentsWithStats(coarse, connectivity=8)
    lazy = _LazySignal(g, background)
    parts = []
    for k in range(1, n):
        cx0, cy0, cw, ch, _ = cstats[k]
        x0, y0 = max((cx0 - 1) * t, 0), max((cy0 - 1) * t, 0)
        x1, y1 = min((cx0 + cw + 1) * t, fw), min((cy0 + ch + 1) * t, fh)
        sig = lazy[y0:y1, x0:x1]
        m = _threshold_mask(sig, cfg.threshold)
        _, labels, stats, _ = cv2.connectedComponentsWithStats(m, connectivity=8)
        edge = (x0 == 0, y0 == 0, x1 == fw, y1 == fh)
        blobs, _ = _measure(sig, g[y0:y1, x0:x1], labels, stats, x0, y0, g.shape, cfg, sat, edge, _quantum(g))
        parts.append(blobs)
    return flag_bright(Blobs.concat(parts), cfg)


def _merge_boxes(boxes: list) -> list:
    boxes = [list(b) for b in boxes]
    changed = True
    while changed:
        changed = False
        out = []
        while boxes:
            a = boxes.pop()
            i = 0
            while i < len(boxes):
                b = boxes[i]
                if a[0] < b[2] and b[0] < a[2] and a[1] < b[3] and b[1] < a[3]:
                    a = [min(a[0], b[0]), min(a[1], b[1]), max(a[2], b[2]), max(a[3], b[3])]
                    boxes.pop(i)
                    changed = True
                else:
                    i += 1
            out.append(a)
        boxes = out
    return boxes


def detect_roi(frame, centres, cfg: DetectionConfig = DetectionConfig(), background=None,
               radius: int | None = None) -> Blobs:
    """Detect blobs only in windows of half-size ``radius`` (default ``cfg.roi_radius``) around the
    predicted pixel positions ``centres`` (m, 2); NaN centres are skipped."""
    g = _as_gray(frame)
    sat = _saturation_level(g, cfg)
    fh, fw = g.shape
    r = cfg.roi_radius if radius is None else int(radius)
    boxes = []
    for u, v in np.asarray(centres, float).reshape(-1, 2):
        if not (np.isfinite(u) and np.isfinite(v)):
            continue
        iu, iv = int(round(u)), int(round(v))
        x0, y0, x1, y1 = max(iu - r, 0), max(iv - r, 0), min(iu + r + 1, fw), min(iv + r + 1, fh)
        if x1 > x0 and y1 > y0:
            boxes.append((x0, y0, x1, y1))
    if not boxes:
        return Blobs()
    lazy = _LazySignal(g, background)
    for _ in range(6):  # grow windows that cut a blob
        boxes = _merge_boxes(boxes)
        parts, grown = [], False
        new_boxes = []
        for (x0, y0, x1, y1) in boxes:
            sig = lazy[y0:y1, x0:x1]
            m = _threshold_mask(sig, cfg.threshold)
            _, labels, stats, _ = cv2.connectedComponentsWithStats(m, connectivity=8)
            edge = (x0 == 0, y0 == 0, x1 == fw, y1 == fh)
            blobs, cut = _measure(sig, g[y0:y1, x0:x1], labels, stats, x0, y0, g.shape, cfg, sat, edge, _quantum(g))
            if any(cut):
                grown = True
                new_boxes.append((max(x0 - r, 0), max(y0 - r, 0), min(x1 + r, fw), min(y1 + r, fh)))
            else:
                new_boxes.append((x0, y0, x1, y1))
            parts.append(blobs)
        if not grown:
            return flag_bright(Blobs.concat(parts), cfg)
        boxes = new_boxes
    return flag_bright(Blobs.concat(parts), cfg)


def detect(frame, cfg: DetectionConfig = DetectionConfig(), centres=None, background=None) -> Blobs:
    """Full-frame detection, or ROI detection around ``centres`` (m, 2) when given."""
    if centres is None:
        return detect_full(frame, cfg, background)
    return detect_roi(frame, centres, cfg, background)
