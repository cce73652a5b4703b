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

Equations
---------
The body-axis form of :func:`.equations.state_derivative` in :mod:`.rhs`.

Modules
-------
:mod:`.tableaux` (Butcher tableaux as data), :mod:`.arctan` (branch-free arctangent),
:mod:`.rhs` (right-hand side), :mod:`.integrator` (driver), :mod:`.codegen` (the generated module of one
kernel), :mod:`.kernel_cache` (compiled kernels kept on disk between processes); this module picks
and builds kernels.

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
Marker errors measured when this was written: ≤ 1e-7 m on the four reference cases of ``shared/reference`` (reported by
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

from .arctan import FASTMATH, alpha_and_inverse
from .codegen import kernel_source, step_source
from .integrator import (LANES, LANES_SMALL, MAX_SUBSTEPS, SEGMENT_MAX, STATUS_BOUNDS, STATUS_NONFINITE,
                         STATUS_OK, STATUS_RATE, STATUS_TEXT)
from .kernel_cache import load_kernel
from .tableaux import DEFAULT_METHOD, DEFAULT_STEP_FACTOR, TABLEAUX, get_tableau
from .terms import Term

__all__ = ["FASTMATH", "alpha_and_inverse", "kernel_source", "step_source", "LANES", "LANES_SMALL",
           "MAX_SUBSTEPS", "SEGMENT_MAX", "STATUS_BOUNDS", "STATUS_NONFINITE", "STATUS_OK", "STATUS_RATE",
           "STATUS_TEXT", "DEFAULT_METHOD", "DEFAULT_STEP_FACTOR", "TABLEAUX", "get_kernel"]

_KERNELS: dict[tuple, object] = {}


def get_kernel(terms: tuple[Term, ...] = (), method: str = DEFAULT_METHOD, lanes: int = LANES):
    """The compiled integrator for a tuple of terms, a method and a group width.

    Built once per distinct combination in a process; compiled on first call, or loaded from the disk
    cache (:mod:`.kernel_cache`). Results do not depend on the width.

    Parameters
    ----------
    terms : tuple of Term
        Extra physics terms.
    method : str
        A key of :data:`.tableaux.TABLEAUX`.
    lanes : int
        Lanes per group (:data:`LANES` or :data:`LANES_SMALL`).

    Returns
    -------
    callable
        ``integrate(y0, coef, ext, k, t0, times, marker_body, step_factor, omega_cap, speed_cap,
        fixed_rate, rate_margin, out_states, out_markers, status)`` (see :mod:`.integrator`).
    """
    tableau = get_tableau(method)
    key = (tuple(t.id for t in terms), method, int(lanes))
    if key not in _KERNELS:
        terms = tuple(terms)
        _KERNELS[key] = load_kernel(kernel_source(terms, tableau, int(lanes), cache=True),
                                    kernel_source(terms, tableau, int(lanes), cache=False))
    return _KERNELS[key]
