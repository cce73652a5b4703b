"""Observation models: how each kind of recording is predicted from a simulated flight, and its likelihood.

One unit per kind of data (model: scipy.integrate's ``OdeSolver`` subclasses): the contract is
:class:`.base.ObservationModel`; :class:`.markers.MarkerPositions` is the 3-D marker model of Hummel &
Hubbard (2002). A flight may carry several; the log-posterior sums them.
"""
from .base import ObservationModel, gaussian_marginal_loglik
from .markers import MarkerPositions

__all__ = ["ObservationModel", "MarkerPositions", "gaussian_marginal_loglik"]
