"""Disc constants, environment and the ten aerodynamic coefficients (docs/conventions.md).

Symbols follow Hummel & Hubbard (2002), Table 1 and Table 2.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass, fields

import numpy as np

#: Names of the ten aerodynamic coefficients, in the order used by every array in bayes-disc.
COEFFICIENT_NAMES: tuple[str, ...] = (
    "CL0", "CLa", "CD0", "CDa", "CM0", "CMa", "CMq", "CRr", "CRp", "CNr",
)

#: Units of the coefficients (α in rad, rates p, q, r in rad/s; "1" = dimensionless).
COEFFICIENT_UNITS: dict[str, str] = {
    "CL0": "1", "CLa": "1/rad", "CD0": "1", "CDa": "1/rad²", "CM0": "1", "CMa": "1/rad",
    "CMq": "s/rad", "CRr": "s/rad", "CRp": "s/rad", "CNr": "s/rad",
}


@dataclass(frozen=True)
class Disc:
    """Rigid axisymmetric disc (seed Table 1).

    mass m [kg], axial moment of inertia Ia [kg m^2], diametral moment of inertia Id [kg m^2],
    diameter d [m] (reference length of the moments), planform area A [m^2].
    """

    mass: float = 0.175
    Ia: float = 0.00235
    Id: float = 0.00122
    diameter: float = 0.269
    area: float = 0.057

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if not (np.isfinite(value) and value > 0):
                raise ValueError(f"disc.{f.name} must be a positive finite number, got {value!r}")


@dataclass(frozen=True)
class Environment:
    """Air density rho [kg/m^3] and gravitational acceleration g [m/s^2] (seed Table 1)."""

    rho: float = 1.23
    g: float = 9.794

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if not (np.isfinite(value) and value > 0):
                raise ValueError(f"environment.{f.name} must be a positive finite number, got {value!r}")


@dataclass(frozen=True)
class Coefficients:
    """The ten aerodynamic coefficients of docs/conventions.md (rates in rad/s, dimensional as in the paper).

    Lift      L = (CL0 + CLa·α) Q A
    Drag      D = (CD0 + CDa·α²) Q A
    Roll      R = (CRr·r + CRp·p) Q A d
    Pitch     M = (CM0 + CMa·α + CMq·q) Q A d
    Spin-down N = CNr·r Q A d
    """

    CL0: float
    CLa: float
    CD0: float
    CDa: float
    CM0: float
    CMa: float
    CMq: float
    CRr: float
    CRp: float
    CNr: float

    def as_array(self) -> np.ndarray:
        return np.array([getattr(self, n) for n in COEFFICIENT_NAMES], dtype=float)

    def as_dict(self) -> dict[str, float]:
        return asdict(self)

    @classmethod
    def from_array(cls, values) -> "Coefficients":
        values = np.asarray(values, dtype=float)
        if values.shape != (len(COEFFICIENT_NAMES),):
            raise ValueError(f"expected {len(COEFFICIENT_NAMES)} coefficients, got shape {values.shape}")
        return cls(*map(float, values))

    @classmethod
    def from_mapping(cls, mapping) -> "Coefficients":
        missing = [n for n in COEFFICIENT_NAMES if n not in mapping]
        unknown = [k for k in mapping if k not in COEFFICIENT_NAMES]
        if missing or unknown:
            raise ValueError(f"coefficients: missing {missing}, unknown {unknown}")
        return cls(**{n: float(mapping[n]) for n in COEFFICIENT_NAMES})


@dataclass(frozen=True)
class LiteratureSet:
    """A published coefficient set; ``values`` holds only the coefficients the source gives."""

    key: str
    citation: str
    values: dict

    def full(self, fallback: "Coefficients") -> Coefficients:
        """The set completed with ``fallback`` for coefficients the source does not give."""
        merged = fallback.as_dict()
        merged.update(self.values)
        return Coefficients.from_mapping(merged)


HUMMEL2002 = LiteratureSet(
    key="hummel2002",
    citation="S. A. Hummel & M. Hubbard (2002), Identification of Frisbee aerodynamic coefficients "
    "using flight data, 4th Int. Conf. on the Engineering of Sport; Table 2, four flights.",
    values=dict(CL0=0.188, CLa=2.37, CD0=0.15, CDa=1.24, CM0=-0.06, CMa=0.38,
                CMq=0.0008, CRr=0.0004, CRp=-0.013, CNr=-2.8e-5),
)

POTTS_CROWTHER = LiteratureSet(
    key="potts_crowther",
    citation="J. R. Potts & W. J. Crowther (2000), The flow over a rotating disc-wing, RAeS Aerodynamics "
    "Research Conference; linearised values as quoted in Hummel & Hubbard (2002) Table 2.",
    values=dict(CL0=0.2, CLa=2.96, CD0=0.08, CDa=2.60, CM0=-0.02, CMa=0.13),
)

HUMMEL2003_F2302 = LiteratureSet(
    key="hummel2003_f2302",
    citation="S. A. Hummel (2003), Frisbee flight simulation and throw biomechanics, MS thesis, UC Davis; "
    "long flight f2302, rate terms only (different drag and spin-down forms: not interchangeable).",
    values=dict(CMq=-0.0144, CRp=-0.0125, CNr=-3.41e-5),
)

LITERATURE: dict[str, LiteratureSet] = {s.key: s for s in (HUMMEL2002, POTTS_CROWTHER)}


def literature_coefficients(key: str) -> Coefficients:
    """A named literature set as full Coefficients (rate terms from Hummel 2002 where the source has none)."""
    if key not in LITERATURE:
        raise KeyError(f"unknown coefficient set {key!r}; known: {sorted(LITERATURE)}")
    return LITERATURE[key].full(Coefficients(**HUMMEL2002.values))
