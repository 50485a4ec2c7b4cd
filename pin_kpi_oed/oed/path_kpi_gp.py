r"""The path KPI under model discrepancy: ``kpi_path_gp``, the kriging ``kpi_gp`` with the working paths' samples as
its KPI configurations.

With W = the samples of the cell's ``working_paths`` (:mod:`pin_kpi_oed.cell.paths`) instead of the working
configurations (and their region), φ = tr C_s^UK(Q; W), the universal-kriging TCP covariance of
:mod:`pin_kpi_oed.oed.discrepancy_kpi` summed over the samples (m²): the discrepancy's short length scales make the
TCP error differ along a path, which the noise-only ``kpi_path`` cannot see. Exact dφ/dQ, greedy + exchange pool
selection (no certificate exists); hedged over a family of priors when the discrepancy is the class default
(:meth:`DesignProblem.gp_objective <pin_kpi_oed.design.optimize.DesignProblem.gp_objective>`).
"""

from __future__ import annotations

from typing import Any

from pin_kpi_oed.errors import InputError
from pin_kpi_oed.oed.criteria import ConfigurationCriterion, register
from pin_kpi_oed.oed.design_objective import DesignObjective

__all__ = ["PathDiscrepancyKpi"]


class PathDiscrepancyKpi(ConfigurationCriterion):
    """``kpi_path_gp``: tr of the TCP error covariance with the model discrepancy summed over the working paths'
    samples (m²)."""

    name, label, unit = "kpi_path_gp", "A on C_s with the model discrepancy along the working paths (m^2)", "m^2"
    is_ratio, needs_kpi = True, True

    def objective(self, problem: Any) -> DesignObjective:
        cell = getattr(problem, "cell", None)
        if cell is None or not getattr(cell, "paths", None) or not hasattr(problem, "gp_objective"):
            raise InputError("criterion kpi_path_gp: needs a design problem whose cell has working_paths")
        return problem.gp_objective("kpi_gp", Q_work=cell.q_path)


register(PathDiscrepancyKpi)
