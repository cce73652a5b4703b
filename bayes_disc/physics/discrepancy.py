"""A learned discrepancy: a flexible correction to the aerodynamics, linear in its coefficients.

When no term of the library (nor its family) leaves the residuals white, ``diagnose`` learns what the model
is missing as a sparse sum of simple functions of the flight variables, one coefficient per (direction,
function) column (:mod:`bayes_disc.diagnostics.discrepancy` selects the columns):

    ΔC_X = Σ_f c_X,f · φ_f(z, α, μ),   X ∈ {lift, drag, side, pitch, roll}

    ΔL = ΔC_lift · Q A  along d2 × v̂_a          ΔD = ΔC_drag · Q A  along −v̂_a
    ΔY = ΔC_side · Q A  along d2                 ΔM = ΔC_pitch · Q A d  about d2
    ΔR = ΔC_roll · Q A d  about d1

with z the height of the centre of mass [m], α the angle of attack [rad], μ = r d / 2|v_a| the advance
ratio, and the functions (:data:`FUNCTIONS`)

    h005, h01, h02, h04, h08 = exp(−z/h) for h = 0.05, 0.1, 0.2, 0.4, 0.8 m   (height: ground effects;
                                                           sums of them follow decays of other laws)
    a2, a3        = α², α³                                       (angle of attack beyond the model)
    mu1, mu3      = μ, μ³                                        (spin)
    c             = 1                                            (a constant)

The columns that duplicate a coefficient of the base model (:data:`BASE_COLUMNS`: lift and drag constants,
drag α², pitch constant) are left out. Every coefficient is dimensionless, off at 0, prior sd
:data:`PRIOR_SD`. The term is not a candidate of the missing-physics search and not something a run's
configuration can ask for: it describes, it does not name.
"""
from __future__ import annotations

import math

import numba as nb
import numpy as np

from .terms import (CTX_ALPHA, CTX_AREA, CTX_D1X, CTX_D1Y, CTX_D1Z, CTX_D2X, CTX_D2Y, CTX_D2Z, CTX_DIAM, CTX_Q, CTX_Z,
                    Term, TermParameter, _advance_ratio, _lift_drag_force)

#: directions of the correction: forces along lift, drag, side; moments about the pitch and roll axes
DIRECTIONS = ("lift", "drag", "side", "pitch", "roll")
#: basis functions: id → (flight variable, formula)
FUNCTIONS = {"h005": ("height", "exp(−z/0.05 m)"), "h01": ("height", "exp(−z/0.1 m)"),
             "h02": ("height", "exp(−z/0.2 m)"), "h04": ("height", "exp(−z/0.4 m)"),
             "h08": ("height", "exp(−z/0.8 m)"), "a2": ("alpha", "α²"), "a3": ("alpha", "α³"),
             "mu1": ("spin", "μ"), "mu3": ("spin", "μ³"), "c": ("constant", "1")}
#: decay heights [m] of the height functions, in FUNCTIONS order
HEIGHTS = (0.05, 0.1, 0.2, 0.4, 0.8)
#: (direction, function) columns that duplicate a base-model coefficient (C_L0, C_D0, C_Dα, C_M0)
BASE_COLUMNS = {("lift", "c"), ("drag", "c"), ("drag", "a2"), ("pitch", "c")}
#: the columns of the correction, in parameter order
COLUMNS = tuple((d, f) for d in DIRECTIONS for f in FUNCTIONS if (d, f) not in BASE_COLUMNS)
#: prior sd of every coefficient (dimensionless)
PRIOR_SD = 1.0

_DIR_OF = np.array([DIRECTIONS.index(d) for d, _ in COLUMNS], np.int64)
_FN_OF = np.array([list(FUNCTIONS).index(f) for _, f in COLUMNS], np.int64)
_N_COLUMNS = len(COLUMNS)


def column_name(direction: str, function: str) -> str:
    """Parameter name of a column: ``dc_<direction>_<function>``."""
    return f"dc_{direction}_{function}"


