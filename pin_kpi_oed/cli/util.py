"""Small helpers shared by the CLI modules (parsing option values)."""

from __future__ import annotations

import numpy as np

from pin_kpi_oed.errors import InputError


def parse_floats(text: str, n: int | tuple[int, ...], what: str) -> np.ndarray:
    """Parse ``"x,y,z"`` into floats (SI units); ``n`` is the allowed count(s).

    Raises:
        InputError: not numbers, not finite, or the wrong count (naming the option ``what``).
    """
    ns = (n,) if isinstance(n, int) else n
    try:
        v = np.array([float(s) for s in str(text).replace(" ", "").split(",") if s != ""])
    except ValueError:
        raise InputError(f"{what}: expected {' or '.join(map(str, ns))} comma-separated numbers (SI units), "
                         f"got '{text}'") from None
    if v.size not in ns or not np.all(np.isfinite(v)):
        raise InputError(f"{what}: expected {' or '.join(map(str, ns))} finite comma-separated numbers, got '{text}'")
    return v
