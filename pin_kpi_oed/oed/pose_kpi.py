r"""The 6-D KPI: the TCP's position and the tool's orientation, the orientation weighted by a length L.

A drill's axis, a torch's angle: the orientation error δθ of the tool frame moves a point at distance L along the
tool by about L·δθ. With E_i (3, nb) the position sensitivity (eq. 24e) and R_i (3, nb) the orientation sensitivity
(rad per parameter unit, :meth:`~pin_kpi_oed.model.tracker.TrackerModel.kpi_rotation_jacobian`) at working
configuration i = 1…t::

    E6_i = [E_i ; L·R_i],     φ6 = (1/t) Σ_i tr(E6_i C_p E6_iᵀ) = (1/t) Σ_i (tr C_s,i + L² tr C_θ,i)      (m²)

"orientation at L" (the cell file's ``orientation_length_m``, default 0.2 m: "orientation at 200 mm"). It is the
A-criterion of eq. 24a with the stacked E6 = [E6_i] over t: exact gradient Γ = −C_p E6ᵀE6 C_p / t, pool form
K = E6/√t (relaxation and certificate). L → 0 gives the position KPI over t; a large L designs for the orientation
alone.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from pin_kpi_oed.errors import InputError
from pin_kpi_oed.oed.criteria import ConfigurationCriterion, SampleMeanTrace, register
from pin_kpi_oed.oed.design_objective import DesignObjective
from pin_kpi_oed.oed.objective import criterion_with_E

__all__ = ["PoseTrace", "PoseKpi", "pose_sensitivity"]


class PoseTrace(SampleMeanTrace):
    """(1/t) tr(E6 C_p E6ᵀ) of the stacked 6-D sensitivity (6t rows, m²): the information-matrix form of ``kpi6``
    (not registered: its E is the 6-D one, which only :class:`PoseKpi` builds). Pool form K = E6/√t."""

    name, label, unit = "kpi6", "mean tr of the 6-D TCP covariance, orientation x L (m^2)", "m^2"
    rows_per_sample = 6


def pose_sensitivity(model: Any, p0: np.ndarray, Q_work: np.ndarray, base: np.ndarray,
                     length_m: float) -> np.ndarray:
    """E6 = [E_i ; L·R_i]_i over the parameters ``base``, (6t, nb) m per parameter unit.

    Args:
        model: the measurement model (a tracker model: position and orientation sensitivity).
        p0: linearisation point; Q_work: the working configurations (t, n) rad; base: parameter columns.
        length_m: the orientation's lever L (m).
    """
    Q_work = np.atleast_2d(Q_work)
    t = len(Q_work)
    E = model.kpi_jacobian(p0, Q_work)[:, base].reshape(t, 3, -1)
    R = model.kpi_rotation_jacobian(p0, Q_work)[:, base].reshape(t, 3, -1)
    return np.concatenate([E, length_m * R], axis=1).reshape(6 * t, -1)


class PoseKpi(ConfigurationCriterion):
    """``kpi6``: the mean 6-D TCP covariance at the working configurations, orientation at the cell's
    ``orientation_length_m`` (m²), on the noise-only information or with the measured poses (``design --given``).

    Raises (from :meth:`objective`):
        InputError: on the extended model of ``design --model`` (its effects carry no orientation sensitivity), or
            without a cell (``evaluate`` of a design file leaves it out rather than assume a length).
    """

    name, label, unit = "kpi6", "mean tr of the 6-D TCP covariance, orientation x the cell's length (m^2)", "m^2"
    is_ratio, needs_kpi, uses_discrepancy = True, True, False

    def objective(self, problem: Any) -> DesignObjective:
        if problem.extended is not None:
            raise InputError("criterion kpi6: not available on the extended model of model_file (its effects carry "
                             "no orientation sensitivity); design kpi6 without model_file")
        cell = problem.cell
        if cell is None or not hasattr(cell, "orientation_length_m"):
            raise InputError("criterion kpi6: needs a design problem on a cell (its orientation_length_m)")
        L = float(cell.orientation_length_m)
        E6 = pose_sensitivity(problem.model, problem.p0, problem.q_work, problem.base, L)
        return criterion_with_E(problem, PoseTrace(), E6)


register(PoseKpi)