def basis(z, alpha, mu) -> np.ndarray:
    """The functions φ_f of :data:`FUNCTIONS` at arrays of height z [m], α [rad] and μ (broadcast);
    returns (10, …)."""
    z, alpha, mu = np.broadcast_arrays(np.asarray(z, float), np.asarray(alpha, float), np.asarray(mu, float))
    return np.stack([np.exp(-z / h) for h in HEIGHTS] + [alpha ** 2, alpha ** 3, mu, mu ** 3, np.ones_like(z)])


@nb.njit(inline="always", cache=True)
def _discrepancy_loads(E, off, ctx):
    """ΔC_X = Σ c_X,f φ_f; forces × Q A along lift, drag and d2, moments × Q A d about d2 and d1."""
    z, a = ctx[CTX_Z], ctx[CTX_ALPHA]
    mu = _advance_ratio(ctx)
    phi = (math.exp(-z / 0.05), math.exp(-z / 0.1), math.exp(-z / 0.2), math.exp(-z / 0.4), math.exp(-z / 0.8),
           a * a, a * a * a, mu, mu * mu * mu, 1.0)
    dc0 = 0.0
    dc1 = 0.0
    dc2 = 0.0
    dc3 = 0.0
    dc4 = 0.0
    for j in range(_N_COLUMNS):
        v = E[off + j] * phi[_FN_OF[j]]
        d = _DIR_OF[j]
        if d == 0:
            dc0 += v
        elif d == 1:
            dc1 += v
        elif d == 2:
            dc2 += v
        elif d == 3:
            dc3 += v
        else:
            dc4 += v
    qa = ctx[CTX_Q] * ctx[CTX_AREA]
    fx, fy, fz = _lift_drag_force(ctx, dc0 * qa, dc1 * qa)
    fx += dc2 * qa * ctx[CTX_D2X]
    fy += dc2 * qa * ctx[CTX_D2Y]
    fz += dc2 * qa * ctx[CTX_D2Z]
    pitch = dc3 * qa * ctx[CTX_DIAM]
    roll = dc4 * qa * ctx[CTX_DIAM]
    return (fx, fy, fz, pitch * ctx[CTX_D2X] + roll * ctx[CTX_D1X], pitch * ctx[CTX_D2Y] + roll * ctx[CTX_D1Y],
            pitch * ctx[CTX_D2Z] + roll * ctx[CTX_D1Z])


DISCREPANCY = Term(
    id="learned_discrepancy",
    title="Learned discrepancy: a sparse correction to lift, drag, side force, pitching and rolling moment "
    "in functions of height, angle of attack and spin",
    equations="ΔC_X = Σ_f c_X,f φ_f(z, α, μ) for X = lift, drag, side (× Q A), pitch, roll (× Q A d); "
    "φ: exp(−z/h) for h = 0.05, 0.1, 0.2, 0.4, 0.8 m, α², α³, μ, μ³, 1",
    parameters=tuple(TermParameter(column_name(d, f), "1", f"{d} correction × {FUNCTIONS[f][1]}",
                                   prior_sd=PRIOR_SD) for d, f in COLUMNS),
    loads=_discrepancy_loads,
)


def correction(values: dict, direction: str, z, alpha, mu) -> np.ndarray:
    """ΔC in ``direction`` at height z [m], α [rad], μ (broadcast) for coefficients ``values``
    {parameter name: value} (columns not given: 0)."""
    phi = basis(z, alpha, mu)
    out = np.zeros(phi.shape[1:])
    for i, f in enumerate(FUNCTIONS):
        name = column_name(direction, f)
        if name in values:
            out = out + values[name] * phi[i]
    return out


# -- what a term does to the coefficients ---------------------------------------------------------------

#: flight variables a coefficient curve can run along: height z [m], α [rad], advance ratio μ
CURVE_VARIABLES = ("height", "alpha", "spin")
#: air speed [m/s] of the probe (the coefficients of the library's terms do not depend on it)
PROBE_SPEED = 10.0


