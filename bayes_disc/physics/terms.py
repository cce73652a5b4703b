"""Extra physics terms that plug into the flight model of docs/conventions.md.

A term is one small, self-describing unit: its equations (docstring), its extra parameters with units,
defaults and prior scales, and one or two compiled hooks that the simulator inlines into its
right-hand side:

* ``air(E, off, t, x, y, z) -> (wx, wy, wz)``: a wind velocity [m/s]; the aerodynamics see
  ``v_a = v − Σ wind``.
* ``loads(E, off, ctx) -> (Fx, Fy, Fz, Mx, My, Mz)``: an extra world-frame force [N] and moment
  [N m] at the centre of mass, given the flight context ``ctx`` (layout below).

``E[off + i]`` is the term's i-th parameter (``E``: the lane's term parameters, a tuple inside the compiled
integrator, a 1-D array in the numpy reference equations). The hooks are plain numba functions, so the numpy
reference equations call exactly the same code.

Flight context ``ctx`` (a tuple; indices are the ``CTX_*`` constants): time t [s], centre-of-mass position
x, y, z [m], air speed |v_a| [m/s], angle of attack α [rad], dynamic pressure Q = ρ|v_a|²/2 [Pa], v_a [m/s],
d1, d2, d3 (world components), p, q, r [rad/s], A [m²], d [m], m [kg], ρ [kg/m³], Ia, Id [kg m²] (the
configured disc's axial and diametral moments of inertia), and d1 in body axes (cos β, sin β): β is the
azimuth of the airflow in the disc plane measured from the body's b1 axis (it turns at −r as the disc spins).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable

import numba as nb

from .windtunnel import wind_tunnel_shape

CTX_T, CTX_X, CTX_Y, CTX_Z, CTX_SPEED, CTX_ALPHA, CTX_Q = 0, 1, 2, 3, 4, 5, 6
CTX_VAX, CTX_VAY, CTX_VAZ = 7, 8, 9
CTX_D1X, CTX_D1Y, CTX_D1Z = 10, 11, 12
CTX_D2X, CTX_D2Y, CTX_D2Z = 13, 14, 15
CTX_D3X, CTX_D3Y, CTX_D3Z = 16, 17, 18
CTX_P, CTX_QRATE, CTX_R = 19, 20, 21
CTX_AREA, CTX_DIAM, CTX_MASS, CTX_RHO = 22, 23, 24, 25
CTX_IA, CTX_ID = 26, 27
CTX_D1BX, CTX_D1BY = 28, 29
#: length of the flight context
CTX_SIZE = 30


@dataclass(frozen=True)
class TermParameter:
    """An extra parameter of a term: name, unit, value that switches the term off, prior scale."""

    name: str
    unit: str
    description: str
    off_value: float = 0.0
    prior_sd: float = 1.0
    prior_mean: float | None = None

    @property
    def prior_centre(self) -> float:
        """Centre of the parameter's normal prior: ``prior_mean`` if given, else the value that switches the
        term off (a family's shape parameter: the library's original form)."""
        return self.off_value if self.prior_mean is None else self.prior_mean


@dataclass(frozen=True)
class Term:
    """A physics term: id, a one-line title, its equations and its compiled hooks.

    A term is a *family* when some of its parameters change the shape of the effect rather than its size
    (a decay height, a shear, an exponent, higher powers of α): at their off values the family is the
    original formula, and the missing-physics search fits them with the rest, so an effect whose form in
    nature differs from the formula is still described by its family."""

    id: str
    title: str
    equations: str
    parameters: tuple[TermParameter, ...]
    air: Callable | None = None
    loads: Callable | None = None
    notes: str = field(default="")
    #: the hooks return zero when every parameter sits at its off value (the kernel then skips them)
    zero_when_off: bool = True

    @property
    def parameter_names(self) -> tuple[str, ...]:
        return tuple(p.name for p in self.parameters)


# --- steady wind ---------------------------------------------------------------------------------------

@nb.njit(inline="always", cache=True)
def _wind_air(E, off, t, x, y, z):
    """w = (w_x + s_x z, w_y + s_y z, w_z): steady, horizontal components varying linearly with height."""
    return (E[off] + E[off + 3] * z, E[off + 1] + E[off + 4] * z, E[off + 2])


WIND = Term(
    id="wind",
    title="Steady wind, with a linear shear in height: the aerodynamics see v_a = v − w",
    equations="v_a = v − w,  w = (w_x + s_x z, w_y + s_y z, w_z)  (z: height above the ground plane; "
    "s_x = s_y = 0: uniform wind)",
    parameters=(
        TermParameter("wind_x", "m/s", "wind velocity at z = 0, world x (downrange)", prior_sd=3.0),
        TermParameter("wind_y", "m/s", "wind velocity at z = 0, world y (left)", prior_sd=3.0),
        TermParameter("wind_z", "m/s", "wind velocity, world z (up)", prior_sd=1.0),
        TermParameter("shear_x", "1/s", "height gradient of wind_x", prior_sd=1.0),
        TermParameter("shear_y", "1/s", "height gradient of wind_y", prior_sd=1.0),
    ),
    air=_wind_air,
)


# --- shared geometry --------------------------------------------------------------------------------

@nb.njit(inline="always", cache=True)
def _unit_air(ctx):
    """v̂_a = v_a / |v_a| (world; zero at rest)."""
    s = ctx[CTX_SPEED]
    inv = 1.0 / s if s > 0.0 else 0.0
    return ctx[CTX_VAX] * inv, ctx[CTX_VAY] * inv, ctx[CTX_VAZ] * inv


@nb.njit(inline="always", cache=True)
def _d_frame_moment(roll, pitch, ctx):
    """(0, 0, 0, M): no force and the world-frame moment M = roll d1 + pitch d2 [N m]."""
    return (0.0, 0.0, 0.0,
            roll * ctx[CTX_D1X] + pitch * ctx[CTX_D2X],
            roll * ctx[CTX_D1Y] + pitch * ctx[CTX_D2Y],
            roll * ctx[CTX_D1Z] + pitch * ctx[CTX_D2Z])


@nb.njit(inline="always", cache=True)
def _lift_direction(ctx):
    """d2 × v̂_a (world): the lift direction of docs/conventions.md (perpendicular to v_a, toward the top side)."""
    ax, ay, az = _unit_air(ctx)
    d2x, d2y, d2z = ctx[CTX_D2X], ctx[CTX_D2Y], ctx[CTX_D2Z]
    return d2y * az - d2z * ay, d2z * ax - d2x * az, d2x * ay - d2y * ax


@nb.njit(inline="always", cache=True)
def _advance_ratio(ctx):
    """μ = r d / 2|v_a| (spin rim speed over air speed; zero at rest)."""
    s = ctx[CTX_SPEED]
    return ctx[CTX_R] * ctx[CTX_DIAM] / (2.0 * s) if s > 0.0 else 0.0


@nb.njit(inline="always", cache=True)
def _lift_drag_force(ctx, lift, drag):
    """World force [N] of a lift ``lift`` along d2 × v̂_a and a drag ``drag`` along −v̂_a."""
    lx, ly, lz = _lift_direction(ctx)
    ax, ay, az = _unit_air(ctx)
    return lift * lx - drag * ax, lift * ly - drag * ay, lift * lz - drag * az


# --- side force (Robins–Magnus) ----------------------------------------------------------------------

@nb.njit(inline="always", cache=True)
def _signed_power(x, n):
    """sgn(x) |x|^n (zero at x = 0): a growth law with exponent n that keeps the sign of x."""
    if x == 0.0:
        return 0.0
    return math.copysign(abs(x) ** n, x)


@nb.njit(inline="always", cache=True)
def _side_force_loads(E, off, ctx):
    """F_Y = C_Y · sgn(μ)|μ|^n_Y · Q A · d2,  μ = r d / 2|v_a|."""
    mag = E[off] * _signed_power(_advance_ratio(ctx), E[off + 1]) * ctx[CTX_Q] * ctx[CTX_AREA]
    return (mag * ctx[CTX_D2X], mag * ctx[CTX_D2Y], mag * ctx[CTX_D2Z], 0.0, 0.0, 0.0)


#: prior scale of a growth exponent n (off value 1: linear in the advance ratio)
EXPONENT_SD = 0.5


SIDE_FORCE = Term(
    id="side_force",
    title="Robins–Magnus side force perpendicular to the velocity in the disc plane, growing with spin",
    equations="F_Y = C_Y · sgn(μ)|μ|^n_Y · Q A · d2,  μ = r d / 2|v_a|  (d2 = d3 × d1: to the right in forward "
    "flight; r > 0 pushes right; n_Y = 1: linear in the advance ratio)",
    parameters=(TermParameter("CY", "1", "side-force coefficient per unit advance ratio r d / 2|v_a|",
                              prior_sd=0.5),
                TermParameter("n_Y", "1", "growth exponent in the advance ratio", off_value=1.0,
                              prior_sd=EXPONENT_SD)),
    loads=_side_force_loads,
)


# --- ground effect -------------------------------------------------------------------------------------

@nb.njit(inline="always", cache=True)
def _ground_effect_loads(E, off, ctx):
    """ΔL = ΔC_L,ge · e^(−z/h) · Q A along d2 × v̂_a;  ΔD = ΔC_D,ge · e^(−z/h) · Q A along −v̂_a;  h = d e^(ln_h)."""
    h = ctx[CTX_DIAM] * math.exp(E[off + 2])
    g = math.exp(-ctx[CTX_Z] / h) * ctx[CTX_Q] * ctx[CTX_AREA]
    fx, fy, fz = _lift_drag_force(ctx, E[off] * g, E[off + 1] * g)
    return (fx, fy, fz, 0.0, 0.0, 0.0)


GROUND_EFFECT = Term(
    id="ground_effect",
    title="Ground effect: lift and drag change close to the ground, fading over a decay height h",
    equations="ΔL = ΔC_L,ge · exp(−z/h) · Q A  (along d2 × v̂_a),  ΔD = ΔC_D,ge · exp(−z/h) · Q A  (along −v̂_a),  "
    "h = d · exp(ln_h_ge); z: height of the centre of mass above the ground plane z = 0, d: diameter "
    "(ln_h_ge = 0: h = d)",
    parameters=(TermParameter("CL_ge", "1", "lift change at the ground (z = 0)", prior_sd=0.3),
                TermParameter("CD_ge", "1", "drag change at the ground (z = 0)", prior_sd=0.2),
                TermParameter("ln_h_ge", "1", "log of the decay height in diameters, ln(h/d)", prior_sd=0.7)),
    loads=_ground_effect_loads,
)


# --- non-linear angle-of-attack dependence -------------------------------------------------------------

_TUNNEL = wind_tunnel_shape()


def _shape_parameter(name: str, unit: str, description: str, sd: float) -> TermParameter:
    """A polynomial α term centred on the wind-tunnel table's value, prior sd max(sd, 2 |mean|)."""
    mean = float(getattr(_TUNNEL, name))
    return TermParameter(name, unit, description, prior_sd=max(sd, 2.0 * abs(mean)), prior_mean=mean)


