r"""A design objective φ(Q): a criterion on an information model, as a function of the measurement configurations.

What the IPOPT design minimises (eq. 24), what the pool selection selects with and what ``evaluate`` scores is one
:class:`DesignObjective`: its criterion (name, unit, ratio or logarithm: :attr:`DesignObjective.crit`), φ(Q), the
exact dφ/dQ and the selection of m of a pool's candidates (:meth:`DesignObjective.select`, one
:class:`~pin_kpi_oed.oed.selection_result.PoolSelection`). Every criterion of the information matrix
(:class:`~pin_kpi_oed.oed.criteria.Criterion`) works on every information model:

=====================================================================  =============================================
information model (the objective)                                      M(Q), the pool selection
=====================================================================  =============================================
noise only: :class:`DesignCriterion`                                   FᵀF + P (F the weighted Jacobian, P the
                                                                       layout's prior); relaxation + certificate,
                                                                       rounding, exchange
measured poses: :class:`DesignCriterion` with ``F_given``             F_gᵀF_g + FᵀF (+ their prior rows)
extended with a prior: :class:`~pin_kpi_oed.oed.extended.ExtendedDesignCriterion`  FᵀF + Σ₀⁻¹ over geometry and
                                                                       effects; greedy + Fedorov exchange
GLS under the discrepancy: :class:`~pin_kpi_oed.oed.discrepancy_criteria.GlsDesignCriterion`  Σ_a s_a⁻² J_aᵀ
                                                                       (K_QQ + wI)⁻¹ J_a + Σ₀⁻¹; greedy + exchange
                                                                       with rank-one kernel updates
=====================================================================  =============================================

A criterion of the configurations (:class:`~pin_kpi_oed.oed.criteria.ConfigurationCriterion`, e.g. the kriging
``kpi_gp``: :class:`~pin_kpi_oed.oed.discrepancy_kpi.DiscrepancyDesignCriterion`, re-registered or not) builds its
own objective. An objective without a pool form of its own selects by the generic greedy forward selection with
one exchange pass on φ itself (:meth:`DesignObjective.select`): exact, slower.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from pin_kpi_oed.errors import InputError
from pin_kpi_oed.oed.covariance import prior_of
from pin_kpi_oed.oed.criteria import Criterion, get_criterion
from pin_kpi_oed.oed.design_objective import DesignObjective
from pin_kpi_oed.oed.selection_result import PoolSelection

__all__ = ["DesignContext", "DesignObjective", "DesignCriterion", "information_criterion", "criterion_with_E"]


@dataclass
class DesignContext:
    """What an objective is built on: the measurement model linearised at ``p0``, the identifiable parameters
    ``base``, the KPI sensitivity ``E`` (3t, nb) at the working configurations ``q_work`` (t, n) rad. A
    :class:`~pin_kpi_oed.design.optimize.DesignProblem` has the same interface (with its cell, constraints,
    discrepancy); ``evaluate`` builds a context from a design file, without a cell, an identifiability analysis or an
    extended model unless given.

    Attributes:
        cell: the measurement cell (its working paths, orientation length), or None.
        extended: the :class:`~pin_kpi_oed.oed.extended.ExtendedModel` the criteria of the information matrix are
            taken on, or None (noise-only information).
        ident: the identifiability analysis of ``model`` (checks a KPI's estimability), or None.
    """

    model: Any
    base: np.ndarray
    E: np.ndarray | None
    p0: np.ndarray
    q_work: np.ndarray
    cell: Any = None
    extended: Any = None
    ident: Any = None

    def information_objective(self, crit: Criterion) -> DesignCriterion:
        """A criterion of the information matrix on the noise-only information at ``p0``."""
        return DesignCriterion(self.model, self.base, crit, self.E, self.p0)


def information_criterion(criterion: Any) -> Criterion:
    """The :class:`~pin_kpi_oed.oed.criteria.Criterion` of the information matrix of a name or instance.

    Raises:
        InputError: unknown, or a criterion of the configurations (it has no form on the information matrix).
    """
    crit = get_criterion(criterion)
    if not isinstance(crit, Criterion):
        raise InputError(f"criterion {crit.name}: a criterion of the configurations, not of the information matrix "
                         f"(it builds its own objective on a design problem)")
    return crit


@dataclass
class DesignCriterion(DesignObjective):
    """A criterion of the information matrix on the noise-only information FᵀF + P (F the weighted Jacobian over the
    identifiable parameters at ``p``, P the layout's prior): dφ/dQ chains dφ/dF with dF/dQ.

    Attributes:
        model: the measurement model (evaluated at the linearisation point ``p``).
        base: indices of the identifiable parameters.
        criterion: a registered name or a :class:`~pin_kpi_oed.oed.criteria.Criterion` instance.
        E: KPI sensitivity over the base parameters, (3t, nb), or None.
        p: linearisation point (raw parameters); default nominal.
        F_given: rows every design already has, (k, nb) over the base parameters: the weighted Jacobian of poses
            already measured and the square-root rows of their prior (F_gᵀF_g + Σ₀⁻¹ then counts; only Q moves);
            None: none.

    Raises:
        InputError: unknown criterion name, or a criterion of the configurations.
    """

    model: Any
    base: np.ndarray
    criterion: Any = "kpi"
    E: np.ndarray | None = None
    p: np.ndarray | None = None
    F_given: np.ndarray | None = None
    crit: Criterion = field(init=False, repr=False)

    def __post_init__(self) -> None:
        if self.p is None:
            self.p = np.zeros(self.model.n_params)
        self.crit = information_criterion(self.criterion)
        self.prior = prior_of(self.model, self.base)

    def jacobians(self, Q: np.ndarray) -> np.ndarray:
        """Weighted Jacobians of configurations over the base parameters, (m, nh, nb)."""
        return self.model.weighted_jacobian(self.p, np.atleast_2d(Q))[:, :, self.base]

    def fixed_rows(self) -> np.ndarray | None:
        """Rows every design of this objective already has (:attr:`F_given`, or None)."""
        return self.F_given

    def value(self, Q: np.ndarray) -> float:
        """φ(Q) for configurations Q, (m, n) rad."""
        F = self.jacobians(Q).reshape(-1, self.base.size)
        R = self.fixed_rows()
        return self.crit.value(F if R is None else np.vstack([R, F]), self.E, self.prior)

    def value_and_grad(self, Q: np.ndarray) -> tuple[float, np.ndarray]:
        """φ(Q) and dφ/dQ, (m, n) (per rad): only the configurations Q move."""
        F, dF = self.model.weighted_jacobian_dq(self.p, Q)
        Fb = F[:, :, self.base]
        m, nh, nb = Fb.shape
        R = self.fixed_rows()
        k = 0 if R is None else R.shape[0]
        Fa = Fb.reshape(-1, nb) if R is None else np.vstack([R, Fb.reshape(-1, nb)])
        val, G = self.crit.value_and_grad_F(Fa, self.E, self.prior)
        grad = np.einsum("mac,mack->mk", G[k:].reshape(m, nh, nb), dF[:, :, self.base, :])
        return val, grad

    def select(self, Q_pool: np.ndarray, m: int, seed: int = 0, **kw: Any) -> PoolSelection:
        """m of the candidates by the relaxation (its certificate), rounding and exchange
        (:func:`~pin_kpi_oed.oed.pool.select`), on top of :meth:`fixed_rows` and the prior; ``Fp=`` passes the
        candidates' Jacobians when already computed."""
        from pin_kpi_oed.oed.pool import select

        Fp = kw.pop("Fp", None)
        Fp = self.jacobians(Q_pool) if Fp is None else Fp
        R = self.fixed_rows()
        M0 = None if R is None else R.T @ R
        if self.prior is not None:
            P = np.diag(1.0 / np.asarray(self.prior, float) ** 2)
            M0 = P if M0 is None else M0 + P
        K = self.crit.pool_form(self.E, self.base.size)
        kw.setdefault("names", [self.model.layout.names[i] for i in self.base])
        return select(Fp, m, K, seed=seed, fixed_info=M0, **kw)


def criterion_with_E(problem: DesignContext, crit: Criterion, E: np.ndarray) -> DesignCriterion:
    """``crit`` with a sensitivity of its own (a working path's, a 6-D pose's: not the problem's KPI E) on the
    problem's information (its ``information_objective``: a
    :class:`~pin_kpi_oed.design.optimize.DesignProblem`'s includes the measured poses' rows, a
    :class:`DesignContext`'s is the noise-only information at ``p0``).

    Args:
        problem: a design problem or a :class:`DesignContext`; crit: a criterion of the information matrix;
        E: its sensitivity over the identifiable parameters (rows, nb).
    """
    obj = problem.information_objective(crit)
    obj.E = E
    return obj
