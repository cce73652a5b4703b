"""Compiled batch integrator of the equations in :mod:`bayes_disc.physics.equations`.

One call integrates a batch of B lanes (parameter set × initial state) over one common grid of output
times. Every lane is integrated on its own: its step schedule and its arithmetic depend only on its own
inputs, so a lane's result is bit-identical whatever the other lanes of the batch are, whichever group
width is used, and from run to run.

Layout (why it is fast)
-----------------------
Lanes are processed in groups of ``lanes`` (8 for batches, 4 for batches of at most 4 lanes; an AVX2
register holds 4 float64). A group's state, scaled coefficients, step sizes and term parameters live in
one flat workspace array, one row of ``lanes`` doubles per quantity, at offsets that are compile-time
constants. The Runge–Kutta step is generated from its Butcher tableau as straight-line code (stages
unrolled, the 13-component stage vectors held in tuples, i.e. registers) and the right-hand side,
with the terms' hooks, is inlined into it (LLVM ``alwaysinline``). The loop over a group's lanes is then
one branch-free block that LLVM vectorises (``<4 x double>``); the constant offsets let it prove that
the lanes' loads and stores do not alias, so no runtime checks are needed. Groups of 8 step their two
halves side by side, stage by stage (two independent dependency chains for the out-of-order core).
Per-lane bookkeeping (rates, health checks) is vectorised the same way.

Equations (body-axis form of :func:`.equations.state_derivative`)
-----------------------------------------------------------------
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

Method and step rule
--------------------
An explicit Runge–Kutta method with fixed substeps that land exactly on every output time. Default:
Verner's 7th-order "efficient" method (Verner 2010, RKV76.IIa; 9 stages for the 7th-order solution).
Each output interval (split into segments of at most ``SEGMENT_MAX`` s) is cut into n = ⌈T ω_c / c⌉
equal substeps, ω_c being the lane's fastest physical rate at the segment start

    ω_c = max(|ω|, (Ia/Id)|ω_z|, √((|CM0|+|CMa|) Q' A d / Id),
              (|CMq|+|CRr|+|CRp|) Q' A d / Id + |CNr| Q' A d / Ia, (|CL0|+|CLa|+|CD0|+|CDa|) ρ A V' / 2m, 1)

[rad/s] with V' = √(|v|² + 1 m²/s²), Q' = ρV'²/2: spin, nutation (Ia/Id)·r ≈ 1.93 r, pitch stiffness,
rate damping, flight-path turning. With ``fixed_rate`` > 0 every lane uses ω_c = fixed_rate instead, a
parameter-independent schedule (results smooth in the parameters), and lanes whose own ω_c exceeds
rate_margin · fixed_rate are flagged. The step count is per lane (not shared with other lanes).

The default c = 1.7 gives one Verner step per 120-Hz sample up to ω_c ≈ 204 rad/s (spin r ≈ 105 rad/s).
Marker errors measured when this was written: ≤ 1e-7 m on the four SPEC reference cases (reported by
``benchmarks/bench_simulator.py``); 0.6–2.4e-6 m over 2 s for r = 100 rad/s throws with wobble rates up
to 25 rad/s, against a DOP853 run at c = 0.3. (Butcher's rk6 needs two substeps per 120-Hz sample to
stay below 1e-6 m on the reference cases: 14 right-hand sides per sample instead of 9.)

Failures
--------
Lanes that leave the rated envelope (ω_c above the cap or NaN — any NaN/inf in the state or the
coefficients —, more than ``MAX_SUBSTEPS`` substeps in a segment, non-finite state, |v| above
``speed_cap``, |x| + |y| + |z| above 1e5 m) are flagged with a status code, parked on their initial state
and frozen (no further substeps) so the rest of the batch goes on; their outputs are NaN. The work per
lane is bounded by duration · cap / c substeps, so wild parameters return promptly.
"""
from __future__ import annotations

import math

import numba as nb
import numpy as np

from .terms import Term

