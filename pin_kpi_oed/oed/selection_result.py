"""The one result of every pool selection (the noise-only relaxation with its certificate, the greedy + exchange of
the extended model, of the GLS information and of the universal-kriging KPI): a :class:`~pin_kpi_oed.results.Result`
with the chosen candidates and φ of them."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from pin_kpi_oed.results import Result

__all__ = ["PoolSelection"]


@dataclass(kw_only=True)
class PoolSelection(Result):
    """m candidates chosen from a pool (``nit``: the swaps of the exchange, :mod:`pin_kpi_oed.oed.pool_search`;
    ``time_s``: wall time).

    Attributes:
        indices: the chosen candidates, (m,) distinct (greedy selectors: in order of addition, then swapped).
        value: φ of the chosen set, in the criterion's unit (the exact design's, information not normalised).
        path: φ after each greedy addition, or None (the relaxation's rounding has none).
        approx: the relaxation with its certificate
            (:class:`~pin_kpi_oed.oed.relaxation.ApproximateDesign`), or None where no certificate exists.
    """

    indices: np.ndarray
    value: float
    path: np.ndarray | None = None
    approx: Any = None

    def efficiency(self) -> float:
        """Efficiency of the selection against the relaxation's certificate (A-type, ≤ 1; NaN without one)."""
        if self.approx is None:
            return float("nan")
        return float(self.approx.lower_bound / self.indices.size / self.value)

    def to_dict(self) -> dict:
        """Plain JSON-able dict."""
        return {**self.result_dict(), "indices": np.asarray(self.indices).tolist(), "value": self.value,
                "path": None if self.path is None else np.asarray(self.path).tolist(),
                "relaxation": None if self.approx is None else self.approx.to_dict()}
