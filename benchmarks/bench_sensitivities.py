"""Forward sensitivities against central differences: one flight's marker Jacobian (issue #18).

Least squares, profile fits and the Fisher analysis take their Jacobians by central differences of the
compiled integrator (``inference.fitting.residuals.jacobian_blocks``: two lanes per parameter). Issue #18 asks
whether forward sensitivities — the variational equations integrated alongside the state — are faster at
equal accuracy. This benchmark measures it on each of the demo's four true flights:

* the columns: the 13 initial-state components y0 and the 10 coefficients C (23 columns), for the three
  markers' positions at 120 Hz;
* central differences: the kernel (:func:`bayes_disc.physics.simulate`), 47 lanes in one call (the
  centre and ± a step per column), steps 10⁻⁴ × a column scale (the project's rule; 10⁻³ and 10⁻⁵ show
  how the error scales);
* forward sensitivities: a numba integrator of the same Runge–Kutta tableau on the same step schedule
  (⌈T ω_c / c⌉ substeps per segment, the kernel's rule) that carries S = ∂y/∂(y0, C) (13 × 23) through
  every stage, K'_i = (∂f/∂y)(Y_i) S_i + ∂f/∂C, and through the quaternion's renormalisation after each
  substep. The tangent-linear right-hand side is generated from the source text of the kernel's own
  right-hand side (:func:`bayes_disc.physics.rhs.rhs`) by forward-mode differentiation statement by
  statement (each statement's partial derivatives by sympy), with one loop over the columns that the
  compiler vectorises, as the kernel vectorises over lanes; the step is unrolled over the tableau's
  stages with its coefficients as constants (as the kernel's step is generated), each stage's
  combination one loop over the 13 × 24 sensitivity entries (23 columns padded to 24).

Accuracy is the relative error of each column against (a) forward sensitivities on the same schedule
(the exact derivative, to rounding, of the residuals least squares minimises; central differences
converge to it as the step squared) and (b) forward sensitivities with c / 16 (the derivative of the exact
flight). Times are medians of one flight's Jacobian over runs of the three callables in turn (one lane,
central differences, forward sensitivities), compile time excluded, one thread. Exit status 1 if the
forward-sensitivity integrator does not reproduce the kernel's markers or disagrees with central
differences extrapolated to a zero step (Richardson, steps 10⁻⁴ and 5·10⁻⁵) on the same schedule.

Usage: ``python benchmarks/bench_sensitivities.py [--flights NAME ...] [--repeats N] [--json]``. Uses
``runs/demo/truth.json``. Needs sympy (``pip install -e ".[bench]"``). About a minute, most of it
compiling.
"""
from __future__ import annotations

import argparse
import ast
import inspect
import json
import math
import os
import sys
import textwrap
import time
import types
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
if str(REPO) not in sys.path:
    sys.path.insert(0, str(REPO))

import numba as nb  # noqa: E402
import sympy as sp  # noqa: E402

from bayes_disc.physics import COEFFICIENT_NAMES, Disc, Environment, SimulatorSettings, simulate  # noqa: E402
from bayes_disc.physics import rhs as rhs_module  # noqa: E402
from bayes_disc.physics.arctan import alpha_and_inverse  # noqa: E402
from bayes_disc.physics.integrator import SEGMENT_MAX  # noqa: E402
from bayes_disc.physics.tableaux import DEFAULT_STEP_FACTOR, get_tableau  # noqa: E402

