r"""Where a transfer gap lies: coverage of joint space, predicted uncertainty, and the classification.

A calibration validated on another session (another day, the tracker moved) can fail for
three reasons, told apart by numbers the report prints:

* **set-up change** — re-registering the tracker pose and reflector on a few rows of the new
  session removes most of the error (it cuts it by ≥ :data:`SETUP_GAIN_FACTOR` and leaves at most
  :data:`SETUP_TRAIN_FACTOR` × the within-session level: the smaller of the final model's training
  RMS and the K-fold held-out RMS of the term selection, i.e. what the training session itself
  can be modelled to);
* **extrapolation** — the validation configurations lie outside what the training data
  determine: fewer than :data:`EXTRAPOLATION_COVERAGE` of the rows lie within
  :data:`COVERAGE_TOL_RAD` of a training angle on every joint (angles wrapped to [−π, π)), or the
  predicted TCP uncertainty there is a large share of the observed error
  (σ_pred ≥ :data:`PREDICTED_SHARE` × sqrt(RMS² − floor²));
* **unmodelled effect** — the configurations are covered and the model is confident there
  (σ_pred small), yet wrong.

Predicted TCP uncertainty at a validation configuration i: σ_pred,i = sqrt(Σ_a V_ia σ_ia²) (m),
with V_ia = F_ia C F_iaᵀ the weighted prediction variance from the training fit's parameter
covariance C (eq. 19/25 with E = F; in transfer mode the robot and effect parameters only — the
set-up is re-registered) and σ_ia the noise. It is compared with the observed held-out RMS.

For "extrapolation" the report says which extra poses would fix it: per joint, the circular
range of the validation angles no training angle covers (the range to measure), and the
validation rows with the largest σ_pred (their 1-based row numbers in the validation file).

Units: SI (m, rad); the text prints mm and µm.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from pin_kpi_oed.data.measurements import MeasurementSet

__all__ = ["transfer_section", "circular_range", "predicted_sigma", "SETUP_GAIN_FACTOR", "SETUP_TRAIN_FACTOR",
           "EXTRAPOLATION_COVERAGE", "COVERAGE_TOL_RAD", "PREDICTED_SHARE", "N_WORST"]

#: Re-registration must cut the error by this factor ...
SETUP_GAIN_FACTOR = 2.0
#: ... and leave at most this × the training RMS for "set-up change".
SETUP_TRAIN_FACTOR = 1.5
#: "extrapolation" when fewer than this share of the validation rows are covered on every joint.
EXTRAPOLATION_COVERAGE = 0.5
#: Angle tolerance of the coverage (rad).
COVERAGE_TOL_RAD = 0.05
#: "extrapolation" when σ_pred (RMS) ≥ this share of the observed error above the noise floor.
PREDICTED_SHARE = 0.5
#: Number of validation rows with the largest σ_pred named as poses to add.
N_WORST = 10


def wrap(q: np.ndarray) -> np.ndarray:
    """Angles wrapped to [−π, π) (rad)."""
    return np.mod(np.asarray(q, float) + np.pi, 2 * np.pi) - np.pi


def circular_range(q: np.ndarray) -> tuple[float, float]:
    """Smallest arc holding every angle of ``q`` (wrapped as the coverage): (lo, hi) rad, lo in [−π, π).

    ``hi`` may exceed π when the arc crosses ±π (e.g. 3.0 .. 3.4 for angles 3.0 … π and −π … −2.88).

    Returns:
        (lo, hi) (rad); (nan, nan) for no angles.
    """
    a = np.sort(wrap(q).ravel())
    if a.size == 0:
        return float("nan"), float("nan")
    gaps = np.diff(np.concatenate([a, [a[0] + 2 * np.pi]]))
    k = int(np.argmax(gaps))  # the arc starts after the largest gap
    lo = a[(k + 1) % a.size]
    width = 2 * np.pi - gaps[k]
    return float(lo), float(lo + width)


def predicted_sigma(V: np.ndarray, S: np.ndarray) -> np.ndarray:
    """Predicted TCP standard deviation per row, sqrt(Σ_a V_ia σ_ia²) (m), from the weighted variance V (n, 3)."""
    return np.sqrt(np.clip(np.sum(np.asarray(V, float) * np.asarray(S, float) ** 2, axis=1), 0.0, None))


def _rms(e: np.ndarray) -> float:
    return float(np.sqrt(np.mean(e ** 2))) if e.size else float("nan")


def transfer_section(result: Any, train: MeasurementSet, ho_data: MeasurementSet, ho_rows: np.ndarray,
                     R: np.ndarray, sigma_pred: np.ndarray, floor_m: float, registered: bool,
                     final_R: np.ndarray | None = None, final_sigma_pred: np.ndarray | None = None,
                     final_label: str = "", within_rms_m: float | None = None) -> dict:
    """The report's ``transfer`` dict (SI units): ranges, coverage, predicted vs observed, classification.

    Args:
        result: the geometric training fit (:class:`~pin_kpi_oed.identification.identify.IdentificationResult`).
        train: its data; ho_data: the scored validation rows; ho_rows: their 0-based row numbers in
            the validation file.
        R: held-out residuals of the geometric fit (n, 3) m (after the registration if ``registered``).
        sigma_pred: its predicted TCP σ at the held-out rows (n,) m (:func:`predicted_sigma`).
        floor_m: noise floor (3-D RMS, m).
        registered: the set-up was re-registered on rows of the validation session.
        final_R, final_sigma_pred, final_label: the same for the model with the selected effects
            (if any); the classification then uses it.
        within_rms_m: the within-session level (m) the set-up-change rule compares with (default
            the geometric training RMS).

    Returns:
        ``classification``, ``reason``, ``joints`` (per joint: wrapped train / validation ranges,
        coverage, the uncovered validation range), coverage numbers, RMS inside / outside, the
        predicted σ (RMS, max) vs the observed RMS, ``poses_to_add`` (extrapolation only).
    """
    from pin_kpi_oed.diagnosis.selection import covered_rows
    from pin_kpi_oed.identification.identify import predict
    from pin_kpi_oed.identification.problem import align_data

    robot = result.model.robot
    Qt, Qv = align_data(robot, train), align_data(robot, ho_data)
    cov = covered_rows(Qt, Qv, COVERAGE_TOL_RAD)
    per_joint = cov.mean(axis=0)
    inside = np.all(cov, axis=1)
    overall = float(inside.mean())
    use_R = R if final_R is None else final_R
    use_sp = sigma_pred if final_sigma_pred is None else final_sigma_pred
    e = np.linalg.norm(use_R, axis=1)
    rms, rms_in, rms_out = _rms(e), _rms(e[inside]), _rms(e[~inside])
    train_rms = float(result.rms_m)
    within = train_rms if within_rms_m is None else float(within_rms_m)
    unreg = float("nan")
    if registered:
        Y = predict(result.model, result.p, Qv, aux=ho_data)[:, :3]
        unreg = _rms(np.linalg.norm(ho_data.position_m - Y, axis=1))
    joints = []
    for j, n in enumerate(robot.joint_names):
        tlo, thi = circular_range(Qt[:, j])
        vlo, vhi = circular_range(Qv[:, j])
        ulo, uhi = circular_range(Qv[~cov[:, j], j])
        joints.append({"joint": n, "train_min": tlo, "train_max": thi, "validate_min": vlo, "validate_max": vhi,
                       "coverage": float(per_joint[j]), "uncovered_min": ulo, "uncovered_max": uhi,
                       "n_uncovered": int(np.sum(~cov[:, j]))})
    sp_rms = _rms(use_sp)
    sp_in, sp_out = _rms(use_sp[inside]), _rms(use_sp[~inside])
    excess = float(np.sqrt(max(rms ** 2 - floor_m ** 2, 0.0)))
    um, mm = 1e6, 1e3

    def f3(x: float) -> str:
        return "-" if not np.isfinite(x) else f"{x * mm:.3f}"

    cov_txt = (f"{100 * overall:.0f}% of the validation rows within {COVERAGE_TOL_RAD} rad of a training angle on "
               f"every joint; held-out RMS {f3(rms)} mm (inside the coverage {f3(rms_in)}, outside {f3(rms_out)} mm); "
               f"training RMS {f3(train_rms)} mm")
    model_txt = f" ({final_label})" if final_label else ""
    pred_txt = (f"predicted TCP sigma at the validation configurations{model_txt} {sp_rms * um:.1f} µm RMS "
                f"(inside {'-' if not np.isfinite(sp_in) else f'{sp_in * um:.1f}'}, outside "
                f"{'-' if not np.isfinite(sp_out) else f'{sp_out * um:.1f}'} µm) vs observed {rms * um:.1f} µm RMS ({excess * um:.1f} µm above the noise "
                f"floor {floor_m * um:.1f} µm)")
    reg_txt = (f"; in the training set-up {f3(unreg)} mm before re-registration (the set-up changed too), the "
               f"training session itself is modelled to {f3(within)} mm" if registered else "")
    poses: dict = {}
    setup_gain = registered and unreg >= SETUP_GAIN_FACTOR * rms
    if setup_gain and rms <= SETUP_TRAIN_FACTOR * within:
        cls = "set-up change"
        why = (f"re-registering the set-up removes most of the error ({f3(unreg)} -> {f3(rms)} mm, the training "
               f"session itself is modelled to {f3(within)} mm); {cov_txt}; {pred_txt}")
    elif overall < EXTRAPOLATION_COVERAGE or (excess > 0 and sp_rms >= PREDICTED_SHARE * excess):
        cls = "extrapolation"
        what = ("validation configurations mostly outside the training coverage" if overall < EXTRAPOLATION_COVERAGE
                else "the parameters are poorly determined at the validation configurations")
        why = f"{what}: {cov_txt}; {pred_txt}{reg_txt}"
        worst = np.argsort(-use_sp)[:N_WORST]
        ranges = [{"joint": j["joint"], "min": j["uncovered_min"], "max": j["uncovered_max"],
                   "n_rows": j["n_uncovered"]} for j in joints if j["n_uncovered"] > 0.05 * len(ho_data)]
        poses = {"joint_ranges": ranges, "rows": (np.asarray(ho_rows)[worst] + 1).tolist(),
                 "rows_sigma_m": use_sp[worst].tolist(),
                 "text": ("add training poses covering " + (", ".join(
                     f"{r['joint']} {r['min']:.2f} .. {r['max']:.2f} rad" for r in ranges) or "the validation angles")
                     + f"; or measure first the {len(worst)} validation configurations with the largest predicted "
                       f"sigma ({use_sp[worst[0]] * um:.0f} .. {use_sp[worst[-1]] * um:.0f} µm): rows "
                     + ", ".join(str(r) for r in (np.asarray(ho_rows)[worst] + 1)))}
    else:
        cls = "unmodelled effect"
        why = (f"validation mostly inside the training coverage and the model is confident there, yet the error is "
               f"above the training fit: {cov_txt}; {pred_txt}{reg_txt}")
    return {"classification": cls, "reason": why, "joints": joints, "coverage_tol_rad": COVERAGE_TOL_RAD,
            "coverage_per_joint": [float(c) for c in per_joint], "coverage_all_joints": overall,
            "heldout_rms_m": rms, "heldout_rms_inside_m": rms_in, "heldout_rms_outside_m": rms_out,
            "heldout_rms_geometric_m": _rms(np.linalg.norm(R, axis=1)), "model": final_label or "geometry",
            "train_rms_m": train_rms, "within_session_rms_m": within, "rms_before_registration_m": unreg, "registered": bool(registered),
            "predicted_sigma_rms_m": sp_rms, "predicted_sigma_max_m": float(np.max(use_sp)) if use_sp.size else None,
            "predicted_sigma_inside_m": sp_in, "predicted_sigma_outside_m": sp_out,
            "noise_floor_m": floor_m, "observed_excess_m": excess,
            "poses_to_add": poses}