def probe_context(z: float, alpha: float, mu: float, disc, rho: float = 1.23) -> np.ndarray:
    """A flight context (:mod:`.terms`) at height z [m], angle of attack α [rad] and advance ratio μ, in level
    flight along world x: D frame d1 = x, d3 = −z (the disc normal of docs/conventions.md, down for a disc flying
    upright), d2 = d3 × d1 = −y; v_a = V (cos α d1 + sin α d3), V = :data:`PROBE_SPEED`
    (α = atan2(v_a·d3, v_a·d1)); r = 2 μ V / d."""
    from .terms import (CTX_AREA, CTX_DIAM, CTX_IA, CTX_ID, CTX_MASS, CTX_Q, CTX_R, CTX_RHO, CTX_SPEED, CTX_VAX,
                        CTX_VAZ, CTX_ALPHA, CTX_D1X, CTX_D2Y, CTX_D3Z, CTX_Z, CTX_SIZE, CTX_D1BX)
    ctx = np.zeros(CTX_SIZE)
    V = PROBE_SPEED
    ctx[CTX_Z], ctx[CTX_SPEED], ctx[CTX_ALPHA] = z, V, alpha
    ctx[CTX_Q] = 0.5 * rho * V * V
    ctx[CTX_VAX], ctx[CTX_VAZ] = V * math.cos(alpha), -V * math.sin(alpha)
    ctx[CTX_D1X], ctx[CTX_D2Y], ctx[CTX_D3Z] = 1.0, -1.0, -1.0
    ctx[CTX_R] = 2.0 * mu * V / disc.diameter
    ctx[CTX_AREA], ctx[CTX_DIAM], ctx[CTX_MASS], ctx[CTX_RHO] = disc.area, disc.diameter, disc.mass, rho
    ctx[CTX_IA], ctx[CTX_ID] = disc.Ia, disc.Id
    ctx[CTX_D1BX] = 1.0                                   # the airflow along the body's b1 axis (β = 0)
    return ctx


def coefficient_change(term: Term, values, ctx: np.ndarray) -> dict:
    """{direction: ΔC} a term's loads make in the flight context ``ctx``: force along lift (d2 × v̂_a), drag
    (−v̂_a) and side (d2) over Q A; moment about d2 (pitch) and d1 (roll) over Q A d. ``values``: the term's
    parameters in order. A term without loads (a wind) changes no coefficient: all zero."""
    from .terms import CTX_AREA, CTX_D1X, CTX_D2X, CTX_DIAM, CTX_Q, _lift_direction, _unit_air
    if term.loads is None:
        return {d: 0.0 for d in DIRECTIONS}
    E = np.asarray(values, float)
    fx, fy, fz, mx, my, mz = term.loads(E, 0, ctx)
    F, M = np.array([fx, fy, fz]), np.array([mx, my, mz])
    qa = ctx[CTX_Q] * ctx[CTX_AREA]
    lift, air = np.array(_lift_direction(ctx)), np.array(_unit_air(ctx))
    d1, d2 = ctx[CTX_D1X: CTX_D1X + 3], ctx[CTX_D2X: CTX_D2X + 3]
    return {"lift": F @ lift / qa, "drag": -F @ air / qa, "side": F @ d2 / qa, "pitch": M @ d2 / (qa * ctx[CTX_DIAM]),
            "roll": M @ d1 / (qa * ctx[CTX_DIAM])}


def coefficient_curve(term: Term, values, direction: str, variable: str, grid, state: dict, disc) -> np.ndarray:
    """ΔC in ``direction`` that ``term`` (parameters ``values``) makes along ``variable`` ('height' [m],
    'alpha' [rad] or 'spin': μ) on ``grid``, the other variables at ``state`` {variable: value}.

    Parameters
    ----------
    term : Term
    values : sequence of float
        The term's parameters, in order.
    direction : str
        One of :data:`DIRECTIONS`.
    variable : str
        One of :data:`CURVE_VARIABLES`.
    grid : (n,) array
    state : dict
        {'height': z [m], 'alpha': α [rad], 'spin': μ}.
    disc : Disc

    Returns
    -------
    (n,) array
    """
    if direction not in DIRECTIONS or variable not in CURVE_VARIABLES:
        raise ValueError(f"direction must be one of {DIRECTIONS} and variable one of {CURVE_VARIABLES}")
    out = []
    for g in np.asarray(grid, float):
        s = {**state, variable: g}
        out.append(coefficient_change(term, values, probe_context(s["height"], s["alpha"], s["spin"], disc))[direction])
    return np.array(out)