NY, NC = 13, 10
COLUMNS = ("x", "y", "z", "vx", "vy", "vz", "qw", "qx", "qy", "qz", "wx", "wy", "wz") + tuple(COEFFICIENT_NAMES)
NCOL = NY + NC
#: row length of the tangent arrays: the 23 columns padded to a multiple of 4 (an AVX2 register), so that
#: the column loops have no scalar remainder (the padding column stays zero)
NPAD = 24
#: the tangent workspace W of one right-hand side, rows of NPAD doubles at constant offsets: S of the
#: stage's state (13 rows), the stage's K' = (∂f/∂y) S + ∂f/∂C (13 rows), and the seeds of the scaled
#: coefficients (10 rows: ∂cf_i/∂C_j = cscale_i δ_ij, in column NY + j)
SY_OFF, SK_OFF, C_OFF = 0, NY * NPAD, 2 * NY * NPAD
REL_STEPS = (1e-3, 1e-4, 1e-5)
#: column scales for the difference steps: position [m], velocity [m/s], quaternion, ω [rad/s], and
#: coefficients (max(|C|, 0.01))
STATE_SCALE = np.r_[np.full(3, 0.05), np.full(3, 0.5), np.full(4, 0.02), np.full(3, 2.0)]


def _sym(name):
    return sp.Symbol(name, real=True)


def tangent_source():
    """Source of ``f_tangent(Y, cf, kd, W, F)``: the kernel's right-hand side
    (:func:`bayes_disc.physics.rhs.rhs`, without terms) and its tangent-linear code, by forward-mode
    differentiation of its source text statement by statement (each statement's partial derivatives by
    sympy). Writes F (13,) = f(Y) and, in the workspace W, K' = (∂f/∂y) S + (∂f/∂C) for the stage's S.

    The primal statements and their partial derivatives (scalars) come first; then one loop over the
    NCOL columns holds every statement's tangent as a scalar, d_a = Σ_b ∂a/∂b · d_b, so that the
    compiler vectorises it over the columns (as the kernel does over lanes)."""
    tree = ast.parse(textwrap.dedent(inspect.getsource(rhs_module.rhs)))
    ns: dict = {"cf": [_sym(f"cf_{i}") for i in range(NC)]}
    # tangent of each active name, as an expression in the column loop (index k)
    tok = {f"cf_{i}": f"W[{C_OFF + i * NPAD} + k]" for i in range(NC)}
    primal = ["    " + ", ".join(f"cf_{i}" for i in range(NC)) + " = " + ", ".join(f"cf[{i}]" for i in range(NC))]
    loop: list = []
    shim = {"math": types.SimpleNamespace(sqrt=sp.sqrt)}
    pr = sp.printing.pycode
    n_gain = 0

    def tangent(gains):
        """'Σ g · d_b' for gains [(python expression of ∂a/∂b, b)] of active b (None if there are none)."""
        nonlocal n_gain
        parts = []
        for g, b in gains:
            if g in ("0", "0.0"):
                continue
            primal.append(f"    g{n_gain} = {g}")
            parts.append(f"g{n_gain} * {tok[b]}")
            n_gain += 1
        return " + ".join(parts) if parts else None

    def derive(src):
        e = sp.sympify(eval(src, shim, ns))
        return [(pr(sp.diff(e, a)), str(a)) for a in sorted(e.free_symbols, key=str) if str(a) in tok]

    def assign(name, src):
        primal.append(f"    {name} = {src}")
        if src in tok:                                       # a copy shares its tangent
            tok[name] = tok[src]
        else:
            body = tangent(derive(src))
            if body is not None:
                loop.append(f"        d_{name} = {body}")
                tok[name] = f"d_{name}"
        ns[name] = _sym(name)

    def visit(stmts):
        for st in stmts:
            if isinstance(st, ast.Expr):
                continue                                     # docstring
            if isinstance(st, ast.If):
                if ast.unparse(st.test) not in ("HAS_AIR", "HAS_LOADS"):
                    raise ValueError(f"unexpected branch {ast.unparse(st.test)}")
                visit(st.orelse)                             # no terms: both flags are False
            elif isinstance(st, ast.Return):
                for i, elt in enumerate(st.value.elts):
                    src = ast.unparse(elt)
                    primal.append(f"    F[{i}] = {src}")
                    body = tangent(derive(src))
                    loop.append(f"        W[{SK_OFF + i * NPAD} + k] = {body if body else '0.0'}")
            elif isinstance(st, ast.Assign) and isinstance(st.targets[0], ast.Tuple):
                names = [e.id for e in st.targets[0].elts]
                val = st.value
                if isinstance(val, ast.Name) and val.id == "y":
                    for j, nm in enumerate(names):
                        primal.append(f"    {nm} = Y[{j}]")
                        ns[nm] = _sym(nm)
                        tok[nm] = f"W[{SY_OFF + j * NPAD} + k]"
                elif isinstance(val, ast.Name) and val.id == "kd":
                    for j, nm in enumerate(names):
                        primal.append(f"    {nm} = kd[{j}]")
                        ns[nm] = _sym(nm)
                elif isinstance(val, ast.Call) and ast.unparse(val.func) == "alpha_and_inverse":
                    w, vpar = (ast.unparse(a) for a in val.args)
                    al, iv = names
                    primal.append(f"    {al}, {iv} = alpha_and_inverse({w}, {vpar})")
                    # α = atan2(w, V∥): dα = (V∥ dw − w dV∥)/(w² + V∥²);  d(1/V∥) = −(1/V∥)² dV∥
                    den = f"({w} * {w} + {vpar} * {vpar})"
                    for nm, gains in ((al, [(f"{vpar} / {den}", w), (f"-{w} / {den}", vpar)]),
                                      (iv, [(f"-{iv} * {iv}", vpar)])):
                        body = tangent([(g, b) for g, b in gains if b in tok])
                        if body is not None:
                            loop.append(f"        d_{nm} = {body}")
                            tok[nm] = f"d_{nm}"
                        ns[nm] = _sym(nm)
                else:
                    for nm, e in zip(names, val.elts):
                        assign(nm, ast.unparse(e))
            elif isinstance(st, ast.Assign):
                assign(st.targets[0].id, ast.unparse(st.value))
            else:
                raise ValueError(f"unexpected statement {ast.unparse(st)}")

    visit(tree.body[0].body)
    text = "\n".join(["def f_tangent(Y, cf, kd, W, F):"] + primal + [f"    for k in range({NPAD}):"] + loop)
    return text + "\n", sum(1 for ln in loop if ln.lstrip().startswith("d_"))


