"""Forms of nature: physics that differs from every formula of the library, for concealed synthetic data.

Real effects never use the library's formula. To show what ``diagnose`` does then, synthetic data can be
made with one of these forms (``nature:`` in a synth file, :mod:`bayes_disc.observation.synth`): each is a
physics term like those of :mod:`.terms` (same hooks, same flight context), but it is not a candidate of
the missing-physics search and not a term a run can fit. A parameter's ``off_value`` is its default.

* ``ground_effect_power``: a ground effect with another decay law (exp(−(z/h)^p), p = 2: Gaussian),
  where the library's family decays as exp(−z/h).
* ``wind_tunnel_aero``: the α-dependence of the measured wind-tunnel table (its bend away from the
  model's linear lift, quadratic drag and linear moment), where the library's family is polynomial.
* ``wind_power_shear``: a boundary-layer wind w(z) = w_ref (z/z_ref)^(1/7), where the library's wind
  varies linearly with height.
* ``side_force_saturating``: a side force that saturates with the advance ratio (tanh), where the
  library's grows as a power of it.
"""
from __future__ import annotations

import math

import numba as nb
import numpy as np
from scipy.interpolate import CubicSpline

from .terms import (CTX_AREA, CTX_ALPHA, CTX_D2X, CTX_D2Y, CTX_D2Z, CTX_DIAM, CTX_Q, CTX_Z, Term, TermParameter,
                    _advance_ratio, _lift_drag_force, select_terms)
from .windtunnel import load_wind_tunnel, wind_tunnel_shape


# --- ground effect with a power-law exponent in the decay ---------------------------------------------------

@nb.njit(inline="always", cache=True)
def _ground_power_loads(E, off, ctx):
    """ΔL = C_L,gp · exp(−(z/h)^p) · Q A along d2 × v̂_a;  ΔD = C_D,gp · exp(−(z/h)^p) · Q A along −v̂_a."""
    z = max(ctx[CTX_Z], 0.0)
    g = math.exp(-((z / E[off + 2]) ** E[off + 3])) * ctx[CTX_Q] * ctx[CTX_AREA]
    fx, fy, fz = _lift_drag_force(ctx, E[off] * g, E[off + 1] * g)
    return (fx, fy, fz, 0.0, 0.0, 0.0)


GROUND_EFFECT_POWER = Term(
    id="ground_effect_power",
    title="Ground effect fading as exp(−(z/h)^p) (p = 2: much faster near h than the library's exp(−z/h))",
    equations="ΔL = C_L,gp · exp(−(z/h_gp)^p_gp) · Q A  (along d2 × v̂_a),  "
    "ΔD = C_D,gp · exp(−(z/h_gp)^p_gp) · Q A  (along −v̂_a);  z: height above the ground plane (clipped at 0)",
    parameters=(TermParameter("CL_gp", "1", "lift change at the ground"),
                TermParameter("CD_gp", "1", "drag change at the ground"),
                TermParameter("h_gp", "m", "decay height", off_value=0.3),
                TermParameter("p_gp", "1", "decay-law exponent", off_value=2.0)),
    loads=_ground_power_loads,
)


# --- the wind-tunnel table's α-dependence ---------------------------------------------------------------------

#: grid step [rad] of the tabulated bend (a cubic spline of the table, sampled finely)
_BEND_STEP = math.radians(0.25)


def _bend_tables():
    """(α grid [rad], bend of C_L, C_D, C_M): the wind-tunnel table minus its best fit in the base model's
    forms over the shape range (:func:`.windtunnel.wind_tunnel_shape`), smoothed by a cubic spline through
    the table points and sampled every 0.25°; constant beyond the range."""
    shape = wind_tunnel_shape(load_wind_tunnel())
    a = shape.alpha_rad
    grid = np.arange(a[0], a[-1] + 0.5 * _BEND_STEP, _BEND_STEP)
    return (grid, CubicSpline(a, shape.bend_CL)(grid), CubicSpline(a, shape.bend_CD)(grid),
            CubicSpline(a, shape.bend_CM)(grid))


_BEND_ALPHA, _BEND_CL, _BEND_CD, _BEND_CM = _bend_tables()


