"""The command jobs, at the top of the layers with the API and the command line.

Each job reads a run configuration, does its work with the lower layers (inference, diagnostics) and
writes its results into the run folder; the jobs that end with a sampled run then build its HTML report
inside that folder (:mod:`.outputs`):

* :mod:`.sample` — least squares, profiles, emcee: ``summary.json``, ``posterior.nc`` (``bayes-disc sample``);
* :mod:`.identifiability` — Fisher information, verdicts, next throw: ``identifiability.json``;
* :mod:`.diagnose` — candidate terms, refit, the diagnosis: ``diagnosis.json``;
* :mod:`.predict` — held-out validation: ``prediction.json``.

The command line (:mod:`bayes_disc.cli`) and the Python API (:mod:`bayes_disc.api`) both call them.
"""