def marker_source():
    """Source of ``marker_dq(q, mb, out)``: ∂(R(q) mb)/∂q (3, 4) for the kernel's output formula of R."""
    q = sp.symbols("qw qx qy qz", real=True)
    mb = sp.symbols("mx my mz", real=True)
    qw, qx, qy, qz = q
    R = sp.Matrix([[1 - 2 * (qy * qy + qz * qz), 2 * (qx * qy - qw * qz), 2 * (qx * qz + qw * qy)],
                   [2 * (qx * qy + qw * qz), 1 - 2 * (qx * qx + qz * qz), 2 * (qy * qz - qw * qx)],
                   [2 * (qx * qz - qw * qy), 2 * (qy * qz + qw * qx), 1 - 2 * (qx * qx + qy * qy)]])
    D = (R * sp.Matrix(mb)).jacobian(q)
    lines = ["def marker_dq(q, mb, out):", "    qw, qx, qy, qz = q[0], q[1], q[2], q[3]",
             "    mx, my, mz = mb[0], mb[1], mb[2]"]
    lines += [f"    out[{i}, {j}] = {sp.printing.pycode(D[i, j])}" for i in range(3) for j in range(4)]
    return "\n".join(lines) + "\n"


def rk_source(tab) -> str:
    """Source of ``rk_sens_step(y, S, h, cf, kd, W, Ks, SKs, Y)``: one Runge–Kutta step of the state y (13,)
    and its sensitivities S (13 · NPAD,), with the tableau's coefficients as constants and its stages
    unrolled (zero coefficients left out), so that each combination is one loop over the 13 · NPAD
    tangent entries."""
    ne = NY * NPAD
    lines = ["def rk_sens_step(y, S, h, cf, kd, W, Ks, SKs, Y):"]
    for st in range(tab.stages):
        terms = [(j, repr(float(tab.A[st, j]))) for j in range(st) if tab.A[st, j] != 0.0]
        ky = " + ".join(f"{a} * Ks[{j}, i]" for j, a in terms)
        ks = " + ".join(f"{a} * SKs[{j}, e]" for j, a in terms)
        lines += [f"    for i in range({NY}):", f"        Y[i] = y[i] + h * ({ky})" if terms else "        Y[i] = y[i]",
                  f"    for e in range({ne}):", f"        W[{SY_OFF} + e] = S[e] + h * ({ks})" if terms else
                  f"        W[{SY_OFF} + e] = S[e]",
                  f"    f_tangent(Y, cf, kd, W, Ks[{st}])",
                  f"    for e in range({ne}):", f"        SKs[{st}, e] = W[{SK_OFF} + e]"]
    terms = [(j, repr(float(tab.b[j]))) for j in range(tab.stages) if tab.b[j] != 0.0]
    lines += [f"    for i in range({NY}):", "        y[i] += h * (" + " + ".join(f"{a} * Ks[{j}, i]" for j, a in terms) + ")",
              f"    for e in range({ne}):", "        S[e] += h * (" + " + ".join(f"{a} * SKs[{j}, e]" for j, a in terms) + ")"]
    return "\n".join(lines) + "\n"


