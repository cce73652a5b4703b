"""Convergence statistics of ensemble chains (n_ensembles, n_steps, n_walkers, dim).

R-hat is computed across *ensembles* (each ensemble one chain, its walkers' draws pooled step by step,
so split-R-hat splits in time); bulk ESS treats every walker as a chain (autocorrelation along steps).
Both are ArviZ's rank-normalised estimators (Vehtari et al. 2021).
"""
from __future__ import annotations

import warnings

import arviz as az
import numpy as np


def _dataset(x):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # "more chains than draws" is intended here
        return az.convert_to_dataset({"p": x})


def rhat_across(chain: np.ndarray) -> np.ndarray:
    n_ens, n_steps, n_w, dim = chain.shape
    x = chain.reshape(n_ens, n_steps * n_w, dim)  # step-major: halves are early and late steps
    ds = _dataset(x)
    return np.asarray(az.rhat(ds, method="rank")["p"].values)


def ess_bulk(chain: np.ndarray) -> np.ndarray:
    n_ens, n_steps, n_w, dim = chain.shape
    x = np.moveaxis(chain, 2, 1).reshape(n_ens * n_w, n_steps, dim)
    ds = _dataset(x)
    return np.asarray(az.ess(ds, method="bulk")["p"].values)