#: lanes per group for batches (two AVX2 registers of float64: two independent dependency chains)
LANES = 8
#: lanes per group for batches of at most this many lanes (one AVX2 register)
LANES_SMALL = 4
#: longest stretch [s] integrated on one step-size decision (the rate is re-evaluated at least this often)
SEGMENT_MAX = 0.05
#: a lane needing more substeps than this in one segment is flagged (guards absurd caps and fixed rates)
MAX_SUBSTEPS = 100_000
#: LLVM fast-math flags of the integrator: FMA contraction, reciprocal and signed-zero freedom. Not
#: 'nnan'/'ninf': NaN and infinity detection is how failing lanes are found.
FASTMATH = {"contract", "arcp", "nsz"}

STATUS_OK = 0
STATUS_NONFINITE = 1
STATUS_RATE = 2
STATUS_BOUNDS = 3
STATUS_TEXT = {
    STATUS_OK: "ok",
    STATUS_NONFINITE: "state became non-finite",
    STATUS_RATE: "angular or aerodynamic rate above the integrator's rated envelope",
    STATUS_BOUNDS: "speed or position out of physical bounds",
}

# Cephes atan constants (double precision, |error| < 2e-16)
_P0, _P1, _P2, _P3, _P4 = (-8.750608600031904122785e-01, -1.615753718733365076637e01,
                           -7.500855792314704667340e01, -1.228866684490136173410e02,
                           -6.485021904942025371773e01)
_Q0, _Q1, _Q2, _Q3, _Q4 = (2.485846490142306297962e01, 1.650270098316988542046e02,
                           4.328810604912902668951e02, 4.853903996359136964868e02,
                           1.945506571482613964425e02)
_T3P8 = 2.41421356237309504880     # tan(3π/8)
_MOREBITS = 6.123233995736765886130e-17
_V_TINY = 1e-150                    # in-plane air speed [m/s] below which the D frame is undefined


@nb.njit(inline="always", cache=True)
def atan_vec(x):
    """Branch-free Cephes arctangent (vectorisable; same accuracy as libm)."""
    ax = abs(x)
    big = ax > _T3P8
    mid = (ax > 0.66) and not big
    xr = -1.0 / ax if big else ((ax - 1.0) / (ax + 1.0) if mid else ax)
    y0 = 0.5 * math.pi if big else (0.25 * math.pi if mid else 0.0)
    extra = _MOREBITS if big else (0.5 * _MOREBITS if mid else 0.0)
    z = xr * xr
    num = (((_P0 * z + _P1) * z + _P2) * z + _P3) * z + _P4
    den = ((((z + _Q0) * z + _Q1) * z + _Q2) * z + _Q3) * z + _Q4
    res = y0 + (xr * (z * num / den) + xr) + extra
    return res if x >= 0 else -res


@nb.njit(forceinline=True, fastmath=FASTMATH)
def alpha_and_inverse(w, vpar):
    """(α, 1/V∥) for α = atan2(w, V∥), V∥ ≥ 0 [rad, s/m], branch-free, one division for both.

    Cephes range reduction of x = |w|/V∥: above tan(3π/8) atan x = π/2 + atan(−V∥/|w|), above 0.66
    atan x = π/4 + atan((|w| − V∥)/(|w| + V∥)); the reduced argument num/den and 1/V∥ share the
    reciprocal of den·V∥. Without an in-plane air speed (V∥ ≤ 1e-150) α = ±π/2 and 1/V∥ is taken as 0
    (d1 undefined: lift and pitch/roll moments vanish, as in :func:`.frames.velocity_frame`)."""
    a = abs(w)
    big = a > _T3P8 * vpar
    mid = a > 0.66 * vpar
    num = -vpar if big else (a - vpar if mid else a)
    den = a if big else (a + vpar if mid else vpar)
    ok = vpar > _V_TINY
    inv = 1.0 / (den * vpar) if ok else 0.0
    xr = num * vpar * inv
    y0 = 0.5 * math.pi if big else (0.25 * math.pi if mid else 0.0)
    extra = _MOREBITS if big else (0.5 * _MOREBITS if mid else 0.0)
    z = xr * xr
    pn = (((_P0 * z + _P1) * z + _P2) * z + _P3) * z + _P4
    pd = ((((z + _Q0) * z + _Q1) * z + _Q2) * z + _Q3) * z + _Q4
    res = y0 + (xr * (z * pn / pd) + xr) + extra
    alpha = (res if w >= 0 else -res) if ok else (0.5 * math.pi if w >= 0 else -0.5 * math.pi)
    return alpha, den * inv


