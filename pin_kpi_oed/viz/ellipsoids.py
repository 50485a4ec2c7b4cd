"""The TCP's confidence ellipsoids (from C_s, eq. 19) and the magnification that makes them visible."""

from __future__ import annotations

import numpy as np

#: Default confidence level of the ellipsoids.
DEFAULT_LEVEL = 0.95


def confidence_ellipsoid(C: np.ndarray, level: float = DEFAULT_LEVEL) -> tuple[np.ndarray, np.ndarray]:
    """Semi-axes and axes of the ``level`` confidence ellipsoid of N(0, C).

    The ellipsoid is {x : xᵀ C⁻¹ x <= χ²₃(level)}; χ²₃(0.95) = 7.815, so the semi-axes are
    2.80 σ along the principal directions.

    Args:
        C: covariance (3, 3) m².
        level: confidence level in (0, 1).

    Returns:
        (semi-axes (3,) m, axes (3, 3): columns of a proper rotation).
    """
    from scipy.special import chdtri  # chi-square quantile, without importing scipy.stats (slow)

    k = float(chdtri(C.shape[0], 1.0 - level))
    w, V = np.linalg.eigh(0.5 * (C + C.T))
    radii = np.sqrt(k * np.clip(w, 0.0, None))
    if np.linalg.det(V) < 0:
        V[:, -1] *= -1
    return radii, V


def nice_factor(raw: float) -> float:
    """The number 1, 2 or 5 × 10^k closest to ``raw`` on a log scale (a readable magnification)."""
    if not np.isfinite(raw) or raw <= 0:
        return 1.0
    e = np.floor(np.log10(raw))
    cands = [m * 10 ** (e + de) for de in (0, 1) for m in (1.0, 2.0, 5.0)]
    return float(min(cands, key=lambda c: abs(np.log(c / raw))))


def fmt_factor(f: float) -> str:
    """``20000`` -> ``"20 000"`` (thin grouping, readable in the legend)."""
    if f >= 1 and abs(f - round(f)) < 1e-9:
        return f"{int(round(f)):,}".replace(",", " ")
    return f"{f:g}"
