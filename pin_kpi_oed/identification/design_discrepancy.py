"""What a calibrated model file brings to a design (``design --model model.json``, :func:`model_design_inputs`): its
discrepancy (with measured poses, ``--given measured.csv``, re-fitted on the measured batch — geometry and set-up by
least squares, then the Gaussian process on the residuals — when the file holds measured positions and enough rows,
:func:`refit_discrepancy`) and its own σ at the working configurations as ``predict`` gives it. The design layer
cannot fit (it is upstream of identification): these go into
:class:`~pin_kpi_oed.design.runner.DesignSettings` (``discrepancy``, ``model_sigma_at_work``)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from pin_kpi_oed.errors import InputError

__all__ = ["refit_discrepancy", "ModelDesignInputs", "model_design_inputs"]


@dataclass(frozen=True)
class ModelDesignInputs:
    """What a model file brings to a design run.

    Attributes:
        discrepancy: the :class:`~pin_kpi_oed.discrepancy.prior.DiscrepancyPrior` to design with (the model's, or
            re-fitted on the measured poses), None when the file holds none.
        model_sigma: the model's own 3-D σ at the working configurations (``sigma_m``, m) and which lie outside its
            joint-space coverage (``extrapolated``), as ``predict`` gives them; None without a discrepancy.
        sigma_line: the σ at the working configurations in words (None without a discrepancy).
        refit_line: the re-fit's decision, or why the discrepancy was not re-fitted (None without measured poses).
    """

    discrepancy: Any
    model_sigma: dict | None
    sigma_line: str | None = None
    refit_line: str | None = None


def model_design_inputs(cm: Any, cell: Any, model_file: str, given_file: str | None = None) -> ModelDesignInputs:
    """The discrepancy and σ a calibrated model brings to a design in ``cell`` (with measured poses ``given_file``:
    the discrepancy re-fitted on them when they hold positions).

    Raises:
        InputError: a model of other joints than the cell's robot (named ``model_file``), a discrepancy that can be
            neither re-fitted nor taken from the file (named ``Q_given``).
    """
    from pin_kpi_oed.design.declare import model_discrepancy
    from pin_kpi_oed.calibrated.tcp_sigma import tcp_sigma

    model_sigma = sigma_line = refit_line = None
    prior = model_discrepancy(cell, cm, model_file)
    if prior is not None:
        at = tcp_sigma(cm, cell.q_work, cell.tcp_m)
        sig, far = at.sigma_m, at.extrapolation
        model_sigma = {"sigma_m": sig.tolist(), "extrapolated": far.tolist(),
                       "held_sigma_m": at.held_sigma_m.tolist(),
                       "note": "at the cell's TCP, as predict at='tcp' gives it (the held parameters included)"}
        sigma_line = (f"model_file {model_file}: predicted sigma now at the TCP at the working configurations (as "
                     "predict at='tcp' gives it): "
                     + ", ".join(f"{s * 1e3:.4f} mm" + (" (outside the coverage)" if f else "")
                                 for s, f in zip(sig, far))
                     + (f"; {int(far.sum())} of {len(far)} outside the calibration's joint-space coverage: its "
                        "discrepancy was not learnt there (the sigma is widened by the parameters' extrapolation "
                        "error, predict / compensate flag them); the design's poses near them measure it"
                        if far.any() else ""))
    if given_file:  # a measurement campaign: the discrepancy re-fitted on the measured batch, geometric design
        prior, refit_line = refit_discrepancy(cell.tracker_model(), given_file, prior)
    return ModelDesignInputs(prior, model_sigma, sigma_line, refit_line)


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
