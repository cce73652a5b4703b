"""A randomly forced nutation in the transverse gyro: the noise of a logger's gyro x and y when the disc's
free wobble is kept alive by forcing the flight model does not carry (``gyro_noise: nutation``).

A flight model without process noise (an *output-error* fit) must reproduce the wobble's phase from release to
landing. A free nutation that is forced along the way — by gusts, turbulence in the air the disc flies
through, or any moment the model lacks that is not repeatable — has a phase no deterministic model can
follow; its residual then looks like a narrow-band signal at the wobble's rate and is counted as misfit.
The *filter-error* method of flight-vehicle identification (Jategaonkar, Flight Vehicle System
Identification: A Time Domain Methodology, AIAA, 2nd ed. 2015, ch. 5) gives that part of the state its own
random dynamics and fits the model through a Kalman filter. This unit does so for the one mode it concerns,
about the simulated flight: the transverse rate the model misses,

    z = δω_x + i δω_y     [rad/s, sensor axes, complex]

turns in the disc at κ_N times the spin r and relaxes at the rate λ, driven by white forcing:

    dz/dt = (i κ_N r − λ) z + √(4 λ a²) σ w(t),   w: complex white noise of unit intensity

so that its stationary variance is E|z|² = 2 a² σ², i.e. a σ per axis, with σ the gyro's white noise
(``sigma_gyro_transverse``, integrated out as every noise scale). The gyro reads

    y_k = ω_model(t_k) + z(t_k) + σ ε_k,   ε_k ~ N(0, I₂)

Over a row step Δt_k = t_k − t_(k−1) the exact transition is

    z_k = e^(−λ Δt_k) e^(i κ_N r̄_k Δt_k) z_(k−1) + η_k,    E|η_k|² = 2 a² σ² (1 − e^(−2 λ Δt_k))

with r̄_k the mean of the measured spin rates (gyro z) of the two rows. The Kalman filter in units of σ²
(P̃ = E|z − ẑ|²/σ²) starts from z = 0 at release (P̃_0 = 0: the wobble at release is the flight model's,
fitted with the throw's initial body rates; the random part builds up after it, towards E|z|² = 2a²σ²
within about 1/(2λ)) and runs

    predict:  ẑ ← e^(−λ Δt) e^(i κ_N r̄ Δt) ẑ,   P̃ ← e^(−2λ Δt) P̃ + 2 a² (1 − e^(−2λ Δt))
    innovate: v_k = r_k − ẑ,   S̃_k = 1 + P̃/2   (per axis, in units of σ²)
    update:   ẑ ← ẑ + K v_k,   P̃ ← (1 − K) P̃,   K = P̃ / (P̃ + 2)

with r_k the residual (model − data) of the row's gyro x + i y. The innovations are a causal, lower-triangular
map of the residuals, so e_k = v_k / √S̃_k are independent N(0, σ²) per axis and log |W| = −Σ_k log S̃_k
(both axes): the unit whitens the residuals exactly (:meth:`.base.ObservationModel.whiten`) and the
likelihood with σ integrated out keeps its form. With a = 0 it is the white gyro noise exactly.

Parameters, shared by the throws of one logger (one disc, one air): ``nutation_decay`` λ [1/s] (> 0),
``nutation_kappa`` κ_N [–], ``nutation_amplitude`` a [–] (≥ 0, the random nutation's RMS per axis in units
of the gyro noise σ). Priors: λ ~ N(3, 3²) truncated to λ > 0 (a free wobble that relaxes in about 0.3 s;
0 is a mode that never relaxes), κ_N ~ N(0.93, 0.1²) (the torque-free rigid disc's κ = Ia/Id − 1 of the
default disc, and the 0.78–1.01 the real throws span), a ~ N(1, 3²) truncated to a ≥ 0 (outside the
truncations the likelihood is zero).

What it does not do: the random nutation is a deviation of the angular velocity only. Its small attitude
change (|z| / (κ_N + 1) r ≈ 0.3° for 0.5 rad/s at r = 60 rad/s) and what that does to the accelerometer,
magnetometer and flight path are neglected, and the forcing is not named: it is whatever moves the wobble
without being repeatable. The fitted a, λ say how large and how long-lived that part is; what the model
then leaves in σ is what neither the flight model nor the random nutation explain.
"""
from __future__ import annotations

import math

import numba as nb
import numpy as np

from ...physics import TermParameter

#: ``gyro_noise`` values of an ``imu:`` entry
GYRO_NOISE = ("white", "nutation")

NUTATION_SHARED_PARAMETERS = (
    TermParameter("nutation_decay", "1/s", "relaxation rate λ of the randomly forced nutation (> 0)",
                  off_value=3.0, prior_sd=3.0),
    TermParameter("nutation_kappa", "1", "turning rate κ_N of the randomly forced nutation in the disc, per unit "
                  "spin", off_value=0.93, prior_sd=0.1),
    TermParameter("nutation_amplitude", "1", "RMS per axis a of the randomly forced nutation, in units of the "
                  "transverse gyro noise σ (≥ 0; 0: white gyro noise)", off_value=0.0, prior_sd=3.0,
                  prior_mean=1.0),
)


