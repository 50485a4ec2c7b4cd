r"""Accuracy before and after calibration on held-out rows: the numbers ``identify --validate`` computes.

Before: the nominal robot with its set-up (tracker pose, reflector) fitted on the training rows
(``identify(..., setup_only=True)``, the options the calibration used); after: the calibrated model. Both are
scored on the held-out rows by :func:`~pin_kpi_oed.identification.heldout.validate`, or, for another session,
re-registered on some of its rows and scored on the others by
:func:`~pin_kpi_oed.upkeep.transfer.validate_transfer` — the same calls, in the same order, as
``identify --validate`` (``--register-rows`` / ``--register-data``), so every figure equals identify's.

Added to those statistics (:func:`accuracy_figures`), from the same per-row residuals e_i = measured − predicted
(tracker frame, m): the mean + 3σ of the 3-D error, ē + 3·s with s the sample standard deviation of |e_i|; per
axis the mean, RMS and largest |e|; the error against the reach (distance of the reflector from the first joint
axis' origin, in bins) and against each joint's angle (bins), as means per bin.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

__all__ = ["Heldout", "before_after", "accuracy_figures", "fit_options"]


@dataclass
class Heldout:
    """Held-out scores before and after calibration.

    Attributes:
        before, after: the statistics dicts of ``validate`` / ``validate_transfer`` (m; with ``residuals_m``).
        Q: the scored rows' configurations (rad); reach_m: their reflector distance from the base axis origin (m).
        mode: ``split`` (held-out rows of the same set-up) or ``transfer`` (set-up re-registered on other rows).
        registration: what the transfer registration used (``validate_transfer``'s ``registration``), or None.
        coverage: share of the held-out rows inside the training's joint angles (``coverage_summary``).
        model: the calibrated model the scored rows are predicted with: the model itself, or (another session) the
            model with the set-up registered as ``validate_transfer`` registers it (station ``transfer``).
        station: the station of ``model`` the scored rows belong to.
    """

    before: dict
    after: dict
    Q: np.ndarray
    reach_m: np.ndarray
    mode: str = "split"
    registration: dict | None = None
    coverage: dict = field(default_factory=dict)
    model: Any = None
    station: str | None = None


def fit_options(cm: Any) -> tuple[Any, np.ndarray]:
    """(:class:`IdentifyOptions`, nominal reflector (m)) the calibration used, as its model file recorded them
    (``history[-1].options``); the package defaults and the first station's reflector where not recorded."""
    from pin_kpi_oed.identification.identify_options import IdentifyOptions

    step = (cm.history or [{}])[-1]
    o = step.get("options") or {}
    fit = cm.fit or {}
    opts = IdentifyOptions(weights=o.get("weights", "auto"), loss=o.get("loss", fit.get("loss", "linear")),
                           use_orientation=bool(o.get("use_orientation", True)),
                           scale_covariance=bool(o.get("scale_covariance", fit.get("covariance_scaled", False))),
                           max_nfev=o.get("max_nfev"),
                           reflector_per_station=bool(o.get("reflector_per_station", False)))
    refl = step.get("reflector_nominal_m")
    if refl is None:
        refl = next(iter(cm.setups.values())).reflector_m
    return opts, np.asarray(refl, float)


def _reach(cm: Any, Q: np.ndarray) -> np.ndarray:
    """Distance of the reflector (first station) from the origin of the first joint (m), per row."""
    rb = cm.robot
    refl = next(iter(cm.setups.values())).reflector_m
    origin = rb.model.jointPlacements[rb.joint_ids[0]].translation
    out = np.empty(len(Q))
    for i, q in enumerate(Q):
        M = rb.oMtool(q)
        out[i] = np.linalg.norm(M.act(np.asarray(refl, float)) - origin)
    return out


def before_after(cm: Any, train: Any, test: Any, *, register_rows: int | None = None, register_data: Any = None,
                 seed: int = 0) -> Heldout:
    """Score the nominal robot and the calibration on the held-out rows, as ``identify --validate`` does.

    Args:
        cm: the calibrated model.
        train: the training measurements (the nominal robot's set-up is fitted on them).
        test: the held-out measurements.
        register_rows, register_data, seed: re-register the set-up on rows of another session
            (``--register-rows`` / ``--register-data``, ``--seed``).

    Raises:
        InputError: as ``validate`` / ``validate_transfer`` (joints, stations, too few rows).
    """
    from pin_kpi_oed.calibrated.coverage import coverage_summary
    from pin_kpi_oed.identification.heldout import validate
    from pin_kpi_oed.identification.identify import identify
    from pin_kpi_oed.identification.problem import align_data
    from pin_kpi_oed.upkeep.transfer import register_setup, registration_split, validate_transfer
    from pin_kpi_oed.model.tracker import TrackerModel

    opts, refl = fit_options(cm)
    model = TrackerModel(cm.robot, reflector_m=refl, noise=cm.noise)
    before = identify(model, train, opts, setup_only=True, discrepancy="none")
    Q = align_data(cm.robot, test)
    if register_rows is None and register_data is None:
        vb, va = validate(before, test), validate(cm, test)
        return Heldout(vb, va, Q, _reach(cm, Q), "split", None, coverage_summary(cm.robot, train, test), cm,
                       cm.default_station or next(iter(cm.setups)))
    kw = dict(register_rows=register_rows, register_data=register_data, seed=seed)
    vb = validate_transfer(before.calibrated_model(), test, **kw)
    va = validate_transfer(cm, test, **kw)
    Q = Q[np.asarray(va["scored_rows"], int) - 1]
    # the registered model validate_transfer scored with (same rows, same call): for the trust map
    rows = registration_split(len(test), register_rows, seed)[0] if register_data is None else None
    reg = register_setup(cm, test.subset(rows) if rows is not None else register_data, station="transfer").model
    return Heldout(vb, va, Q, _reach(cm, Q), "transfer", va["registration"], coverage_summary(cm.robot, train, test),
                   reg, "transfer")


def _binned(x: np.ndarray, e: np.ndarray, bins: int) -> dict:
    edges = np.linspace(float(x.min()), float(x.max()), bins + 1) if x.size else np.zeros(bins + 1)
    idx = np.clip(np.searchsorted(edges, x, side="right") - 1, 0, bins - 1)
    mean = [float(e[idx == b].mean()) if np.any(idx == b) else None for b in range(bins)]
    count = [int(np.sum(idx == b)) for b in range(bins)]
    return {"edges": edges.tolist(), "mean_m": mean, "n": count}


def accuracy_figures(stats: dict, Q: np.ndarray, reach_m: np.ndarray, joint_names: list[str], bins: int = 8) -> dict:
    """The certificate's accuracy figures of one model on the scored rows (SI, m).

    Args:
        stats: ``validate`` / ``validate_transfer`` statistics (``errors_m``, ``residuals_m``, ...).
        Q: the scored rows' configurations (rad); reach_m: their reach (m).
        joint_names: the robot's joints (for the per-joint bins).
        bins: bins of the reach and joint-angle curves.

    Returns:
        ``n, mean_m, rms_m, median_m, p95_m, max_m`` (as ``stats``), ``mean_3sigma_m``, ``std_m``, ``per_axis``
        (x, y, z: ``mean_m``, ``rms_m``, ``max_abs_m``), ``vs_reach`` and ``per_joint`` (binned means).
    """
    e = np.asarray(stats["errors_m"], float)
    r = np.asarray(stats["residuals_m"], float)
    sd = float(np.std(e, ddof=1)) if e.size > 1 else 0.0
    out = {k: stats[k] for k in ("n", "mean_m", "rms_m", "median_m", "p95_m", "max_m")}
    out.update({"std_m": sd, "mean_3sigma_m": float(e.mean() + 3.0 * sd)})
    out["per_axis"] = {a: {"mean_m": float(r[:, i].mean()), "rms_m": float(np.sqrt(np.mean(r[:, i] ** 2))),
                           "max_abs_m": float(np.abs(r[:, i]).max())} for i, a in enumerate("xyz")}
    out["vs_reach"] = _binned(np.asarray(reach_m, float), e, bins)
    out["per_joint"] = {n: _binned(Q[:, j], e, bins) for j, n in enumerate(joint_names)}
    for k in ("z_rms", "inside_95", "sigma_mean_m", "extrapolation_share", "sigma_scale", "rot_rms_rad"):
        if k in stats:
            out[k] = stats[k]
    return out
