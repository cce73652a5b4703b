"""Plausibility of a least-squares fit before sampling: a flight whose residual RMS is many times any
plausible marker noise means the data or the set-up are wrong, and sampling would only spend minutes
quantifying the uncertainty of nonsense.

Threshold :data:`MAX_PLAUSIBLE_RMS_M` = 20 mm: motion capture measures disc markers to 0.1–3 mm and
video triangulation to a few mm; physics the base model lacks (side force, wind, ground effect, marker
offsets of a few mm, a gust) leaves 1–3× the noise on synthetic flights (tests/test_missing_physics.py),
i.e. below 10 mm even with 3 mm noise. A y-up export gave 22–70 mm; time in milliseconds,
a wrong layout or two throws under one flight name give tens of mm or more.
"""
from __future__ import annotations

import numpy as np

from ...observation.plausibility import ImplausibleDataError

MAX_PLAUSIBLE_RMS_M = 0.020


def check_fit_plausible(ls, problem, max_rms_m: float = MAX_PLAUSIBLE_RMS_M) -> None:
    """Stop when any flight's least-squares residual RMS exceeds ``max_rms_m``.

    Parameters
    ----------
    ls : LeastSquaresResult
        The fit (``ls.sigma`` holds each noise group's residual RMS; the marker group of a flight is
        ``sigma_<flight>`` [m]; flights without markers are not checked here).
    problem : Problem
        Its problem (``problem.flights`` give the file, line and name of each flight).
    max_rms_m : float
        Largest plausible RMS [m].

    Raises
    ------
    ImplausibleDataError
        Naming the worst flight, its RMS and the likely causes.
    """
    names = list(problem.sigma_names)
    marker = [k for k, f in enumerate(problem.flights) if f"sigma_{f.name}" in names]   # flights with markers
    rms = np.zeros(problem.n_flights)
    rms[marker] = [ls.sigma[names.index(f"sigma_{problem.flights[k].name}")] for k in marker]
    bad = np.flatnonzero(rms > max_rms_m)
    if not bad.size:
        return
    k = int(bad[np.argmax(rms[bad])])
    others = [problem.flights[i].name for i in bad if i != k]
    also = f" (also {', '.join(others)})" if others else ""
    raise ImplausibleDataError(
        problem.flights[k],
        f"the least-squares fit leaves a marker RMS of {rms[k] * 1e3:.1f} mm{also}, more than "
        f"{max_rms_m * 1e3:g} mm (many times any plausible marker noise): the model cannot describe these "
        "data, and sampling them would only quantify nonsense. Likely causes: axes (z must point up), time "
        "units (s), marker layout or ids in the config, two throws under one flight name, or a flight cut "
        "badly (check flight_options windows)")
