"""The discrepancy of a design with measured poses and a model file (``design --given measured.csv --model
model.json``): re-fitted on the measured batch (geometry and set-up by least squares, then the Gaussian process on the
residuals) when the file holds measured positions and enough rows, else the model file's."""

from __future__ import annotations

from typing import Any

import numpy as np

from pin_kpi_oed.errors import InputError

__all__ = ["refit_discrepancy"]


def refit_discrepancy(model: Any, given_file: str, fallback: Any = None) -> tuple[Any, str]:
    """Re-fit the discrepancy on the measured batch (geometry and set-up by least squares, then the Gaussian process
    on the residuals, mode ``on``) when the file holds measured positions and enough rows; else keep ``fallback``
    (the model file's discrepancy).

    Args:
        model: the cell's measurement model (its robot's joint names read the file).
        given_file: the measured poses (CSV with x, y, z for a re-fit).
        fallback: the :class:`~pin_kpi_oed.discrepancy.prior.DiscrepancyPrior` of the model file, or None.

    Returns:
        (the discrepancy to design with: re-fitted, else ``fallback``; one line: the Gaussian process's decision, or
        why the discrepancy was not re-fitted).

    Raises:
        InputError: the discrepancy cannot be re-fitted and ``fallback`` is None (named ``Q_given``).
    """
    from pin_kpi_oed.data.measurement_reader import read_measurements
    from pin_kpi_oed.discrepancy import DiscrepancyOptions
    from pin_kpi_oed.identification.identify import identify
    from pin_kpi_oed.discrepancy.prior import DiscrepancyPrior

    ms = read_measurements(given_file, joint_names=list(model.robot.joint_names), require_position=False)
    pos = getattr(ms, "position_m", None)
    n_min = DiscrepancyOptions().min_rows
    why = None
    if pos is None or not np.all(np.isfinite(pos)):
        why = "it holds no measured positions (x, y, z)"
    elif len(pos) < n_min:
        why = f"its {len(pos)} rows are fewer than the {n_min} a Gaussian process needs"
    if why is None:
        fit = identify(model, ms, discrepancy=DiscrepancyOptions(mode="on"))
        if fit.discrepancy is not None:
            prior = DiscrepancyPrior.from_discrepancy(
                fit.discrepancy, f"re-fitted on the measured poses {given_file} ({len(pos)} rows; geometry + set-up "
                                 f"by least squares, then the Gaussian process on the residuals)")
            return prior, str(fit.discrepancy.decision)
        why = "the fit returned no discrepancy"
    if fallback is None:
        raise InputError(f"Q_given {given_file}: the discrepancy cannot be re-fitted ({why}) and the model file holds "
                         f"none")
    return fallback, f"Q_given {given_file}: discrepancy not re-fitted ({why}); the model file's is used"