@nb.njit(inline="always", cache=True)
def _nonlinear_aero_loads(E, off, ctx):
    """ΔC_L = C_L2 α² + C_L3 α³, ΔC_D = C_D3 |α|³ + C_D4 α⁴, ΔC_M = C_M2 α² + C_M3 α³ (α in rad); forces × Q A,
    moment × Q A d about d2."""
    a = ctx[CTX_ALPHA]
    a2 = a * a
    qa = ctx[CTX_Q] * ctx[CTX_AREA]
    dcl = (E[off] + E[off + 3] * a) * a2
    dcd = (E[off + 1] * abs(a) + E[off + 4] * a2) * a2
    fx, fy, fz = _lift_drag_force(ctx, dcl * qa, dcd * qa)
    pitch = (E[off + 2] + E[off + 5] * a) * a2 * qa * ctx[CTX_DIAM]
    return (fx, fy, fz, pitch * ctx[CTX_D2X], pitch * ctx[CTX_D2Y], pitch * ctx[CTX_D2Z])


NONLINEAR_AERO = Term(
    id="nonlinear_aero",
    title="Angle-of-attack dependence beyond linear lift, quadratic drag and linear pitching moment",
    equations="C_L = C_L0 + C_Lα α + C_L2 α² + C_L3 α³,  C_D = C_D0 + C_Dα α² + C_D3 |α|³ + C_D4 α⁴,  "
    "C_M = C_M0 + C_Mα α + C_Mq q + C_M2 α² + C_M3 α³  (α in rad; the wind-tunnel table bends this way: lift "
    "saturates, drag and pitching moment grow faster at high α). Prior means: the table's shape over −10°…30° "
    "(physics.windtunnel.wind_tunnel_shape), prior sd at least twice their size",
    parameters=(_shape_parameter("CL2", "1/rad²", "quadratic lift term", 2.0),
                _shape_parameter("CD3", "1/rad³", "cubic drag term", 2.0),
                _shape_parameter("CM2", "1/rad²", "quadratic pitching-moment term", 0.5),
                _shape_parameter("CL3", "1/rad³", "cubic lift term", 4.0),
                _shape_parameter("CD4", "1/rad⁴", "quartic drag term", 4.0),
                _shape_parameter("CM3", "1/rad³", "cubic pitching-moment term", 1.0)),
    loads=_nonlinear_aero_loads,
)