@nb.njit(cache=True)
def nutation_filter(rx, ry, dt, spin, decay, kappa, amplitude):
    """Kalman-filter innovations of the transverse gyro residuals under a randomly forced nutation
    (module docstring).

    Parameters
    ----------
    rx, ry : (B, n) arrays
        Residuals of gyro x and y [rad/s] of n consecutive rows.
    dt : (B, n) array
        Time since the previous row [s] (the first column is not read).
    spin : (n,) array
        Spin rate r of each row [rad/s] (the measured gyro z).
    decay, kappa, amplitude : (B,) arrays
        λ [1/s], κ_N [–], a [–].

    Returns
    -------
    ex, ey : (B, n) arrays
        Whitened residuals v_k / √S̃_k [rad/s]; NaN for a lane with λ ≤ 0, a < 0 or a non-finite parameter.
    log_diag : (B, n) array
        −½ log S̃_k, the log of the whitening's diagonal for each axis of row k.
    """
    B, n = rx.shape
    ex = np.empty((B, n))
    ey = np.empty((B, n))
    ld = np.empty((B, n))
    for b in range(B):
        lam, kap, a = decay[b], kappa[b], amplitude[b]
        if not (lam > 0.0 and a >= 0.0 and math.isfinite(lam) and math.isfinite(kap) and math.isfinite(a)):
            ex[b, :] = np.nan
            ey[b, :] = np.nan
            ld[b, :] = np.nan
            continue
        p_inf = 2.0 * a * a
        p = 0.0
        zx = 0.0
        zy = 0.0
        for k in range(n):
            if k > 0:
                d = math.exp(-lam * dt[b, k])
                ang = kap * 0.5 * (spin[k] + spin[k - 1]) * dt[b, k]
                c, s = math.cos(ang), math.sin(ang)
                zx, zy = d * (c * zx - s * zy), d * (s * zx + c * zy)
                p = d * d * p + p_inf * (1.0 - d * d)
            s_k = 1.0 + 0.5 * p
            vx, vy = rx[b, k] - zx, ry[b, k] - zy
            w = 1.0 / math.sqrt(s_k)
            ex[b, k] = vx * w
            ey[b, k] = vy * w
            ld[b, k] = -0.5 * math.log(s_k)
            gain = p / (p + 2.0)
            zx += gain * vx
            zy += gain * vy
            p *= 1.0 - gain
    return ex, ey, ld


def nutation_covariance(t: np.ndarray, spin: np.ndarray, decay: float, kappa: float, amplitude: float) -> np.ndarray:
    """The covariance (2n, 2n) of the transverse gyro noise of n rows in units of σ² (rows x₁ y₁ x₂ y₂ …):
    the random nutation's (zero at the first row, the release) plus the identity. Dense, for checking
    :func:`nutation_filter` and :func:`sample_nutation`.

    Parameters
    ----------
    t : (n,) array
        Row times [s], increasing; the first is the release.
    spin : (n,) array
        Spin rate of each row [rad/s].
    decay, kappa, amplitude : float
        λ [1/s], κ_N [–], a [–].

    Returns
    -------
    (2n, 2n) array
    """
    t, spin = np.asarray(t, float), np.asarray(spin, float)
    # phase of the nutation's turning: ∫ κ_N r dt with the row means of r (as the filter)
    phase = np.r_[0.0, np.cumsum(kappa * 0.5 * (spin[1:] + spin[:-1]) * np.diff(t))]
    since = t - t[0]
    # E[z_k z̄_j] / 2 = a² e^(−λ|t_k − t_j|) (1 − e^(−2λ min(t_k, t_j))) e^(i(φ_k − φ_j))
    dec = np.exp(-decay * np.abs(t[:, None] - t[None, :])) * (1.0 - np.exp(-2.0 * decay * np.minimum.outer(since, since)))
    ang = phase[:, None] - phase[None, :]
    c = amplitude ** 2 * dec * np.cos(ang)                    # E[x_k x_j] = E[y_k y_j]
    s = amplitude ** 2 * dec * np.sin(ang)                    # E[y_k x_j] = −E[x_k y_j]
    n = t.size
    cov = np.empty((2 * n, 2 * n))
    cov[0::2, 0::2] = c
    cov[1::2, 1::2] = c
    cov[1::2, 0::2] = s
    cov[0::2, 1::2] = -s
    return cov + np.eye(2 * n)


def sample_nutation(t: np.ndarray, spin: np.ndarray, decay: float, kappa: float, rms: float,
                    rng: np.random.Generator) -> np.ndarray:
    """A randomly forced nutation z (n, 2) [rad/s] (x, y) at the rows t, drawn with the filter's exact
    transition (module docstring) from z = 0 at the first row (the release): what a logger's gyro adds to the
    flight model's transverse rates.

    Parameters
    ----------
    t : (n,) array
        Row times [s], increasing.
    spin : (n,) array
        Spin rate r of each row [rad/s].
    decay, kappa : float
        λ [1/s] (> 0), κ_N [–].
    rms : float
        The nutation's stationary RMS per axis a σ [rad/s].
    rng : numpy.random.Generator

    Returns
    -------
    (n, 2) array
    """
    if not decay > 0 or rms < 0:
        raise ValueError(f"sample_nutation: decay must be > 0 and rms ≥ 0, got {decay!r}, {rms!r}")
    t, spin = np.asarray(t, float), np.asarray(spin, float)
    eps = rng.standard_normal((t.size, 2))
    z = np.empty((t.size, 2))
    z[0] = 0.0
    for k in range(1, t.size):
        dt = t[k] - t[k - 1]
        d = np.exp(-decay * dt)
        ang = kappa * 0.5 * (spin[k] + spin[k - 1]) * dt
        c, s = np.cos(ang), np.sin(ang)
        z[k] = d * np.array([c * z[k - 1, 0] - s * z[k - 1, 1], s * z[k - 1, 0] + c * z[k - 1, 1]])
        z[k] += rms * np.sqrt(1.0 - d * d) * eps[k]
    return z
