"""Float arrays as plain JSON data (shape and base64 of little-endian float64 bytes): compact and exact."""

from __future__ import annotations

import base64
from typing import Any
from collections.abc import Sequence

import numpy as np

__all__ = ["encode_array", "decode_array"]


def encode_array(a: np.ndarray) -> dict:
    """A float64 array as plain data: shape and base64 of its little-endian bytes (compact, exact)."""
    a = np.ascontiguousarray(np.asarray(a, dtype="<f8"))
    return {"shape": list(a.shape), "float64_b64": base64.b64encode(a.tobytes()).decode("ascii")}


def decode_array(d: Any, where: str, shape: Sequence[int | None] | None = None) -> np.ndarray:
    """Inverse of :func:`encode_array` (``shape`` entries None = any), finite values required.

    Raises:
        ValueError: not such an object, bad base64, a size or shape that does not match, non-finite values.
    """
    if not isinstance(d, dict) or "shape" not in d or "float64_b64" not in d:
        raise ValueError(f"{where}: must be an object with 'shape' and 'float64_b64'")
    try:
        shp = tuple(int(s) for s in d["shape"])
        raw = base64.b64decode(str(d["float64_b64"]).encode("ascii"), validate=True)
        a = np.frombuffer(raw, dtype="<f8").reshape(shp).astype(float)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{where}: damaged array ({exc})") from None
    if shape is not None and (len(shp) != len(shape) or any(s is not None and s != t for s, t in zip(shape, shp))):
        raise ValueError(f"{where}: shape {shp} where {tuple(shape)} is expected")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{where}: non-finite values")
    return a
