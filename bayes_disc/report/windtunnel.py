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
