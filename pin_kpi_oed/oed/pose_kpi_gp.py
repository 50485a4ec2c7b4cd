r"""The 6-D KPI under model discrepancy: ``kpi6_gp``, the TCP's position and the tool's orientation at the working
configurations (orientation × the cell's ``orientation_length_m`` L, as ``kpi6``), the parameters estimated by
generalised least squares under the discrepancy.

The discrepancy δ of :mod:`pin_kpi_oed.discrepancy` is a 3-D position GP on the measured rows: it correlates the
measurements (Σ_a = s_a²(K_QQ + wI)), which changes the parameter covariance to the GLS one, C_p = M⁻¹ with
M = Σ_a s_a⁻² J_aᵀ(K_QQ + wI)⁻¹J_a + Σ₀⁻¹, and the position at W is predicted by universal kriging. With E_i, R_i the
position and orientation sensitivities at working configuration i = 1…t (as in ``kpi6``,
:mod:`pin_kpi_oed.oed.pose_kpi`) and the KPI rows [E; L·R] (orientation rows after all position rows)::

    φ = (1/t) [tr C_s^UK(Q; W) + L² tr(R C_p Rᵀ)]                                                     (m²)

tr C_s^UK the kriging TCP covariance of ``kpi_gp`` (:mod:`pin_kpi_oed.oed.kriging`: the kernel's conditional variance
at W plus (E − K_WQ Σ⁻¹J) C_p (…)ᵀ). The orientation rows get no discrepancy term: the package has no orientation
discrepancy model, so their kernel rows are zero (:func:`~pin_kpi_oed.oed.kriging.pad_rows`: H = L·R there) and they
count through C_p alone. The same kriging code gives the value, the exact dφ/dQ (J(Q), K_QQ, K_WQ) and the pool
selection (greedy + exchange with the rank-one / rank-three updates of
:class:`~pin_kpi_oed.oed.discrepancy_pool.GreedyState`; no certificate exists). With the discrepancy's kernel level
→ 0 and white σ = the tracker's σ it is ``kpi6`` (tested). Not hedged over a family of priors (``kpi_gp`` alone is),
not re-registered (``design --reregister``: refused).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from pin_kpi_oed.errors import InputError
from pin_kpi_oed.oed.criteria import ConfigurationCriterion, register
from pin_kpi_oed.oed.discrepancy_kpi import DiscrepancyDesignCriterion
from pin_kpi_oed.oed.design_objective import DesignObjective
from pin_kpi_oed.oed.selection_result import PoolSelection

__all__ = ["PoseDiscrepancyCriterion", "PoseDiscrepancyKpi"]


@dataclass
class PoseDiscrepancyCriterion(DiscrepancyDesignCriterion):
    """``kpi6_gp`` as a function of the measurement configurations Q: the mean over the t working configurations of
    tr of the 6-D TCP covariance (position by universal kriging, orientation × ``length_m`` through the GLS C_p
    alone), m². Attributes as :class:`~pin_kpi_oed.oed.discrepancy_kpi.DiscrepancyDesignCriterion`, plus
    ``length_m`` (L, m); :attr:`E` holds the 6t KPI rows (t, 3, nb) position then (t, 3, nb) L·orientation.

    Raises:
        InputError: ``Q_register`` given (the re-registration is of the position KPI only), a non-positive or
            non-finite length, a 6-D probe model.
    """

    length_m: float = 0.2

    def __post_init__(self) -> None:
        if self.Q_register is not None:
            raise InputError("criterion kpi6_gp: not available with a re-registration (reregister); design kpi_gp "
                             "or kpi6_gp without it")
        if not (np.isfinite(self.length_m) and self.length_m > 0):
            raise InputError(f"criterion kpi6_gp: orientation_length_m must be > 0 m, got {self.length_m}")
        super().__post_init__()
        t = self.Q_work.shape[0]
        Rot = self.model.kpi_rotation_jacobian(self.p, self.Q_work)[:, self.base].reshape(t, 3, -1)
        self.E = np.concatenate([self.E, float(self.length_m) * Rot])

    @property
    def t(self) -> int:
        """Working configurations."""
        return int(self.Q_work.shape[0])

    def value(self, Q: np.ndarray) -> float:
        """φ (m²)."""
        return super().value(Q) / self.t

    def value_and_grad(self, Q: np.ndarray) -> tuple[float, np.ndarray]:
        """φ (m²) and its exact gradient w.r.t. Q (m, n) (m² per rad)."""
        v, g = super().value_and_grad(Q)
        return v / self.t, g / self.t

    def select(self, Q_pool: np.ndarray, m: int, seed: int = 0, J_pool: np.ndarray | None = None, **kw: Any
               ) -> PoolSelection:
        """m of the candidate poses (on top of ``Q_given``), greedy + exchange on the kriging state; φ (m²)."""
        sel = super().select(Q_pool, m, seed=seed, J_pool=J_pool, **kw)
        sel.value /= self.t
        sel.path = np.asarray(sel.path) / self.t
        return sel


class PoseDiscrepancyKpi(ConfigurationCriterion):
    """``kpi6_gp``: the mean 6-D TCP covariance at the working configurations with the model discrepancy (position
    kriged, orientation × the cell's ``orientation_length_m`` without a discrepancy term), m².

    Raises (from :meth:`objective`):
        InputError: without a cell (its ``orientation_length_m``), with a re-registration.
    """

    name, label, unit = ("kpi6_gp", "mean tr of the 6-D TCP covariance with the model discrepancy (position only), "
                         "orientation x the cell's length (m^2)", "m^2")
    is_ratio, needs_kpi = True, True

    def objective(self, problem: Any) -> DesignObjective:
        cell = getattr(problem, "cell", None)
        if cell is None or not hasattr(cell, "orientation_length_m") or not hasattr(problem, "discrepancy_prior"):
            raise InputError("criterion kpi6_gp: needs a design problem on a cell (its orientation_length_m)")
        return PoseDiscrepancyCriterion(problem.model, problem.base, problem.discrepancy_prior(), problem.q_work,
                                        Q_given=problem.Q_given, p=problem.p0, Q_register=problem.Q_register,
                                        length_m=float(cell.orientation_length_m))


register(PoseDiscrepancyKpi)
