"""The statistical problem and its solution.

* :mod:`.model` — run configuration, parameter layout, priors, the problem (log-posterior) built from data;
* :mod:`.fitting` — least squares, profiles, robust refits and checks of a fit;
* :mod:`.sampling` — the ensemble sampler, its moves and proposals, chain stores and convergence statistics;
* :mod:`.results` — summary, InferenceData, posterior files and comparison of runs.
"""
