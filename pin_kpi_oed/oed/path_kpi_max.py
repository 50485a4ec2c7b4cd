r"""The worst-sample path KPI: a smooth maximum of the TCP covariance over a working path's samples.

``kpi_path`` (:mod:`pin_kpi_oed.oed.path_kpi`) minimises the mean of t_i = tr(E_i C_p E_iᵀ) over the path samples
i = 1…S; a seam's accuracy is often judged by its worst point. The maximum itself is not differentiable where two
samples tie, so this criterion minimises its smooth form, the power mean of order κ::

    φ_max = ( (1/S) Σ_i t_i^κ )^{1/κ}
          = exp( (1/κ) log( (1/S) Σ_i exp(κ log t_i) ) )                      (m²)

the log-sum-exp (with sharpness κ) of log t_i: free of the unit, independent of the sampling density, and between
the mean and the worst sample, max_i t_i · S^{−1/κ} ≤ φ_max ≤ max_i t_i (κ = 1: ``kpi_path``; κ → ∞: the worst
sample). With ∂φ/∂t_i = (1/S) (t_i/φ)^{κ−1} = w_i and ∂t_i/∂M = −C_p E_iᵀ E_i C_p, the exact gradient is

    Γ = ∂φ/∂M = −Σ_i w_i C_p E_iᵀ E_i C_p,

evaluated with every t_i divided by the largest first (the power mean is homogeneous of degree one, so nothing
overflows). It works on every information model that takes an E (noise only, measured poses, extended with a prior).
The worst sample has no A-type pool form: a pool selection starts from the relaxation of the mean (``kpi_path``'s
form K = E/√S) and reports φ_max of the chosen poses (its certificate is the mean's, not the worst sample's); the
IPOPT design then minimises φ_max itself.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from pin_kpi_oed.oed.criteria import ConfigurationCriterion, CovarianceCriterion, register
from pin_kpi_oed.oed.design_objective import DesignObjective
from pin_kpi_oed.oed.selection_result import PoolSelection

__all__ = ["DEFAULT_SHARPNESS", "PathMaxTrace", "PathMaxKpi", "WorstSampleObjective", "sample_traces"]

#: κ of the power mean: with the 161 samples of the shipped seam φ_max lies within [0.73, 1] × the worst sample
DEFAULT_SHARPNESS = 16.0


def sample_traces(E: np.ndarray, C: np.ndarray, rows_per_sample: int = 3) -> tuple[np.ndarray, np.ndarray]:
    """(t_i = tr(E_i C Eᵢᵀ) per sample (S,), C Eᵀ (nb, rows)) of a stacked sensitivity E (S·rows, nb)."""
    CE = C @ E.T
    t = np.sum(E * CE.T, axis=1).reshape(-1, rows_per_sample).sum(axis=1)
    return t, CE


class PathMaxTrace(CovarianceCriterion):
    """φ_max = ((1/S) Σ_i t_i^κ)^{1/κ}, t_i = tr C_s at path sample i (module docstring): the information-matrix form
    of ``kpi_path_max`` (not registered: its E is the path's, which only :class:`PathMaxKpi` builds).

    Args:
        sharpness: κ ≥ 1 (1: the mean, ``kpi_path``; large: the worst sample).
    """

    name, label, unit = "kpi_path_max", "smooth worst tr of the TCP covariance over the path samples (m^2)", "m^2"
    is_ratio, needs_kpi, has_pool_form = True, True, False
    rows_per_sample = 3

    def __init__(self, sharpness: float = DEFAULT_SHARPNESS):
        if not (np.isfinite(sharpness) and sharpness >= 1.0):
            raise ValueError(f"sharpness must be a number >= 1, got {sharpness!r}")
        self.sharpness = float(sharpness)

    def from_covariance(self, E, M, L, C):
        E = self.need_E(E)
        t, CE = sample_traces(E, C, self.rows_per_sample)
        k, S = self.sharpness, t.size
        top = float(t.max())
        if not top > 0:
            return 0.0, np.zeros_like(C)
        r = t / top
        phi = top * float(np.mean(r ** k)) ** (1.0 / k)
        w = (t / phi) ** (k - 1.0) / S                       # ∂φ/∂t_i
        W = np.repeat(w, self.rows_per_sample)
        return phi, -((CE * W) @ CE.T)

    def pool_form(self, E, nb):
        """The mean's A-type form K = E/√S: the pool selection's start (module docstring)."""
        E = self.need_E(E)
        return E / np.sqrt(E.shape[0] // self.rows_per_sample)


class WorstSampleObjective(DesignObjective):
    """``kpi_path_max`` on an information model (``inner``, its value and exact gradient), with the pool selection of
    the module docstring: the mean's relaxation, rounding and exchange (``inner``'s own), reported with φ_max of the
    chosen poses and without a certificate (none exists for the worst sample)."""

    def __init__(self, inner: DesignObjective):
        self.inner = inner
        self.crit = inner.crit

    def value(self, Q: np.ndarray) -> float:
        return self.inner.value(Q)

    def value_and_grad(self, Q: np.ndarray) -> tuple[float, np.ndarray]:
        return self.inner.value_and_grad(Q)

    def select(self, Q_pool: np.ndarray, m: int, seed: int = 0, **kw: Any) -> PoolSelection:
        sel = self.inner.select(Q_pool, m, seed=seed, **kw)
        Q = np.atleast_2d(np.asarray(Q_pool, float))[sel.indices]
        return PoolSelection(indices=sel.indices, value=float(self.value(Q)), nit=sel.nit, time_s=sel.time_s,
                             success=sel.success, status="selected",
                             message=f"{m} of {len(Q_pool)} candidates by the mean's (kpi_path) relaxation, rounding "
                                     "and exchange; no certificate exists for the worst sample")


class PathMaxKpi(ConfigurationCriterion):
    """``kpi_path_max``: the smooth worst tr C_s over the working paths' samples (m², module docstring) on the
    problem's information model: noise only, with the measured poses (``design --given``) or the extended model
    (``design --model``)."""

    name, label, unit = "kpi_path_max", "smooth worst tr of the TCP covariance along the working paths (m^2)", "m^2"
    is_ratio, needs_kpi, uses_discrepancy = True, True, False

    def objective(self, problem: Any) -> DesignObjective:
        from pin_kpi_oed.oed.path_kpi import path_objective

        return WorstSampleObjective(path_objective(problem, PathMaxTrace()))


register(PathMaxKpi)
