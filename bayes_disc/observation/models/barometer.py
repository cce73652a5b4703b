"""The barometer of an inertial logger: the height of the simulated flight, seen as pressure through a lag.

A logger fixed in the disc reads the pressure at its sensor. Over a throw (a few metres of height, a few
seconds) the hydrostatic relation is linear, the sensor's port may also see a part of the dynamic pressure of
the flow past the disc, and the sensor follows the outside pressure with a first-order lag:

    p_e(t) = p_0 − ρ g (z(t) − z(0)) + c_q · ½ ρ |v(t)|²                                      [Pa]
    τ_b dp_s/dt = p_e(t) − p_s(t),   p_s(0) = s_0
    reading k:  p_s(t_k)

with z the simulated height of the centre of mass [m], v its velocity [m/s] (no wind: air speed = ground
speed; the run's wind terms are not seen by this channel), ρ the air density [kg/m³] and g the gravitational
acceleration [m/s²] of the run, p_0 the outside pressure at the release height in that throw [Pa], c_q the
port's pressure coefficient [–] (0: only the static pressure; the flow under a lifting disc is above it, over
it below), τ_b the lag [s] (a vented enclosure or the sensor's own filter) and s_0 the sensor's pressure at
release [Pa] (the throwing motion before release moved the disc through the air).

Why a lag: the flatball logger's pressure keeps rising for seconds after the disc has landed and lies still
(|ω| = 0, |a| = g): 5–28 Pa, approaching its final value roughly as e^(−t/τ) with τ ≈ 0.5–0.9 s over the
first 1.5 s. A sensor that read the outside pressure directly would be constant there.

After the flight: the rows that follow the impact (``landing``: the disc on the ground, sliding to rest)
carry readings too. Their outside pressure is taken as p_0 − ρ g (z(T) − z(0)), the height at the flight's
last row T (the impact follows within a row) held and no dynamic part, so the sensor relaxes as
p_s(t) = p_e(T) + (p_s(T) − p_e(T)) e^(−(t − T)/τ_b). These readings fix the lag and the landing height:
the pressure the flight has to end at.

Which rows are readings: the flatball firmware reads the barometer in its own task, which sleeps 0.1 s after
each reading, and every log row repeats the latest reading. So only the rows where the pressure changes are
readings (about one in eight); a reading was taken between the row before and its own row, and its time is
taken as half a row before the row, t_k = (row_k − row_0 − ½) P with the throw's row period P (the same
clock as the gyroscope's). A reading that repeats the previous value by chance is lost, not counted twice.

Not modelled: the sensor's conversion time (a few milliseconds), pressure changes of the weather during a
throw, the spin's centrifugal pressure in the logger's enclosure (½ ρ r² ω² ≈ 1 Pa at 2 cm and 55 rad/s,
nearly constant), any dependence of the port's coefficient on the angle of attack or the spin phase, the
sliding disc's speed after the impact and a lag that is not first order (over longer rests the approach
slows: a slower second part is not described).

Parameters — shared by the run's throws (one logger, one port): ``baro_dynamic_coefficient`` c_q [–],
prior N(0, 0.5²); ``baro_lag`` τ_b [s], prior N(0.5, 1²) (positive: a lag ≤ 0 has no prediction). Per throw:
``baro_reference`` p_0 and ``baro_state`` s_0 [Pa], priors N(p_release, 50²) centred on the throw's reading
at release. Noise: one group per throw (``baro``, Pa), its σ integrated out (Jeffreys prior) as the
observation-model contract does.
"""
from __future__ import annotations

import numpy as np

from ...physics import TermParameter

BARO_SHARED_PARAMETERS = (
    TermParameter("baro_dynamic_coefficient", "1", "pressure coefficient c_q of the barometer's port "
                  "(fraction of the dynamic pressure it reads)", 0.0, 0.5),
    TermParameter("baro_lag", "s", "time constant τ_b of the barometer's first-order lag", 0.5, 1.0),
)
#: prior sd [Pa] of the pressure at the release height around the throw's reading at release
BARO_REFERENCE_SD = 50.0
BARO_GROUPS = ("baro",)
BARO_SERIES = ("baro",)
#: nominal noise scale [Pa]: first least-squares weight
BARO_NOMINAL_NOISE = (0.5,)


def own_parameters(release_reading: float) -> tuple[TermParameter, TermParameter]:
    """The per-throw parameters p_0 and s_0 [Pa], centred on the throw's pressure reading at release.

    Parameters
    ----------
    release_reading : float
        The log's first pressure reading from the release row on [Pa].

    Returns
    -------
    tuple of TermParameter
        ``baro_reference`` (p_0), ``baro_state`` (s_0).
    """
    return (TermParameter("baro_reference", "Pa", "outside pressure p_0 at the release height",
                          float(release_reading), BARO_REFERENCE_SD),
            TermParameter("baro_state", "Pa", "sensor pressure s_0 at release", float(release_reading),
                          BARO_REFERENCE_SD))


def reading_rows(pressure: np.ndarray) -> np.ndarray:
    """Indices of the rows that carry a new barometer reading (the value differs from the row before).

    Parameters
    ----------
    pressure : (n,) array
        The log's pressure column [Pa], one value per row (the latest reading repeated).

    Returns
    -------
    (m,) int array
        Row indices i ≥ 1 with ``pressure[i] != pressure[i − 1]`` (both finite).
    """
    p = np.asarray(pressure, float)
    new = np.isfinite(p[1:]) & np.isfinite(p[:-1]) & (p[1:] != p[:-1])
    return np.flatnonzero(new) + 1


def outside_pressure(climb: np.ndarray, speed: np.ndarray, reference: np.ndarray, dynamic: np.ndarray, rho: float,
                     g: float) -> np.ndarray:
    """The pressure the sensor follows (module docstring): p_e = p_0 − ρ g Δz + c_q ½ ρ |v|².

    Parameters
    ----------
    climb : (B, n) array
        Height above the release height, z(t) − z(0) [m].
    speed : (B, n) array
        |v(t)| [m/s].
    reference, dynamic : (B,) arrays
        p_0 [Pa] and c_q [–].
    rho, g : float
        Air density [kg/m³] and gravitational acceleration [m/s²].

    Returns
    -------
    (B, n) array
        p_e [Pa].
    """
    return reference[:, None] - rho * g * climb + dynamic[:, None] * 0.5 * rho * speed ** 2


def relax(start: np.ndarray, target: np.ndarray, elapsed: np.ndarray, lag: np.ndarray) -> np.ndarray:
    """The lagged sensor after the flight: p_s = p_e + (p_s(T) − p_e) e^(−(t − T)/τ_b).

    Parameters
    ----------
    start, target : (B,) arrays
        p_s(T) and the held outside pressure p_e(T) [Pa].
    elapsed : (B, n) array
        t − T [s] (≥ 0).
    lag : (B,) array
        τ_b [s] (> 0).

    Returns
    -------
    (B, n) array
        p_s [Pa].
    """
    return target[:, None] + (start - target)[:, None] * np.exp(-elapsed / lag[:, None])
