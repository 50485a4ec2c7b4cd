"""The one Cholesky factor with jitter of the package's kernel and GLS matrices: K + j·mean(diag K)·I for the jitters
j tried in order (0 first: no jitter unless K needs it)."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

__all__ = ["jitter_cholesky"]


def jitter_cholesky(K: np.ndarray, jitters: Sequence[float] = (0.0, 1e-10), what: str = "the kernel matrix"
                    ) -> np.ndarray:
    """Lower Cholesky factor of K + j·mean(diag K)·I with the first jitter j of ``jitters`` that succeeds.

    Args:
        K: a symmetric positive semi-definite matrix (n, n).
        jitters: relative jitters to try, in order.
        what: what K is (the error's words).

    Returns:
        L (n, n), lower triangular.

    Raises:
        numpy.linalg.LinAlgError: K plus the largest jitter is not positive definite.
    """
    n = len(K)
    scale = float(np.mean(np.diag(K))) if n else 0.0
    for j in jitters:
        try:
            return np.linalg.cholesky(K if j == 0 else K + j * scale * np.eye(n))
        except np.linalg.LinAlgError:
            continue
    raise np.linalg.LinAlgError(f"{what} is not positive definite")
