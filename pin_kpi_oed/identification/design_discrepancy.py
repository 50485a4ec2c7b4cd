"""The discrepancy of a design with measured poses (``design --given measured.csv --model model.json``): re-fitted
on the measured batch (geometry and set-up by least squares, then the Gaussian process on the residuals) when the
file holds measured positions and enough rows, else the model file's."""

from __future__ import annotations

from typing import Any

import numpy as np

from pin_kpi_oed.errors import InputError

__all__ = ["refit_discrepancy"]


def refit_discrepancy(problem: Any, given_file: str) -> str:
    """``--given measured.csv --model model.json``: re-fit the discrepancy on the measured batch (geometry and set-up
    by least squares, then the Gaussian process on the residuals, mode ``on``) when the file holds measured positions
    and enough rows; else keep the model file's discrepancy.

    Returns:
        One line: the Gaussian process's decision, or why the discrepancy was not re-fitted.

    Raises:
        InputError: the discrepancy cannot be re-fitted and the problem holds none.
    """
    from pin_kpi_oed.data.measurement_reader import read_measurements
    from pin_kpi_oed.discrepancy import DiscrepancyOptions
    from pin_kpi_oed.identification.identify import identify
    from pin_kpi_oed.discrepancy.prior import DiscrepancyPrior

    ms = read_measurements(given_file, joint_names=list(problem.cell.robot.joint_names), require_position=False)
    pos = getattr(ms, "position_m", None)
    n_min = DiscrepancyOptions().min_rows
    why = None
    if pos is None or not np.all(np.isfinite(pos)):
        why = "it holds no measured positions (x, y, z)"
    elif len(pos) < n_min:
        why = f"its {len(pos)} rows are fewer than the {n_min} a Gaussian process needs"
    if why is None:
        fit = identify(problem.model, ms, discrepancy=DiscrepancyOptions(mode="on"))
        if fit.discrepancy is not None:
            problem.discrepancy = DiscrepancyPrior.from_discrepancy(
                fit.discrepancy, f"re-fitted on --given {given_file} ({len(pos)} rows; geometry + set-up by least "
                                 f"squares, then the Gaussian process on the residuals)")
            return str(fit.discrepancy.decision)
        why = "the fit returned no discrepancy"
    if problem.discrepancy is None:
        raise InputError(f"--given {given_file}: the discrepancy cannot be re-fitted ({why}) and --model holds none")
    return f"--given {given_file}: discrepancy not re-fitted ({why}); the --model one is used"
