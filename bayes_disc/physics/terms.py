"""Extra physics terms that plug into the flight model of SPEC §2.

A term is one small, self-describing unit: its equations (docstring), its extra parameters with units,
defaults and prior scales, and one or two compiled hooks that the simulator inlines into its
right-hand side:

* ``air(E, off, b, t, x, y, z) -> (wx, wy, wz)``: a wind velocity [m/s]; the aerodynamics see
  ``v_a = v − Σ wind``.
* ``loads(E, off, b, ctx) -> (Fx, Fy, Fz, Mx, My, Mz)``: an extra world-frame force [N] and moment
  [N m] at the centre of mass, given the flight context ``ctx`` (layout below).

``E[off + i, b]`` is the term's i-th parameter for batch lane ``b``. The hooks are plain numba functions,
so the numpy reference equations call exactly the same code.

Flight context ``ctx`` (a tuple; indices are the ``CTX_*`` constants): time t [s], centre-of-mass position
x, y, z [m], air speed |v_a| [m/s], angle of attack α [rad], dynamic pressure Q = ρ|v_a|²/2 [Pa], v_a [m/s],
d1, d2, d3 (world components), p, q, r [rad/s], A [m²], d [m], m [kg], ρ [kg/m³].
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

import numba as nb

CTX_T, CTX_X, CTX_Y, CTX_Z, CTX_SPEED, CTX_ALPHA, CTX_Q = 0, 1, 2, 3, 4, 5, 6
CTX_VAX, CTX_VAY, CTX_VAZ = 7, 8, 9
CTX_D1X, CTX_D1Y, CTX_D1Z = 10, 11, 12
CTX_D2X, CTX_D2Y, CTX_D2Z = 13, 14, 15
CTX_D3X, CTX_D3Y, CTX_D3Z = 16, 17, 18
CTX_P, CTX_QRATE, CTX_R = 19, 20, 21
CTX_AREA, CTX_DIAM, CTX_MASS, CTX_RHO = 22, 23, 24, 25


@dataclass(frozen=True)
class TermParameter:
    """An extra parameter of a term: name, unit, value that switches the term off, prior scale."""

    name: str
    unit: str
    description: str
    off_value: float = 0.0
    prior_sd: float = 1.0


@dataclass(frozen=True)
class Term:
    """A physics term: SPEC id, a one-line title, its equations and its compiled hooks."""

    id: str
    title: str
    equations: str
    parameters: tuple[TermParameter, ...]
    air: Callable | None = None
    loads: Callable | None = None
    notes: str = field(default="")

    @property
    def parameter_names(self) -> tuple[str, ...]:
        return tuple(p.name for p in self.parameters)


# --- side force (Robins–Magnus) ----------------------------------------------------------------------

@nb.njit(inline="always", cache=True)
def _side_force_loads(E, off, b, ctx):
    """F_Y = CY · (r d / 2|v_a|) · Q A · d2  =  CY · r · d/2 · (ρ A |v_a| / 2) · d2."""
    cy = E[off, b]
    mag = cy * ctx[CTX_R] * 0.5 * ctx[CTX_DIAM] * 0.5 * ctx[CTX_RHO] * ctx[CTX_AREA] * ctx[CTX_SPEED]
    return (mag * ctx[CTX_D2X], mag * ctx[CTX_D2Y], mag * ctx[CTX_D2Z], 0.0, 0.0, 0.0)


SIDE_FORCE = Term(
    id="side_force",
    title="Robins–Magnus side force perpendicular to the velocity in the disc plane, growing with spin",
    equations="F_Y = C_Y · (r d / 2|v_a|) · Q A · d2   (d2 = d3 × d1: to the right in forward flight; "
    "r > 0 pushes right)",
    parameters=(TermParameter("CY", "1", "side-force coefficient per unit advance ratio r d / 2|v_a|",
                              prior_sd=0.5),),
    loads=_side_force_loads,
)


# --- steady wind ---------------------------------------------------------------------------------------

@nb.njit(inline="always", cache=True)
def _wind_air(E, off, b, t, x, y, z):
    """w = (wx, wy, wz), constant in time and space."""
    return (E[off, b], E[off + 1, b], E[off + 2, b])


WIND = Term(
    id="wind",
    title="Steady wind: the aerodynamics see the air-relative velocity v_a = v − w",
    equations="v_a = v − w,  w = (w_x, w_y, w_z) constant",
    parameters=(
        TermParameter("wind_x", "m/s", "wind velocity, world x (downrange)", prior_sd=3.0),
        TermParameter("wind_y", "m/s", "wind velocity, world y (left)", prior_sd=3.0),
        TermParameter("wind_z", "m/s", "wind velocity, world z (up)", prior_sd=1.0),
    ),
    air=_wind_air,
)


TERMS: dict[str, Term] = {t.id: t for t in (SIDE_FORCE, WIND)}


def get_terms(ids) -> tuple[Term, ...]:
    """Terms by SPEC id, in the order given; unknown ids raise KeyError naming the known ones."""
    out = []
    for i in ids:
        if i not in TERMS:
            raise KeyError(f"unknown physics term {i!r}; known: {sorted(TERMS)}")
        out.append(TERMS[i])
    if len({t.id for t in out}) != len(out):
        raise ValueError(f"physics terms listed twice: {list(ids)}")
    return tuple(out)


def extension_names(terms) -> tuple[str, ...]:
    """Names of all extra parameters of ``terms`` in kernel order."""
    return tuple(n for t in terms for n in t.parameter_names)
