"""Closest points of segments, batched: the distance kernels of the capsule constraints (m)."""

from __future__ import annotations

import numpy as np

__all__ = ["segment_closest", "point_segment_distance", "cross"]


def segment_closest(A1: np.ndarray, B1: np.ndarray, A2: np.ndarray, B2: np.ndarray, eps: float = 1e-14
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Closest points of segment pairs [A1, B1], [A2, B2], batched over leading axes.

    Args:
        A1, B1, A2, B2: end points, (..., 3) m.
        eps: squared length below which a segment is a point (m²).

    Returns:
        (s, t, w1, w2): parameters in [0, 1], (...), and witness points w1 = A1 + s(B1 − A1),
        w2 = A2 + t(B2 − A2), (..., 3).
    """
    d1, d2, r = B1 - A1, B2 - A2, A1 - A2
    a = np.einsum("...i,...i->...", d1, d1)
    e = np.einsum("...i,...i->...", d2, d2)
    f = np.einsum("...i,...i->...", d2, r)
    c = np.einsum("...i,...i->...", d1, r)
    b = np.einsum("...i,...i->...", d1, d2)
    pa, pe = a <= eps, e <= eps
    a_s, e_s = np.where(pa, 1.0, a), np.where(pe, 1.0, e)
    denom = a * e - b * b
    gen = denom > 1e-12 * np.maximum(a * e, 1e-300)
    s = np.where(gen, np.clip((b * f - c * e) / np.where(gen, denom, 1.0), 0.0, 1.0), 0.0)
    t = (b * s + f) / e_s
    lo, hi = t < 0.0, t > 1.0
    s = np.where(lo, np.clip(-c / a_s, 0.0, 1.0), np.where(hi, np.clip((b - c) / a_s, 0.0, 1.0), s))
    t = np.clip(t, 0.0, 1.0)
    # degenerate segments (points)
    s = np.where(pa, 0.0, np.where(pe, np.clip(-c / a_s, 0.0, 1.0), s))
    t = np.where(pe, 0.0, np.where(pa, np.clip(f / e_s, 0.0, 1.0), t))
    w1 = A1 + s[..., None] * d1
    w2 = A2 + t[..., None] * d2
    return s, t, w1, w2


def cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Cross product over the last axis (broadcast), faster than ``np.cross`` for small arrays."""
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    return np.stack([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0], axis=-1)


def point_segment_distance(p: np.ndarray, A: np.ndarray, B: np.ndarray) -> np.ndarray:
    """Distance of points p to segments [A, B] (broadcast, m)."""
    d = B - A
    L2 = np.einsum("...i,...i->...", d, d)
    u = np.clip(np.einsum("...i,...i->...", p - A, d) / np.where(L2 > 0, L2, 1.0), 0.0, 1.0)
    return np.linalg.norm(p - (A + u[..., None] * d), axis=-1)
