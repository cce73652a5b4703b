"""Compiled batch integrator of the equations in :mod:`bayes_disc.physics.equations`.

Layout: one call integrates a batch of B lanes (parameter set × initial state) over one common time grid.
Lanes are processed in chunks of ``CHUNK`` with the state stored lane-innermost (13 × CHUNK), so the
right-hand side is a straight-line loop over lanes that LLVM vectorises (AVX2: four lanes per instruction).

Method: an explicit Runge–Kutta tableau (default Butcher's 7-stage 6th-order method) with fixed substeps
that land exactly on every output time. The substep is h ≤ c / ω_c with the fastest physical rate

    ω_c = max(|ω|, (Ia/Id)|ω3|, √(|CMa| Q A d / Id), (|CL0|+|CLa|+|CD0|+|CDa|) ρ A |v| / 2m, ...)

(spin, nutation, pitch stiffness, flight-path turning), the largest over the chunk's live lanes.
Lanes that leave the rated envelope (ω_c above ``omega_cap``, non-finite state, |v| above ``speed_cap``)
are flagged and frozen so the rest of the batch goes on: the sampler visits such parameters.
"""
from __future__ import annotations

import math

import numba as nb
import numpy as np

from .terms import Term

CHUNK = 32
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
_T3P8 = 2.41421356237309504880
_MOREBITS = 6.123233995736765886130e-17


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


# ------------------------------------------------------------------------------------------------------
# Butcher tableaux
def _butcher6():
    A = np.zeros((7, 7))
    A[1, 0] = 1 / 3
    A[2, 1] = 2 / 3
    A[3, :3] = [1 / 12, 1 / 3, -1 / 12]
    A[4, :4] = [-1 / 16, 9 / 8, -3 / 16, -3 / 8]
    A[5, :5] = [0, 9 / 8, -3 / 8, -3 / 4, 1 / 2]
    A[6, :6] = [9 / 44, -9 / 11, 63 / 44, 18 / 11, 0, -16 / 11]
    b = np.array([11 / 120, 0, 27 / 40, 27 / 40, -4 / 15, -4 / 15, 11 / 120])
    return A, b, A.sum(axis=1)


def _rk4():
    A = np.zeros((4, 4))
    A[1, 0] = 0.5
    A[2, 1] = 0.5
    A[3, 2] = 1.0
    return A, np.array([1 / 6, 1 / 3, 1 / 3, 1 / 6]), A.sum(axis=1)