def build(text):
    """The generated functions compiled with numba: (rk_sens_step, marker_dq); ``f_tangent`` is inlined
    into every stage of ``rk_sens_step``."""
    ns: dict = {"alpha_and_inverse": alpha_and_inverse, "math": math}
    exec(compile(text, "<sensitivities>", "exec"), ns)
    opts = dict(cache=False, fastmath={"contract", "arcp", "nsz"})
    ns["f_tangent"] = nb.njit(inline="always", **opts)(ns["f_tangent"])
    return nb.njit(**opts)(ns["rk_sens_step"]), nb.njit(inline="always", **opts)(ns["marker_dq"])


def make_integrator(rk_sens_step, marker_dq):
    """A numba integrator of one lane with forward sensitivities (module docstring):
    ``integrate(y0 (13,), coef (10,), k = (m, Ia, Id, d, A, ρ, g), t0, times (n,), marker_body (nm, 3), c,
    stages)`` → (markers (n, nm, 3), their Jacobian (n, nm, 3, 23), right-hand-side stages taken)."""

    @nb.njit(fastmath={"contract", "arcp", "nsz"})
    def integrate(y0, coef, k, t0, times, mb, c, s):
        m, Ia, Id, d, Ar, rho, g = k[0], k[1], k[2], k[3], k[4], k[5], k[6]
        kd = np.array([g, (Id - Ia) / Id, 1.0 / m, 1.0 / Id, 1.0 / Ia, m, Ar, d, rho])
        f_acc, f_mom, f_spin = 0.5 * rho * Ar / m, 0.5 * rho * Ar * d / Id, 0.5 * rho * Ar * d / Ia
        cscale = np.empty(NC)
        cscale[:4] = f_acc
        cscale[4:9] = f_mom
        cscale[9] = f_spin
        cf = coef * cscale
        K0 = math.sqrt(abs(cf[4]) + abs(cf[5]))
        K1 = abs(cf[6]) + abs(cf[7]) + abs(cf[8]) + abs(cf[9])
        K2 = abs(cf[0]) + abs(cf[1]) + abs(cf[2]) + abs(cf[3])
        y = y0.copy()
        S = np.zeros(NY * NPAD)
        for i in range(NY):
            S[i * NPAD + i] = 1.0
        Ks = np.empty((s, NY))
        SKs = np.empty((s, NY * NPAD))
        Y = np.empty(NY)
        W = np.zeros(C_OFF + NC * NPAD)
        for i in range(NC):
            W[C_OFF + i * NPAD + NY + i] = cscale[i]
        nm = mb.shape[0]
        out = np.empty((times.size, nm, 3))
        dout = np.empty((times.size, nm, 3, NCOL))
        Dq = np.empty((3, 4))
        tcur = t0
        stages = 0
        for it in range(times.size):
            T = times[it] - tcur
            if T > 0.0:
                nseg = max(1, int(math.ceil(T / SEGMENT_MAX)))
                for seg in range(nseg):
                    Tseg = T / nseg
                    vx, vy, vz = y[3], y[4], y[5]
                    ox, oy, oz = y[10], y[11], y[12]
                    sp2 = vx * vx + vy * vy + vz * vz + 1.0
                    spd = math.sqrt(sp2)
                    r2 = max(ox * ox + oy * oy + oz * oz, (Ia / Id) ** 2 * oz * oz)
                    r2 = max(r2, K0 * K0 * sp2)
                    damping, turning = K1 * sp2, K2 * spd
                    r2 = max(max(r2, damping * damping), max(turning * turning, 1.0))
                    nsub = max(1, int(math.ceil(Tseg * math.sqrt(r2) / c)))
                    h = Tseg / nsub
                    stages += nsub * s
                    for sub in range(nsub):
                        rk_sens_step(y, S, h, cf, kd, W, Ks, SKs, Y)
                        # renormalise q → q/|q|: S_q → (I − q̂ q̂ᵀ) S_q / |q|
                        nq = math.sqrt(y[6] * y[6] + y[7] * y[7] + y[8] * y[8] + y[9] * y[9])
                        for j in range(4):
                            y[6 + j] /= nq
                        for col in range(NPAD):
                            dot = (y[6] * S[6 * NPAD + col] + y[7] * S[7 * NPAD + col] + y[8] * S[8 * NPAD + col]
                                   + y[9] * S[9 * NPAD + col])
                            for j in range(4):
                                S[(6 + j) * NPAD + col] = (S[(6 + j) * NPAD + col] - y[6 + j] * dot) / nq
                tcur = times[it]
            # markers r + R(q) mb and their sensitivities; R(q) is the kernel's output formula
            # (integrator.integrate) on purpose: the markers are compared with the kernel's to 1e-14 m
            qw, qx, qy, qz = y[6], y[7], y[8], y[9]
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
                mx, my, mz = mb[mk, 0], mb[mk, 1], mb[mk, 2]
                out[it, mk, 0] = y[0] + r00 * mx + r01 * my + r02 * mz
                out[it, mk, 1] = y[1] + r10 * mx + r11 * my + r12 * mz
                out[it, mk, 2] = y[2] + r20 * mx + r21 * my + r22 * mz
                marker_dq(y[6:10], mb[mk], Dq)
                for a in range(3):
                    for col in range(NCOL):
                        dout[it, mk, a, col] = (S[a * NPAD + col] + Dq[a, 0] * S[6 * NPAD + col]
                                                + Dq[a, 1] * S[7 * NPAD + col] + Dq[a, 2] * S[8 * NPAD + col]
                                                + Dq[a, 3] * S[9 * NPAD + col])
        return out, dout, stages

    return integrate


