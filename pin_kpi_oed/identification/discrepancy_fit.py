r"""The discrepancy step of a calibration: δ(q) fitted to the residuals of the parametric fit.

:func:`result_discrepancy` takes an :class:`~pin_kpi_oed.identification.identify.IdentificationResult`
and its data, turns every station's residuals (measured − predicted, in that station's tracker
frame) into the robot base frame with the station's fitted rotation (``r_base = R_sᵀ r``), leaves
out the rows the fit flagged as outliers, and fits
:class:`~pin_kpi_oed.discrepancy.gp.Discrepancy` (see there for the model, the separation of the
parametric part and δ, and the K-fold decision of ``--discrepancy auto``).

The white level is corrected for the fit's p parameters (3m − p) and never below the data's stated noise
(:func:`~pin_kpi_oed.discrepancy.gp.white_level`). With 6-D data the rows left out are the *position* outliers
(:func:`position_outliers`): a row whose orientation residual was flagged still carries a good position residual,
and δ is a position discrepancy.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from pin_kpi_oed.model.nests import nest_column
from pin_kpi_oed.data.measurements import MeasurementSet
from pin_kpi_oed.discrepancy.fit import fit_discrepancy
from pin_kpi_oed.discrepancy.gp import Discrepancy, DiscrepancyOptions
from pin_kpi_oed.errors import InputError

__all__ = ["result_discrepancy", "base_frame_residuals", "discrepancy_options", "position_outliers",
           "stated_noise_m", "joint_jacobian", "parameter_jacobian"]

#: False-alarm probability of the position-outlier flag of 6-D fits.
POSITION_OUTLIER_ALPHA = 1e-3


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


def position_outliers(result: Any, alpha: float = POSITION_OUTLIER_ALPHA) -> np.ndarray:
    """Rows whose *position* residual is an outlier: ‖r_i‖ > sqrt(χ²₃(1 − α)) · s with s the robust (MAD) scale of
    the position residual components (m). For a 3-D fit these are the fit's own flags."""
    if getattr(result, "residuals_rad", None) is None:
        return np.asarray(result.outliers, int)
    from scipy.special import gammaincinv  # scipy.stats.chi2.ppf's own formula
    r = np.asarray(result.residuals_m, float)
    s = 1.4826 * float(np.median(np.abs(r - np.median(r, axis=0))))
    limit = np.sqrt(2.0 * gammaincinv(1.5, 1 - alpha)) * s
    return np.flatnonzero(np.linalg.norm(r - np.median(r, axis=0), axis=1) > limit)


def stated_noise_m(result: Any, data: MeasurementSet) -> np.ndarray | None:
    """The data's stated noise per axis (3,) m: RMS of the weights' σ (sigma columns, else the noise model); None
    when the noise level is unknown (the covariance was scaled by the reduced χ²)."""
    if bool(getattr(result, "covariance_scaled", False)):
        return None
    if getattr(result, "sigma_source", "") == "data" and data.sigma_m is not None:
        sig = np.asarray(data.sigma_m, float)
    else:
        sig = np.asarray(result.model.noise.sigma(np.asarray(data.position_m, float)), float).reshape(-1, 3)
    return np.full(3, float(np.sqrt(np.mean(sig ** 2))))


def keep_flagged_rows(result: Any, opts: Any) -> bool:
    """Whether the rows flagged as outliers go into the discrepancy too: when the plain (linear) loss kept them in the
    parametric fit. A fit that misses an effect flags its largest residuals, which are the discrepancy's information:
    left out, they made δ's level too small (designs of 70 poses with an unmodelled gear harmonic: held-out
    standardised RMS 1.24 and 82 % inside the 95 % ellipsoid on a Panda, 1.08 and 91 % with them). With a robust
    loss the flagged rows are out of the parametric fit and stay out of δ."""
    return bool(position_outliers(result).size and getattr(result, "loss", "linear") == "linear")


