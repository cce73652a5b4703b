"""θ at the truth of a synthetic data set (``bayes-disc synth``'s truth JSON, docs/configuration.md).

Used where a known truth is compared with what the fit reports: calibration checks at the truth, recovery
benchmarks and tests. Entries the truth JSON does not give (physics-term parameters, explanations, noise
parameters of models the synthesis did not use) stay at the problem's start values (:meth:`Problem.start_vector`).
"""
from __future__ import annotations

import numpy as np

from ...observation.markers import FlightObservation
from ...physics import COEFFICIENT_NAMES
from .problem import Problem

#: the inertial logger's shared mount parameters: θ name -> (truth key, index or None)
_LOGGER_SHARED = {"imu_offset_x": ("offset_m", 0), "imu_offset_y": ("offset_m", 1), "imu_offset_z": ("offset_m", 2),
                  "imu_lpf_tau": ("lpf_tau_s", None), "imu_tilt_1": ("tilt_rad", 0), "imu_tilt_2": ("tilt_rad", 1)}


def initial_state(truth: dict, flight: str) -> np.ndarray:
    """(13,) true state at release of ``flight``: position [m], velocity [m/s], quaternion (w, x, y, z,
    body → world), body rates [rad/s]."""
    s = truth["flights"][flight]["initial_state"]
    return np.concatenate([s["position_m"], s["velocity_m_s"], s["quaternion_wxyz_body_to_world"],
                           s["omega_body_rad_s"]]).astype(float)


def truth_theta(problem: Problem, truth: dict) -> np.ndarray:
    """θ (dim,) of ``problem`` at the truth: the coefficients, every flight's initial conditions, the
    logger's mount and per-throw parameters (when the truth has a logger) and each flight's AR(1) coefficient
    ``rho_<flight>`` (when the truth's marker noise was AR(1) and the problem fits it).

    Parameters
    ----------
    problem : Problem
    truth : dict
        The truth JSON of the data set (:func:`bayes_disc.observation.synth.synthesize`).

    Returns
    -------
    (dim,) array

    Raises
    ------
    KeyError
        If the truth has no entry for one of the problem's flights.
    ValueError
        If a marker flight's samples do not start where the truth's initial state is given.
    """
    theta = problem.start_vector()
    names = problem.names
    coef = truth["coefficients"]
    theta[: problem.n_coef] = [coef[n] for n in COEFFICIENT_NAMES]
    logger = truth.get("imu", {}).get("logger")
    if logger is not None:
        for n, (key, i) in _LOGGER_SHARED.items():
            if n in names:
                theta[names.index(n)] = logger[key] if i is None else logger[key][i]
    for k, f in enumerate(problem.flights):
        t0 = float(truth["flights"][f.name]["initial_state"].get("t", 0.0))
        if isinstance(f, FlightObservation) and abs(float(f.times[0]) - t0) > 1e-9:
            raise ValueError(f"flight {f.name!r}: its samples start at t = {float(f.times[0]):g} s, the truth's "
                             f"initial state is at t = {t0:g} s (a trimmed window has other initial conditions)")
        theta[problem.ic_slice(k)] = problem.state_to_ic(initial_state(truth, f.name), k)
        rho = truth["flights"][f.name].get("defects", {}).get("ar1_rho")
        if rho is not None and f"rho_{f.name}" in names:
            theta[names.index(f"rho_{f.name}")] = rho
        t = truth.get("imu", {}).get("throws", {}).get(f.name)
        if t is None or f"imu_period_{f.name}" not in names:
            continue
        own = {"imu_period": t["period_s"], **{f"gyro_bias_{a}": v for a, v in zip("xyz", t["gyro_bias_rad_s"])},
               **{f"acc_bias_{a}": v for a, v in zip("xyz", t["acc_bias_m_s2"])},
               **{f"lpf_state_{a}": v for a, v in zip("xyz", t["lpf_state_m_s2"])}}
        for n, v in own.items():
            theta[names.index(f"{n}_{f.name}")] = v
    return theta
