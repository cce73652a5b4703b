"""Priors on the coefficients (named sets) and on the nuisance parameters.

``potts_crowther``: Gaussians on CL0, CLa, CD0, CDa, CM0, CMa centred on the Potts & Crowther (2000)
linearised wind-tunnel values (docs/conventions.md) with widths of about half the value or more, so a few flights
dominate them: CL0 0.2 ± 0.2, CLa 2.96 ± 1.5, CD0 0.08 ± 0.1, CDa 2.6 ± 1.5, CM0 −0.02 ± 0.1,
CMa 0.13 ± 0.3. Rate coefficients get weak zero-centred priors an order of magnitude wider than any
published value: CMq, CRp 0 ± 0.05, CRr 0 ± 0.01 (rad/s)⁻¹, CNr 0 ± 1e−3 (rad/s)⁻¹.
``weak``: zero-centred Gaussians on everything: CL0, CD0, CM0 ± 1, CLa, CDa ± 5, CMa ± 2, rate terms as above.
``around`` (:func:`prior_around`): independent Gaussians θ_k ~ N(v_k, s_k²) around a literature set or given
values v_k, with s_k = relative_sd·|v_k| unless given per coefficient — the prior of a calibration campaign
whose truths are drawn from it (simulation-based calibration is exact only when the fit's prior is the
distribution the truths come from), or a user's informed prior.
Initial conditions (both): centred on the data-derived start with sd 0.5 m, 5 m/s, 0.5 rad, 30 rad/s.
Noise scales: p(σ_f) ∝ 1/σ_f (Jeffreys), integrated out analytically (see ``model``).
"""
from __future__ import annotations

from dataclasses import dataclass


from ...physics import COEFFICIENT_NAMES, POTTS_CROWTHER

RATE_PRIORS = {"CMq": (0.0, 0.05), "CRr": (0.0, 0.01), "CRp": (0.0, 0.05), "CNr": (0.0, 1e-3)}
PC_WIDTHS = {"CL0": 0.2, "CLa": 1.5, "CD0": 0.1, "CDa": 1.5, "CM0": 0.1, "CMa": 0.3}
WEAK = {"CL0": (0.0, 1.0), "CLa": (0.0, 5.0), "CD0": (0.0, 1.0), "CDa": (0.0, 5.0), "CM0": (0.0, 1.0),
        "CMa": (0.0, 2.0)}
IC_SD = {"position": 0.5, "velocity": 5.0, "attitude": 0.5, "omega": 30.0}


@dataclass(frozen=True)
class CoefficientPrior:
    """Independent Gaussian priors θ_k ~ N(mean_k, sd_k²) on the ten coefficients.

    Attributes
    ----------
    name : str
        ``potts_crowther``, ``weak`` or ``around``.
    mean, sd : dict
        {coefficient: value} in the coefficient's unit (docs/conventions.md); every sd > 0.
    description : str
        One line for summary.json and the report.
    """

    name: str
    mean: dict
    sd: dict
    description: str


def prior_around(values: dict, relative_sd: float, sd: dict | None = None, label: str = "given values") -> CoefficientPrior:
    """Gaussians around given coefficient values: θ_k ~ N(v_k, s_k²), s_k = ``sd[k]`` or relative_sd·|v_k|.

    Parameters
    ----------
    values : dict
        {coefficient: v_k} for all ten coefficients (units as in docs/conventions.md).
    relative_sd : float
        s_k / |v_k| where ``sd`` does not give s_k.
    sd : dict, optional
        {coefficient: s_k} overriding the relative width.
    label : str
        Where the values come from (a literature key), for the description.

    Returns
    -------
    CoefficientPrior
        Named ``around``.

    Raises
    ------
    ValueError
        A coefficient missing from ``values``, or a width that is not positive (a zero value needs its sd).
    """
    missing = [k for k in COEFFICIENT_NAMES if k not in values]
    if missing:
        raise ValueError(f"prior around {label}: no value for {', '.join(missing)}")
    sd = dict(sd or {})
    widths = {k: float(sd[k]) if k in sd else relative_sd * abs(float(values[k])) for k in COEFFICIENT_NAMES}
    bad = [k for k, w in widths.items() if not w > 0]
    if bad:
        raise ValueError(f"prior around {label}: sd of {', '.join(bad)} is not positive (give it under sd)")
    own = f"sd {relative_sd:g}·|value|" + (f" ({', '.join(f'{k} {sd[k]:g}' for k in sd)} given)" if sd else "")
    return CoefficientPrior(name="around", mean={k: float(values[k]) for k in COEFFICIENT_NAMES}, sd=widths,
                            description=f"independent Gaussians around {label}, {own}")


def coefficient_prior(name: "str | CoefficientPrior") -> CoefficientPrior:
    """The coefficient prior of a run: a named set (module docstring), or a :class:`CoefficientPrior` as is.

    Parameters
    ----------
    name : str or CoefficientPrior
        ``potts_crowther`` or ``weak``; an ``around`` prior (:func:`prior_around`) is passed through.

    Returns
    -------
    CoefficientPrior

    Raises
    ------
    KeyError
        An unknown name.
    """
    if isinstance(name, CoefficientPrior):
        return name
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
