"""Held-out validation of an identified model: position (and orientation) errors on data it was not fitted to."""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from pin_kpi_oed.data.measurements import MeasurementSet
from pin_kpi_oed.identification.identify_result import IdentificationResult
from pin_kpi_oed.calibrated.model_file import CalibratedModel
from pin_kpi_oed.identification.problem import align_data, log3

__all__ = ["error_stats", "validate", "format_validation"]


def error_stats(err: np.ndarray) -> dict:
    """n, mean, RMS, median, p95 and max of position error norms (m), plus the norms themselves."""
    err = np.asarray(err, float)
    if err.size == 0:
        return {"n": 0, "mean_m": None, "rms_m": None, "median_m": None, "p95_m": None, "max_m": None,
                "errors_m": err}
    return {"n": int(err.size), "mean_m": float(err.mean()), "rms_m": float(np.sqrt(np.mean(err ** 2))),
            "median_m": float(np.median(err)), "p95_m": float(np.percentile(err, 95)), "max_m": float(err.max()),
            "errors_m": err}


def validate(result: IdentificationResult | CalibratedModel, data: MeasurementSet) -> dict:
    """Position errors of the identified model on held-out measurements (nothing is re-fitted).

    The tracker pose, reflector offset, geometry and effect parameters all come from
    ``result``; rows of a station the result knows use that station's set-up (a data set
    without a station column: the result's only or default station); the effects see
    ``data`` as their auxiliary data (temperature, ...).

    Args:
        result: an identification result, or a calibrated model (e.g. re-registered on another day).
        data: held-out measurements (same robot joints, SI units).

    Returns:
        ``{"n", "mean_m", "rms_m", "median_m", "p95_m", "max_m", "errors_m"}`` (m), plus
        ``"rot_rms_rad"``, ``"rot_max_rad"`` when both the result and the data are 6-D; per row
        ``"residuals_m"`` (measured − predicted, (m, 3)) and ``"sigma_axes_m"`` (its predicted σ per axis).

    Raises:
        InputError: missing joint columns, NaN, degrees or out-of-limit joint values, a station
            the result does not know, or several stations and no station column.
    """
    cm = result if isinstance(result, CalibratedModel) else result.calibrated_model()
    Q = align_data(cm.robot, data)
    want_rot = bool(cm.pose6d and data.rotvec_rad is not None)
    pred = cm.predict_with_sigma(Q, data)
    out = error_stats(np.linalg.norm(data.position_m - pred[0], axis=1))
    out.update(calibration_stats(cm, Q, data, prediction=pred))
    out["residuals_m"], out["sigma_axes_m"] = data.position_m - pred[0], pred[1]
    if want_rot:
        Y = cm.predict(Q, data, orientation=True)
        Rp = Rotation.from_rotvec(Y[:, 3:]).as_matrix()
        Rm = Rotation.from_rotvec(data.rotvec_rad).as_matrix()
        a = np.linalg.norm(log3(Rm @ np.swapaxes(Rp, 1, 2)), axis=1)
        out["rot_rms_rad"] = float(np.sqrt(np.mean(a ** 2)))
        out["rot_max_rad"] = float(a.max())
    return out


def calibration_stats(cm: CalibratedModel, Q: np.ndarray, data: MeasurementSet, station: str | None = None,
                      prediction: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None) -> dict:
    """How honest the model's σ is on measured rows: standardised errors z = (measured − predicted)/σ per axis.

    ``prediction``: the (Y, σ, extrapolation) of :meth:`CalibratedModel.predict_with_sigma` for these rows when
    the caller has it already (not computed again).

    Returns:
        ``z_rms`` (RMS of z over rows and axes; 1 when σ is right), ``inside_95`` (share of rows whose
        Σ z² ≤ χ²₃(0.95) = 7.815: their 95 % ellipsoid holds the measurement), ``sigma_mean_m`` (mean
        predicted 3-D σ = sqrt(Σ σ²), m), ``extrapolation_share`` (rows outside the training coverage).
    """
    Yp, sig, extra = prediction if prediction is not None else cm.predict_with_sigma(Q, data, station=station)
    z2 = ((data.position_m - Yp) / sig) ** 2
    return {"z_rms": float(np.sqrt(z2.mean())), "inside_95": float(np.mean(z2.sum(axis=1) <= 7.8147)),
            "sigma_mean_m": float(np.sqrt((sig ** 2).sum(axis=1)).mean()),
            "extrapolation_share": float(np.mean(extra))}


def format_validation(stats: dict, title: str = "held-out") -> str:
    """One line of validation statistics in mm (``stats`` from :func:`validate`)."""
    s = (f"{title}: n={stats['n']}, mean {stats['mean_m'] * 1e3:.4f} mm, RMS {stats['rms_m'] * 1e3:.4f} mm, "
         f"p95 {stats['p95_m'] * 1e3:.4f} mm, max {stats['max_m'] * 1e3:.4f} mm")
    if "rot_rms_rad" in stats:
        s += f", orientation RMS {stats['rot_rms_rad'] * 1e3:.4f} mrad"
    if "z_rms" in stats:
        s += (f"; predicted σ (3-D) mean {stats['sigma_mean_m'] * 1e3:.4f} mm, standardised error RMS "
              f"{stats['z_rms']:.2f} (1 = honest), {stats['inside_95'] * 100:.0f} % inside the 95 % ellipsoid"
              + (f", {stats['extrapolation_share'] * 100:.0f} % of rows outside the training coverage"
                 if stats.get("extrapolation_share") else ""))
    return s