# --- spin-dependent lift ---------------------------------------------------------------------------------

@nb.njit(inline="always", cache=True)
def _spin_lift_loads(E, off, ctx):
    """ΔL = C_Lr · sgn(μ)|μ|^n_Lr · Q A along d2 × v̂_a,  μ = r d / 2|v_a|."""
    mu = _signed_power(_advance_ratio(ctx), E[off + 1])
    fx, fy, fz = _lift_drag_force(ctx, E[off] * mu * ctx[CTX_Q] * ctx[CTX_AREA], 0.0)
    return (fx, fy, fz, 0.0, 0.0, 0.0)


SPIN_LIFT = Term(
    id="spin_lift",
    title="Lift that grows with the spin's advance ratio μ = r d / 2|v_a|",
    equations="ΔL = C_Lr · sgn(μ)|μ|^n_Lr · Q A  (along d2 × v̂_a; n_Lr = 1: linear)",
    parameters=(TermParameter("CLr", "1", "lift per unit advance ratio", prior_sd=0.5),
                TermParameter("n_Lr", "1", "growth exponent in the advance ratio", off_value=1.0,
                              prior_sd=EXPONENT_SD)),
    loads=_spin_lift_loads,
)


# --- roll moment coupled to the advance ratio --------------------------------------------------------------

