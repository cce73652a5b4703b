"""Fits of the problem: least squares (Levenberg–Marquardt), profiles, robust refits, checks of a fit."""
