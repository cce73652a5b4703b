"""From a run configuration to the statistical problem: flights, windows, data-derived starts."""
from __future__ import annotations

import numpy as np

from ..observation.config_io import ConfigError
from ..observation.markers import load_flights
from ..observation.plausibility import check_flights
from ..observation.registry import split_extensions
from ..physics import SimulatorSettings
from .config import RunConfig
from .initial import initial_state_from_data
from .model import Problem


def load_run_flights(cfg: RunConfig):
    flights = []
    for file in cfg.files:
        flights += load_flights(file, cfg.marker_ids)
    names = [f.name for f in flights]
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise ConfigError(cfg.path, "flights", f"flight name(s) {dup} appear in more than one place")
    unknown = sorted(set(cfg.flight_options) - set(names))
    if unknown:
        raise ConfigError(cfg.path, f"flight_options.{unknown[0]}", f"no such flight (flights: {names})")
    out = []
    for f in flights:
        o = cfg.flight_options.get(f.name)
        if o is not None:
            f = f.window(o.t_start, o.t_end)
            if f.times.size < 5:
                raise ConfigError(cfg.path, f"flight_options.{f.name}", "window leaves fewer than 5 samples")
        out.append(f)
    return out


def build_problem(cfg: RunConfig, terms_override=None, flights=None) -> Problem:
    """The Problem of a run; ``terms_override`` (ids of physics terms and data explanations) replaces the
    config's ``physics`` block."""
    flights = load_run_flights(cfg) if flights is None else flights
    mb = np.array([cfg.markers[i] for i in cfg.marker_ids], float)
    check_flights(flights, mb, cfg.env.g)  # physical plausibility before any fitting (ImplausibleDataError)
    starts = []
    for f in flights:
        try:
            starts.append(initial_state_from_data(f, mb))
        except ValueError as e:
            raise ConfigError(cfg.path, "flights", str(e)) from None
    ids = list(cfg.physics) if terms_override is None else list(terms_override)
    terms, explanations = split_extensions(ids)
    settings = SimulatorSettings(method=cfg.simulator_method, step_factor=cfg.simulator_step_factor)
    given = {name: v for tid in ids for name, v in cfg.physics.get(tid, {}).items()}
    ext = [p for t in terms for p in t.parameters] + [p for e in explanations for p in e.parameters_for(cfg.marker_ids)]
    return Problem(flights=flights, marker_body=mb, disc=cfg.disc, env=cfg.env, prior_name=cfg.prior,
                   terms=terms, explanations=explanations, start_states=starts, settings=settings,
                   term_start=np.array([given.get(p.name, p.off_value) for p in ext], float))
