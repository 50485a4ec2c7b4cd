r"""Is a new session's registration consistent with the calibration, and if not, why?

``register`` re-fits the set-up (tracker pose, reflector) of a calibrated model on a few rows of a new session
with the robot held (:func:`~pin_kpi_oed.upkeep.transfer.register_setup`). Its residuals are judged
(:func:`~pin_kpi_oed.identification.quality.assess_registration`: reduced χ² against ``CHI2_POOR``) against the
level the calibration itself reached, per axis

.. math::  σ_\mathrm{ref}^2 = \max(σ_\mathrm{noise}^2,\; s^2) + σ_δ^2,

where σ_noise is the data's sigma columns or the model's noise, s the calibration's own residual level
(``fit.residual_sigma_m`` of the model file, corrected for the fitted parameters,
:meth:`~pin_kpi_oed.identification.identify_result.IdentificationResult.residual_sigma_m`) and σ_δ the
discrepancy's prior σ (none without one). A model written without the tracker's noise keeps a default noise
far below what the robot fits to; its residual level, not that default, is what a new session of the same robot
is expected to reach. A session that is somewhat worse passes, and the station's σ factor
(:attr:`~pin_kpi_oed.calibrated.model_file.Setup.sigma_scale`) carries it into every prediction.

When the registration is poor, the cause is tested, not guessed (:func:`poor_registration_cause`):

1. **Effects or discrepancy extrapolating.** The same rows are registered again with the robot's geometry only
   (effects and discrepancy dropped). If the geometry alone fits them within the gate or clearly better
   (χ² at most :data:`GEOMETRY_BETTER` of the full model's),
   the model's effects are what fails here: terms fitted in one region of joint space (transmission-error
   harmonics, bending terms) extrapolate outside it. The share of the rows inside the model's joint coverage
   and the joint ranges the calibration did not measure are named, with the fixes: a geometry-only model
   (``effects=[]``, ``--effects none``), a prior on the terms (``transfer_prior_rad``, ``--term-prior``), or
   measuring the missing ranges.
2. **Rows outside the coverage**, the geometry poor as well and the RMS below a gross 10 mm: the ranges to measure.
3. Otherwise: another robot's or another session's data, the joint order, or units.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import Any

import numpy as np

from pin_kpi_oed.data.measurements import MeasurementSet
from pin_kpi_oed.errors import PinKpiOedError
from pin_kpi_oed.calibrated.model_file import CalibratedModel
from pin_kpi_oed.identification.quality import CHI2_POOR, RegistrationQuality, assess_registration

#: A registration RMS beyond this (m) is not a calibration extrapolating outside its coverage (a geometric model's
#: error there stays at the millimetre level): the rows are likely of another robot, in another joint order or unit.
GROSS_RMS_M = 0.01

#: The geometry alone fits the registration rows "better" when its reduced χ² is at most this share of the full
#: model's (its RMS about 13 % lower): the model's terms, not the session, are what the rows cannot fit.
GEOMETRY_BETTER = 0.75

__all__ = ["GEOMETRY_BETTER", "reference_sigma_m", "registration_gates", "poor_registration_cause",
           "training_configurations", "coverage_share", "uncovered_ranges"]


def reference_sigma_m(model: CalibratedModel, data: MeasurementSet | None = None,
                      rows: np.ndarray | None = None) -> np.ndarray:
    """Per-axis σ a new session's registration residuals are compared with (see the module docstring), (m, 3) or (3,) m.

    Args:
        model: the calibrated model.
        data: the registration rows' file (its sigma columns, if any, stand for the noise).
        rows: the rows of ``data`` registered (default all).
    """
    if data is not None and data.sigma_m is not None:
        base = np.asarray(data.sigma_m, float)[rows if rows is not None else slice(None)]
    else:
        base = np.asarray(model.noise.sigma_xyz_m, float)
    var = np.asarray(base, float) ** 2
    level = model.residual_sigma_m
    if level is not None:
        var = np.maximum(var, np.asarray(level, float) ** 2)
    if model.discrepancy is not None:  # the robot's discrepancy is part of what the registration leaves
        var = var + model.discrepancy.prior_sigma_m ** 2
    return np.sqrt(var)


def training_configurations(model: CalibratedModel) -> np.ndarray | None:
    """The configurations (k, n) rad the calibration measured, as far as the model file keeps them, or None."""
    for cov in (getattr(model, "coverage", None), getattr(model.discrepancy, "coverage", None)):
        if cov is not None and getattr(cov, "Z", None) is not None:  # the joint-space coverage measure's rows
            return np.asarray(cov.Z, float)
    if model.discrepancy is not None:
        return np.asarray(model.discrepancy.Z, float)
    return None


def coverage_share(model: CalibratedModel, Q: np.ndarray) -> float | None:
    """Share of the configurations Q (m, n) rad inside the model's joint coverage, or None when it keeps none."""
    cov = getattr(model, "coverage", None)
    if cov is not None and callable(getattr(cov, "covered", None)):
        return float(np.mean(cov.covered(Q)))
    if model.discrepancy is not None:
        return float(np.mean(~model.discrepancy.extrapolation(Q)))
    return None


