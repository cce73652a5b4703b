"""The measured wind-tunnel table shipped with the package (``bayes_disc/data/potts_wind_tunnel.csv``).

Potts (2005) disc-wing wind-tunnel data at V = 20 m/s, α from −100° to 100°; the citation is kept in the
file's ``#`` header lines and returned with the table.
"""
from __future__ import annotations

from dataclasses import dataclass
from importlib import resources

import numpy as np

RESOURCE = "potts_wind_tunnel.csv"


@dataclass(frozen=True)
class WindTunnelTable:
    """Measured static coefficients: alpha_deg, CL, CD, CM (1-D arrays), and the citation text."""

    alpha_deg: np.ndarray
    CL: np.ndarray
    CD: np.ndarray
    CM: np.ndarray
    citation: str


def load_wind_tunnel() -> WindTunnelTable:
    """Read the packaged wind-tunnel table via :mod:`importlib.resources`."""
    text = resources.files("bayes_disc").joinpath("data", RESOURCE).read_text(encoding="utf-8")
    comments, rows, header = [], [], None
    for line in text.splitlines():
        s = line.strip()
        if not s:
            continue
        if s.startswith("#"):
            comments.append(s.lstrip("#").strip())
        elif header is None:
            header = [h.strip() for h in s.split(",")]
        else:
            rows.append([float(v) for v in s.split(",")])
    if header != ["alpha_deg", "CL", "CD", "CM"]:
        raise ValueError(f"packaged {RESOURCE}: unexpected header {header}")
    a = np.array(rows, float)
    return WindTunnelTable(alpha_deg=a[:, 0], CL=a[:, 1], CD=a[:, 2], CM=a[:, 3], citation=" ".join(comments[:3]))


#: angle-of-attack range [deg] over which the table's shape is summarised (the range flown in throws)
SHAPE_RANGE_DEG = (-10.0, 30.0)


@dataclass(frozen=True)
class WindTunnelShape:
    """The table's α-dependence over :data:`SHAPE_RANGE_DEG` in the polynomial forms of the model (α in rad):

    C_L ≈ a0 + a1 α + CL2 α² + CL3 α³,   C_D ≈ b0 + b2 α² + CD3 |α|³ + CD4 α⁴,   C_M ≈ c0 + c1 α + CM2 α² + CM3 α³,

    and the bend: the table minus its best fit in the base model's forms (C_L0 + C_Lα α, C_D0 + C_Dα α²,
    C_M0 + C_Mα α) on the table's α grid [rad]."""

    CL2: float
    CL3: float
    CD3: float
    CD4: float
    CM2: float
    CM3: float
    alpha_rad: np.ndarray
    bend_CL: np.ndarray
    bend_CD: np.ndarray
    bend_CM: np.ndarray


def _lstsq(columns, y):
    return np.linalg.lstsq(np.column_stack(columns), y, rcond=None)[0]


def wind_tunnel_shape(table: WindTunnelTable | None = None) -> WindTunnelShape:
    """Polynomial summary and bend of the wind-tunnel table (:class:`WindTunnelShape`).

    Parameters
    ----------
    table : WindTunnelTable, optional
        Default: the packaged table.

    Returns
    -------
    WindTunnelShape
    """
    t = load_wind_tunnel() if table is None else table
    sel = (t.alpha_deg >= SHAPE_RANGE_DEG[0]) & (t.alpha_deg <= SHAPE_RANGE_DEG[1])
    a = np.deg2rad(t.alpha_deg[sel])
    one = np.ones_like(a)
    cl = _lstsq([one, a, a ** 2, a ** 3], t.CL[sel])
    cd = _lstsq([one, a ** 2, np.abs(a) ** 3, a ** 4], t.CD[sel])
    cm = _lstsq([one, a, a ** 2, a ** 3], t.CM[sel])
    base_l = _lstsq([one, a], t.CL[sel])
    base_d = _lstsq([one, a ** 2], t.CD[sel])
    base_m = _lstsq([one, a], t.CM[sel])
    return WindTunnelShape(CL2=float(cl[2]), CL3=float(cl[3]), CD3=float(cd[2]), CD4=float(cd[3]), CM2=float(cm[2]),
                           CM3=float(cm[3]), alpha_rad=a,
                           bend_CL=t.CL[sel] - (base_l[0] + base_l[1] * a),
                           bend_CD=t.CD[sel] - (base_d[0] + base_d[1] * a ** 2),
                           bend_CM=t.CM[sel] - (base_m[0] + base_m[1] * a))