@nb.njit(inline="always", cache=True)
def _tunnel_loads(E, off, ctx):
    """ΔC_X = s · bend_X(α) for X = L, D, M; forces × Q A, moment × Q A d about d2."""
    a = ctx[CTX_ALPHA]
    s = E[off]
    qa = ctx[CTX_Q] * ctx[CTX_AREA]
    dcl = s * np.interp(a, _BEND_ALPHA, _BEND_CL)
    dcd = s * np.interp(a, _BEND_ALPHA, _BEND_CD)
    pitch = s * np.interp(a, _BEND_ALPHA, _BEND_CM) * qa * ctx[CTX_DIAM]
    fx, fy, fz = _lift_drag_force(ctx, dcl * qa, dcd * qa)
    return (fx, fy, fz, pitch * ctx[CTX_D2X], pitch * ctx[CTX_D2Y], pitch * ctx[CTX_D2Z])


WIND_TUNNEL_AERO = Term(
    id="wind_tunnel_aero",
    title="The α-dependence of the measured wind-tunnel table (Potts 2005) beyond the model's linear lift, "
    "quadratic drag and linear moment",
    equations="ΔC_L = s · bend_L(α),  ΔC_D = s · bend_D(α),  ΔC_M = s · bend_M(α);  bend_X: the table minus its "
    "least-squares fit C_L0 + C_Lα α, C_D0 + C_Dα α², C_M0 + C_Mα α over −10°…30° (cubic spline through the "
    "table, constant outside); forces × Q A, moment × Q A d about d2",
    parameters=(TermParameter("s_tunnel", "1", "scale of the table's bend (1: as measured)", off_value=1.0),),
    loads=_tunnel_loads,
    zero_when_off=False,
)


# --- boundary-layer wind ---------------------------------------------------------------------------------------

#: lowest height [m] at which the power law is evaluated (it has an infinite gradient at z = 0)
_Z_FLOOR = 0.05


@nb.njit(inline="always", cache=True)
def _power_shear_air(E, off, t, x, y, z):
    """w = w_ref · (max(z, 0.05 m)/z_ref)^(1/7), horizontal."""
    f = (max(z, _Z_FLOOR) / E[off + 2]) ** (1.0 / 7.0)
    return (E[off] * f, E[off + 1] * f, 0.0)


WIND_POWER_SHEAR = Term(
    id="wind_power_shear",
    title="Boundary-layer wind growing with height as the 1/7 power law",
    equations="w = (w_ref,x, w_ref,y, 0) · (max(z, 0.05 m)/z_ref)^(1/7)",
    parameters=(TermParameter("wref_x", "m/s", "wind at z_ref, world x"),
                TermParameter("wref_y", "m/s", "wind at z_ref, world y"),
                TermParameter("z_ref", "m", "reference height", off_value=1.0)),
    air=_power_shear_air,
)


# --- side force saturating with the advance ratio ------------------------------------------------------------

@nb.njit(inline="always", cache=True)
def _saturating_side_loads(E, off, ctx):
    """F_Y = C_Y,s · tanh(μ/μ0) · Q A · d2,  μ = r d / 2|v_a|."""
    mag = E[off] * math.tanh(_advance_ratio(ctx) / E[off + 1]) * ctx[CTX_Q] * ctx[CTX_AREA]
    return (mag * ctx[CTX_D2X], mag * ctx[CTX_D2Y], mag * ctx[CTX_D2Z], 0.0, 0.0, 0.0)


SIDE_FORCE_SATURATING = Term(
    id="side_force_saturating",
    title="Side force that saturates with the spin's advance ratio",
    equations="F_Y = C_Y,s · tanh(μ/μ0) · Q A · d2,  μ = r d / 2|v_a|",
    parameters=(TermParameter("CY_s", "1", "side-force coefficient at saturation"),
                TermParameter("mu0", "1", "advance ratio of saturation", off_value=0.2)),
    loads=_saturating_side_loads,
)


#: the forms of nature by id
NATURE: dict[str, Term] = {t.id: t for t in (GROUND_EFFECT_POWER, WIND_TUNNEL_AERO, WIND_POWER_SHEAR,
                                              SIDE_FORCE_SATURATING)}

#: the library family each form of nature belongs to (what ``diagnose`` should name)
FAMILY = {"ground_effect_power": "ground_effect", "wind_tunnel_aero": "nonlinear_aero",
          "wind_power_shear": "wind", "side_force_saturating": "side_force"}


def get_nature(ids) -> tuple[Term, ...]:
    """Forms of nature by id, in the order given (:func:`.terms.select_terms`: unknown ids name the known)."""
    return select_terms(NATURE, ids, "form of nature")
