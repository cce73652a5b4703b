"""bayes-disc: Bayesian estimation of flying-disc aerodynamic coefficients from tracked flights."""
__version__ = "0.1.0"
