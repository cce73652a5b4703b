"""Pixel-integrated Gaussian spots, shared by the renderer and the deblender.

A spot of flux F [DN], centre (u, v) and standard deviation σ [px] gives pixel (x, y) (pixel centres at
integers) the value F · e(x; u, σ) · e(y; v, σ) with

    e(x; u, σ) = ½ [erf((x + ½ − u) / (√2 σ)) − erf((x − ½ − u) / (√2 σ))],

the exact integral of the Gaussian over the pixel.
"""
from __future__ import annotations

import numpy as np
from scipy.special import erf


def pixel_integrals(centres, sigma, first: int, count: int) -> np.ndarray:
    """e(x; c, σ) for pixels x = first .. first+count−1 and spots c (S,), σ (S,): array (S, count)."""
    xs = np.arange(first, first + count, dtype=float)
    s2 = (np.sqrt(2.0) * np.asarray(sigma, float).reshape(-1))[:, None]
    c = np.asarray(centres, float).reshape(-1)[:, None]
    return 0.5 * (erf((xs + 0.5 - c) / s2) - erf((xs - 0.5 - c) / s2))


def pixel_integrated_gaussian(u, v, sigma, x0, x1, y0, y1):
    """Per-axis pixel integrals of unit Gaussians centred at (u, v) (S,) with σ (S,) [px] over columns
    x0..x1−1 and rows y0..y1−1: returns ex (S, nx), ey (S, ny); spot s is F · ey[s]ᵀ ex[s]."""
    return pixel_integrals(u, sigma, x0, x1 - x0), pixel_integrals(v, sigma, y0, y1 - y0)


def spots(shape, origin, u, v, sigma, flux) -> np.ndarray:
    """Image (shape) with top-left pixel at ``origin`` (x0, y0) holding Gaussian spots (S,)."""
    h, w = shape
    x0, y0 = origin
    ex, ey = pixel_integrated_gaussian(u, v, sigma, x0, x0 + w, y0, y0 + h)
    return np.einsum("s,sy,sx->yx", np.asarray(flux, float).reshape(-1), ey, ex)
