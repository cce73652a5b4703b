"""Marker detection: threshold, connected components and intensity-weighted centroids.

For a grey frame I (DN; uint8, uint16 or float) and an optional background image B:

1. pixels with I − B > ``threshold`` form a binary mask; connected components (8-connectivity,
   ``cv2.connectedComponentsWithStats``) with ``min_area`` ≤ area ≤ ``max_area`` px are blobs;
2. each blob's centroid is measured on a window = its bounding box grown by ``pad`` px: the local
   background b (median of the window's border ring, other blobs excluded) and noise σ_b (1.4826 × MAD)
   are subtracted, pixels of other blobs (grown by ``mask_dilation`` px) get zero weight, and

       w = max(I − B − b − k σ_b, 0),   (u, v) = Σ w·(x, y) / Σ w

   with k = ``noise_floor_sigma`` (pixel centres at integer coordinates, OpenCV convention);
3. flags (bit mask):

   - ``SATURATED``: a pixel at or above the saturation level (the centroid stays usable: clipping is
     symmetric about the centre);
   - ``ELONGATED``: ratio of the principal axes of the weighted second moments > ``max_elongation``
     (motion blur; usable);
   - ``CROWDED``: another blob reached into the window and was masked. Its tail can still bias the
     centroid by up to a few tenths of a pixel, so with ``deblend`` the centroids of a group of
     crowded blobs are refined by a joint least-squares fit of pixel-integrated Gaussians (:mod:`.psf`,
     compiled in :mod:`._kernels`). A single component with two or more separate intensity peaks (two
     markers touching in the image) is split by the same fit into crowded blobs;
   - ``MERGED``: a multi-peak component that could not be split, or a blob whose flux exceeds
     ``merge_flux_ratio`` × the median flux of the frame's other blobs (or area > ``merge_area_ratio``
     × their median, or × ``expected_area``): two markers imaged as one, a centroid of neither.
     Not usable;
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

from ._kernels import fit_spots_lm

SATURATED = 1
ELONGATED = 2
MERGED = 4
EDGE = 8
CROWDED = 16
FLAG_NAMES = {SATURATED: "saturated", ELONGATED: "elongated", MERGED: "merged", EDGE: "edge", CROWDED: "crowded"}


@dataclass(frozen=True)
class DetectionConfig:
    """Detection settings (pixel units; intensities in DN of the frame)."""

    threshold: float = 30.0
    min_area: int = 2
    max_area: int = 5000
    pad: int = 3
    mask_dilation: int = 2
    noise_floor_sigma: float = 2.0
    saturation: float | None = None  # default: the dtype's maximum (255 for uint8)
    max_elongation: float = 2.0
    merge_flux_ratio: float = 1.6
    merge_area_ratio: float = 2.0
    expected_area: float | None = None
    roi_radius: int = 16
    tile: int = 8
    deblend: bool = True

    def __post_init__(self):
        if self.threshold <= 0:
            raise ValueError("detection.threshold must be positive")
        if self.min_area < 1 or self.max_area < self.min_area:
            raise ValueError("detection: need 1 ≤ min_area ≤ max_area")
        if self.pad < 1 or self.roi_radius < 2 or self.tile < 2:
            raise ValueError("detection: pad ≥ 1, roi_radius ≥ 2 and tile ≥ 2 are required")


@dataclass
class Blobs:
    """Blobs of one frame: uv (n, 2) centroids [px]; area (n,) [px]; flux (n,) background-subtracted
    sum [DN]; peak (n,) brightest raw pixel [DN]; elongation (n,) ≥ 1; flags (n,) bit mask."""

    uv: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    area: np.ndarray = field(default_factory=lambda: np.zeros(0, int))
    flux: np.ndarray = field(default_factory=lambda: np.zeros(0))
    peak: np.ndarray = field(default_factory=lambda: np.zeros(0))
    elongation: np.ndarray = field(default_factory=lambda: np.zeros(0))
    flags: np.ndarray = field(default_factory=lambda: np.zeros(0, int))

    def __len__(self) -> int:
        return len(self.uv)

    @property
    def usable(self) -> np.ndarray:
        """True for blobs whose centroid can be trusted (not merged, not cut by the frame border)."""
        return (self.flags & (MERGED | EDGE)) == 0

    def subset(self, keep) -> "Blobs":
        return Blobs(self.uv[keep], self.area[keep], self.flux[keep], self.peak[keep], self.elongation[keep],
                     self.flags[keep])

    @staticmethod
    def concat(parts: list) -> "Blobs":
        if not parts:
            return Blobs()
        return Blobs(*(np.concatenate([getattr(p, f) for p in parts]) for f in
                       ("uv", "area", "flux", "peak", "elongation", "flags")))


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


def _measure(signal: np.ndarray, raw: np.ndarray, labels: np.ndarray, stats: np.ndarray, x_off: int, y_off: int,
             frame_shape, cfg: DetectionConfig, sat: float, region_is_frame_edge) -> tuple[Blobs, list]:
    """Centroids of the components of ``labels`` inside one region (offset x_off, y_off in the frame).

    Returns the blobs and, for each, whether it touches the region border where the region is not the
    frame border (then the caller must grow the region).

    Long: one pass over the components whose split, edge and saturation decisions share each blob's window
    and background."""
    H, W = signal.shape
    fh, fw = frame_shape
    out = {k: [] for k in ("uv", "area", "flux", "peak", "el", "flags", "cut")}
    info = []  # per blob: label (−1 after a split), window, background, σ estimate, neighbour labels
    pad, dd = cfg.pad, cfg.mask_dilation

    def emit(uv, area, flux, peak, el, flags, cut, inf):
        for key, val in zip(("uv", "area", "flux", "peak", "el", "flags", "cut"), (uv, area, flux, peak, el, flags, cut)):
            out[key].append(val)
        info.append(inf)

    for k in range(1, len(stats)):
        x0, y0, w, h, area = (int(v) for v in stats[k])
        if area < cfg.min_area or area > cfg.max_area:
            continue
        touches = (x0 == 0 and not region_is_frame_edge[0]) or (y0 == 0 and not region_is_frame_edge[1]) or \
                  (x0 + w == W and not region_is_frame_edge[2]) or (y0 + h == H and not region_is_frame_edge[3])
        wx0, wy0 = max(x0 - pad, 0), max(y0 - pad, 0)
        wx1, wy1 = min(x0 + w + pad, W), min(y0 + h + pad, H)
        S = signal[wy0:wy1, wx0:wx1]
        L = labels[wy0:wy1, wx0:wx1]
        own = L == k
        # other components in or near the window (up to mask_dilation px outside), grown by mask_dilation
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
            continue
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
        elong = float(np.sqrt(l1 / l2))
        peak_raw = float(raw[wy0:wy1, wx0:wx1][own].max())
        flags = 0
        if peak_raw >= sat:
            flags |= SATURATED
        gx0, gy0 = x0 + x_off, y0 + y_off
        if gx0 == 0 or gy0 == 0 or gx0 + w == fw or gy0 + h == fh:
            flags |= EDGE
        if others.any():
            flags |= CROWDED
        window = (wx0, wy0, wx1, wy1)
        # two markers ≥ 3 px apart make a blob elongated (ratio ≥ 1.25 for σ ≤ 2 px): only then look for peaks
        peaks = _peaks(S - b, own) if elong > 1.15 else [None]
        if len(peaks) >= 2:
            if cfg.deblend and len(peaks) <= 4 and not flags & EDGE:
                # two or more markers in one component: split it by a joint fit
                valid = ~((L != 0) & ~own)
                u0 = np.array([p[0] + wx0 + x_off for p in peaks], float)
                v0 = np.array([p[1] + wy0 + y_off for p in peaks], float)
                fit = _fit_spots(S.astype(np.float64) - b, valid, (wx0 + x_off, wy0 + y_off), u0, v0,
                                 np.full(len(peaks), 1.0), np.full(len(peaks), max(tot, 1.0) / len(peaks)), 2.0)
                if fit is not None and _min_separation(fit[0], fit[1]) >= 1.0:
                    for j in range(len(peaks)):
                        emit((fit[0][j], fit[1][j]), area, float(fit[3][j]), peak_raw, 1.0, flags | CROWDED, touches,
                             (-1, window, b, float(fit[2][j]), set()))
                    continue
            flags |= MERGED
        if elong > cfg.max_elongation:
            flags |= ELONGATED
        if cfg.expected_area is not None and area > cfg.merge_area_ratio * cfg.expected_area:
            flags |= MERGED
        emit((cx + x_off, cy + y_off), area, tot, peak_raw, elong, flags, touches,
             (k, window, b, float(np.sqrt(max(tr / 2 - 1 / 12, 0.09))), neighbours))
    blobs = Blobs(np.array(out["uv"], float).reshape(-1, 2), np.array(out["area"], int), np.array(out["flux"], float),
                  np.array(out["peak"], float), np.array(out["el"], float), np.array(out["flags"], int))
    if cfg.deblend and any(i[4] for i in info):
        _deblend(signal, labels, blobs, info, x_off, y_off, cfg)
    return blobs, out["cut"]


def _min_separation(u, v) -> float:
    d = np.hypot(u[:, None] - u[None, :], v[:, None] - v[None, :])
    d[np.diag_indices(len(u))] = np.inf
    return float(d.min())


def _fit_spots(data, valid, origin, u0, v0, s0, f0, max_shift: float):
    """Least-squares fit of pixel-integrated Gaussians (centre, σ, flux each) to ``data`` on ``valid``
    pixels of a window whose top-left pixel is ``origin`` (frame coordinates). Returns (u, v, σ, F) or
    None when the fit fails, a centre moves more than ``max_shift`` px, or σ leaves [0.3, 10] px."""
    n = len(u0)
    if valid.sum() <= 4 * n:
        return None
    p0 = np.concatenate([u0, v0, np.log(s0), np.log(f0)]).astype(np.float64)
    try:
        p, ok = fit_spots_lm(np.ascontiguousarray(data, np.float64), np.ascontiguousarray(valid), int(origin[0]),
                             int(origin[1]), p0, 60)
    except Exception:  # singular normal equations etc.
        return None
    u, v, sg, fl = p[:n], p[n:2 * n], np.exp(p[2 * n:3 * n]), np.exp(p[3 * n:])
    if not (ok and np.all(np.isfinite(p)) and np.all(np.hypot(u - u0, v - v0) < max_shift)
            and np.all((sg > 0.3) & (sg < 10))):
        return None
    return u, v, sg, fl


def _deblend(signal, labels, blobs: Blobs, info: list, x_off: int, y_off: int, cfg: DetectionConfig) -> None:
    """Refine the centroids of crowded blobs by a joint least-squares fit of pixel-integrated Gaussians
    (centre, σ, flux each) to their union window; other components there get zero weight. The fit is
    accepted when it converges with every centre within 1.5 px of its centroid and σ in [0.3, 10] px."""
    label_to_idx = {inf[0]: i for i, inf in enumerate(info) if inf[0] > 0}
    parent = list(range(len(info)))

    def find(i):
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    for i, inf in enumerate(info):
        for lab in inf[4]:
            j = label_to_idx.get(lab)
            if j is not None:
                parent[find(i)] = find(j)
    groups: dict = {}
    for i in range(len(info)):
        if info[i][0] > 0:
            groups.setdefault(find(i), []).append(i)
    for members in groups.values():
        if len(members) < 2 or len(members) > 6:
            continue
        x0 = min(info[i][1][0] for i in members)
        y0 = min(info[i][1][1] for i in members)
        x1 = max(info[i][1][2] for i in members)
        y1 = max(info[i][1][3] for i in members)
        data = signal[y0:y1, x0:x1].astype(np.float64) - float(np.mean([info[i][2] for i in members]))
        L = labels[y0:y1, x0:x1]
        valid = (L == 0) | np.isin(L, [info[i][0] for i in members])
        u0, v0 = blobs.uv[members, 0].copy(), blobs.uv[members, 1].copy()
        s0 = np.array([info[i][3] for i in members])
        f0 = np.array([max(float(data[L == info[i][0]].sum()), 1.0) for i in members])
        fit = _fit_spots(data, valid, (x0 + x_off, y0 + y_off), u0, v0, s0, f0, 1.5)
        if fit is None:
            continue
        blobs.uv[members, 0] = fit[0]
        blobs.uv[members, 1] = fit[1]


def flag_bright(blobs: Blobs, cfg: DetectionConfig) -> Blobs:
    """Flag blobs much brighter or larger than the frame's other blobs as ``MERGED`` (in place)."""
    n = len(blobs)
    if n < 2:
        return blobs
    for i in range(n):
        others = np.arange(n) != i
        f_ref = _median(blobs.flux[others])
        a_ref = _median(blobs.area[others].astype(float))
        if (f_ref > 0 and blobs.flux[i] > cfg.merge_flux_ratio * f_ref) or blobs.area[i] > cfg.merge_area_ratio * a_ref:
            blobs.flags[i] |= MERGED
    return blobs