def central_differences(y0, coef, times, mb, disc, env, settings, steps):
    """(markers (n, nm, 3), Jacobian (n, nm, 3, 23)) by the kernel: one call of 47 lanes."""
    base = np.r_[y0, coef]
    lanes = np.repeat(base[None], 2 * NCOL + 1, axis=0)
    lanes[np.arange(NCOL), np.arange(NCOL)] += steps
    lanes[NCOL + np.arange(NCOL), np.arange(NCOL)] -= steps
    tr = simulate(lanes[:, :NY], lanes[:, NY:], times, marker_body=mb, disc=disc, env=env,
                  settings=settings, want_states=False)
    if not np.all(tr.ok):
        raise RuntimeError("a perturbed lane failed")
    d = (tr.markers[:NCOL] - tr.markers[NCOL:2 * NCOL]) / (2 * steps)[:, None, None, None]
    return tr.markers[-1], np.moveaxis(d, 0, -1)


def column_errors(J, ref):
    """Relative error of every column, |J_c − ref_c| / |ref_c| (23,)."""
    a, b = J.reshape(-1, NCOL), ref.reshape(-1, NCOL)
    return np.linalg.norm(a - b, axis=0) / np.linalg.norm(b, axis=0)


def alternating_times(fns, repeats):
    """Median, min and max wall time [s] of each callable, the callables run in turn ``repeats`` times (so
    that a change of the machine's load falls on all of them)."""
    times = [[] for _ in fns]
    for _ in range(repeats):
        for i, fn in enumerate(fns):
            t = time.perf_counter()
            fn()
            times[i].append(time.perf_counter() - t)
    return [(float(np.median(t)), float(np.min(t)), float(np.max(t))) for t in times]