@nb.njit(inline="always", cache=True)
def _roll_spin_loads(E, off, ctx):
    """ΔR = C_Rμ · sgn(μ)|μ|^n_Rμ · Q A d about d1,  μ = r d / 2|v_a|."""
    roll = E[off] * _signed_power(_advance_ratio(ctx), E[off + 1]) * ctx[CTX_Q] * ctx[CTX_AREA] * ctx[CTX_DIAM]
    return (0.0, 0.0, 0.0, roll * ctx[CTX_D1X], roll * ctx[CTX_D1Y], roll * ctx[CTX_D1Z])


ROLL_SPIN_COUPLING = Term(
    id="roll_spin_coupling",
    title="Roll moment depending on the advance ratio μ = r d / 2|v_a|",
    equations="ΔR = C_Rμ · sgn(μ)|μ|^n_Rμ · Q A d  (about d1; n_Rμ = 1: linear)",
    parameters=(TermParameter("CRmu", "1", "roll moment per unit advance ratio", prior_sd=0.05),
                TermParameter("n_Rmu", "1", "growth exponent in the advance ratio", off_value=1.0,
                              prior_sd=EXPONENT_SD)),
    loads=_roll_spin_loads,
)


# --- the instrumented disc's inertia ratio ---------------------------------------------------------------