def base_frame_residuals(result: Any, keep_flagged: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """(rows, residuals in the robot base frame (n, 3) m) of a fit, outliers left out (kept with ``keep_flagged``)."""
    R_rows = np.empty((len(result.residuals_m), 3))
    for lab, rows in zip(result.stations, result.station_rows):
        R = np.asarray(result.setups[lab].tracker_T_base, float)[:3, :3]
        R_rows[rows] = result.residuals_m[rows] @ R
    keep = np.ones(len(R_rows), bool)
    if not keep_flagged:
        keep[position_outliers(result)] = False
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
    rows, R = base_frame_residuals(result, keep_flagged=keep_flagged_rows(result, opts))
    Q = np.asarray(Q, float)
    n_out = position_outliers(result).size
    nest = nest_column(data, result.model.n_nests)
    F, names = parameter_jacobian(result, Q, nest)
    try:
        disc = fit_discrepancy(Q[rows], R, list(result.model.robot.joint_names), opts, n_params=len(result.names),
                               noise_floor_m=stated_noise_m(result, data),
                               periodic=result.model.robot.periodic_joints,
                               linear=~result.model.robot.is_revolute,
                               joint_span=result.model.robot.q_upper - result.model.robot.q_lower,
                               jacobian=F[rows], joint_jacobian=joint_jacobian(result, Q, nest)[rows])
    except InputError as exc:
        left = np.setdiff1d(np.arange(len(Q)), rows)
        flagged = left if left.size else position_outliers(result)
        if not flagged.size:
            raise
        shown = ", ".join(str(int(r) + 1) for r in flagged[:5]) + (f" (+{flagged.size - 5} more)"
                                                                    if flagged.size > 5 else "")
        how = "left out" if left.size else "kept"
        raise InputError(f"{exc} ({len(Q)} rows given: row{'s' * (flagged.size > 1)} {shown} flagged as outlier"
                         f"{'s' * (flagged.size > 1)} and {how}; check {'them' if flagged.size > 1 else 'it'} or "
                         "measure more poses)") from None
    if disc is not None and rows.size > len(result.residuals_m) - n_out:
        disc.decision += (f" (the {n_out} rows flagged as outliers are kept: the plain least-squares fit used them, "
                          "and an unmodelled effect shows first in the largest residuals)")
    if disc is not None:
        disc.set_parametric(F[rows], names, list(result.stations))
    return disc


def _row_model(result: Any, s: int, rows: np.ndarray, nest: np.ndarray | None) -> Any:
    """Station ``s``'s model measuring its ``rows`` at their reflector nests (``nest``: every row's, or None)."""
    model = result.station_models[s]
    return model if nest is None else model.at_nests(nest[rows])


def joint_jacobian(result: Any, Q: np.ndarray, nest: np.ndarray | None = None) -> np.ndarray:
    """∂y/∂q of a fit's predictions at its rows (at their nests ``nest``, or the reflector), rotated into the robot
    base frame, (n, 3, d) m/rad."""
    out = np.zeros((len(Q), 3, result.model.robot.nq))
    for s, rows in enumerate(result.station_rows):
        model, p = _row_model(result, s, rows, nest), result.station_p[s]
        out[rows] = np.einsum("ba,mbj->maj", model.tracker_pose(p).rotation, model.prediction_dq(p, Q[rows]))
    return out


def parameter_jacobian(result: Any, Q: np.ndarray, nest: np.ndarray | None = None) -> tuple[np.ndarray, list[str]]:
    """Jacobian of a fit's predictions at its rows w.r.t. its robot parameters and every station's set-up,
    rotated into the robot base frame: ((n, 3, R + 9 S), the R robot parameters' names).

    The robot parameters are the estimated joint-placement errors of the fit (its identifiable set); each
    station adds its tracker pose (6) and reflector (3) columns, zero on the other stations' rows. ``nest``: the
    reflector nest of every row (:mod:`~pin_kpi_oed.model.nests`), or None.
    """
    robot = result.model.robot
    L0 = result.station_models[0].layout
    robot_names = [n for n in result.names if n in set(L0.names[:6 * robot.nq])]
    S = len(result.stations)
    F = np.zeros((len(Q), 3, len(robot_names) + 9 * S))
    for s, rows in enumerate(result.station_rows):
        model, p = _row_model(result, s, rows, nest), result.station_p[s]
        L = model.layout
        cols = [L.names.index(n) for n in robot_names]
        setup = list(range(L.tracker.start, L.tracker.stop)) + list(range(L.reflector.start, L.reflector.stop))
        Jb = model.base_jacobian(p, Q[rows])
        F[rows, :, :len(robot_names)] = Jb[:, :, cols]
        F[rows, :, len(robot_names) + 9 * s: len(robot_names) + 9 * (s + 1)] = Jb[:, :, setup]
    return F, robot_names
