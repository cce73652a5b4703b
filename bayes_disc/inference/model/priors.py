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
Initial conditions (both): centred on the data-derived start with sd 0.5 m, 5 m/s, 0.5 rad, 30 rad/s; with
``initial_conditions: reference`` (the default, :data:`IC_PRIORS`) also the conditional reference (Jeffreys)
factor below.
Noise scales: p(σ_f) ∝ 1/σ_f (Jeffreys), integrated out analytically (see ``model``).

Conditional reference prior of the initial conditions. Every flight f brings its own initial conditions x_f
(12 numbers), so the coefficients c are estimated beside a number of nuisance parameters that grows with the
flights. Under wide priors on x_f the marginal posterior of c is, to second order,

    p(c | y) ∝ π(c) L(c, x̂(c)) Π_f |H_xx,f(c)|^(−1/2),

x̂_f(c) the flights' conditional optima and H_xx,f flight f's information about its own initial conditions. The
volume factor |H_xx,f|^(−1/2) changes with c (the pitching-moment trio CM0, CMa, CMq turns the disc and with it
how sharply each flight's wobble pins its start), once per flight: the Neyman–Scott pattern, a shift of the
marginal away from the joint optimum that grows with the number of flights while the interval does not, so the
intervals under-cover. The conditional reference prior π(x_f | c) ∝ |I_xx,f(c, x_f)|^(1/2), I_xx,f = J_fᵀ W_f J_f
(the Gauss–Newton information of flight f's initial conditions), cancels that factor: the marginal of c then
follows the profile likelihood L(c, x̂(c)) (Cox–Reid's adjusted profile), as in a model with one flight. It is
evaluated through a surrogate of its only c-dependent part,

    g(c) = ½ Σ_f ln det I_xx,f(c, x̂_f(c)),

a quadratic in the whitened coefficients z = L⁻¹(c − ĉ) (ĉ, LLᵀ: the least-squares optimum and covariance of
the coefficients) with cubic and quartic terms along its most curved direction (where g bends most: the
pitching-moment ridge), fitted to exact values at design points (:class:`ReferenceSurrogate`,
:func:`fit_reference_surrogate`; built by :mod:`bayes_disc.inference.fitting.reference`). The log-prior adds
g(c) (:meth:`.problem.Problem.log_prior`).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ...physics import COEFFICIENT_NAMES, POTTS_CROWTHER

RATE_PRIORS = {"CMq": (0.0, 0.05), "CRr": (0.0, 0.01), "CRp": (0.0, 0.05), "CNr": (0.0, 1e-3)}
PC_WIDTHS = {"CL0": 0.2, "CLa": 1.5, "CD0": 0.1, "CDa": 1.5, "CM0": 0.1, "CMa": 0.3}
WEAK = {"CL0": (0.0, 1.0), "CLa": (0.0, 5.0), "CD0": (0.0, 1.0), "CDa": (0.0, 5.0), "CM0": (0.0, 1.0),
        "CMa": (0.0, 2.0)}
IC_SD = {"position": 0.5, "velocity": 5.0, "attitude": 0.5, "omega": 30.0}
#: ``prior.initial_conditions`` values: the conditional reference factor on (``reference``) or off (``flat``:
#: the wide Gaussians alone)
IC_PRIORS = ("reference", "flat")
#: the default of ``prior.initial_conditions``: ``reference``; at fixed truths on varied designs the flat prior's
#: pitching-moment coefficients sit off the truth on the same side in every design and the reference prior's
#: nearly do not (docs/validation.md)
IC_PRIOR_DEFAULT = "reference"


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


@dataclass(frozen=True)
class ReferenceSurrogate:
    """Quadratic surrogate of the conditional reference prior's log-density g(c) (module docstring).

    g̃(c) = offset + gradientᵀ z + ½ zᵀ hessian z + a₃ t³ + a₄ t⁴,  t = directionᵀ z,  z = whiten (c − centre),

    where |z| ≤ ``radius``; beyond it z is drawn back radially onto the sphere |z| = ``radius`` (a polynomial
    fitted inside would otherwise grow without bound where no design point lies), and g̃ is held within
    ``bounds``, the range of the exact values at the design points: between the design points, too, a polynomial
    can rise where nothing constrains it (four short flights with AR(1) noise: 34 nats above the exact g at 5.6
    whitened units, which drew the sampler there, the likelihood 6.8 nats down; the bound still allows the
    range's top there, 14.5 nats above the exact g: :func:`.fitting.reference.build_ic_reference` therefore
    also checks g̃ where its own approximate posterior goes and refits it with those points). On the demo the
    terms in t bring the error at held-out points from 0.43 to 0.13 nats rms (max 2.3 to 0.44): g is not
    quadratic along the pitching-moment ridge, where it rises by ~10 nats over 3 sds.

    Attributes
    ----------
    centre : (n,) array
        ĉ, the least-squares optimum of the coefficients (their units, docs/conventions.md).
    whiten : (n, n) array
        L⁻¹, L the Cholesky factor of the coefficients' least-squares covariance (scaled, with the correlation
        matrix's eigenvalues floored where it is numerically singular: ``fitting.covariance.scaled_cholesky``).
    offset : float
        g̃ at the centre [nats].
    gradient : (n,) array
        [nats per whitened unit].
    hessian : (n, n) array
        Symmetric [nats per whitened unit²].
    direction : (n,) array
        Unit vector in whitened coordinates: the first-pass quadratic's most curved direction.
    ridge : (2,) array
        a₃, a₄ [nats per whitened unit³, unit⁴].
    radius : float
        Trust radius in whitened units.
    bounds : (2,) array
        Least and greatest value of g̃ [nats]; (−inf, inf) in surrogates recorded without them.
    accuracy : dict
        How well g̃ matched the exact g at held-out points (:func:`surrogate_accuracy`); recorded with the run.
    """

    centre: np.ndarray
    whiten: np.ndarray
    offset: float
    gradient: np.ndarray
    hessian: np.ndarray
    direction: np.ndarray
    ridge: np.ndarray
    radius: float
    bounds: np.ndarray = field(default_factory=lambda: np.array([-np.inf, np.inf]))
    accuracy: dict = field(default_factory=dict)

    def whitened(self, c: np.ndarray) -> np.ndarray:
        """(B, n) z = whiten (c − centre) of coefficients c (B, n) or (n,), drawn back inside ``radius``."""
        z = (np.atleast_2d(c) - self.centre) @ self.whiten.T
        r = np.linalg.norm(z, axis=1, keepdims=True)
        return z * np.minimum(1.0, self.radius / np.maximum(r, 1e-300))

    def __call__(self, c: np.ndarray) -> np.ndarray:
        """(B,) g̃(c) [nats] of coefficients c (B, n) or (n,)."""
        z = self.whitened(c)
        t = z @ self.direction
        g = (self.offset + z @ self.gradient + 0.5 * np.einsum("bi,ij,bj->b", z, self.hessian, z)
             + self.ridge[0] * t ** 3 + self.ridge[1] * t ** 4)
        return np.clip(g, self.bounds[0], self.bounds[1])

    def to_dict(self) -> dict:
        """JSON-ready record (every array as nested lists): :func:`surrogate_from_dict` reads it back."""
        return {"centre": self.centre.tolist(), "whiten": self.whiten.tolist(), "offset": float(self.offset),
                "gradient": self.gradient.tolist(), "hessian": self.hessian.tolist(), "direction": self.direction.tolist(),
                "ridge": self.ridge.tolist(), "radius": float(self.radius),
                "bounds": [float(b) for b in self.bounds], "accuracy": dict(self.accuracy)}


def surrogate_from_dict(d: dict) -> ReferenceSurrogate:
    """The :class:`ReferenceSurrogate` of a :meth:`ReferenceSurrogate.to_dict` record."""
    return ReferenceSurrogate(centre=np.asarray(d["centre"], float), whiten=np.asarray(d["whiten"], float),
                              offset=float(d["offset"]), gradient=np.asarray(d["gradient"], float),
                              hessian=np.asarray(d["hessian"], float), direction=np.asarray(d["direction"], float),
                              ridge=np.asarray(d["ridge"], float), radius=float(d["radius"]),
                              bounds=np.asarray(d.get("bounds", [-np.inf, np.inf]), float),
                              accuracy=dict(d.get("accuracy", {})))


def quadratic_features(z: np.ndarray) -> np.ndarray:
    """(B, 1 + n + n(n+1)/2) design matrix of a full quadratic in z (B, n): 1, z_i, then z_i z_j (i ≤ j) with
    ½ on the squares, so that the coefficients of the products are the Hessian's entries."""
    z = np.atleast_2d(z)
    i, j = np.triu_indices(z.shape[1])
    products = z[:, i] * z[:, j] * np.where(i == j, 0.5, 1.0)
    return np.column_stack([np.ones(z.shape[0]), z, products])


def _hessian(beta: np.ndarray, n: int) -> np.ndarray:
    """The symmetric (n, n) Hessian of a :func:`quadratic_features` coefficient vector."""
    H = np.zeros((n, n))
    i, j = np.triu_indices(n)
    H[i, j] = beta[1 + n: 1 + n + i.size]
    H[j, i] = beta[1 + n: 1 + n + i.size]
    return H


def fit_reference_surrogate(points: np.ndarray, values: np.ndarray, centre: np.ndarray, factor: np.ndarray,
                            radius: float, huber: float | None = None) -> ReferenceSurrogate:
    """Least-squares surrogate of g through exact values at design points, in two passes: a full quadratic in
    the whitened coefficients, then the quadratic again with t³ and t⁴ along the first one's most curved
    direction (:class:`ReferenceSurrogate`).

    Parameters
    ----------
    points : (m, n) array
        Coefficient values where g was computed; m ≥ 3 + n + n(n+1)/2 and spread enough to fix every term
        (:func:`reference_design`).
    values : (m,) array
        g there [nats].
    centre : (n,) array
        ĉ.
    factor : (n, n) array
        Lower-triangular L with L Lᵀ the coefficients' least-squares covariance: z = L⁻¹ (c − ĉ).
    radius : float
        Trust radius in whitened units (:class:`ReferenceSurrogate`).
    huber : float, optional
        Huber's threshold δ [nats]: points whose residual exceeds it weigh δ/|residual| (iteratively reweighted
        least squares), so that isolated values far above or below the smooth trend do not bend it; None: plain
        least squares.

    Returns
    -------
    ReferenceSurrogate
        Held within the range of ``values``; without ``accuracy`` (:func:`surrogate_accuracy`).

    Raises
    ------
    ValueError
        Too few points, or points that do not fix every term.
    """
    n = centre.size
    whiten = np.linalg.inv(factor)
    z = (np.atleast_2d(points) - centre) @ whiten.T
    X = quadratic_features(z)
    first = _robust_lstsq(X, values, huber)
    w, V = np.linalg.eigh(_hessian(first, n))
    u = V[:, int(np.argmax(np.abs(w)))]
    t = z @ u
    X = np.column_stack([X, t ** 3, t ** 4])
    if np.linalg.matrix_rank(X) < X.shape[1]:
        raise ValueError(f"{z.shape[0]} design points do not fix the {X.shape[1]} terms of the surrogate in {n} "
                         "coefficients")
    beta = _robust_lstsq(X, values, huber)
    return ReferenceSurrogate(centre=np.asarray(centre, float), whiten=whiten, offset=float(beta[0]),
                              gradient=beta[1: 1 + n], hessian=_hessian(beta, n), direction=u,
                              ridge=beta[-2:].copy(), radius=float(radius),
                              bounds=np.array([np.min(values), np.max(values)], float))


def _robust_lstsq(X: np.ndarray, y: np.ndarray, huber: float | None, iterations: int = 30) -> np.ndarray:
    """Coefficients β of y ≈ X β: least squares, or Huber's M-estimate with threshold ``huber`` (iteratively
    reweighted: weights min(1, δ/|r|) of the last residuals r)."""
    beta = np.linalg.lstsq(X, y, rcond=None)[0]
    for _ in range(iterations if huber is not None else 0):
        r = np.abs(y - X @ beta)
        root = np.sqrt(np.minimum(1.0, huber / np.maximum(r, 1e-300)))
        new = np.linalg.lstsq(root[:, None] * X, root * y, rcond=None)[0]
        if np.allclose(new, beta, rtol=1e-10, atol=1e-12):
            return new
        beta = new
    return beta


def reference_design(n: int, axis_radii: tuple, n_random: int, spread: float,
                     rng: np.random.Generator) -> np.ndarray:
    """Design points in whitened coefficients: the centre, ±r on every axis for each r in ``axis_radii``, and
    ``n_random`` draws of N(0, spread² I) (where a posterior about as wide as the least-squares one lies; a
    10-dimensional standard normal lies at |z| ≈ 3.2 ± 0.7).

    Parameters
    ----------
    n : int
        Coefficients.
    axis_radii : tuple of float
        Distances along the axes (whitened units).
    n_random : int
        Random points.
    spread : float
        Their sd per axis (whitened units).
    rng : numpy.random.Generator

    Returns
    -------
    (1 + 2 n len(axis_radii) + n_random, n) array
    """
    axes = [s * r * np.eye(n) for r in axis_radii for s in (1.0, -1.0)]
    return np.vstack([np.zeros((1, n)), *axes, spread * rng.standard_normal((n_random, n))])


def surrogate_accuracy(surrogate: ReferenceSurrogate, points: np.ndarray, exact: np.ndarray) -> dict:
    """How well the surrogate follows the exact g at held-out points, constants aside (a log-density's
    constant does not matter): the errors e_j = g̃ − g less their mean.

    Parameters
    ----------
    surrogate : ReferenceSurrogate
    points : (m, n) array
        Held-out coefficient values (not among the fitted design points).
    exact : (m,) array
        g there [nats].

    Returns
    -------
    dict
        ``points`` m; ``rms_error``, ``max_error`` of e [nats]; ``sd_exact``, the sd of g over the points
        [nats] (how much the factor varies where the surrogate is checked).
    """
    e = surrogate(points) - exact
    e = e - e.mean()
    return {"points": int(len(exact)), "rms_error": float(np.sqrt(np.mean(e * e))),
            "max_error": float(np.max(np.abs(e))), "sd_exact": float(np.std(exact))}