@nb.njit(inline="always", cache=True)
def _inertia_ratio_loads(E, off, ctx):
    """ΔM = ε_I · Ia · r · (p d2 − q d1): the gyroscopic moment of an axial inertia Ia (1 + ε_I) (:data:`INERTIA_RATIO`)."""
    s = E[off] * ctx[CTX_IA] * ctx[CTX_R]
    p, q = ctx[CTX_P], ctx[CTX_QRATE]
    return (0.0, 0.0, 0.0,
            s * (p * ctx[CTX_D2X] - q * ctx[CTX_D1X]),
            s * (p * ctx[CTX_D2Y] - q * ctx[CTX_D1Y]),
            s * (p * ctx[CTX_D2Z] - q * ctx[CTX_D1Z]))


INERTIA_RATIO = Term(
    id="inertia_ratio",
    title="The flying disc's own inertia ratio Ia/Id (a logger or a different disc changes it): the wobble's "
    "turning rate in the body frame",
    equations="Ia → Ia (1 + ε_I) at fixed Id, as the moment ΔM = ε_I · Ia · r · (p d2 − q d1)  "
    "(body axes: ΔM_B = ε_I Ia ω_z (−ω_y, ω_x, 0)); the torque-free wobble turns in the body frame at "
    "κ r, κ = (Ia/Id)(1 + ε_I) − 1",
    parameters=(TermParameter("eps_I", "1", "relative change of the axial moment of inertia Ia at fixed Id, "
                              "i.e. of the ratio Ia/Id", prior_sd=0.05),),
    loads=_inertia_ratio_loads,
    notes="""Euler's equations of the axisymmetric disc, I = diag(Id, Id, Ia), body axes b1 b2 b3:

    Id dω_x/dt = M_x + (Id − Ia) ω_y ω_z
    Id dω_y/dt = M_y − (Id − Ia) ω_z ω_x
    Ia dω_z/dt = M_z

Without moments the transverse rate W = ω_x + i ω_y obeys dW/dt = i (Ia/Id − 1) ω_z W: it turns in the
body frame at κ ω_z, κ = (Ia − Id)/Id (0.926 for the default Ia = 0.00235, Id = 0.00122 kg m²).

A disc whose axial inertia is Ia' = Ia (1 + ε_I) (same Id) has

    Id dω_x/dt = M_x + (Id − Ia) ω_y ω_z − ε_I Ia ω_y ω_z
    Id dω_y/dt = M_y − (Id − Ia) ω_z ω_x + ε_I Ia ω_z ω_x

i.e. the configured disc's equations with the extra body moment

    ΔM_B = ε_I Ia ω_z (−ω_y, ω_x, 0) = ε_I Ia ω_z (b3 × ω_B)

which in the D frame (ω = p d1 + q d2 + r d3, r = ω_z, d3 = b3: d3 × d1 = d2, d3 × d2 = −d1) reads

    ΔM = ε_I Ia r (p d2 − q d1)

and the wobble turns at κ' = (Ia/Id)(1 + ε_I) − 1: Δκ = (Ia/Id) ε_I ≈ 1.93 ε_I. The spin equation
Ia' dω_z/dt = M_z is the configured one with M_z/(1 + ε_I): the spin-down coefficient absorbs it exactly
(fitted CNr = CNr' / (1 + ε_I)), so the term adds no axial moment. Only the ratio is identifiable: a common
scale of Ia and Id rescales every moment coefficient (docs/inertial.md), which the fit absorbs.

Prior: ε_I ~ N(0, 0.05²), i.e. κ ± 0.1. Upper bound: for any body Ia = ∫(x² + y²) dm and Id = ∫(y² + z²) dm =
Ia/2 + ∫z² dm, so Ia/Id = 2/(1 + 2∫z² dm/Ia) ≤ 2 (a flat lamina), ε_I ≤ 2/1.926 − 1 = 0.04. Below: a logger
mounted under the flight plate adds ∫z² dm (its height and its offset from the disc's centre of mass) and the
published inertias of one disc model differ by a few per cent; 0.05 covers both, not the κ = 0.78–1.01 spread
of the real throws by itself (1.01 needs Ia/Id > 2: no rigid disc).""",
)


