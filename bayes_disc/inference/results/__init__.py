"""Results of a run: summary, InferenceData, posterior files, comparison of runs, software versions."""

# posterior.nc's attributes name ``bayes_disc.inference.results.ensemble_view`` (R-hat across ensembles)
from .draws import ensemble_view

__all__ = ["ensemble_view"]
