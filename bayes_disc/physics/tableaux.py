"""Butcher tableaux of the explicit Runge–Kutta methods the compiled integrator offers, as data.

A tableau (A, b, c) with s stages advances y' = f(t, y) by one step h:

    k_i = f(t + c_i h, y + h Σ_j A_ij k_j)   (j < i, explicit),   y_new = y + h Σ_i b_i k_i.

Each :class:`Tableau` states its classical order p: all Butcher rooted-tree order conditions up to
order p hold (``tests/test_tableaux.py`` checks them, and that those of order p + 1 do not all hold).
Modelled on ``scipy.integrate._ivp``, whose methods keep their coefficients in their own module.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Tableau:
    """An explicit Runge–Kutta method.

    Attributes
    ----------
    name : str
        Key in :data:`TABLEAUX`.
    A : numpy.ndarray, shape (s, s)
        Stage coefficients, strictly lower triangular.
    b : numpy.ndarray, shape (s,)
        Weights of the solution.
    c : numpy.ndarray, shape (s,)
        Nodes (fractions of the step), c_i = Σ_j A_ij.
    order : int
        Classical order p of the solution.
    reference : str
        Where the coefficients come from.
    """

    name: str
    A: np.ndarray
    b: np.ndarray
    c: np.ndarray
    order: int
    reference: str

    @property
    def stages(self) -> int:
        """Number of stages s (right-hand-side evaluations per step)."""
        return len(self.b)


def _rk4() -> Tableau:
    A = np.zeros((4, 4))
    A[1, 0] = 0.5
    A[2, 1] = 0.5
    A[3, 2] = 1.0
    return Tableau("rk4", A, np.array([1 / 6, 1 / 3, 1 / 3, 1 / 6]), A.sum(axis=1), 4,
                   "classical 4-stage, 4th-order method (Kutta 1901)")


def _butcher6() -> Tableau:
    A = np.zeros((7, 7))
    A[1, 0] = 1 / 3
    A[2, 1] = 2 / 3
    A[3, :3] = [1 / 12, 1 / 3, -1 / 12]
    A[4, :4] = [-1 / 16, 9 / 8, -3 / 16, -3 / 8]
    A[5, :5] = [0, 9 / 8, -3 / 8, -3 / 4, 1 / 2]
    A[6, :6] = [9 / 44, -9 / 11, 63 / 44, 18 / 11, 0, -16 / 11]
    b = np.array([11 / 120, 0, 27 / 40, 27 / 40, -4 / 15, -4 / 15, 11 / 120])
    return Tableau("rk6", A, b, A.sum(axis=1), 6, "Butcher (1964), 7 stages, order 6")


def _verner7() -> Tableau:
    c = [0.0, 0.005, 0.10888888888888888888888888888888888889, 0.16333333333333333333333333333333333333,
         0.4555, 0.60950944899783813170870044214860249496, 0.884, 0.925, 1.0]
    rows = [
        [0.005],
        [-1.076790123456790123456790123456790123457, 1.185679012345679012345679012345679012346],
        [0.04083333333333333333333333333333333333333, 0.0, 0.1225],
        [0.6389139236255726780508121615993336109954, 0.0, -2.455672638223656809662640566430653894211,
         2.272258714598084131611828404831320283215],
        [-2.661577375018757131119259297861818119279, 0.0, 10.80451388645613769565396655365532838482,
         -8.353914657396199411968048547819291691541, 0.8204875949566569791420417341743839209619],
        [6.067741434696770992718360183877276714679, 0.0, -24.71127363591108579734203485290746001803,
         20.42751793078889394045773111748346612697, -1.906157978816647150624096784352757010879,
         1.006172249242068014790040335899474187268],
        [12.05467007625320299509109452892778311648, 0.0, -49.75478495046898932807257615331444758322,
         41.14288863860467663259698416710157354209, -4.461760149974004185641911603484815375051,
         2.042334822239174959821717077708608543738, -0.09834843665406107379530801693870224403537],
        [10.13814652288180787641845141981689030769, 0.0, -42.64113603171750214622846006736635730625,
         35.76384003992257007135021178023160054034, -4.348022840392907653340370296908245943710,
         2.009862268377035895441943593011827554771, 0.3487490460338272405953822853053145879140,
         -0.2714390051048312842371587140910297407572],
    ]
    b = [0.047155618486272221704317651088381756796, 0.0, 0.0, 0.25750564298434151895964361010376875810,
         0.26216653977412620477138630957645277111, 0.15216092656738557403231331991651175355,
         0.49399691700324842469071758932278768443, -0.29430311714032504415572447440927034291,
         0.081317472324951099997345994401367618925]
    A = np.zeros((9, 9))
    for i, row in enumerate(rows):
        A[i + 1, :len(row)] = row
    return Tableau("vern7", A, np.array(b), np.array(c), 7,
                   'Verner\'s "efficient" 7(6) pair RKV76.IIa (J. H. Verner, Numer. Algorithms 53 (2010) '
                   "383–396): the 9 stages of its 7th-order solution (the embedded 6th-order estimate is unused)")


def _dop853() -> Tableau:
    from scipy.integrate._ivp import dop853_coefficients as d
    return Tableau("dop853", np.array(d.A[:12, :12]), np.array(d.B), np.array(d.C[:12]), 8,
                   "the 12-stage 8th-order solution of Dormand & Prince's DOP853 (Hairer, Nørsett & Wanner), "
                   "coefficients from scipy.integrate")


#: the methods by name
TABLEAUX: dict[str, Tableau] = {t.name: t for t in (_verner7(), _butcher6(), _rk4())}
try:   # scipy's coefficient table is private API: offer the method only where it is found
    TABLEAUX["dop853"] = _dop853()
except (ImportError, AttributeError):   # pragma: no cover
    pass

#: default step factor c per method: h ≤ c/ω_c (benchmarks/bench_simulator.py measures the errors)
DEFAULT_STEP_FACTOR = {"vern7": 1.7, "dop853": 2.2, "rk6": 0.8, "rk4": 0.25}
DEFAULT_METHOD = "vern7"


def get_tableau(name: str) -> Tableau:
    """The tableau called ``name``.

    Parameters
    ----------
    name : str
        A key of :data:`TABLEAUX`.

    Returns
    -------
    Tableau

    Raises
    ------
    ValueError
        If the method is unknown (the message lists the known ones).
    """
    if name not in TABLEAUX:
        raise ValueError(f"unknown integration method {name!r}; known: {sorted(TABLEAUX)}")
    return TABLEAUX[name]
