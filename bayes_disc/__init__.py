"""bayes-disc: Bayesian estimation of flying-disc aerodynamic coefficients from tracked flights.

The Python API (:mod:`bayes_disc.api`)::

    import bayes_disc as bd
    run = bd.sample("config.yaml")          # or a RunConfig, or a dict with flights as DataFrames
    run.summary                             # pandas table: mean, sd, quantiles, R-hat, ESS per parameter
    run.idata                               # ArviZ InferenceData
    run.report()                            # <output>/reports/<name>.html
    run.ensembles                           # the posterior with the ensembles as chains (summary.json's R-hat)
    bd.load(run.output)                     # the same run, from disk
    bd.compare([run_a, run_b])              # PSIS-LOO comparison of runs of the same flights

See docs/api.md for a worked example.
"""
from ._version import __version__
from .api import (DiagnosisResult, IdentifiabilityResult, SampleResult, compare, diagnose, identifiability,
                  load, run_config, sample)

__all__ = ["__version__", "sample", "identifiability", "diagnose", "load", "compare", "run_config", "SampleResult",
           "IdentifiabilityResult", "DiagnosisResult"]
