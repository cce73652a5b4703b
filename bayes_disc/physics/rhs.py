"""Right-hand side of the compiled integrator: dy/dt of one lane, with the terms' hooks inlined.

Body-axis form of :func:`.equations.state_derivative`.

State y = (r_W [m], v_W [m/s], q = (w, x, y, z) body→world, ω_B = (ω_x, ω_y, ω_z) [rad/s]).
With R = R(q/|q|) (v_W = R v_B), the air-relative velocity in body axes u_B = Rᵀ(v_W − wind) = (u, v, w),
the in-plane air speed V∥ = √(u² + v²), the air speed V = |u_B|, Q = ρV²/2 and the D frame in body axes
d1 = (u, v, 0)/V∥, d2 = b3 × d1 = (−d1y, d1x, 0), d3 = b3 = (0, 0, 1):

    α = atan2(w, V∥),   p = ω_B·d1,   q = ω_B·d2,   r = ω_z
    m dv_W/dt = (CL0 + CLa α) (ρAV/2) (d2 × v_a) − (CD0 + CDa α²) (ρAV/2) v_a − m g ẑ,
                 with d2 × v_a = (w/V∥)(v_a − w b3) − V∥ b3 in world axes
    M_B = [(CRr r + CRp p) d1 + (CM0 + CMa α + CMq q) d2 + CNr r d3] Q A d
    dω_x/dt = M_x/Id + (Id − Ia)/Id · ω_y ω_z,   dω_y/dt = M_y/Id − (Id − Ia)/Id · ω_z ω_x,
    dω_z/dt = M_z/Ia
    dq/dt = ½ q ⊗ (0, ω_B)

The coefficients are pre-multiplied once per lane by ρA/2m (CL*, CD*), ρAd/2Id (CM*, CR*) or ρAd/2Ia
(CNr). Extra terms (:mod:`.terms`) add a wind to v_a and world-frame loads.

:func:`rhs` is a source template: :func:`.codegen.kernel_source` compiles its text inside each generated
kernel module, where ``HAS_AIR``, ``HAS_LOADS``, ``air`` and ``extra_loads`` are the chains of that
kernel's terms (:mod:`.terms`) and the function is inlined into the Runge–Kutta step. The module-level
values below are those of a kernel without terms, so that ``rhs`` here is also plain, callable Python
(the tests compare it with :func:`.equations.state_derivative`).
"""
from __future__ import annotations

import math

from .arctan import alpha_and_inverse

#: a kernel's terms add a wind (``air``) / loads (``extra_loads``); the defaults: no terms
HAS_AIR = False
HAS_LOADS = False


def air(E, t, x, y, z):
    """Σ of the terms' wind velocities [m/s] for a lane with term parameters E (none here)."""
    return (0.0, 0.0, 0.0)


def extra_loads(E, ctx):
    """Σ of the terms' world-frame force [N] and moment [N m] for a lane with term parameters E (none here)."""
    return (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)


