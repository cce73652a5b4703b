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


def _pdf(z):
    return np.exp(-0.5 * z * z) / np.sqrt(2 * np.pi)


def spots_and_jacobian(shape, origin, u, v, sigma, flux):
    """Spots image (shape) and its derivatives with respect to (u, v, ln σ, ln F) of every spot:
    returns image (h, w) and J (h, w, 4 S) ordered [u_1..u_S, v_1..v_S, lnσ_1.., lnF_1..]."""
    h, w = shape
    x0, y0 = origin
    u = np.asarray(u, float).reshape(-1)
    v = np.asarray(v, float).reshape(-1)
    sg = np.asarray(sigma, float).reshape(-1)
    fl = np.asarray(flux, float).reshape(-1)
    S = len(u)
    xs = np.arange(x0, x0 + w, dtype=float)[None, :]
    ys = np.arange(y0, y0 + h, dtype=float)[None, :]
    s = sg[:, None]
    ax, bx = (xs + 0.5 - u[:, None]) / s, (xs - 0.5 - u[:, None]) / s
    ay, by = (ys + 0.5 - v[:, None]) / s, (ys - 0.5 - v[:, None]) / s
    r2 = np.sqrt(2.0)
    ex = 0.5 * (erf(ax / r2) - erf(bx / r2))
    ey = 0.5 * (erf(ay / r2) - erf(by / r2))
    pax, pbx, pay, pby = _pdf(ax), _pdf(bx), _pdf(ay), _pdf(by)
    dex_du = -(pax - pbx) / s                 # ∂ex/∂u
    dey_dv = -(pay - pby) / s
    dex_dls = -(ax * pax - bx * pbx)          # σ ∂ex/∂σ
    dey_dls = -(ay * pay - by * pby)
    img = np.einsum("s,sy,sx->yx", fl, ey, ex)
    J = np.empty((h, w, 4 * S))
    for k in range(S):
        J[:, :, k] = fl[k] * np.outer(ey[k], dex_du[k])
        J[:, :, S + k] = fl[k] * np.outer(dey_dv[k], ex[k])
        J[:, :, 2 * S + k] = fl[k] * (np.outer(dey_dls[k], ex[k]) + np.outer(ey[k], dex_dls[k]))
        J[:, :, 3 * S + k] = fl[k] * np.outer(ey[k], ex[k])
    return img, J
