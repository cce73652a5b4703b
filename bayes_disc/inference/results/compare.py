"""Comparison of runs: the coefficients' posterior summaries of several run folders side by side.
"""
from __future__ import annotations

import warnings
from pathlib import Path

import arviz as az
import numpy as np

from .posterior_file import load_posterior


def run_label(run_dir) -> str:
    """A run's label in comparisons: its folder's name, or its parent folder's name for a folder called ``out``.

    Parameters
    ----------
    run_dir : str or Path

    Returns
    -------
    str
    """
    run_dir = Path(run_dir)
    return run_dir.parent.name if run_dir.name == "out" else run_dir.name


def compare_runs(run_dirs):
    """PSIS-LOO comparison of sampled runs of the same observations (``az.compare``).

    Parameters
    ----------
    run_dirs : sequence of str or Path, or dict {label: path}
        Output folders of ``bayes-disc sample`` (each with a posterior.nc that has a ``log_likelihood``
        group); labels default to the folder's run name (its parent folder's name for ``out``).

    Returns
    -------
    pandas.DataFrame
        ``az.compare``'s table, best model first: ``elpd_loo`` (log density, sum over observed marker
        points), ``p_loo``, ``elpd_diff``, ``weight``, ``se``, ``dse``, ``warning``; and ``pareto_k_high``,
        the number of points whose Pareto k̂ exceeds ArviZ's threshold min(1 − 1/log10 S, 0.7) for S draws
        (their PSIS-LOO values are unreliable).

    Notes
    -----
    With AR(1) noise a point's log-likelihood is its density given the flight's earlier points (see
    :func:`pointwise_log_likelihood`), so its "leave-one-out" value leaves out that conditional term; the
    sum over a flight is still the joint log-likelihood, and runs of the same points stay comparable.

    Raises
    ------
    ValueError
        If fewer than two runs are given, a posterior.nc lacks the ``log_likelihood`` group, or the runs'
        observed marker points differ (their LOO values would not be comparable).
    """
    items = dict(run_dirs) if isinstance(run_dirs, dict) else {run_label(d): d for d in run_dirs}
    if len(items) < 2:
        raise ValueError("compare_runs needs at least two runs (distinct labels)")
    data, ref = {}, None
    for label, d in items.items():
        path = Path(d) / "posterior.nc"
        idata = load_posterior(path)
        if "log_likelihood" not in idata.groups():
            raise ValueError(f"{path}: no log_likelihood group (written before pointwise log-likelihoods; re-run "
                             "`bayes-disc sample`)")
        ll = idata.log_likelihood
        key = tuple(np.asarray(ll[c].values).tobytes() for c in ("point_flight", "point_time", "point_marker"))
        if ref is not None and key != ref[1]:
            raise ValueError(f"{path}: observed marker points differ from {ref[0]}'s: LOO is not comparable")
        ref = ref or (path, key)
        data[label] = idata
    with warnings.catch_warnings():
        # ArviZ warns of high Pareto k̂ per run (counted in the table instead) and pandas of ArviZ's own
        # use of a deprecated keyword
        warnings.filterwarnings("ignore", message="Estimated shape parameter of Pareto")
        warnings.filterwarnings("ignore", message="The inplace keyword")
        loos = {label: az.loo(idata, pointwise=True) for label, idata in data.items()}   # once per run
        table = az.compare(loos)
    table["pareto_k_high"] = [int(np.sum(np.asarray(loos[label].pareto_k) > loos[label].good_k))
                              for label in table.index]
    return table