# ------------------------------------------------------------------------------------------------------
# Butcher tableaux (A, b, c)

def _rk4():
    """Classical 4-stage, 4th-order method."""
    A = np.zeros((4, 4))
    A[1, 0] = 0.5
    A[2, 1] = 0.5
    A[3, 2] = 1.0
    return A, np.array([1 / 6, 1 / 3, 1 / 3, 1 / 6]), A.sum(axis=1)


def _butcher6():
    """Butcher (1964), 7 stages, order 6."""
    A = np.zeros((7, 7))
    A[1, 0] = 1 / 3
    A[2, 1] = 2 / 3
    A[3, :3] = [1 / 12, 1 / 3, -1 / 12]
    A[4, :4] = [-1 / 16, 9 / 8, -3 / 16, -3 / 8]
    A[5, :5] = [0, 9 / 8, -3 / 8, -3 / 4, 1 / 2]
    A[6, :6] = [9 / 44, -9 / 11, 63 / 44, 18 / 11, 0, -16 / 11]
    b = np.array([11 / 120, 0, 27 / 40, 27 / 40, -4 / 15, -4 / 15, 11 / 120])
    return A, b, A.sum(axis=1)


def _verner7():
    """Verner's "efficient" 7(6) pair RKV76.IIa (J. H. Verner, Numer. Algorithms 53 (2010) 383–396):
    the 9 stages of its 7th-order solution (the embedded 6th-order estimate is not used). All 85 order
    conditions up to order 7 hold to 1e-14 (checked when this module was written)."""
    c = [0.0, 0.005, 0.10888888888888888888888888888888888889, 0.16333333333333333333333333333333333333,
         0.4555, 0.60950944899783813170870044214860249496, 0.884, 0.925, 1.0]
    rows = [
        [0.005],
        [-1.076790123456790123456790123456790123457, 1.185679012345679012345679012345679012346],
        [0.04083333333333333333333333333333333333333, 0.0, 0.1225],
        [0.6389139236255726780508121615993336109954, 0.0, -2.455672638223656809662640566430653894211,
         2.272258714598084131611828404831320283215],
        [-2.661577375018757131119259297861818119279, 0.0, 10.80451388645613769565396655365532838482,
         -8.353914657396199411968048547819291691541, 0.8204875949566569791420417341743839209619],
        [6.067741434696770992718360183877276714679, 0.0, -24.71127363591108579734203485290746001803,
         20.42751793078889394045773111748346612697, -1.906157978816647150624096784352757010879,
         1.006172249242068014790040335899474187268],
        [12.05467007625320299509109452892778311648, 0.0, -49.75478495046898932807257615331444758322,
         41.14288863860467663259698416710157354209, -4.461760149974004185641911603484815375051,
         2.042334822239174959821717077708608543738, -0.09834843665406107379530801693870224403537],
        [10.13814652288180787641845141981689030769, 0.0, -42.64113603171750214622846006736635730625,
         35.76384003992257007135021178023160054034, -4.348022840392907653340370296908245943710,
         2.009862268377035895441943593011827554771, 0.3487490460338272405953822853053145879140,
         -0.2714390051048312842371587140910297407572],
    ]
    b = [0.047155618486272221704317651088381756796, 0.0, 0.0, 0.25750564298434151895964361010376875810,
         0.26216653977412620477138630957645277111, 0.15216092656738557403231331991651175355,
         0.49399691700324842469071758932278768443, -0.29430311714032504415572447440927034291,
         0.081317472324951099997345994401367618925]
    A = np.zeros((9, 9))
    for i, row in enumerate(rows):
        A[i + 1, :len(row)] = row
    return A, np.array(b), np.array(c)


def _dop853():
    """The 12-stage 8th-order solution of Dormand & Prince's DOP853 (Hairer, Nørsett & Wanner)."""
    from scipy.integrate._ivp import dop853_coefficients as d
    return np.array(d.A[:12, :12]), np.array(d.B), np.array(d.C[:12])


