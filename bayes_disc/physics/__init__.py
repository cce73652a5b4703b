"""Flight physics: constants, frames, the Newton–Euler model, extra terms and the simulator."""
from .conditions import FlightConditions, flight_conditions
from .constants import (COEFFICIENT_NAMES, COEFFICIENT_UNITS, HUMMEL2002, LITERATURE, POTTS_CROWTHER, Coefficients,
                        Disc,
                        Environment, LiteratureSet, literature_coefficients)
from .equations import STATE_SIZE, marker_positions, state_derivative
from .simulator import SimulatorSettings, Trajectories, simulate, simulate_reference
from .terms import TERMS, Term, TermParameter, axial_inertia, get_terms

__all__ = [
    "COEFFICIENT_NAMES", "COEFFICIENT_UNITS", "HUMMEL2002", "LITERATURE", "POTTS_CROWTHER", "Coefficients", "Disc", "Environment",
    "LiteratureSet", "literature_coefficients", "STATE_SIZE", "marker_positions", "state_derivative",
    "SimulatorSettings", "Trajectories", "simulate", "simulate_reference", "TERMS", "Term", "TermParameter",
    "get_terms", "axial_inertia", "FlightConditions", "flight_conditions",
]
