"""Model discrepancy δ(q): a Gaussian process over the joint angles beside the parametric robot model.

:class:`JointKernel` (the kernel, with its derivative in q), :class:`Discrepancy` (a fitted δ: posterior
mean and variance, coverage, model-file block), :func:`fit_discrepancy` (hyper-parameters by maximum
marginal likelihood, exact or inducing-point posterior, K-fold decision).
"""

from pin_kpi_oed.discrepancy.fit import fit_discrepancy
from pin_kpi_oed.discrepancy.gp import Discrepancy, DiscrepancyOptions
from pin_kpi_oed.discrepancy.kernel import JointKernel

__all__ = ["Discrepancy", "DiscrepancyOptions", "JointKernel", "fit_discrepancy"]