TABLEAUX = {"vern7": _verner7(), "rk6": _butcher6(), "rk4": _rk4()}
try:   # scipy's coefficient table is private API: offer the method only where it is found
    TABLEAUX["dop853"] = _dop853()
except (ImportError, AttributeError):   # pragma: no cover
    pass

#: default step factor c per method: h ≤ c/ω_c (benchmarks/bench_simulator.py measures the errors)
DEFAULT_STEP_FACTOR = {"vern7": 1.7, "dop853": 2.2, "rk6": 0.8, "rk4": 0.25}
DEFAULT_METHOD = "vern7"


def step_source(A, b, c, n=13, P=1) -> str:
    """Python source of ``rk_step(ts, hs, ys, cfs, lanes, E, kd)``: one explicit RK step of the tableau
    (A, b, c) for P independent lanes (P-tuples of times, steps, n-tuple states, coefficient tuples and
    lane indices); returns the P new states. Stages are unrolled and zero coefficients dropped; the
    products h·a_ij are formed once per step, so every stage value is a chain of fused multiply-adds.
    The P lanes' stages are interleaved (stage i of every lane, then stage i + 1): independent
    dependency chains side by side, which the out-of-order core overlaps. Calls ``rhs``."""
    ns = len(b)
    lines = ["def rk_step(ts, hs, ys, cfs, lanes, E, kd):",
             f'    """{ns}-stage explicit Runge–Kutta step of {P} lane(s) (generated by kernel.step_source)."""']
    for p in range(P):
        lines.append(f"    t{p}, h{p}, y{p}, cf{p}, lane{p} = ts[{p}], hs[{p}], ys[{p}], cfs[{p}], lanes[{p}]")
        for i in range(ns):
            lines += [f"    a{p}_{i}_{j} = h{p} * {float(A[i, j])!r}" for j in range(i) if A[i, j] != 0.0]
        lines += [f"    b{p}_{j} = h{p} * {float(b[j])!r}" for j in range(ns) if b[j] != 0.0]
    for i in range(ns):
        for p in range(P):
            if i == 0:
                arg = f"y{p}"
            else:
                comps = [" + ".join([f"y{p}[{m}]"] + [f"a{p}_{i}_{j} * k{p}_{j}[{m}]" for j in range(i)
                                                      if A[i, j] != 0.0]) for m in range(n)]
                lines.append(f"    s{p} = ({', '.join(comps)},)")
                arg = f"s{p}"
            lines.append(f"    k{p}_{i} = rhs(t{p} + {float(c[i])!r} * h{p}, {arg}, cf{p}, E, lane{p}, kd)")
    outs = []
    for p in range(P):
        comps = [" + ".join([f"y{p}[{m}]"] + [f"b{p}_{j} * k{p}_{j}[{m}]" for j in range(ns) if b[j] != 0.0])
                 for m in range(n)]
        outs.append(f"({', '.join(comps)},)")
    lines.append(f"    return ({', '.join(outs)},)")
    return "\n".join(lines)


# ------------------------------------------------------------------------------------------------------
# hook chains: fold the terms' compiled hooks into one inlined function each

@nb.njit(inline="always", cache=True)
def _no_air(E, b, t, x, y, z):
    return (0.0, 0.0, 0.0)


@nb.njit(inline="always", cache=True)
def _no_loads(E, b, ctx):
    return (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)


def _link_air(prev, hook, off):
    @nb.njit(inline="always", error_model="numpy")
    def linked(E, b, t, x, y, z):
        a = prev(E, b, t, x, y, z)
        w = hook(E, off, b, t, x, y, z)
        return (a[0] + w[0], a[1] + w[1], a[2] + w[2])
    return linked


def _link_loads(prev, hook, off):
    @nb.njit(inline="always", error_model="numpy")
    def linked(E, b, ctx):
        a = prev(E, b, ctx)
        f = hook(E, off, b, ctx)
        return (a[0] + f[0], a[1] + f[1], a[2] + f[2], a[3] + f[3], a[4] + f[4], a[5] + f[5])
    return linked


