"""The per-row sandwich D_i C D_iᵀ every σ of the package forms: a parameter covariance C carried through each
row's Jacobian D_i (the parametric part of the discrepancy's σ, the prediction σ, the orientation σ, the joint-angle
term's white covariance)."""

from __future__ import annotations

import numpy as np

__all__ = ["row_sandwich"]


def row_sandwich(D: np.ndarray, C: np.ndarray) -> np.ndarray:
    """D_i C D_iᵀ of every row i: a covariance C (P, P) carried through each row's Jacobian D_i (a, P).

    The one matrix product (m a, P) × (P, P) and a batched (a, P) × (P, a) per row, instead of the three-operand
    ``einsum("map,pq,mbq->mab", D, C, D)`` (no BLAS; 50× slower at 1,400 rows of 60 parameters): the same sums in
    another order, equal to it within 4e-15 relative (``tests/test_discrepancy.py``).

    Args:
        D: (m, a, P), in the unit of the output per parameter unit.
        C: (P, P), in parameter units squared.

    Returns:
        (m, a, a), the output's unit squared.
    """
    D = np.asarray(D, float)
    m, a, P = D.shape
    return np.matmul((D.reshape(m * a, P) @ np.asarray(C, float)).reshape(m, a, P), D.transpose(0, 2, 1))
