"""The constraint rows of one measurement configuration: their kinds (capsule pair, half-space, incidence), names,
the joints each row depends on (the structural non-zeros of its gradient) and units (m or cos)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

# row kinds
PAIR, HALF, INCID = 0, 1, 2


@dataclass
class ConstraintRows:
    """Description of the constraint rows of one configuration.

    Attributes:
        names: readable name of each row (``link_4|car_body``, ``link_2@floor:b``, ``incidence``).
        kind: PAIR, HALF or INCID per row.
        deps: 0-based joint indices each row depends on (structural non-zeros of its gradient).
        units: ``"m"`` (distances) or ``"cos"`` (incidence).
    """

    names: list[str]
    kind: np.ndarray
    deps: list[np.ndarray]
    units: list[str] = field(default_factory=list)

    @property
    def n(self) -> int:
        """Number of rows per configuration."""
        return len(self.names)

    def count(self) -> dict[str, int]:
        """Rows per category (self-collision, obstacle, half-space, beam, incidence)."""
        out = {"self": 0, "obstacle": 0, "half_space": 0, "beam": 0, "incidence": 0}
        for nm, k in zip(self.names, self.kind):
            if k == INCID:
                out["incidence"] += 1
            elif nm.startswith("beam"):
                out["beam"] += 1
            elif k == HALF:
                out["half_space"] += 1
            elif nm.startswith("robot:"):
                out["self"] += 1
            else:
                out["obstacle"] += 1
        return out