def _chains(terms: tuple[Term, ...]):
    air, loads, off = _no_air, _no_loads, 0
    for term in terms:
        if term.air is not None:
            air = _link_air(air, term.air, off)
        if term.loads is not None:
            loads = _link_loads(loads, term.loads, off)
        off += len(term.parameters)
    return air, loads


# ------------------------------------------------------------------------------------------------------
# workspace of one group: rows of `lanes` doubles
_ROW_S = 0          # 13 state rows
_ROW_C = 13         # 10 scaled-coefficient rows
_ROW_H = 23         # substep h [s]
_ROW_T = 24         # segment start time [s]
_ROW_N = 25         # number of substeps in this segment (0: frozen or padding lane)
_ROW_K = 26         # 3 rate constants: √(|c4|+|c5|), |c6|+|c7|+|c8|+|c9|, |c0|+|c1|+|c2|+|c3| (scaled c)
_ROW_R = 29         # ω_c at the segment start [rad/s] (NaN when the state or coefficients are not finite)
_ROW_X = 30         # health after an output step: 0 ok, 1 non-finite, 2 out of bounds
_ROW_E = 31         # term parameters


def _make_kernel(terms: tuple[Term, ...], method: str, lanes: int):
    """Build (not yet compile) the integrator for these terms, method and group width; groups of 8 or
    more lanes step two half-groups side by side (P = 2)."""
    air, extra_loads = _chains(terms)
    has_air = any(t.air is not None for t in terms)
    has_loads = any(t.loads is not None for t in terms)
    NE = sum(len(t.parameters) for t in terms)
    L = lanes
    P = 2 if L >= 8 and L % 8 == 0 else 1
    NW = (_ROW_E + max(NE, 1)) * L
    oS, oC, oH, oT, oN = _ROW_S * L, _ROW_C * L, _ROW_H * L, _ROW_T * L, _ROW_N * L
    oK, oR, oX, oE = _ROW_K * L, _ROW_R * L, _ROW_X * L, _ROW_E * L

    @nb.njit(forceinline=True, error_model="numpy", fastmath=FASTMATH)
    def rhs(t, y, cf, E, b, kd):
        """dy/dt of one lane (module docstring). cf: the 10 scaled coefficients; E, b: term parameters
        and lane; kd = (g, (Id − Ia)/Id, 1/m, 1/Id, 1/Ia, m, A, d, ρ)."""
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
        if has_air:
            wnd = air(E, b, t, x, yy, z)
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
        if has_loads:
            # the flight context of terms.py (world axes) and the terms' world-frame loads
            D1x, D1y, D1z = r00 * d1x + r01 * d1y, r10 * d1x + r11 * d1y, r20 * d1x + r21 * d1y
            D2x, D2y, D2z = r01 * d1x - r00 * d1y, r11 * d1x - r10 * d1y, r21 * d1x - r20 * d1y
            ctx = (t, x, yy, z, sp, alpha, 0.5 * rho * sp2, ax, ay, az, D1x, D1y, D1z, D2x, D2y, D2z,
                   r02, r12, r22, p, q, oz, A, d, m, rho)
            e = extra_loads(E, b, ctx)
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

    A_rk, b_rk, c_rk = TABLEAUX[method]
    namespace = {"rhs": rhs}
    exec(step_source(A_rk, b_rk, c_rk, P=P), namespace)
    rk_step = nb.njit(forceinline=True, error_model="numpy", fastmath=FASTMATH)(namespace["rk_step"])

    @nb.njit(forceinline=True, error_model="numpy", fastmath=FASTMATH)
    def load_lane(W, b):
        """(state, scaled coefficients) of lane b."""
        y = (W[oS + 0 * L + b], W[oS + 1 * L + b], W[oS + 2 * L + b], W[oS + 3 * L + b],
             W[oS + 4 * L + b], W[oS + 5 * L + b], W[oS + 6 * L + b], W[oS + 7 * L + b],
             W[oS + 8 * L + b], W[oS + 9 * L + b], W[oS + 10 * L + b], W[oS + 11 * L + b],
             W[oS + 12 * L + b])
        cf = (W[oC + 0 * L + b], W[oC + 1 * L + b], W[oC + 2 * L + b], W[oC + 3 * L + b],
              W[oC + 4 * L + b], W[oC + 5 * L + b], W[oC + 6 * L + b], W[oC + 7 * L + b],
              W[oC + 8 * L + b], W[oC + 9 * L + b])
        return y, cf

    @nb.njit(forceinline=True, error_model="numpy", fastmath=FASTMATH)
    def store_lane(W, b, y, yn, sub):
        """Lane b takes the stepped state yn (quaternion renormalised) if sub < its substep count,
        else keeps y (branch-free)."""
        nq = 1.0 / math.sqrt(yn[6] * yn[6] + yn[7] * yn[7] + yn[8] * yn[8] + yn[9] * yn[9])
        act = sub < W[oN + b]
        W[oS + 0 * L + b] = yn[0] if act else y[0]
        W[oS + 1 * L + b] = yn[1] if act else y[1]
        W[oS + 2 * L + b] = yn[2] if act else y[2]
        W[oS + 3 * L + b] = yn[3] if act else y[3]
        W[oS + 4 * L + b] = yn[4] if act else y[4]
        W[oS + 5 * L + b] = yn[5] if act else y[5]
        W[oS + 6 * L + b] = yn[6] * nq if act else y[6]
        W[oS + 7 * L + b] = yn[7] * nq if act else y[7]
        W[oS + 8 * L + b] = yn[8] * nq if act else y[8]
        W[oS + 9 * L + b] = yn[9] * nq if act else y[9]
        W[oS + 10 * L + b] = yn[10] if act else y[10]
        W[oS + 11 * L + b] = yn[11] if act else y[11]
        W[oS + 12 * L + b] = yn[12] if act else y[12]

    HALF = L // 2

    @nb.njit(forceinline=True, error_model="numpy", fastmath=FASTMATH)
    def group_substep(W, E, kd, sub):
        """Substep number ``sub`` of the segment for every lane of the group; lanes with sub ≥ n keep
        their state. Vectorised over the lanes; with P = 2 lanes b and b + L/2 are stepped together."""
        if P == 1:
            for b in range(L):
                y, cf = load_lane(W, b)
                h = W[oH + b]
                (yn,) = rk_step((W[oT + b] + sub * h,), (h,), (y,), (cf,), (b,), E, kd)
                store_lane(W, b, y, yn, sub)
        else:
            for b in range(HALF):
                c2 = b + HALF
                y, cf = load_lane(W, b)
                y2, cf2 = load_lane(W, c2)
                h, h2 = W[oH + b], W[oH + c2]
                yn, yn2 = rk_step((W[oT + b] + sub * h, W[oT + c2] + sub * h2), (h, h2), (y, y2), (cf, cf2),
                                  (b, c2), E, kd)
                store_lane(W, b, y, yn, sub)
                store_lane(W, c2, y2, yn2, sub)

    @nb.njit(forceinline=True, error_model="numpy", fastmath=FASTMATH)
    def group_rates(W, nutation):
        """ω_c [rad/s] of every lane into the rate row (module docstring; nutation = Ia/Id). Any NaN
        or ±inf in a lane's state or coefficients makes its rate NaN."""
        for b in range(L):
            vx, vy, vz = W[oS + 3 * L + b], W[oS + 4 * L + b], W[oS + 5 * L + b]
            ox, oy, oz = W[oS + 10 * L + b], W[oS + 11 * L + b], W[oS + 12 * L + b]
            sp2 = vx * vx + vy * vy + vz * vz + 1.0
            sp = math.sqrt(sp2)
            r2 = max(ox * ox + oy * oy + oz * oz, nutation * nutation * oz * oz)
            r2 = max(r2, W[oK + b] * W[oK + b] * sp2)
            damping = W[oK + L + b] * sp2
            turning = W[oK + 2 * L + b] * sp
            r2 = max(max(r2, damping * damping), max(turning * turning, 1.0))
            poison = 0.0
            for j in range(13):
                poison += 0.0 * W[oS + j * L + b]
            for j in range(3):
                poison += 0.0 * W[oK + j * L + b]
            W[oR + b] = math.sqrt(r2) + poison

    @nb.njit(forceinline=True, error_model="numpy", fastmath=FASTMATH)
    def group_health(W, speed_cap):
        """Health row: 1 if a state component is NaN/inf, 2 if |v| > speed_cap or |x|+|y|+|z| > 1e5 m."""
        for b in range(L):
            poison = 0.0
            for j in range(13):
                poison += 0.0 * W[oS + j * L + b]
            vx, vy, vz = W[oS + 3 * L + b], W[oS + 4 * L + b], W[oS + 5 * L + b]
            pos = abs(W[oS + b]) + abs(W[oS + L + b]) + abs(W[oS + 2 * L + b])
            out = vx * vx + vy * vy + vz * vz > speed_cap * speed_cap or pos > 1e5
            W[oX + b] = 0.0 if (poison == 0.0 and not out) else (1.0 if poison != 0.0 else 2.0)

    @nb.njit(error_model="numpy", fastmath=FASTMATH)
    def integrate(y0, coef, ext, k, t0, times, marker_body, step_factor, omega_cap, speed_cap,
                  fixed_rate, rate_margin, out_states, out_markers, status):
        """Integrate lanes y0 (B,13) with coefficients (B,10) and term parameters ext (B,ne) from t0 to
        every time in ``times`` (non-decreasing, ≥ t0); k = (m, Ia, Id, d, A, ρ, g). Writes out_states
        (B,n,13) when it has n rows, out_markers (B,n,nm,3) when it has n rows, and status (B,).

        Each lane takes ⌈T ω_c / c⌉ equal substeps per segment (module docstring); fixed_rate > 0 fixes
        ω_c = fixed_rate for every lane (results smooth in the parameters) and flags lanes whose own ω_c
        exceeds rate_margin · fixed_rate instead of omega_cap."""
        B = y0.shape[0]
        n = times.shape[0]
        nm = marker_body.shape[0]
        want_states = out_states.shape[1] == n
        want_markers = out_markers.shape[1] == n
        m, Ia, Id, d, A, rho, g = k[0], k[1], k[2], k[3], k[4], k[5], k[6]
        kd = (g, (Id - Ia) / Id, 1.0 / m, 1.0 / Id, 1.0 / Ia, m, A, d, rho)
        f_acc = 0.5 * rho * A / m           # CL*, CD* → specific force per V·(velocity)
        f_mom = 0.5 * rho * A * d / Id      # CM*, CR* → angular acceleration per V²
        f_spin = 0.5 * rho * A * d / Ia     # CNr
        cap = rate_margin * fixed_rate if fixed_rate > 0.0 else omega_cap
        W = np.zeros(NW)
        E = W[oE:oE + max(NE, 1) * L].reshape((max(NE, 1), L))    # the terms' E[off + i, lane]
        Y0 = np.empty((L, 13))
        for g0 in range(0, B, L):
            nl = min(L, B - g0)
            # load the group; padding lanes copy the group's first lane and are never stepped or written
            for b in range(L):
                src = g0 + b if b < nl else g0
                for j in range(13):
                    Y0[b, j] = y0[src, j]
                    W[oS + j * L + b] = y0[src, j]
                for j in range(4):
                    W[oC + j * L + b] = coef[src, j] * f_acc
                for j in range(4, 9):
                    W[oC + j * L + b] = coef[src, j] * f_mom
                W[oC + 9 * L + b] = coef[src, 9] * f_spin
                W[oK + b] = math.sqrt(abs(W[oC + 4 * L + b]) + abs(W[oC + 5 * L + b]))
                W[oK + L + b] = (abs(W[oC + 6 * L + b]) + abs(W[oC + 7 * L + b]) + abs(W[oC + 8 * L + b])
                                 + abs(W[oC + 9 * L + b]))
                W[oK + 2 * L + b] = (abs(W[oC + b]) + abs(W[oC + L + b]) + abs(W[oC + 2 * L + b])
                                     + abs(W[oC + 3 * L + b]))
                for j in range(NE):
                    W[oE + j * L + b] = ext[src, j]
                W[oN + b] = 0.0
                if b < nl:
                    status[g0 + b] = STATUS_OK
            tcur = t0
            for i in range(n):
                T = times[i] - tcur
                if T > 0.0:
                    nseg = max(1, int(math.ceil(T / SEGMENT_MAX)))
                    for seg in range(nseg):
                        ts = tcur + T * seg / nseg if seg > 0 else tcur
                        Tseg = T / nseg
                        group_rates(W, Ia / Id)
                        nmax = 0
                        for b in range(nl):
                            W[oN + b] = 0.0
                            if status[g0 + b] != STATUS_OK:
                                continue
                            rate = W[oR + b]
                            w = fixed_rate if fixed_rate > 0.0 else rate
                            if not (rate <= cap and Tseg * w <= MAX_SUBSTEPS * step_factor):
                                status[g0 + b] = STATUS_RATE
                                for j in range(13):       # park the lane on harmless numbers
                                    W[oS + j * L + b] = Y0[b, j]
                                continue
                            nsub = max(1, int(math.ceil(Tseg * w / step_factor)))
                            W[oN + b] = nsub
                            W[oH + b] = Tseg / nsub
                            W[oT + b] = ts
                            nmax = max(nmax, nsub)
                        for sub in range(nmax):
                            group_substep(W, E, kd, sub)
                    tcur = times[i]
                # health check and output
                group_health(W, speed_cap)
                for b in range(nl):
                    gl = g0 + b
                    if status[gl] == STATUS_OK and W[oX + b] != 0.0:
                        status[gl] = STATUS_NONFINITE if W[oX + b] == 1.0 else STATUS_BOUNDS
                        for j in range(13):
                            W[oS + j * L + b] = Y0[b, j]
                    ok = status[gl] == STATUS_OK
                    if want_states:
                        for j in range(13):
                            out_states[gl, i, j] = W[oS + j * L + b] if ok else np.nan
                    if want_markers:
                        px, py, pz = W[oS + b], W[oS + L + b], W[oS + 2 * L + b]
                        qw, qx = W[oS + 6 * L + b], W[oS + 7 * L + b]
                        qy, qz = W[oS + 8 * L + b], W[oS + 9 * L + b]
                        r00 = 1 - 2 * (qy * qy + qz * qz)
                        r01 = 2 * (qx * qy - qw * qz)
                        r02 = 2 * (qx * qz + qw * qy)
                        r10 = 2 * (qx * qy + qw * qz)
                        r11 = 1 - 2 * (qx * qx + qz * qz)
                        r12 = 2 * (qy * qz - qw * qx)
                        r20 = 2 * (qx * qz - qw * qy)
                        r21 = 2 * (qy * qz + qw * qx)
                        r22 = 1 - 2 * (qx * qx + qy * qy)
                        for mk in range(nm):
                            mx, my, mz = marker_body[mk, 0], marker_body[mk, 1], marker_body[mk, 2]
                            if ok:
                                out_markers[gl, i, mk, 0] = px + r00 * mx + r01 * my + r02 * mz
                                out_markers[gl, i, mk, 1] = py + r10 * mx + r11 * my + r12 * mz
                                out_markers[gl, i, mk, 2] = pz + r20 * mx + r21 * my + r22 * mz
                            else:
                                out_markers[gl, i, mk, 0] = np.nan
                                out_markers[gl, i, mk, 1] = np.nan
                                out_markers[gl, i, mk, 2] = np.nan
        return status

    return integrate


_KERNELS: dict[tuple, object] = {}


def get_kernel(terms: tuple[Term, ...] = (), method: str = DEFAULT_METHOD, lanes: int = LANES):
    """The compiled integrator for a tuple of terms, a method of :data:`TABLEAUX` and a group width
    (built once per distinct combination; compiled on first call). Results do not depend on the width."""
    if method not in TABLEAUX:
        raise ValueError(f"unknown integration method {method!r}; known: {sorted(TABLEAUX)}")
    key = (tuple(t.id for t in terms), method, int(lanes))
    if key not in _KERNELS:
        _KERNELS[key] = _make_kernel(tuple(terms), method, int(lanes))
    return _KERNELS[key]