def uncovered_ranges(model: CalibratedModel, Q: np.ndarray, limit: int = 3) -> list[str]:
    """The joints whose angles in Q (m, n) rad the calibration never measured (no training angle of that joint
    within :data:`~pin_kpi_oed.calibrated.coverage.COVERAGE_TOL_RAD`, wrapped mod 2π for a periodic joint), most
    rows first:
    ``"shoulder_pan_joint -3.06..-1.06 rad (60 of 60 rows)"`` (the uncovered rows' own joint values, within the
    joint's limits), at most ``limit`` of them with at least 5 % of the rows; none when the model keeps no training
    configurations."""
    from pin_kpi_oed.calibrated.coverage import COVERAGE_TOL_RAD, covered_rows

    Z = training_configurations(model)
    Q = np.atleast_2d(np.asarray(Q, float))
    if Z is None or not len(Z) or not len(Q):
        return []
    out_rows = ~covered_rows(Z, Q, COVERAGE_TOL_RAD, model.robot.periodic_joints)
    share = out_rows.mean(axis=0)
    out = []
    for j in np.argsort(-share, kind="stable")[:limit]:
        if share[j] < 0.05:
            continue
        a = Q[out_rows[:, j], j]  # the rows' own values: within the joint's limits
        out.append(f"{model.robot.joint_names[j]} {a.min():.2f}..{a.max():.2f} {model.robot.joint_units[j]} "
                   f"({int(out_rows[:, j].sum())} of {len(Q)} rows)")
    return out


def _geometry_only(model: CalibratedModel) -> CalibratedModel:
    return dataclasses.replace(model, effects=[], thetas=[], discrepancy=None)


