"""Diagnostics of a run: identifiability of the coefficients (and, later, missing physics)."""
