"""Defects of synthetic marker data (the ``defects`` block of SYNTH.yaml): AR(1) noise, per-point noise scales,
swapped labels and gross outliers.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


#: kinds of data defect (``defects:`` keys)
DEFECT_KINDS = ("outliers", "swaps", "ar1", "sigma_m")


@dataclass(frozen=True)
class Defects:
    """Data defects of one synthetic flight (module docstring); the defaults are off.

    Attributes
    ----------
    outlier_fraction : float
        Fraction of the observed points made gross outliers.
    outlier_size_m : tuple of float
        (low, high) displacement of an outlier [m]; the size is uniform in it, the direction uniform on
        the sphere.
    swap_frames : int
        Number of frames (sample times) in which two markers' labels are exchanged.
    swap_fraction : float
        Fraction of the frames with a swap (added to ``swap_frames``: ``round(fraction · n_frames)``).
    ar1_rho : float
        AR(1) coefficient ρ of the marker noise between consecutive samples (0: white noise).
    sigma_fraction : float
        Fraction of the flight's samples with ``sigma_factor`` × the noise.
    sigma_factor : float
        Noise multiplier k of those samples.
    sigma_where : str
        ``segment`` (one contiguous block of samples, all markers) or ``random`` (random points).
    """

    outlier_fraction: float = 0.0
    outlier_size_m: tuple = (0.02, 0.06)
    swap_frames: int = 0
    swap_fraction: float = 0.0
    ar1_rho: float = 0.0
    sigma_fraction: float = 0.0
    sigma_factor: float = 1.0
    sigma_where: str = "segment"
    per_point_sigma: bool = False   # write a sigma_m column (set when any sigma_m block is given)

    @property
    def any(self) -> bool:
        """Whether the flight has any defect (or a sigma_m column)."""
        return (self.outlier_fraction > 0 or self.swap_frames > 0 or self.swap_fraction > 0 or self.ar1_rho != 0
                or self.per_point_sigma)


# ------------------------------------------------------------------------------------------- defects
def ar1_noise(z: np.ndarray, rho: float) -> np.ndarray:
    """Unit-variance AR(1) noise along the first axis from white standard normals.

    e_0 = z_0, e_t = ρ e_{t−1} + √(1−ρ²) z_t: stationary from the first sample, Var e_t = 1,
    Corr(e_t, e_{t+k}) = ρ^k.

    Parameters
    ----------
    z : ndarray, shape (n, ...)
        White N(0, 1) draws; axis 0 is time (one sample interval per step).
    rho : float
        AR(1) coefficient, |ρ| < 1 (0 returns ``z`` itself).

    Returns
    -------
    ndarray, shape of ``z``
    """
    if rho == 0.0:
        return z
    e = np.empty_like(z)
    e[0] = z[0]
    c = np.sqrt(1.0 - rho * rho)
    for t in range(1, z.shape[0]):
        e[t] = rho * e[t - 1] + c * z[t]
    return e


def point_sigmas(n: int, n_markers: int, sigma: float, d: Defects, rng: np.random.Generator):
    """Every point's noise sd: ``sigma`` [m], times ``d.sigma_factor`` on a fraction of the samples.

    Parameters
    ----------
    n, n_markers : int
        Samples and markers of the flight.
    sigma : float
        The flight's noise sd [m].
    d : Defects
        ``sigma_fraction`` of the samples (``segment``: one contiguous block of all markers, at a uniformly
        random place; ``random``: random points) get ``sigma_factor`` × ``sigma``.
    rng : numpy.random.Generator

    Returns
    -------
    sig : ndarray, shape (n, n_markers)
        Point sds [m].
    truth : dict
        fraction, factor, where, and the points with the larger noise (``t_range_s`` index range for a
        segment, ``n_points``).
    """
    sig = np.full((n, n_markers), sigma)
    truth = {"fraction": d.sigma_fraction, "factor": d.sigma_factor, "where": d.sigma_where}
    if d.sigma_fraction <= 0.0:
        truth["n_points"] = 0
        return sig, truth
    if d.sigma_where == "segment":
        m = int(round(d.sigma_fraction * n))
        start = int(rng.integers(0, n - m + 1))
        sig[start:start + m] *= d.sigma_factor
        truth["samples"] = [start, start + m]
        truth["n_points"] = m * n_markers
    else:
        hit = rng.random((n, n_markers)) < d.sigma_fraction
        sig[hit] *= d.sigma_factor
        truth["n_points"] = int(hit.sum())
    return sig, truth


def swap_labels(pos: np.ndarray, sig: np.ndarray | None, d: Defects, rng: np.random.Generator) -> list:
    """Exchange two observed markers' labels in randomly chosen frames (in place).

    Parameters
    ----------
    pos : ndarray, shape (n, n_markers, 3)
        Recorded positions [m], NaN where missing; modified.
    sig : ndarray, shape (n, n_markers), or None
        Point sds [m], exchanged with the positions; modified.
    d : Defects
        ``swap_frames`` + round(``swap_fraction`` · n) frames, among those with ≥ 2 observed markers.
    rng : numpy.random.Generator

    Returns
    -------
    list of (frame, marker a, marker b)
        Indices of every swapped frame and its two markers, in time order.
    """
    observed = np.all(np.isfinite(pos), axis=-1)
    eligible = np.flatnonzero(observed.sum(axis=1) >= 2)
    want = d.swap_frames + int(round(d.swap_fraction * pos.shape[0]))
    if want > eligible.size:
        raise ValueError(f"{want} label swaps asked for but only {eligible.size} frames have two markers")
    out = []
    for i in np.sort(rng.choice(eligible, size=want, replace=False)):
        a, b = np.sort(rng.choice(np.flatnonzero(observed[i]), size=2, replace=False))
        pos[i, [a, b]] = pos[i, [b, a]]
        if sig is not None:
            sig[i, [a, b]] = sig[i, [b, a]]
        out.append((int(i), int(a), int(b)))
    return out


def inject_outliers(pos: np.ndarray, d: Defects, rng: np.random.Generator) -> list:
    """Displace a fraction of the observed points by a gross error (in place).

    Each chosen point moves by s·u, s ~ U(``outlier_size_m``) [m], u uniform on the unit sphere.

    Parameters
    ----------
    pos : ndarray, shape (n, n_markers, 3)
        Recorded positions [m], NaN where missing; modified.
    d : Defects
        ``outlier_fraction`` of the observed points (rounded) become outliers.
    rng : numpy.random.Generator

    Returns
    -------
    list of (frame, marker, offset)
        Index of each outlier's frame and marker and its displacement [m] (list of 3), in time order.
    """
    obs = np.argwhere(np.all(np.isfinite(pos), axis=-1))
    m = int(round(d.outlier_fraction * len(obs)))
    if m == 0:
        return []
    chosen = obs[np.sort(rng.choice(len(obs), size=m, replace=False))]
    u = rng.normal(size=(m, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    size = rng.uniform(d.outlier_size_m[0], d.outlier_size_m[1], size=m)
    out = []
    for (i, k), uj, sj in zip(chosen, u, size):
        off = uj * sj
        pos[i, k] += off
        out.append((int(i), int(k), off.tolist()))
    return out