def _median(a: np.ndarray) -> float:
    a = np.sort(a, axis=None)
    n = a.size
    return 0.5 * float(a[(n - 1) // 2] + a[n // 2])


def _peaks(S: np.ndarray, own: np.ndarray) -> list:
    """Separate intensity peaks inside a blob, as window (x, y): local maxima of the 3×3-smoothed image
    ≥ 30 % of the highest, ≥ 3 px apart and with a valley in the image (< 80 % of the lower maximum)
    between them."""
    if own.sum() < 6:
        return [None]
    Sm = cv2.blur(S, (3, 3))
    mx = cv2.dilate(Sm, np.ones((3, 3), np.uint8))
    top = Sm[own].max()
    cand = ((Sm >= mx) & own & (Sm >= 0.3 * top)).astype(np.uint8)
    n, lab = cv2.connectedComponents(cand, connectivity=8)  # a plateau of maxima is one peak
    if n <= 2:
        return [None]
    xs, ys = [], []
    for k in range(1, n):
        yy, xx = np.nonzero(lab == k)
        j = int(np.argmax(Sm[yy, xx]))
        xs.append(xx[j])
        ys.append(yy[j])
    xs, ys = np.array(xs), np.array(ys)
    centres = []
    for i in np.argsort(-Sm[ys, xs], kind="stable"):  # greedy: brightest first
        p = (float(xs[i]), float(ys[i]))
        if all(np.hypot(p[0] - c[0], p[1] - c[1]) >= 3.0 and _valley(S, p, c) for c in centres):
            centres.append(p)
    return centres


def _valley(S: np.ndarray, a, b, depth: float = 0.8) -> bool:
    """True if the intensity dips below ``depth`` × the lower of two maxima somewhere between them
    (two blobs), False for a ridge or plateau (a motion streak, a saturated top)."""
    n = int(np.ceil(2 * np.hypot(a[0] - b[0], a[1] - b[1]))) + 1
    t = np.linspace(0.0, 1.0, n)
    xs = np.rint(a[0] + t * (b[0] - a[0])).astype(int)
    ys = np.rint(a[1] + t * (b[1] - a[1])).astype(int)
    low = min(S[int(a[1]), int(a[0])], S[int(b[1]), int(b[0])])
    return bool(S[ys, xs].min() < depth * low)


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
        blobs, _ = _measure(sig, g[y0:y1, x0:x1], labels, stats, x0, y0, g.shape, cfg, sat, edge)
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
            blobs, cut = _measure(sig, g[y0:y1, x0:x1], labels, stats, x0, y0, g.shape, cfg, sat, edge)
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
