"""Configuration blocks shared by run configurations and synthetic-flight descriptions.

``disc``/``environment`` (physical constants), ``markers`` (body-frame marker positions) and ``physics``
(extra model terms and data explanations), ``nature`` (forms of physics outside the library, synth files only). Each reader takes the file path (named in errors) and the
:class:`~.config_io.Section` being read, and raises :class:`~.config_io.ConfigError` naming the key.
"""
from __future__ import annotations

import numpy as np

from ..physics import Disc, Environment
from ..physics.nature import get_nature
from .config_io import ConfigError, Section
from .registry import DATA_EXPLANATION, PHYSICS_TERM, unit


def read_disc_env(path, sec: Section) -> tuple[Disc, Environment]:
    """The optional ``disc`` and ``environment`` blocks (SI units; defaults docs/conventions.md).

    Parameters
    ----------
    path : str or Path
        The configuration file (named in errors).
    sec : Section
        The top-level mapping being read.

    Returns
    -------
    (Disc, Environment)
        Mass [kg], inertias [kg·m²], diameter [m], area [m²]; air density [kg/m³], gravity [m/s²].
    """
    d = sec.section("disc")
    disc = Disc(mass=d.number("mass", Disc.mass, positive=True), Ia=d.number("Ia", Disc.Ia, positive=True),
                Id=d.number("Id", Disc.Id, positive=True),
                diameter=d.number("diameter", Disc.diameter, positive=True),
                area=d.number("area", Disc.area, positive=True))
    d.finish()
    e = sec.section("environment")
    env = Environment(rho=e.number("rho", Environment.rho, positive=True), g=e.number("g", Environment.g, positive=True))
    e.finish()
    return disc, env


def read_markers(path, sec: Section, default=None) -> dict:
    """The ``markers`` block: marker id → body-frame position.

    Parameters
    ----------
    path : str or Path
        The configuration file (named in errors).
    sec : Section
        The top-level mapping being read.
    default : dict, optional
        Used when the key is absent; without it the key is required.

    Returns
    -------
    dict of str to list of float
        At least 3 markers, each ``[x, y, z]`` in metres (body frame B).
    """
    raw = sec.raw("markers", default, required=default is None)
    if not isinstance(raw, dict) or len(raw) < 3:
        raise ConfigError(path, "markers", "must map at least 3 marker ids to [x, y, z] body positions (m)")
    m = Section(path, {str(k): v for k, v in raw.items()}, "markers")
    out = {str(k): m.vector(str(k), 3) for k in list(m.data)}
    m.finish()
    pts = np.array(list(out.values()))
    if np.abs(pts).max() > 1.0:
        raise ConfigError(path, "markers", "body positions larger than 1 m: give metres, not millimetres")
    return out


def read_physics(path, sec: Section, marker_ids=None) -> dict:
    """The ``physics:`` block: term id → {parameter: starting value}.

    Parameters
    ----------
    path : str or Path
        The configuration file (named in errors).
    sec : Section
        The top-level mapping being read.
    marker_ids : tuple of str, optional
        With them (run configurations) the data explanations ``marker_geometry`` and ``time_offset``
        are allowed too.

    Returns
    -------
    dict
        ``{term id: {parameter name: starting value}}`` (parameter units as in :data:`~..physics.TERMS`).
    """
    raw = sec.raw("physics", {}) or {}
    if not isinstance(raw, dict):
        raise ConfigError(path, "physics", "must map term ids to their parameters")
    out = {}
    kinds = (PHYSICS_TERM, DATA_EXPLANATION) if marker_ids is not None else (PHYSICS_TERM,)
    for tid, params in raw.items():
        try:
            parameters = unit(str(tid), kinds).parameters(tuple(marker_ids or ()))
        except KeyError as e:
            raise ConfigError(path, f"physics.{tid}", e.args[0]) from None
        s = Section(path, params, f"physics.{tid}")
        out[tid] = {p.name: s.number(p.name, p.off_value) for p in parameters}
        s.finish()
    return out


def read_nature(path, sec: Section) -> dict:
    """The ``nature:`` block of a synth file: form id (:data:`~..physics.nature.NATURE`) → {parameter: value}
    (a parameter not given: its default).

    Parameters
    ----------
    path : str or Path
        The configuration file (named in errors).
    sec : Section
        The top-level mapping being read.

    Returns
    -------
    dict
        ``{form id: {parameter name: value}}``.
    """
    raw = sec.raw("nature", {}) or {}
    if not isinstance(raw, dict):
        raise ConfigError(path, "nature", "must map forms of nature to their parameters")
    out = {}
    for nid, params in raw.items():
        try:
            (form,) = get_nature([str(nid)])
        except KeyError as e:
            raise ConfigError(path, f"nature.{nid}", e.args[0]) from None
        s = Section(path, params or {}, f"nature.{nid}")
        out[nid] = {p.name: s.number(p.name, p.off_value) for p in form.parameters}
        s.finish()
    return out