def one_flight(name, truth, integrate, repeats):
    """Accuracy and timing of both methods on one flight of the demo's truth (module docstring)."""
    fl = truth["flights"][name]
    st = fl["initial_state"]
    y0 = np.r_[st["position_m"], st["velocity_m_s"], st["quaternion_wxyz_body_to_world"], st["omega_body_rad_s"]]
    coef = np.array([truth["coefficients"][n] for n in COLUMNS[NY:]])
    mb = np.array([truth["markers"][key] for key in sorted(truth["markers"])], float)
    rate = float(truth["sample_rate_hz"])
    times = np.arange(int(round(fl["launch"]["duration"] * rate)) + 1) / rate
    disc, env = Disc(), Environment()
    k = np.array([disc.mass, disc.Ia, disc.Id, disc.diameter, disc.area, env.rho, env.g])
    tab = get_tableau("vern7")
    c = DEFAULT_STEP_FACTOR["vern7"]
    scale = np.r_[STATE_SCALE, np.maximum(np.abs(coef), 0.01)]
    run = lambda cc: integrate(y0, coef, k, 0.0, times, mb, cc, tab.stages)  # noqa: E731
    settings = SimulatorSettings(method="vern7")
    markers_fs, J_fs, stages = run(c)
    _, J_fine, _ = run(c / 16)
    primal, _ = central_differences(y0, coef, times, mb, disc, env, settings, 1e-4 * scale)
    errors = {}
    for rel in REL_STEPS:
        _, J_cd = central_differences(y0, coef, times, mb, disc, env, settings, rel * scale)
        a, b = column_errors(J_cd, J_fs), column_errors(J_cd, J_fine)
        errors[f"central {rel:g}"] = dict(same_median=float(np.median(a)), same_max=float(a.max()),
                                          exact_median=float(np.median(b)), exact_max=float(b.max()),
                                          worst=COLUMNS[int(np.argmax(a))])
    b = column_errors(J_fs, J_fine)
    errors["forward"] = dict(same_median=0.0, same_max=0.0, exact_median=float(np.median(b)),
                             exact_max=float(b.max()), worst=COLUMNS[int(np.argmax(b))])
    # the check: Richardson's extrapolation of central differences (steps 10⁻⁴ and 5·10⁻⁵ of the scale, the
    # step-squared error removed) against forward sensitivities, both on the kernel's schedule
    _, J_h = central_differences(y0, coef, times, mb, disc, env, settings, 1e-4 * scale)
    _, J_h2 = central_differences(y0, coef, times, mb, disc, env, settings, 5e-5 * scale)
    check = column_errors((4 * J_h2 - J_h) / 3, J_fs)
    one = lambda: simulate(y0, coef, times, marker_body=mb, disc=disc, env=env, settings=settings,  # noqa: E731
                           want_states=False)
    cd = lambda: central_differences(y0, coef, times, mb, disc, env, settings, 1e-4 * scale)  # noqa: E731
    t_one, t_cd, t_fs = alternating_times([one, cd, lambda: run(c)], repeats)
    return {"flight": name, "samples": int(times.size), "rhs_stages": int(stages),
            "primal_max_diff_m": float(np.nanmax(np.abs(markers_fs - primal))),
            "check_max_rel": float(check.max()),
            "errors": errors, "one_flight_s": t_one, "central_s": t_cd, "forward_s": t_fs,
            "ratio_central_over_forward": t_cd[0] / t_fs[0], "ratio_forward_over_one": t_fs[0] / t_one[0]}


