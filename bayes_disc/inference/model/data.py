"""From a run configuration to the statistical problem: flights, windows, data-derived starts."""
from __future__ import annotations

import numpy as np

from ...observation.config_io import ConfigError
from ...observation.markers import load_flights
from ...observation.plausibility import check_flights
from ...observation.registry import split_extensions
from ...physics import SimulatorSettings
from .config import AUTO, RunConfig
from ...observation.models import MarkerPositions
from ...observation.models.magnetometer import MAG_OWN_PARAMETERS
from .inertial import (heading_start, inertial_model, level_start, load_run_throws, magnetometer_shared_start,
                       own_start, search_starts)
from .initial import initial_state_from_data
from .problem import Problem, shared_observation_parameters


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


def build_problem(cfg: RunConfig, terms_override=None, flights=None, throws=None) -> Problem:
    """The Problem of a run.

    Long: flights, throws, observation models, explanations and starts are assembled in the order the
    parameter layout lays them out.

    Parameters
    ----------
    cfg : RunConfig
    terms_override : list of str, optional
        Ids of physics terms and data explanations replacing the config's ``physics`` block.
    flights : list of FlightObservation, optional
        Marker flights (default: read from the config's files).
    throws : list of InertialThrow, optional
        Inertial throws (default: read from the config's ``imu`` sources); only those with status ``ok``
        are fitted. A throw named like a marker flight is the same flight seen by both (its marker times
        must start at release).

    Notes
    -----
    A marker flight whose ``noise.model`` is ``auto`` gets white Gaussian noise here (per-point errors as its
    ``per_point`` says): the model the evidence for the others is measured against
    (:func:`bayes_disc.inference.fitting.noise_choice.choose_noise`).

    Returns
    -------
    Problem
    """
    flights = load_run_flights(cfg) if flights is None else flights
    throws = [t for t in (load_run_throws(cfg) if throws is None else throws) if t.status == "ok"]
    mb = np.array([cfg.markers[i] for i in cfg.marker_ids], float) if cfg.markers else np.zeros((1, 3))
    if flights:
        check_flights(flights, mb, cfg.env.g)  # physical plausibility before any fitting (ImplausibleDataError)
    ids = list(cfg.physics) if terms_override is None else list(terms_override)
    terms, explanations = split_extensions(ids)
    settings = SimulatorSettings(method=cfg.simulator_method, step_factor=cfg.simulator_step_factor)
    by_name = {t.name: t for t in throws}
    records, observations, starts, own = [], [], [], []
    for f in flights:
        try:
            starts.append(initial_state_from_data(f, mb))
        except ValueError as e:
            raise ConfigError(cfg.path, "flights", str(e)) from None
        noise, key = cfg.flight_noise(f.name)
        model = "gaussian" if noise.model == AUTO else noise.model    # auto: white until the evidence is in
        try:
            channels = [MarkerPositions(f, mb, tuple(explanations), noise_model=model, per_point=noise.per_point)]
        except ValueError as e:
            raise ConfigError(cfg.path, key, str(e)) from None
        extra = [p.off_value for p in channels[0].parameters]
        t = by_name.pop(f.name, None)
        if t is not None:
            channels.append(inertial_model(t, cfg.env))
            extra += list(own_start(channels[-1], t))
        records.append(f)
        observations.append(tuple(channels))
        own.append(np.array(extra, float))
    inertial_only = []
    for t in by_name.values():
        model = inertial_model(t, cfg.env)
        inertial_only.append(len(records))
        records.append(t.log)
        observations.append((model,))
        starts.append(level_start(t))
        own.append(own_start(model, t))
    if not records:
        raise ConfigError(cfg.path, "imu", "no throw to fit (every inertial throw is out of the model)")
    given = {name: v for tid in ids for name, v in cfg.physics.get(tid, {}).items()}
    shared = shared_observation_parameters(observations)
    ext = ([q for t in terms for q in t.parameters] + [q for e in explanations for q in e.parameters_for(cfg.marker_ids)]
           + list(shared.values()))
    given = {**magnetometer_shared_start(c for ch in observations for c in ch), **given}
    term_start = np.array([given.get(q.name, q.off_value) for q in ext], float)

    def make(start_states):
        return Problem(flights=records, marker_body=mb, disc=cfg.disc, env=cfg.env, prior_name=cfg.prior,
                       terms=terms, explanations=explanations, start_states=start_states, settings=settings,
                       observations=observations, own_start=own, term_start=term_start)

    problem = make(starts)
    if inertial_only:
        for k in inertial_only:
            starts[k] = search_starts(problem, k)
        problem = make(starts)
    headed = False                    # each magnetometer's field heading, along its flight's start
    for k in range(len(records)):
        psi = heading_start(problem, k)
        if np.isfinite(psi):
            own[k][problem.layout.flight_parameters[k].index(MAG_OWN_PARAMETERS[0])] = psi
            headed = True
    return make(starts) if headed else problem
