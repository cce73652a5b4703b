"""Priors on the coefficients (named sets) and on the nuisance parameters.

``potts_crowther``: Gaussians on CL0, CLa, CD0, CDa, CM0, CMa centred on the Potts & Crowther (2000)
linearised wind-tunnel values (SPEC §2) with widths of about half the value or more, so a few flights
dominate them: CL0 0.2 ± 0.2, CLa 2.96 ± 1.5, CD0 0.08 ± 0.1, CDa 2.6 ± 1.5, CM0 −0.02 ± 0.1,
CMa 0.13 ± 0.3. Rate coefficients get weak zero-centred priors an order of magnitude wider than any
published value: CMq, CRp 0 ± 0.05, CRr 0 ± 0.01 (rad/s)⁻¹, CNr 0 ± 1e−3 (rad/s)⁻¹.
``weak``: zero-centred Gaussians on everything: CL0, CD0, CM0 ± 1, CLa, CDa ± 5, CMa ± 2, rate terms as above.
Initial conditions (both): centred on the data-derived start with sd 0.5 m, 5 m/s, 0.5 rad, 30 rad/s.
Noise scales: p(σ_f) ∝ 1/σ_f (Jeffreys), integrated out analytically (see ``model``).
"""
from __future__ import annotations

from dataclasses import dataclass


from ..physics import COEFFICIENT_NAMES, POTTS_CROWTHER

RATE_PRIORS = {"CMq": (0.0, 0.05), "CRr": (0.0, 0.01), "CRp": (0.0, 0.05), "CNr": (0.0, 1e-3)}
PC_WIDTHS = {"CL0": 0.2, "CLa": 1.5, "CD0": 0.1, "CDa": 1.5, "CM0": 0.1, "CMa": 0.3}
WEAK = {"CL0": (0.0, 1.0), "CLa": (0.0, 5.0), "CD0": (0.0, 1.0), "CDa": (0.0, 5.0), "CM0": (0.0, 1.0),
        "CMa": (0.0, 2.0)}
IC_SD = {"position": 0.5, "velocity": 5.0, "attitude": 0.5, "omega": 30.0}


@dataclass(frozen=True)
class CoefficientPrior:
    name: str
    mean: dict
    sd: dict
    description: str


def coefficient_prior(name: str) -> CoefficientPrior:
    if name == "potts_crowther":
        mean = {k: POTTS_CROWTHER.values[k] for k in PC_WIDTHS}
        sd = dict(PC_WIDTHS)
        desc = ("Potts & Crowther (2000) linearised wind-tunnel values ± "
                + ", ".join(f"{k} {v:g}" for k, v in PC_WIDTHS.items()) + "; weak zero-centred rate terms")
    elif name == "weak":
        mean = {k: v[0] for k, v in WEAK.items()}
        sd = {k: v[1] for k, v in WEAK.items()}
        desc = "broad zero-centred Gaussians on all coefficients"
    else:
        raise KeyError(f"unknown prior {name!r}; known: potts_crowther, weak")
    for k, (m, s) in RATE_PRIORS.items():
        mean[k], sd[k] = m, s
    assert set(mean) == set(COEFFICIENT_NAMES)
    return CoefficientPrior(name=name, mean=mean, sd=sd, description=desc)
