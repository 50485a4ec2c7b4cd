"""The objective of a design: φ(Q), to be minimised over the measurement configurations, with its exact gradient
and its pool selection — the interface the IPOPT design, the pool selection and ``evaluate`` use, and what every
criterion says about itself (:class:`CriterionInfo`).

A criterion of the information matrix (:class:`~pin_kpi_oed.oed.criteria.Criterion`) becomes an objective on an
information model (:mod:`pin_kpi_oed.oed.objective`); a criterion of the configurations
(:class:`~pin_kpi_oed.oed.criteria.ConfigurationCriterion`) builds its own. This module is below both, so that
a criterion can name the objective it builds and the objective the criterion it evaluates.
"""

from __future__ import annotations

import time
from abc import ABC, abstractmethod
from typing import Any

import numpy as np

from pin_kpi_oed.errors import IdentifiabilityError, InputError
from pin_kpi_oed.oed.pool_search import ValueState, greedy_exchange
from pin_kpi_oed.oed.selection_result import PoolSelection

__all__ = ["CriterionInfo", "DesignObjective"]


class CriterionInfo:
    """What every criterion says about itself (both kinds, :class:`Criterion` and :class:`ConfigurationCriterion`).

    Attributes:
        name: registry key, as typed on the command line (``--criteria``).
        label: one readable line (what it measures, where it comes from).
        unit: unit of the value (``m^2``, ``1`` for dimensionless, ``log`` for logarithmic indices).
        is_ratio: the value is a positive quantity (the design solver divides by its start value);
            otherwise it is a logarithm (the solver subtracts its start value).
        needs_kpi: the value needs the KPI sensitivity E (working configurations).
    """

    name: str = ""
    label: str = ""
    unit: str = ""
    is_ratio: bool = False
    needs_kpi: bool = False

    def __repr__(self) -> str:
        return f"<criterion {self.name}: {self.label} [{self.unit}]>"


class DesignObjective(ABC):
    """φ(Q) of a criterion, to be minimised over the measurement configurations Q (m, n) rad.

    Subclasses set :attr:`crit` and implement :meth:`value` and :meth:`value_and_grad`; they override
    :meth:`select` with the low-rank updates of their information model.

    Attributes:
        crit: the criterion (its ``name``, ``label``, ``unit``, ``is_ratio``).
    """

    crit: CriterionInfo

    @property
    def name(self) -> str:
        """The criterion's name."""
        return self.crit.name

    @property
    def is_ratio(self) -> bool:
        """Whether φ is a positive quantity (the design solver scales it by its start value; else shifts it)."""
        return self.crit.is_ratio

    @abstractmethod
    def value(self, Q: np.ndarray) -> float:
        """φ(Q) in the criterion's unit.

        Raises:
            IdentifiabilityError: Q does not identify the parameters.
        """

    @abstractmethod
    def value_and_grad(self, Q: np.ndarray) -> tuple[float, np.ndarray]:
        """φ(Q) and the exact dφ/dQ, (m, n) per rad."""

    def select(self, Q_pool: np.ndarray, m: int, seed: int = 0, **kw: Any) -> PoolSelection:
        """m of the candidate configurations ``Q_pool`` (N, n): the one pool selector
        (:func:`~pin_kpi_oed.oed.pool_search.greedy_exchange`) on :class:`~pin_kpi_oed.oed.pool_search.ValueState`:
        greedy forward selection on φ (while no addition identifies the parameters, the next candidate of a seeded
        order), then one exchange pass. Generic and exact (N·m evaluations of φ); the information models override
        it with their low-rank updates.

        Raises:
            InputError: m larger than the pool.
        """
        t0 = time.perf_counter()
        Q_pool = np.atleast_2d(np.asarray(Q_pool, float))
        N = len(Q_pool)
        if m > N:
            raise InputError(f"cannot choose {m} measurements from a pool of {N} candidates")

        def phi(idx: list[int]) -> float:
            try:
                return self.value(Q_pool[idx])
            except IdentifiabilityError:
                return np.inf

        st = ValueState(phi, N, seed)
        found = greedy_exchange(st, m, passes=1, rel_tol=0.0)
        cur, swaps = found.value, found.swaps
        return PoolSelection(indices=found.indices, value=float(cur), path=np.array(found.path), nit=swaps,
                             time_s=time.perf_counter() - t0, success=bool(np.isfinite(cur)), status="selected",
                             message=f"generic greedy + one exchange pass ({swaps} swaps); no certificate")
