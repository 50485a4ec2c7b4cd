r"""The discrepancy step of a calibration: δ(q) fitted to the residuals of the parametric fit.

:func:`result_discrepancy` takes an :class:`~pin_kpi_oed.identification.identify.IdentificationResult`
and its data, turns every station's residuals (measured − predicted, in that station's tracker
frame) into the robot base frame with the station's fitted rotation (``r_base = R_sᵀ r``), leaves
out the rows the fit flagged as outliers, and fits
:class:`~pin_kpi_oed.discrepancy.gp.Discrepancy` (see there for the model, the separation of the
parametric part and δ, and the K-fold decision of ``--discrepancy auto``).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from pin_kpi_oed.data.measurements import MeasurementSet
from pin_kpi_oed.discrepancy.gp import Discrepancy, DiscrepancyOptions, fit_discrepancy
from pin_kpi_oed.errors import InputError

__all__ = ["result_discrepancy", "base_frame_residuals", "discrepancy_options"]


def discrepancy_options(value: Any, seed: int = 0) -> DiscrepancyOptions:
    """``auto`` / ``on`` / ``none`` (or options) as :class:`DiscrepancyOptions`.

    Raises:
        InputError: an unknown mode.
    """
    if isinstance(value, DiscrepancyOptions):
        return value
    if value is None or value is False:
        return DiscrepancyOptions(mode="none", seed=seed)
    return DiscrepancyOptions(mode=str(value), seed=seed)


def _keep_flagged(result: Any, opts: Any) -> bool:
    """Whether the rows flagged as outliers go into the discrepancy too: only when the plain (linear) loss kept them
    in the parametric fit and leaving them out would leave fewer rows than the Gaussian process needs (a fit that
    misses an effect flags its largest residuals, which are the discrepancy's information)."""
    n, k = len(result.residuals_m), np.asarray(result.outliers).size
    return bool(k and getattr(result, "loss", "linear") == "linear" and n - k < opts.min_rows <= n)


def base_frame_residuals(result: Any, keep_flagged: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """(rows, residuals in the robot base frame (n, 3) m) of a fit, outliers left out (kept with ``keep_flagged``)."""
    R_rows = np.empty((len(result.residuals_m), 3))
    for lab, rows in zip(result.stations, result.station_rows):
        R = np.asarray(result.setups[lab].tracker_T_base, float)[:3, :3]
        R_rows[rows] = result.residuals_m[rows] @ R
    keep = np.ones(len(R_rows), bool)
    if not keep_flagged:
        keep[np.asarray(result.outliers, int)] = False
    return np.flatnonzero(keep), R_rows[keep]


def result_discrepancy(result: Any, data: MeasurementSet, options: Any = "auto", Q: np.ndarray | None = None
                       ) -> Discrepancy | None:
    """Fit the discrepancy of a calibration (None for mode ``none``).

    Args:
        result: the parametric fit (:func:`~pin_kpi_oed.identification.identify.identify`).
        data: its training data.
        options: ``auto``, ``on``, ``none`` or :class:`DiscrepancyOptions`.
        Q: the data's configurations in the robot's joint order (default: aligned from ``data``).

    Raises:
        InputError: too few rows for mode ``on``; an unknown mode.
    """
    opts = discrepancy_options(options)
    if opts.mode == "none":
        return None
    if Q is None:
        from pin_kpi_oed.identification.problem import align_data
        Q = align_data(result.model.robot, data)
    if len(Q) != len(result.residuals_m):
        raise InputError(f"discrepancy: {len(Q)} configurations for {len(result.residuals_m)} residuals")
    rows, R = base_frame_residuals(result, keep_flagged=_keep_flagged(result, opts))
    Q = np.asarray(Q, float)
    try:
        disc = fit_discrepancy(Q[rows], R, list(result.model.robot.joint_names), opts)
    except InputError as exc:
        left = np.setdiff1d(np.arange(len(Q)), rows)
        if not left.size:
            raise
        shown = ", ".join(str(int(r) + 1) for r in left[:5]) + (f" (+{left.size - 5} more)" if left.size > 5 else "")
        raise InputError(f"{exc} ({len(Q)} rows given: row{'s' * (left.size > 1)} {shown} flagged as outlier"
                         f"{'s' * (left.size > 1)} and left out; check {'them' if left.size > 1 else 'it'} or "
                         "measure more poses)") from None
    if disc is not None and rows.size > len(result.residuals_m) - np.asarray(result.outliers).size:
        disc.decision += (f" (the {np.asarray(result.outliers).size} rows flagged as outliers are kept: the "
                          f"plain least-squares fit used them, "
                          f"and without them {rows.size - np.asarray(result.outliers).size} "
                          f"rows are fewer than the {opts.min_rows} a Gaussian process needs)")
    if disc is not None:
        F, names = parameter_jacobian(result, Q)
        disc.set_parametric(F[rows], names)
    return disc


def parameter_jacobian(result: Any, Q: np.ndarray) -> tuple[np.ndarray, list[str]]:
    """Jacobian of a fit's predictions at its rows w.r.t. its robot parameters and every station's set-up,
    rotated into the robot base frame: ((n, 3, R + 9 S), the R robot parameters' names).

    The robot parameters are the estimated joint-placement errors of the fit (its identifiable set); each
    station adds its tracker pose (6) and reflector (3) columns, zero on the other stations' rows.
    """
    robot = result.model.robot
    L0 = result.station_models[0].layout
    robot_names = [n for n in result.names if n in set(L0.names[:6 * robot.nq])]
    S = len(result.stations)
    F = np.zeros((len(Q), 3, len(robot_names) + 9 * S))
    for s, rows in enumerate(result.station_rows):
        model, p = result.station_models[s], result.station_p[s]
        L = model.layout
        cols = [L.names.index(n) for n in robot_names]
        setup = list(range(L.tracker.start, L.tracker.stop)) + list(range(L.reflector.start, L.reflector.stop))
        Jb = model.base_jacobian(p, Q[rows])
        F[rows, :, :len(robot_names)] = Jb[:, :, cols]
        F[rows, :, len(robot_names) + 9 * s: len(robot_names) + 9 * (s + 1)] = Jb[:, :, setup]
    return F, robot_names
