"""Branch-free arctangent of the compiled integrator: α = atan2(w, V∥) and 1/V∥ with one division.

Cephes' double-precision arctangent (|error| < 2e-16, as libm) written without branches (selects only),
so the loop over a group's lanes stays one vectorisable block.
"""
from __future__ import annotations

import math

import numba as nb

#: LLVM fast-math flags of the integrator: FMA contraction, reciprocal and signed-zero freedom. Not
#: 'nnan'/'ninf': NaN and infinity detection is how failing lanes are found.
FASTMATH = {"contract", "arcp", "nsz"}

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


# inlined by numba (its IR), not only by LLVM: a copy already compiled on its own (a call from Python) would
# otherwise be linked into a kernel as a call, and the kernel's loop over lanes would not be vectorised
@nb.njit(inline="always", fastmath=FASTMATH)
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
