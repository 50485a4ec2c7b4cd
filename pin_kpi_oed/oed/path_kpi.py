r"""The path KPI: the mean TCP covariance along a working path (the paper's outlook: "working path trajectories of
welding manipulators could be defined as KPIs").

With E_i the KPI sensitivity (eq. 24e) at the path's sample i = 1…S (the samples of the cell's ``working_paths``,
:mod:`pin_kpi_oed.cell.paths`, solved by IK on one branch) and C_p = (M₀ + P)⁻¹ the parameter covariance of the
design (eq. 19)::

    φ_path = (1/S) Σ_i tr(E_i C_p E_iᵀ) = (1/S) tr(E_path C_p E_pathᵀ)        (m²)

the A-criterion on C_s of eq. 24a with the path's samples as the working configurations, weighted so that the value
is the mean per sample (independent of the sampling density). Being of the information matrix with a fixed E_path,
it has the exact gradient Γ = −C_p E_pathᵀ E_path C_p / S, the pool form K = E_path/√S (relaxation,
equivalence-theorem certificate, rounding and exchange) and works on every information model of
:mod:`pin_kpi_oed.oed.objective` that takes an E. :class:`PathKpi` (``kpi_path``) is the registered criterion of the
configurations: on a design problem whose cell has working paths it builds E_path and returns :class:`PathTrace` on
the problem's information model (noise only, measured poses, extended with a prior). The worst sample,
max_i tr(E_i C_p E_iᵀ), is reported in the path profile (:mod:`pin_kpi_oed.design.path_profile`), not designed for
(non-smooth).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from pin_kpi_oed.errors import InputError
from pin_kpi_oed.oed.criteria import ConfigurationCriterion, Criterion, SampleMeanTrace, register
from pin_kpi_oed.oed.design_objective import DesignObjective
from pin_kpi_oed.oed.objective import DesignContext, criterion_with_E

__all__ = ["PathTrace", "PathKpi", "path_sensitivity", "path_objective"]


class PathTrace(SampleMeanTrace):
    """(1/S) tr(E C_p Eᵀ) with E the path's sensitivity (3S rows): the mean tr C_s per path sample (m²), the
    information-matrix form of ``kpi_path`` (not registered: its E is the path's, which only :class:`PathKpi`
    builds). Γ = −C_p Eᵀ E C_p / S; pool form K = E/√S."""

    name, label, unit = "kpi_path", "mean tr of the TCP covariance over the working paths' samples (m^2)", "m^2"
    rows_per_sample = 3


def path_sensitivity(problem: DesignContext) -> np.ndarray:
    """E of the TCP at every working path sample over the problem's identifiable parameters, (3S, nb) m per
    parameter unit.

    Raises:
        InputError: the problem has no cell or its cell no working paths.
        IdentifiabilityError: the TCP along the path is not estimable.
    """
    from pin_kpi_oed.oed.identifiability import check_kpi

    cell = problem.cell
    if cell is None or not getattr(cell, "paths", None):
        raise InputError("criterion kpi_path: needs a cell with working_paths (the cell file's working_paths key)")
    E_full = problem.model.kpi_jacobian(problem.p0, cell.q_path)
    if problem.ident is not None:
        check_kpi(problem.ident, problem.model, E_full, f"{cell.name}: the TCP along the working paths")
    return E_full[:, problem.base]


class PathKpi(ConfigurationCriterion):
    """``kpi_path``: the mean tr C_s over the working paths' samples (m²) on the problem's information model:
    noise only, with the measured poses (``design --given``) or the extended model (``design --model``)."""

    name, label, unit = "kpi_path", "mean tr of the TCP covariance along the working paths (m^2)", "m^2"
    is_ratio, needs_kpi, uses_discrepancy = True, True, False

    def objective(self, problem: Any) -> DesignObjective:
        return path_objective(problem, PathTrace())


def path_objective(problem: DesignContext, crit: Criterion) -> DesignObjective:
    """A criterion of the path samples' covariance (``crit``: :class:`PathTrace`, ``kpi_path_max``'s smooth worst
    sample) on the problem's information model: the extended model when the problem has one, else the noise-only
    information with the measured poses' rows (:func:`~pin_kpi_oed.oed.objective.criterion_with_E`).

    Raises:
        InputError, IdentifiabilityError: as :func:`path_sensitivity`.
    """
    E = path_sensitivity(problem)
    if problem.extended is not None:
        from pin_kpi_oed.oed.extended import ExtendedDesignCriterion

        return ExtendedDesignCriterion(problem.extended, crit, problem.cell.q_path)
    return criterion_with_E(problem, crit, E)


register(PathKpi)
