"""Profile-likelihood intervals: a coefficient's interval from its profile path alone.

Along the path of θ_i (:mod:`.profile`) the other parameters — the other coefficients and every flight's
initial conditions — are re-optimised at each value v, and the profile deviance D(v) of the least-squares
objective (the coefficients' prior included) is recorded. The profile interval treats the normalised profile as
the coefficient's distribution:

    p(v) ∝ exp(−D(v)/2),                                          D(v) = r(v)²
    r(v) = sgn(v − v̂) √D(v)            (signed root, linear in v between the path's points)
    r(v) = r_end + (v − v_end)/sd       (beyond the path's ends: the Laplace slope, sd the Laplace sd at θ̂)

and its quantiles are the interval's ends. For a Gaussian posterior r(v) = (v − θ̂)/sd exactly, and the
interval is the Laplace one; along a curved valley (CM0, CMq with the flights' wobble initial conditions) the
profile is flatter than the Laplace approximation and the interval wider.

Unlike the posterior's marginal, the profile maximises over the nuisance parameters instead of integrating
over them: no volume term enters it, so neither the initial conditions' conditional volume (which shifts the
marginal along the pitching-moment valley, once per flight) nor the curvature Gauss–Newton leaves out (which
narrows the marginal of the roll coefficients where the posterior's mass lies off the optimum) does. At fixed
truths of varied four-flight designs (docs/validation.md) its intervals' z scatter by 0.89–1.16, the credible
intervals' of the same data by 0.91–1.29.
"""
from __future__ import annotations

import numpy as np

#: the probabilities whose values an interval record gives
LEVELS = (0.05, 0.25, 0.5, 0.75, 0.95)
#: points of the grid the profile's distribution is integrated on
GRID_POINTS = 4001
#: the grid reaches this many Laplace sds beyond the path's end points
TAIL_SDS = 6.0


def _path_arrays(path: dict) -> tuple[np.ndarray, np.ndarray, float, float]:
    """Values v (sorted), deviances D (≥ 0 from the path's lowest point), the lowest point's value and the
    Laplace sd at the optimum [coefficient units] of a path record."""
    v, t, D = (np.asarray(path[k], float) for k in ("value", "t", "deviance"))
    keep = np.isfinite(D)
    v, t, D = v[keep], t[keep], D[keep]
    if v.size < 2 or not np.any(t == 0.0) or not np.any(t != 0.0):
        raise ValueError("a profile path needs its optimum (t = 0) and at least one other point")
    centre = v[t == 0.0][0]
    sd = float(np.median((v[t != 0.0] - centre) / t[t != 0.0]))
    order = np.argsort(v)
    v, D = v[order], D[order]
    return v, D - D.min(), float(v[np.argmin(D)]), sd


def signed_root(path: dict, values) -> np.ndarray:
    """r(v) of the module docstring at ``values``: linear between the path's points, the Laplace slope beyond.

    Parameters
    ----------
    path : dict
        A coefficient's profile path: ``value`` (m,) [coefficient units], ``t`` (m,) (value − optimum in
        Laplace sds; 0 at the optimum) and ``deviance`` (m,), as in ``profiles.json``.
    values : float or (k,) array
        Coefficient values [coefficient units].

    Returns
    -------
    (k,) array
        Signed root deviance r [dimensionless].
    """
    v, D, lowest, sd = _path_arrays(path)
    r = np.sign(v - lowest) * np.sqrt(D)
    values = np.atleast_1d(np.asarray(values, float))
    out = np.interp(values, v, r)
    out = np.where(values < v[0], r[0] + (values - v[0]) / sd, out)
    return np.where(values > v[-1], r[-1] + (values - v[-1]) / sd, out)


def _grid_cdf(path: dict) -> tuple[np.ndarray, np.ndarray]:
    """The profile distribution's CDF on a grid over the path and :data:`TAIL_SDS` Laplace sds beyond it."""
    v, _, _, sd = _path_arrays(path)
    grid = np.linspace(v[0] - TAIL_SDS * sd, v[-1] + TAIL_SDS * sd, GRID_POINTS)
    r = signed_root(path, grid)
    w = np.exp(-0.5 * (r * r - np.min(r * r)))
    cdf = np.concatenate([[0.0], np.cumsum(0.5 * (w[1:] + w[:-1]) * np.diff(grid))])
    return grid, cdf / cdf[-1]


def profile_cdf(path: dict, values) -> np.ndarray:
    """Probability below ``values`` under the normalised profile p(v) ∝ exp(−r(v)²/2).

    Parameters
    ----------
    path : dict
        A coefficient's profile path (:func:`signed_root`).
    values : float or (k,) array
        Coefficient values [coefficient units].

    Returns
    -------
    (k,) array
        The CDF at ``values`` (0 … 1).
    """
    grid, cdf = _grid_cdf(path)
    return np.interp(np.atleast_1d(np.asarray(values, float)), grid, cdf)


def profile_interval(path: dict, levels=LEVELS) -> dict:
    """Quantiles of the normalised profile: the profile interval's ends and median.

    Parameters
    ----------
    path : dict
        A coefficient's profile path (:func:`signed_root`).
    levels : sequence of float
        Probabilities (0 … 1).

    Returns
    -------
    dict
        {``q05``, ``q25``, ``q50``, ``q75``, ``q95`` for the default levels: value [coefficient units]}.
    """
    grid, cdf = _grid_cdf(path)
    keep = np.concatenate([[True], np.diff(cdf) > 0])           # strictly increasing for the inverse
    return {f"q{round(100 * p):02d}": float(np.interp(p, cdf[keep], grid[keep])) for p in levels}
