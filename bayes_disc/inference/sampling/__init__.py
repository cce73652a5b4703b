"""Ensemble MCMC: the sampler, its moves and proposals, chain stores and convergence statistics."""
