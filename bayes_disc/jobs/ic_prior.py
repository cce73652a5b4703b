"""The prior of the initial conditions in a sampling run: the conditional reference prior's surrogate built (or
read back on resume) before sampling, and checked at the posterior's own draws after it
(:mod:`bayes_disc.inference.fitting.reference`); both recorded in summary.json's ``initial_condition_prior``."""
from __future__ import annotations

import json
import logging
from pathlib import Path

import numpy as np

from ..inference.fitting.reference import REFINE_TOLERANCE, build_ic_reference, check_at_draws
from ..inference.model.config import RunConfig
from ..inference.model.priors import surrogate_from_dict
from ..observation.config_io import ConfigError
from .progress import stage

logger = logging.getLogger(__name__)
#: the conditional reference prior's surrogate of a run (``prior.initial_conditions: reference``), read on resume
IC_REFERENCE = "ic_reference.json"
#: a surrogate whose held-out rms error exceeds this share of the exact value's spread is reported (a warning)
POOR_SURROGATE = 0.1


def initial_condition_prior(problem, ls, cfg: RunConfig, out: Path, resume: bool):
    """The problem with the initial conditions' prior of ``prior.initial_conditions``: for ``reference`` the
    conditional reference prior's surrogate (:func:`bayes_disc.inference.fitting.reference.build_ic_reference`),
    built and written to ``ic_reference.json``, or read back from it on resume; for ``flat`` the problem as is.

    Parameters
    ----------
    problem : Problem
        The problem sampled.
    ls : LeastSquaresResult or None
        Its least-squares optimum (None on resume).
    cfg : RunConfig
    out : Path
        The run folder.
    resume : bool
        Read the saved surrogate instead of building it.

    Returns
    -------
    problem : Problem
    record : dict
        summary.json's ``initial_condition_prior``: ``initial_conditions`` and, for ``reference``, the
        surrogate's accuracy at held-out points and the file.

    Raises
    ------
    ConfigError
        On resume of a ``reference`` run whose ``ic_reference.json`` is missing.
    """
    if cfg.ic_prior == "flat":
        return problem, {"initial_conditions": "flat",
                         "description": "independent wide Gaussians around the data-derived starts"}
    path = out / IC_REFERENCE
    if resume:
        if not path.is_file():
            raise ConfigError(cfg.path, "prior.initial_conditions", f"cannot resume: {path} is missing, so the "
                              "reference prior the chains were sampled with is unknown (run without --resume)")
        surrogate = surrogate_from_dict(json.loads(path.read_text()))
    else:
        with stage("reference prior", "the initial conditions' conditional reference prior at design points of "
                                      "the coefficients") as st:
            surrogate = build_ic_reference(problem, ls, cfg.sampler.seed)
            path.write_text(json.dumps(surrogate.to_dict(), indent=1))
            a = surrogate.accuracy
            if a["rms_error"] > POOR_SURROGATE * a["sd_exact"]:
                logger.warning(f"the reference prior's surrogate is off the exact value by {a['rms_error']:.2f} nats "
                               f"rms at held-out points, where the value varies by {a['sd_exact']:.2f}: the "
                               "coefficients' marginal follows the profile only roughly (weakly informative flights)")
            if a["posterior_rms_error"] > REFINE_TOLERANCE:
                logger.info(f"the reference prior's surrogate is still {a['posterior_rms_error']:.2f} nats rms off "
                            f"the exact value where its approximate posterior goes, after {a['refinement_rounds']} "
                            "rounds of refinement there (the exact factor varies faster than the surrogate follows); "
                            "it is checked again at the posterior's own draws after sampling")
            st.result = (f"surrogate within {a['rms_error']:.2f} nats rms ({a['max_error']:.2f} max) of the exact "
                         f"value at {a['points']} held-out points, where it varies by {a['sd_exact']:.2f} (sd); "
                         f"within {a['posterior_rms_error']:.2f} nats rms where its posterior goes, after "
                         f"{a['refinement_rounds']} rounds of refinement there")
    return problem.with_ic_reference(surrogate), {
        "initial_conditions": "reference",
        "description": "wide Gaussians around the data-derived starts times the conditional reference prior "
                       "|I_xx,f(c)|^(1/2) of every flight's initial conditions given the coefficients",
        "surrogate_accuracy": dict(surrogate.accuracy), "file": IC_REFERENCE}


def check_initial_condition_prior(problem, ls, chains, cfg: RunConfig, record: dict) -> None:
    """After sampling a ``reference`` run: the surrogate against the exact reference prior at posterior draws
    (:func:`bayes_disc.inference.fitting.reference.check_at_draws`), logged (a warning where reweighting to the
    exact prior would move a coefficient's mean or sd by more than its tolerance, or the weights cannot say) and
    added to ``record`` (summary.json's ``initial_condition_prior``) as ``posterior_check``.

    Parameters
    ----------
    problem : Problem
        The problem sampled (it carries the surrogate).
    ls : LeastSquaresResult or None
        Its least-squares optimum; None on resume (the check is then not made, and ``posterior_check`` says so).
    chains : Chains
        The run's post-burn-in draws.
    cfg : RunConfig
    record : dict
        Updated in place.
    """
    if cfg.ic_prior != "reference":
        return
    if ls is None:
        record["posterior_check"] = {"made": False, "why": "resumed run: the least-squares optimum the conditional "
                                                          "fits start from is not kept"}
        return
    names = problem.names[: problem.n_coef]
    with stage("reference prior check", "the surrogate against the exact reference prior at posterior draws") as st:
        check = check_at_draws(problem, ls, problem.ic_reference, chains.chain.reshape(-1, problem.dim),
                               np.random.default_rng([cfg.sampler.seed, 7412]), names)
        record["posterior_check"] = {"made": True, **check.to_dict()}
        if check.moves_intervals:
            logger.warning("the reference prior's surrogate matters where the posterior went: " + check.text() +
                           "; the intervals follow the surrogate" + ("" if not check.reweighted else
                           " (the exact prior's quantiles: summary.json's initial_condition_prior.posterior_check."
                           "reweighted, and the report's appendix)"))
        st.result = check.text()