TABLEAUX = {"rk6": _butcher6(), "rk4": _rk4()}
#: default step factor c per method: h ≤ c/ω_c (chosen by benchmarks/bench_simulator.py for ≲1e-6 m)
DEFAULT_STEP_FACTOR = {"rk6": 0.8, "rk4": 0.25}


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
def _make_kernel(terms: tuple[Term, ...]):
    air, extra_loads = _chains(terms)

    @nb.njit(inline="always", error_model="numpy")
    def rhs_lane(t, S, C, E, k, D, b):
        m, Ia, Id, d, A, rho, g = k[0], k[1], k[2], k[3], k[4], k[5], k[6]
        x, y, z = S[0, b], S[1, b], S[2, b]
        vx, vy, vz = S[3, b], S[4, b], S[5, b]
        qw, qx, qy, qz = S[6, b], S[7, b], S[8, b], S[9, b]
        ox, oy, oz = S[10, b], S[11, b], S[12, b]
        inv = 1.0 / math.sqrt(qw * qw + qx * qx + qy * qy + qz * qz)
        qw *= inv
        qx *= inv
        qy *= inv
        qz *= inv
        # rotation matrix R(q), v_W = R v_B
        r00 = 1 - 2 * (qy * qy + qz * qz)
        r01 = 2 * (qx * qy - qw * qz)
        r02 = 2 * (qx * qz + qw * qy)
        r10 = 2 * (qx * qy + qw * qz)
        r11 = 1 - 2 * (qx * qx + qz * qz)
        r12 = 2 * (qy * qz - qw * qx)
        r20 = 2 * (qx * qz - qw * qy)
        r21 = 2 * (qy * qz + qw * qx)
        r22 = 1 - 2 * (qx * qx + qy * qy)
        # air-relative velocity and the D frame
        w = air(E, b, t, x, y, z)
        ax, ay, az = vx - w[0], vy - w[1], vz - w[2]
        sp2 = ax * ax + ay * ay + az * az
        sp = math.sqrt(sp2)
        vb3 = ax * r02 + ay * r12 + az * r22
        px, py, pz = ax - vb3 * r02, ay - vb3 * r12, az - vb3 * r22
        vpn = math.sqrt(px * px + py * py + pz * pz)
        ivp = 1.0 / vpn if vpn > 1e-300 else 0.0
        d1x, d1y, d1z = px * ivp, py * ivp, pz * ivp
        d2x = r12 * d1z - r22 * d1y
        d2y = r22 * d1x - r02 * d1z
        d2z = r02 * d1y - r12 * d1x
        alpha = atan_vec(vb3 * ivp) if vpn > 1e-300 else (0.5 * math.pi if vb3 > 0 else -0.5 * math.pi)
        half_rho_A = 0.5 * rho * A
        Q = 0.5 * rho * sp2
        QAd = Q * A * d
        # body rates in the D frame
        wx = r00 * ox + r01 * oy + r02 * oz
        wy = r10 * ox + r11 * oy + r12 * oz
        wz = r20 * ox + r21 * oy + r22 * oz
        p = wx * d1x + wy * d1y + wz * d1z
        q = wx * d2x + wy * d2y + wz * d2z
        r = wx * r02 + wy * r12 + wz * r22
        # lift along d2 × v̂_a, drag along −v̂_a; (C·Q·A)·v̂ = C·(ρA|v|/2)·v
        cl = (C[0, b] + C[1, b] * alpha) * half_rho_A * sp
        cd = (C[2, b] + C[3, b] * alpha * alpha) * half_rho_A * sp
        lx = d2y * az - d2z * ay
        ly = d2z * ax - d2x * az
        lz = d2x * ay - d2y * ax
        Fx = cl * lx - cd * ax
        Fy = cl * ly - cd * ay
        Fz = cl * lz - cd * az
        roll = (C[7, b] * r + C[8, b] * p) * QAd
        pitch = (C[4, b] + C[5, b] * alpha + C[6, b] * q) * QAd
        spin = C[9, b] * r * QAd
        Mx = roll * d1x + pitch * d2x + spin * r02
        My = roll * d1y + pitch * d2y + spin * r12
        Mz = roll * d1z + pitch * d2z + spin * r22
        ctx = (t, x, y, z, sp, alpha, Q, ax, ay, az, d1x, d1y, d1z, d2x, d2y, d2z, r02, r12, r22,
               p, q, r, A, d, m, rho)
        e = extra_loads(E, b, ctx)
        Fx += e[0]
        Fy += e[1]
        Fz += e[2]
        Mx += e[3]
        My += e[4]
        Mz += e[5]
        # moment in the body frame: M_B = Rᵀ M_W
        mbx = r00 * Mx + r10 * My + r20 * Mz
        mby = r01 * Mx + r11 * My + r21 * Mz
        mbz = r02 * Mx + r12 * My + r22 * Mz
        D[0, b] = vx
        D[1, b] = vy
        D[2, b] = vz
        D[3, b] = Fx / m
        D[4, b] = Fy / m
        D[5, b] = Fz / m - g
        D[6, b] = 0.5 * (-qx * ox - qy * oy - qz * oz)
        D[7, b] = 0.5 * (qw * ox + qy * oz - qz * oy)
        D[8, b] = 0.5 * (qw * oy - qx * oz + qz * ox)
        D[9, b] = 0.5 * (qw * oz + qx * oy - qy * ox)
        D[10, b] = (mbx - (Ia - Id) * oy * oz) / Id
        D[11, b] = (mby - (Id - Ia) * oz * ox) / Id
        D[12, b] = mbz / Ia

    @nb.njit(error_model="numpy")
    def rhs_chunk(t, S, C, E, k, D, nb_):
        for b in range(nb_):
            rhs_lane(t, S, C, E, k, D, b)

    @nb.njit(error_model="numpy")
    def lane_rate(S, C, k, b):
        """ω_c of lane b [rad/s]: the fastest physical rate the step must resolve."""
        m, Ia, Id, d, A, rho = k[0], k[1], k[2], k[3], k[4], k[5]
        ox, oy, oz = S[10, b], S[11, b], S[12, b]
        sp = math.sqrt(S[3, b] ** 2 + S[4, b] ** 2 + S[5, b] ** 2) + 1.0
        om = math.sqrt(ox * ox + oy * oy + oz * oz)
        QAd = 0.5 * rho * sp * sp * A * d
        rate = max(om, Ia / Id * abs(oz))
        rate = max(rate, math.sqrt((abs(C[5, b]) + abs(C[4, b])) * QAd / Id))
        rate = max(rate, (abs(C[6, b]) + abs(C[7, b]) + abs(C[8, b])) * QAd / Id + abs(C[9, b]) * QAd / Ia)
        rate = max(rate, (abs(C[0, b]) + abs(C[1, b]) + abs(C[2, b]) + abs(C[3, b]))
                   * 0.5 * rho * A * sp / m)
        return max(rate, 1.0)

    @nb.njit(error_model="numpy")
    def integrate(y0, coef, ext, k, t0, times, marker_body, A_rk, b_rk, c_rk, step_factor,
                  omega_cap, speed_cap, fixed_rate, rate_margin, out_states, out_markers, status):
        """Integrate lanes y0 (B,13) with coefficients (B,10) and term parameters ext (B,ne) from t0 to
        every time in ``times`` (non-decreasing, ≥ t0). Writes out_states (B,n,13) when it has n rows,
        out_markers (B,n,nm,3) when it has n rows, and status (B,).

        fixed_rate > 0 fixes the step schedule (h = c / fixed_rate) so results are smooth functions of
        the parameters (finite-difference Jacobians, MCMC); lanes whose own rate exceeds
        rate_margin · fixed_rate are then flagged instead of shortening everyone's step."""
        B = y0.shape[0]
        n = times.shape[0]
        ns = b_rk.shape[0]
        nm = marker_body.shape[0]
        ne = ext.shape[1]
        want_states = out_states.shape[1] == n
        want_markers = out_markers.shape[1] == n
        S = np.empty((13, CHUNK))
        S0 = np.empty((13, CHUNK))
        Tmp = np.empty((13, CHUNK))
        K = np.empty((ns, 13, CHUNK))
        C = np.empty((10, CHUNK))
        E = np.empty((max(ne, 1), CHUNK))
        for start in range(0, B, CHUNK):
            nl = min(CHUNK, B - start)
            for b in range(nl):
                status[start + b] = STATUS_OK
                for j in range(13):
                    S[j, b] = y0[start + b, j]
                    S0[j, b] = y0[start + b, j]
                for j in range(10):
                    C[j, b] = coef[start + b, j]
                for j in range(ne):
                    E[j, b] = ext[start + b, j]
            tcur = t0
            for i in range(n):
                T = times[i] - tcur
                if T > 0.0:
                    wmax = 0.0
                    for b in range(nl):
                        if status[start + b] == STATUS_OK:
                            rate = lane_rate(S, C, k, b)
                            cap = rate_margin * fixed_rate if fixed_rate > 0.0 else omega_cap
                            if not (rate <= cap):
                                status[start + b] = STATUS_RATE
                            elif rate > wmax:
                                wmax = rate
                    if fixed_rate > 0.0:
                        wmax = fixed_rate
                    for b in range(nl):
                        if status[start + b] != STATUS_OK:
                            for j in range(13):
                                S[j, b] = S0[j, b]
                    nsub = max(1, int(math.ceil(T * wmax / step_factor)))
                    h = T / nsub
                    for sub in range(nsub):
                        ts = tcur + sub * h
                        for st in range(ns):
                            for j in range(13):
                                for b in range(nl):
                                    Tmp[j, b] = S[j, b]
                            for l in range(st):
                                a = h * A_rk[st, l]
                                if a != 0.0:
                                    for j in range(13):
                                        for b in range(nl):
                                            Tmp[j, b] += a * K[l, j, b]
                            rhs_chunk(ts + c_rk[st] * h, Tmp, C, E, k, K[st], nl)
                        for st in range(ns):
                            a = h * b_rk[st]
                            if a != 0.0:
                                for j in range(13):
                                    for b in range(nl):
                                        S[j, b] += a * K[st, j, b]
                        for b in range(nl):
                            nq = 1.0 / math.sqrt(S[6, b] ** 2 + S[7, b] ** 2 + S[8, b] ** 2 + S[9, b] ** 2)
                            S[6, b] *= nq
                            S[7, b] *= nq
                            S[8, b] *= nq
                            S[9, b] *= nq
                    tcur = times[i]
                # health check and output
                for b in range(nl):
                    g = start + b
                    if status[g] == STATUS_OK:
                        finite = True
                        for j in range(13):
                            if not math.isfinite(S[j, b]):
                                finite = False
                        if not finite:
                            status[g] = STATUS_NONFINITE
                        else:
                            sp = math.sqrt(S[3, b] ** 2 + S[4, b] ** 2 + S[5, b] ** 2)
                            if sp > speed_cap or abs(S[0, b]) + abs(S[1, b]) + abs(S[2, b]) > 1e5:
                                status[g] = STATUS_BOUNDS
                    ok = status[g] == STATUS_OK
                    if want_states:
                        for j in range(13):
                            out_states[g, i, j] = S[j, b] if ok else np.nan
                    if want_markers:
                        qw, qx, qy, qz = S[6, b], S[7, b], S[8, b], S[9, b]
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
                                out_markers[g, i, mk, 0] = S[0, b] + r00 * mx + r01 * my + r02 * mz
                                out_markers[g, i, mk, 1] = S[1, b] + r10 * mx + r11 * my + r12 * mz
                                out_markers[g, i, mk, 2] = S[2, b] + r20 * mx + r21 * my + r22 * mz
                            else:
                                out_markers[g, i, mk, 0] = np.nan
                                out_markers[g, i, mk, 1] = np.nan
                                out_markers[g, i, mk, 2] = np.nan
        return status

    return integrate


_KERNELS: dict[tuple[str, ...], object] = {}


def get_kernel(terms: tuple[Term, ...] = ()):
    """The compiled integrator for a tuple of terms (built once per distinct tuple)."""
    key = tuple(t.id for t in terms)
    if key not in _KERNELS:
        _KERNELS[key] = _make_kernel(tuple(terms))
    return _KERNELS[key]
