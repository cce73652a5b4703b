"""The statistical problem: run configuration, parameter layout, priors, data and the log-posterior."""