#: the forward-sensitivity integrator must reproduce the kernel's markers [m], and its columns must agree with
#: Richardson-extrapolated central differences on the same schedule (largest relative column error; 1 % on one
#: of the 175 partial derivatives of the tangent code gives 3.6·10⁻⁶ on ffsl5); otherwise the benchmark fails
PRIMAL_TOL_M, CHECK_TOL = 1e-9, 1e-6


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--flights", nargs="+", default=None, help="flights of runs/demo/truth.json (default: all)")
    ap.add_argument("--repeats", type=int, default=31)
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args(argv)
    truth = json.loads((REPO / "runs" / "demo" / "truth.json").read_text())
    names = args.flights or list(truth["flights"])
    t_sym = time.perf_counter()
    text, n_tangents = tangent_source()
    tab = get_tableau("vern7")
    integrate = make_integrator(*build(text + "\n\n" + rk_source(tab) + "\n\n" + marker_source()))
    # compile (a two-sample flight)
    integrate(np.r_[0.0, 0, 1, 10, 0, 0, 1, 0, 0, 0, 0, 0, 50], np.full(NC, 0.1), np.ones(7), 0.0,
              np.array([0.0, 0.01]), np.zeros((1, 3)), 1.7, tab.stages)
    t_setup = time.perf_counter() - t_sym
    rows = [one_flight(n, truth, integrate, args.repeats) for n in names]
    result = {"tangent_statements": n_tangents, "setup_s": t_setup, "repeats": args.repeats,
              "load": os.getloadavg(), "flights": rows}
    bad = [r["flight"] for r in rows if not (r["primal_max_diff_m"] < PRIMAL_TOL_M and r["check_max_rel"] < CHECK_TOL)]
    if args.json:
        print(json.dumps(result, indent=1))
        return 1 if bad else 0
    print(f"one flight's marker Jacobian, 23 columns (y0, C); {n_tangents} tangent statements per right-hand "
          f"side; sympy + compilation {t_setup:.1f} s; medians of {args.repeats} alternated runs")
    print(f"{'flight':<8} {'stages':>6} {'1 lane':>8} {'central':>8} {'forward':>8} {'c/f':>5}  "
          f"{'central 1e-4 err: same / exact (max, col)':>44}  {'forward err: exact (max, col)':>30}  primal, check")
    for r in rows:
        e, f = r["errors"]["central 0.0001"], r["errors"]["forward"]
        print(f"{r['flight']:<8} {r['rhs_stages']:>6} {1e3 * r['one_flight_s'][0]:>6.2f}ms {1e3 * r['central_s'][0]:>6.2f}ms "
              f"{1e3 * r['forward_s'][0]:>6.2f}ms {r['ratio_central_over_forward']:>5.2f}  "
              f"{e['same_median']:.1e} ({e['same_max']:.1e} {e['worst']}) / {e['exact_median']:.1e} "
              f"({e['exact_max']:.1e})  {f['exact_median']:>12.1e} ({f['exact_max']:.1e} {f['worst']})  "
              f"{r['primal_max_diff_m']:.0e} m, {r['check_max_rel']:.0e}")
    for r in rows:
        print(f"{r['flight']}: central-difference error by step (same schedule, max): " + ", ".join(
            f"{key.split()[1]}: {v['same_max']:.1e}" for key, v in r["errors"].items() if key.startswith("central")))
    print(f"load {result['load'][0]:.2f}")
    if bad:
        print(f"FAILED: forward sensitivities disagree with the kernel on {bad}")
    return 1 if bad else 0


if __name__ == "__main__":
    raise SystemExit(main())
