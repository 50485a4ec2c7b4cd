r"""The 6-D KPI: the TCP's position and the tool's orientation, the orientation weighted by a length L.

A drill's axis, a torch's angle: the orientation error δθ of the tool frame moves a point at distance L along the
tool by about L·δθ. With E_i (3, nb) the position sensitivity (eq. 24e) and R_i (3, nb) the orientation sensitivity
(rad per parameter unit, :meth:`~pin_kpi_oed.model.tracker.TrackerModel.kpi_rotation_jacobian`) at working
configuration i = 1…t::

    E6_i = [E_i ; L·R_i],     φ6 = (1/t) Σ_i tr(E6_i C_p E6_iᵀ) = (1/t) Σ_i (tr C_s,i + L² tr C_θ,i)      (m²)

"orientation at L" (the cell file's ``orientation_length_m``, default 0.2 m: "orientation at 200 mm"). It is the
A-criterion of eq. 24a with the stacked Ē = [E6_i] / √t: exact gradient Γ = −C_p ĒᵀĒ C_p, pool form K = Ē
(relaxation and certificate). L → 0 gives the position KPI over t; a large L designs for the orientation alone.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from pin_kpi_oed.oed.criteria import ConfigurationCriterion, KpiTrace, register
from pin_kpi_oed.oed.objective import DesignCriterion, DesignObjective

__all__ = ["PoseTrace", "PoseKpi", "pose_sensitivity"]


class PoseTrace(KpiTrace):
    """tr(Ē C_p Ēᵀ) of the stacked 6-D sensitivity (m²): the information-matrix form of ``kpi6`` (not registered:
    its E is the 6-D one, which only :class:`PoseKpi` builds)."""

    name, label, unit = "kpi6", "mean tr of the 6-D TCP covariance, orientation x L (m^2)", "m^2"


def pose_sensitivity(model: Any, p0: np.ndarray, Q_work: np.ndarray, base: np.ndarray,
                     length_m: float) -> np.ndarray:
    """Ē = [E_i ; L·R_i]_i / √t over the parameters ``base``, (6t, nb) m per parameter unit.

    Args:
        model: the measurement model (a tracker model: position and orientation sensitivity).
        p0: linearisation point; Q_work: the working configurations (t, n) rad; base: parameter columns.
        length_m: the orientation's lever L (m).
    """
    Q_work = np.atleast_2d(Q_work)
    t = len(Q_work)
    E = model.kpi_jacobian(p0, Q_work)[:, base].reshape(t, 3, -1)
    R = model.kpi_rotation_jacobian(p0, Q_work)[:, base].reshape(t, 3, -1)
    return np.concatenate([E, length_m * R], axis=1).reshape(6 * t, -1) / np.sqrt(t)


class PoseKpi(ConfigurationCriterion):
    """``kpi6``: the mean 6-D TCP covariance at the working configurations, orientation at the cell's
    ``orientation_length_m`` (m²), on the noise-only information."""

    name, label, unit = "kpi6", "mean tr of the 6-D TCP covariance, orientation x the cell's length (m^2)", "m^2"
    is_ratio, needs_kpi, uses_discrepancy = True, True, False

    def objective(self, problem: Any) -> DesignObjective:
        cell = getattr(problem, "cell", None)
        L = float(getattr(cell, "orientation_length_m", 0.2))
        Eb = pose_sensitivity(problem.model, problem.p0, problem.q_work, problem.base, L)
        return DesignCriterion(problem.model, problem.base, PoseTrace(), Eb, problem.p0)


register(PoseKpi)