def rhs(t, y, cf, E, kd):
    """dy/dt of one lane (:mod:`.rhs` docstring). cf: the 10 scaled coefficients; E: the lane's term
    parameters (tuple); kd = (g, (Id − Ia)/Id, 1/m, 1/Id, 1/Ia, m, A, d, ρ)."""
    g, gyro, inv_m, inv_Id, inv_Ia, m, A, d, rho = kd
    x, yy, z, vx, vy, vz, qw, qx, qy, qz, ox, oy, oz = y
    # R(q/|q|), v_W = R v_B
    s2 = 2.0 / (qw * qw + qx * qx + qy * qy + qz * qz)
    xx, y2, zz = qx * qx, qy * qy, qz * qz
    xy, xz, yz = qx * qy, qx * qz, qy * qz
    wx, wy, wz = qw * qx, qw * qy, qw * qz
    r00 = 1.0 - s2 * (y2 + zz)
    r01 = s2 * (xy - wz)
    r02 = s2 * (xz + wy)
    r10 = s2 * (xy + wz)
    r11 = 1.0 - s2 * (xx + zz)
    r12 = s2 * (yz - wx)
    r20 = s2 * (xz - wy)
    r21 = s2 * (yz + wx)
    r22 = 1.0 - s2 * (xx + y2)
    # air-relative velocity [m/s], world axes, then body axes u_B = Rᵀ v_a
    if HAS_AIR:
        wnd = air(E, t, x, yy, z)
        ax, ay, az = vx - wnd[0], vy - wnd[1], vz - wnd[2]
    else:
        ax, ay, az = vx, vy, vz
    ub = r00 * ax + r10 * ay + r20 * az
    vb = r01 * ax + r11 * ay + r21 * az
    wb = r02 * ax + r12 * ay + r22 * az
    vp2 = ub * ub + vb * vb
    vpar = math.sqrt(vp2)                               # V∥
    sp2 = vp2 + wb * wb
    sp = math.sqrt(sp2)                                 # V
    alpha, ivp = alpha_and_inverse(wb, vpar)
    d1x, d1y = ub * ivp, vb * ivp                       # d1 (body); d2 = (−d1y, d1x, 0)
    p = ox * d1x + oy * d1y
    q = oy * d1x - ox * d1y
    # specific lift (CL0 + CLa α) ρAV/2m along d2 × v_a = (w/V∥)(v_a − w b3) − V∥ b3 (world) and drag
    # (CD0 + CDa α²) ρAV/2m along −v_a:  dv/dt = (lift w/V∥ − drag) v_a − lift (V²/V∥) b3 − g ẑ
    lift = (cf[0] + cf[1] * alpha) * sp
    drag = (cf[2] + cf[3] * alpha * alpha) * sp
    fa = lift * wb * ivp - drag
    fb = lift * sp2 * ivp
    # moments / inertia [rad/s²]: roll about d1, pitch about d2, spin-down about b3
    roll = (cf[7] * oz + cf[8] * p) * sp2
    pitch = (cf[4] + cf[5] * alpha + cf[6] * q) * sp2
    mx = roll * d1x - pitch * d1y
    my = roll * d1y + pitch * d1x
    mz = cf[9] * oz * sp2
    dvx = fa * ax - fb * r02
    dvy = fa * ay - fb * r12
    dvz = fa * az - fb * r22 - g
    if HAS_LOADS:
        # the flight context of terms.py (world axes) and the terms' world-frame loads
        D1x, D1y, D1z = r00 * d1x + r01 * d1y, r10 * d1x + r11 * d1y, r20 * d1x + r21 * d1y
        D2x, D2y, D2z = r01 * d1x - r00 * d1y, r11 * d1x - r10 * d1y, r21 * d1x - r20 * d1y
        ctx = (t, x, yy, z, sp, alpha, 0.5 * rho * sp2, ax, ay, az, D1x, D1y, D1z, D2x, D2y, D2z,
               r02, r12, r22, p, q, oz, A, d, m, rho, 1.0 / inv_Ia, 1.0 / inv_Id, d1x, d1y)
        e = extra_loads(E, ctx)
        dvx += e[0] * inv_m
        dvy += e[1] * inv_m
        dvz += e[2] * inv_m
        mx += (r00 * e[3] + r10 * e[4] + r20 * e[5]) * inv_Id
        my += (r01 * e[3] + r11 * e[4] + r21 * e[5]) * inv_Id
        mz += (r02 * e[3] + r12 * e[4] + r22 * e[5]) * inv_Ia
    hx, hy, hz = 0.5 * ox, 0.5 * oy, 0.5 * oz
    gz = gyro * oz                                      # (Id − Ia)/Id · ω_z
    return (vx, vy, vz, dvx, dvy, dvz,
            -qx * hx - qy * hy - qz * hz,
            qw * hx + qy * hz - qz * hy,
            qw * hy - qx * hz + qz * hx,
            qw * hz + qx * hy - qy * hx,
            mx + gz * oy,
            my - gz * ox,
            mz)