def poor_registration_cause(model: CalibratedModel, data: MeasurementSet, label: str, chi2_full: float,
                            sigma_m: np.ndarray, hold_reflector: bool = False, *,
                            register: Callable[..., Any]) -> str:
    """Why the registration of ``data`` (one station's rows) is poor: the tested cause and its fix, one clause.

    Args:
        model: the calibrated model the rows were registered with.
        data: the station's registration rows.
        label: the station label.
        chi2_full: the registration's reduced χ² against ``sigma_m``.
        sigma_m: the reference σ of the rows (:func:`reference_sigma_m`), (m, 3) or (3,) m.
        hold_reflector: the registration held the reflector.
        register: :func:`~pin_kpi_oed.upkeep.transfer.register_setup` (passed in: the registration calls
            this check).

    Returns:
        The cause (see the module docstring), naming the coverage, the extrapolating terms and the fix.
    """
    from pin_kpi_oed.identification.problem import align_data

    Q = align_data(model.robot, data)
    share = coverage_share(model, Q)
    ranges = uncovered_ranges(model, Q)
    inside = ("" if share is None else f"{100 * share:.0f} % of the rows lie inside the model's joint coverage")
    measure = ("measure the missing joint ranges (" + "; ".join(ranges) + ")") if ranges else \
        "measure the missing joint ranges"
    names = sorted({getattr(e, "name", type(e).__name__) for e in model.effects})
    if names or model.discrepancy is not None:
        try:
            geo = register(_geometry_only(model), data, station=label, hold_reflector=hold_reflector, check=False)
        except PinKpiOedError:
            geo = None
        if geo is not None:
            dof = max(3 * len(data) - (6 if hold_reflector else 9), 1)
            sig2 = np.mean(np.broadcast_to(np.asarray(sigma_m, float) ** 2, (len(data), 3)), axis=1)
            chi2_geo = float(np.sum(geo.errors_m ** 2 / sig2) / dof)
            if chi2_geo <= CHI2_POOR or chi2_geo <= GEOMETRY_BETTER * chi2_full:
                parts = names + (["discrepancy"] if model.discrepancy is not None else [])
                verb = "extrapolate" if len(parts) > 1 else "extrapolates"
                what = parts[0] if len(parts) == 1 else ", ".join(parts[:-1]) + " and " + parts[-1]
                return (f"cause: the model's {what} {verb} outside the joint coverage of its "
                        f"calibration ({inside or 'coverage unknown'}): the geometry alone registers these rows at "
                        f"RMS {geo.rms_m * 1e3:.3g} mm ({np.sqrt(chi2_geo):.2g}x the expected level); fix: a "
                        "geometry-only model (diagnose effects=[], or identify without parameter 'effects'), a prior "
                        f"on the terms (diagnose transfer_prior_rad=1e-4), or {measure}")
    rms_m = float(np.sqrt(chi2_full * np.mean(np.asarray(sigma_m, float) ** 2)))
    if share is not None and share < 0.5 and rms_m < GROSS_RMS_M:
        return (f"cause: the rows lie outside the joint coverage of the calibration ({inside}); fix: {measure}, "
                "or calibrate on rows that include this session's configurations")
    return ("likely: another robot's or another session's data, the joint order, or units (m, rad)"
            + (f" ({inside})" if inside else ""))


def registration_gates(res: Any, data: MeasurementSet, model: CalibratedModel, hold_reflector: bool = False, *,
                       register: Callable[..., Any]) -> list[RegistrationQuality]:
    """The registration gate of every station of a :class:`~pin_kpi_oed.upkeep.transfer.RegistrationResult`,
    against the calibration's own level (:func:`reference_sigma_m`), a poor one with its tested cause.

    Args:
        res: the registration result (``stations``, ``rows``, ``errors_m``).
        data: the registration data.
        model: the model registered (before the registration).
        hold_reflector: the registration held the reflector.
        register: :func:`~pin_kpi_oed.upkeep.transfer.register_setup` (for the geometry-only registration of
            a poor station's rows; :func:`register_setup` computes these gates itself, ``.quality``).
    """
    from pin_kpi_oed.identification.problem import align_data

    ref = model.default_station if model.default_station in model.setups else next(iter(model.setups))
    n_unknowns = 6 + (0 if hold_reflector else 3)
    Q = align_data(model.robot, data)  # the robot's joint columns in its order (the file may hold other columns)
    gates = []
    for lab in res.stations:
        rows = res.rows[lab]
        sub = data if rows.size == len(data) else data.subset(rows)
        X = model.predict(Q[rows], sub, station=ref)  # the held robot, the model's reflector
        sigma = reference_sigma_m(model, data, rows)

        def explain(chi2_red: float, sub=sub, lab=lab, sigma=sigma) -> str:
            return poor_registration_cause(model, sub, lab, chi2_red, sigma, hold_reflector, register=register)

        gates.append(assess_registration(lab, X, data.position_m[rows], res.errors_m[rows], sigma, n_unknowns,
                                         explain=explain))
    return gates