def axial_inertia(Ia: float, values: dict) -> float:
    """The axial moment of inertia the model's wobble turns with: Ia (1 + ε_I) when the model carries
    :data:`INERTIA_RATIO` (``values`` has its ``eps_I``), else Ia.

    Parameters
    ----------
    Ia : float
        The configured disc's axial moment of inertia [kg m²].
    values : dict
        {parameter name: value} of the fitted model.

    Returns
    -------
    float
        Ia (1 + ε_I) [kg m²].
    """
    return Ia * (1.0 + float(values.get(INERTIA_RATIO.parameters[0].name, 0.0)))


# --- cross-coupled rate moments ------------------------------------------------------------------------

@nb.njit(inline="always", cache=True)
def _rate_coupling_loads(E, off, ctx):
    """ΔR = C_Rq q Q A d about d1,  ΔM = C_Mp p Q A d about d2 (:data:`RATE_COUPLING`)."""
    qad = ctx[CTX_Q] * ctx[CTX_AREA] * ctx[CTX_DIAM]
    roll = E[off + 1] * ctx[CTX_QRATE] * qad
    pitch = E[off] * ctx[CTX_P] * qad
    return _d_frame_moment(roll, pitch, ctx)


RATE_COUPLING = Term(
    id="rate_coupling",
    title="Cross-coupled rate moments: a pitching moment from the roll rate and a rolling moment from the pitch rate",
    equations="M = (C_M0 + C_Mα α + C_Mq q + C_Mp p) Q A d  (about d2),  R = (C_Rr r + C_Rp p + C_Rq q) Q A d  "
    "(about d1); p, q in rad/s as C_Mq, C_Rp",
    parameters=(TermParameter("CMp", "s/rad", "pitching moment per unit roll rate p", prior_sd=0.01),
                TermParameter("CRq", "s/rad", "rolling moment per unit pitch rate q", prior_sd=0.01)),
    loads=_rate_coupling_loads,
    notes="""The transverse rate moment of the model is a 2×2 matrix on ω⊥ = p d1 + q d2:

    (R, M) = Q A d [[C_Rp, C_Rq], [C_Mp, C_Mq]] (p, q)

Its diagonal (C_Rp, C_Mq) damps the wobble; the new off-diagonal terms split into an antisymmetric part
c = (C_Mp − C_Rq)/2, the moment c Q A d (p d2 − q d1) = c Q A d (d3 × ω), and a symmetric part
(C_Mp + C_Rq)/2 (an anisotropic damping with axes at 45° to the air velocity). The antisymmetric part has
the form of the inertia term's moment ε_I Ia r (d3 × ω): it shifts the wobble's body-frame rate by

    Δκ = c Q A d / (Id r)

(about 22 c per s/rad at 13 m/s and r = 60 rad/s with the default disc), largest at high dynamic pressure
and low spin, where an inertia change shifts κ by the same (Ia/Id) ε_I throughout the flight: the data
tell them apart by how κ drifts as Q/r falls.

Prior: N(0, 0.01²) s/rad each, the size of the direct rate damping (C_Mq = −0.0144, C_Rp = −0.0125 s/rad,
Hummel 2003, flight f2302): a cross-coupling as large as the damping itself is one sd.""",
)


