"""Gauss–Newton (Cramér–Rao) covariance of a least-squares optimum and the condition number of its scale-free
information matrix, from the block-arrow Jacobian or a dense one (small problems).
"""
from __future__ import annotations

import numpy as np

from .arrow import ArrowJacobian


def covariance_at(J: ArrowJacobian, free: np.ndarray) -> np.ndarray:
    """(dim, dim) Gauss–Newton covariance (JᵀJ)⁻¹ from a block Jacobian over the ``free`` parameters (held
    parameters' rows and columns zero)."""
    cov = np.zeros((free.size, free.size))
    cov[np.ix_(free, free)] = J.information().inverse()
    return cov


def _scaled_information(J: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Fisher information F = JᵀJ of whitened residuals, scaled to unit diagonal (entries of F span ~12
    decades: CNr ~ 1e−5 beside positions ~ 1 m); returns (F / d dᵀ, d)."""
    F = J.T @ J
    d = np.sqrt(np.diag(F))
    return F / np.outer(d, d), d


def covariance_from_jacobian(J: np.ndarray) -> np.ndarray:
    """Gauss–Newton (Cramér–Rao) covariance (JᵀJ)⁻¹ of the whitened residual Jacobian J (prior rows
    included), inverted in scale-free form."""
    Fn, d = _scaled_information(J)
    return np.linalg.pinv(Fn) / np.outer(d, d)


def condition_number(J: np.ndarray) -> float:
    """Condition number of the scale-free information matrix."""
    ev = np.linalg.eigvalsh(_scaled_information(J)[0])
    return float(ev[-1] / max(ev[0], 1e-300))
