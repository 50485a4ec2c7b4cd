"""Central finite differences of a scalar function of configurations, for the gradient checks of the criteria."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np


def fd_rows(f: Callable[[np.ndarray], float], Q: np.ndarray, rows: int, h: float = 1e-6) -> np.ndarray:
    """(f(Q + h e_ik) − f(Q − h e_ik)) / 2h for the first ``rows`` configurations and every joint, (rows, n)."""
    num = np.zeros((rows, Q.shape[1]))
    for i in range(rows):
        for k in range(Q.shape[1]):
            Qp, Qm = Q.copy(), Q.copy()
            Qp[i, k] += h
            Qm[i, k] -= h
            num[i, k] = (f(Qp) - f(Qm)) / (2 * h)
    return num