# --- wobble damping that depends on the angle of attack and the wobble amplitude ---------------------------

@nb.njit(inline="always", cache=True)
def _rate_damping_loads(E, off, ctx):
    """ΔM = (C_wα α + C_ww |ω⊥|) (p d1 + q d2) Q A d,  |ω⊥| = √(p² + q²) (:data:`RATE_DAMPING`)."""
    p, q = ctx[CTX_P], ctx[CTX_QRATE]
    c = (E[off] * ctx[CTX_ALPHA] + E[off + 1] * math.sqrt(p * p + q * q)) * ctx[CTX_Q] * ctx[CTX_AREA] * ctx[CTX_DIAM]
    return _d_frame_moment(c * p, c * q, ctx)


RATE_DAMPING = Term(
    id="rate_damping",
    title="Wobble damping that changes with the angle of attack and with the wobble amplitude",
    equations="R = (C_Rr r + C_Rp p + ΔC_w p) Q A d  (about d1),  M = (C_M0 + C_Mα α + C_Mq q + ΔC_w q) Q A d  "
    "(about d2),  ΔC_w = C_wα α + C_ww |ω⊥|,  |ω⊥| = √(p² + q²)  (α in rad, p, q in rad/s)",
    parameters=(TermParameter("Cw_alpha", "s/rad²", "change of the transverse rate damping per radian of α",
                              prior_sd=0.03),
                TermParameter("Cw_amp", "s²/rad²", "change of the transverse rate damping per rad/s of wobble "
                              "amplitude √(p² + q²)", prior_sd=0.002)),
    loads=_rate_damping_loads,
    notes="""The base model damps the wobble ω⊥ = p d1 + q d2 with constant C_Rp (roll) and C_Mq (pitch); the
amplitude then decays at a rate ∝ Q that no constant pair makes both fast early and nil (or negative) late.
ΔC_w adds the same damping to both axes, growing linearly with α (the flow over the rim changes with the
angle of attack) and with the wobble amplitude (a quadratic damping: large wobbles decay, small ones are
left): with C_ww > 0 and a negative net linear damping the amplitude settles on a limit cycle.

Priors: C_wα ~ N(0, 0.03²) s/rad², a change of the size of C_Mq, C_Rp (0.01 s/rad, Hummel 2003) over
0.3 rad of α; C_ww ~ N(0, 0.002²) s²/rad², the same change over a 5 rad/s wobble.""",
)


# --- an aerodynamic asymmetry fixed in the disc: a moment at twice the spin --------------------------------

@nb.njit(inline="always", cache=True)
def _disc_asymmetry_loads(E, off, ctx):
    """R + i M = (C_Ac + i C_As) e^{−2iβ} Q A d about d1, d2 (:data:`DISC_ASYMMETRY`)."""
    c, s = ctx[CTX_D1BX], ctx[CTX_D1BY]                  # cos β, sin β
    cos2, sin2 = c * c - s * s, 2.0 * c * s
    qad = ctx[CTX_Q] * ctx[CTX_AREA] * ctx[CTX_DIAM]
    roll = (E[off] * cos2 + E[off + 1] * sin2) * qad
    pitch = (E[off + 1] * cos2 - E[off] * sin2) * qad
    return _d_frame_moment(roll, pitch, ctx)


DISC_ASYMMETRY = Term(
    id="disc_asymmetry",
    title="An aerodynamic asymmetry fixed in the disc (a logger, a bump, a warp): a moment that turns with the "
    "disc and so forces the wobble at twice the spin",
    equations="R + i M = (C_Ac + i C_As) e^{−2iβ} Q A d  (R about d1, M about d2; β: the airflow's azimuth in "
    "the disc plane from the body's b1 axis); in body axes M_x + i M_y = (C_Ac + i C_As) e^{−iβ} Q A d",
    parameters=(TermParameter("CAc", "1", "moment of the asymmetry about the body's b1 axis when the airflow "
                              "comes along b1 (β = 0), per Q A d", prior_sd=0.01),
                TermParameter("CAs", "1", "the same about the body's b2 axis", prior_sd=0.01)),
    loads=_disc_asymmetry_loads,
    notes="""A disc that is not axisymmetric (an instrument mounted off the axis, a dent, a warped rim) sees the
airflow from a direction that turns in its own frame: the airflow's azimuth β (from the body's b1 axis) falls
at the spin rate, dβ/dt = −r. Any pitching or rolling moment the asymmetry adds is a function of β. Written
in body axes as a Fourier series in β, m_B = M_x + i M_y = Σ_n c_n e^{inβ} Q A d:

* n = +1, m_B ∝ e^{iβ}: a moment fixed relative to the airflow — the D frame's own constants C_M0 and a
  roll trim, already in the model;
* n = 0: a moment fixed in the disc — it tilts the spin axis like the sensor tilt and the constant part of
  the wobble;
* n = −1, m_B = (C_Ac + i C_As) e^{−iβ} Q A d: a moment that turns in the body frame at +r, in the same sense
  as the free wobble, which turns at κ r with κ = Ia/Id − 1 ≈ 0.93. This is the term: it drives a wobble at
  κ = 1 (twice the spin in space), close to resonance with the free one, and its response grows as the
  forcing and free rates approach each other;
* higher n turn at −n r in the body, far from the wobble's rate: their response is small.

In the D frame (d1 = e^{iβ} in body axes, d2 = i d1): R + i M = m_B e^{−iβ} = (C_Ac + i C_As) e^{−2iβ} Q A d,
i.e. R = (C_Ac cos 2β + C_As sin 2β) Q A d and M = (C_As cos 2β − C_Ac sin 2β) Q A d. The asymmetry belongs
to the disc, so (C_Ac, C_As) are shared by every flight of one disc: the phase is measured from the body's b1
axis, which for an inertial logger is the sensor's x axis.

The forced response: with W = ω_x + i ω_y and the free wobble turning at κ r, dW/dt = i κ r W + m_B/Id
gives, forced at e^{i r t}, |W| = |C_A| Q A d / (Id (1 − κ) r): at 10 m/s, r = 55 rad/s and κ = 0.93, a
coefficient |C_A| = 0.005 drives |W| ≈ 1 rad/s.

Prior: N(0, 0.01²) each, a moment of the size of the rate damping's at 1 rad/s of wobble (C_Mq ≈ −0.014 s/rad).""",
)


TERMS: dict[str, Term] = {t.id: t for t in (SIDE_FORCE, WIND, GROUND_EFFECT, NONLINEAR_AERO, SPIN_LIFT,
                                             ROLL_SPIN_COUPLING, INERTIA_RATIO, RATE_COUPLING,
                                             RATE_DAMPING, DISC_ASYMMETRY)}


def select_terms(registry: dict, ids, what: str = "physics term") -> tuple[Term, ...]:
    """Terms of ``registry`` by id, in the order given; an unknown id raises KeyError naming the known ones,
    an id listed twice ValueError."""
    out = []
    for i in ids:
        if i not in registry:
            raise KeyError(f"unknown {what} {i!r}; known: {sorted(registry)}")
        out.append(registry[i])
    if len({t.id for t in out}) != len(out):
        raise ValueError(f"{what}s listed twice: {list(ids)}")
    return tuple(out)


def get_terms(ids) -> tuple[Term, ...]:
    """Terms by id (:data:`TERMS`), in the order given (:func:`select_terms`)."""
    return select_terms(TERMS, ids)

