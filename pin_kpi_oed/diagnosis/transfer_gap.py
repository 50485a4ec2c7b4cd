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
  :data:`COVERAGE_TOL_RAD` of a training value on every joint (rad; m on a linear track; wrapped mod 2π
  for a periodic joint only, ``Robot.periodic_joints``), or the
  predicted TCP uncertainty there is a large share of the observed error
  (σ_pred ≥ :data:`PREDICTED_SHARE` × sqrt(RMS² − floor²));
* **unmodelled effect** — the configurations are covered and the model is confident there
  (σ_pred small), yet wrong.

Predicted TCP uncertainty at a validation configuration i: σ_pred,i = sqrt(Σ_a V_ia σ_ia²) (m),
with V_ia = F_ia C F_iaᵀ the weighted prediction variance from the training fit's parameter
covariance C (eq. 19/25 with E = F; in transfer mode the robot and effect parameters only — the
set-up is re-registered) and σ_ia the noise. It is compared with the observed held-out RMS.

For "extrapolation" the report says which extra poses would fix it: per joint, the validation values no
training value covers, as intervals within the joint's limits (the ranges to measure, in the joint's unit: rad,
or m for a track), and the validation rows with the largest σ_pred (their 1-based row numbers in the validation
file). The per-joint train / validation ranges are the smallest arc for a periodic joint (wrapped as the
coverage), the plain min .. max for any other.

Units: SI (m, rad); the text prints mm and µm, joint values in rad (revolute) or m (prismatic).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any
from collections.abc import Sequence

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
    """Predicted standard deviation of the measured point (the reflector, what the held-out rows measure) per row,
    sqrt(Σ_a V_ia σ_ia²) (m), from the weighted variance V (n, 3)."""
    return np.sqrt(np.clip(np.sum(np.asarray(V, float) * np.asarray(S, float) ** 2, axis=1), 0.0, None))


def _f3(x: float) -> str:
    """A length (m) as mm with 3 decimals, "-" when not finite."""
    return "-" if not np.isfinite(x) else f"{x * 1e3:.3f}"


def _rms(e: np.ndarray) -> float:
    return float(np.sqrt(np.mean(e ** 2))) if e.size else float("nan")


@dataclass
class _GapNumbers:
    """The scalar figures of the transfer section (SI units: m; ``overall`` a share of rows)."""

    overall: float
    rms: float
    rms_in: float
    rms_out: float
    train_rms: float
    within: float
    unreg: float
    sp_rms: float
    sp_in: float
    sp_out: float
    excess: float
    floor_m: float
    registered: bool
    track: bool = False


def _coverage(robot: Any, train: MeasurementSet, ho_data: MeasurementSet
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Aligned training / validation configurations (rad / m) and which validation values a training value covers
    (wrapped for a periodic joint only)."""
    from pin_kpi_oed.diagnosis.selection import covered_rows
    from pin_kpi_oed.identification.problem import align_data

    Qt, Qv = align_data(robot, train), align_data(robot, ho_data)
    return Qt, Qv, covered_rows(Qt, Qv, COVERAGE_TOL_RAD, robot.periodic_joints)


def uncovered_intervals(q: np.ndarray, q_train: np.ndarray) -> list[tuple[float, float]]:
    """The uncovered joint values ``q`` (rad, as measured: within the joint's limits, never wrapped) as intervals,
    split where a training value ``q_train`` lies between two of them; [] for none."""
    a = np.sort(np.asarray(q, float).ravel())
    if a.size == 0:
        return []
    t = np.sort(np.asarray(q_train, float).ravel())
    cut = np.flatnonzero(np.searchsorted(t, a[1:]) > np.searchsorted(t, a[:-1], side="right"))
    starts, ends = np.r_[0, cut + 1], np.r_[cut, a.size - 1]
    return [(float(a[i]), float(a[k])) for i, k in zip(starts, ends)]


def _span(q: np.ndarray, periodic: bool) -> tuple[float, float]:
    """The range of joint values ``q``: the smallest arc for a periodic joint, else (min, max); (nan, nan) for none."""
    if periodic:
        return circular_range(q)
    return (float(np.min(q)), float(np.max(q))) if np.size(q) else (float("nan"), float("nan"))


def joint_ranges_of(joint_names: Sequence[str], Qt: np.ndarray, Qv: np.ndarray, cov: np.ndarray,
                  periodic: np.ndarray | None = None, units: Sequence[str] | None = None) -> list[dict]:
    """Per joint: training / validation ranges (the smallest arc, wrapped, for a ``periodic`` joint — None: every
    joint —, else min .. max), coverage and the uncovered validation values (as measured: within the joint's limits),
    as their range and as intervals, in the joint's unit (``units``: ``rad`` / ``m``; None: rad)."""
    per_joint = cov.mean(axis=0)
    per = np.ones(len(joint_names), bool) if periodic is None else np.asarray(periodic, bool)
    joints = []
    for j, n in enumerate(joint_names):
        tlo, thi = _span(Qt[:, j], bool(per[j]))
        vlo, vhi = _span(Qv[:, j], bool(per[j]))
        iv = uncovered_intervals(Qv[~cov[:, j], j], Qt[:, j])
        ulo, uhi = (iv[0][0], iv[-1][1]) if iv else (float("nan"), float("nan"))
        joints.append({"joint": n, "unit": "rad" if units is None else str(units[j]), "periodic": bool(per[j]),
                       "train_min": tlo, "train_max": thi, "validate_min": vlo, "validate_max": vhi,
                       "coverage": float(per_joint[j]), "uncovered_min": ulo, "uncovered_max": uhi,
                       "uncovered_intervals": [list(x) for x in iv], "n_uncovered": int(np.sum(~cov[:, j]))})
    return joints


def _unregistered_rms(result: Any, ho_data: MeasurementSet, Qv: np.ndarray) -> float:
    """Held-out 3-D RMS (m) of the training fit in the training set-up, before any re-registration."""
    from pin_kpi_oed.identification.identify import predict

    Y = predict(result.model, result.p, Qv, aux=ho_data)[:, :3]
    return _rms(np.linalg.norm(ho_data.position_m - Y, axis=1))


def _gap_texts(g: _GapNumbers, final_label: str) -> tuple[str, str, str]:
    """The coverage, predicted-vs-observed and registration sentences of the reason (mm, µm)."""
    um = 1e6

    tol = f"{COVERAGE_TOL_RAD} rad" + (f" ({COVERAGE_TOL_RAD} m on a track)" if g.track else "")
    cov_txt = (f"{100 * g.overall:.0f}% of the validation rows within {tol} of a training value on "
               f"every joint; held-out RMS {_f3(g.rms)} mm (inside the coverage {_f3(g.rms_in)}, outside "
               f"{_f3(g.rms_out)} mm); training RMS {_f3(g.train_rms)} mm")
    model_txt = f" ({final_label})" if final_label else ""
    pred_txt = (f"predicted sigma of the measured point (not the TCP) at the validation configurations{model_txt} "
                f"{g.sp_rms * um:.1f} µm RMS "
                f"(inside {'-' if not np.isfinite(g.sp_in) else f'{g.sp_in * um:.1f}'}, outside "
                f"{'-' if not np.isfinite(g.sp_out) else f'{g.sp_out * um:.1f}'} µm) vs observed {g.rms * um:.1f} µm "
                f"RMS ({g.excess * um:.1f} µm above the noise floor {g.floor_m * um:.1f} µm)")
    reg_txt = (f"; in the training set-up {_f3(g.unreg)} mm before re-registration (the set-up changed too), the "
               f"training session itself is modelled to {_f3(g.within)} mm" if g.registered else "")
    return cov_txt, pred_txt, reg_txt


def gap_poses_to_add(joints: Sequence[dict], use_sp: np.ndarray, ho_rows: np.ndarray, n_rows: int) -> dict:
    """Joint ranges to measure and the validation rows (1-based) with the largest predicted σ (m)."""
    um = 1e6
    worst = np.argsort(-use_sp)[:N_WORST]
    ranges = [{"joint": j["joint"], "unit": j.get("unit", "rad"), "min": j["uncovered_min"], "max": j["uncovered_max"],
               "intervals": j["uncovered_intervals"], "n_rows": j["n_uncovered"]}
              for j in joints if j["n_uncovered"] > 0.05 * n_rows]
    return {"joint_ranges": ranges, "rows": (np.asarray(ho_rows)[worst] + 1).tolist(),
            "rows_sigma_m": use_sp[worst].tolist(),
            "text": ("add training poses covering " + (", ".join(
                f"{r['joint']} " + " and ".join(f"{lo:.2f} .. {hi:.2f}" for lo, hi in r["intervals"][:3])
                + (f" (+{len(r['intervals']) - 3} more)" if len(r["intervals"]) > 3 else "") + f" {r['unit']}"
                for r in ranges) or "the validation angles")
                + f"; or measure first the {len(worst)} validation configurations with the largest predicted "
                  f"sigma ({use_sp[worst[0]] * um:.0f} .. {use_sp[worst[-1]] * um:.0f} µm): rows "
                + ", ".join(str(r) for r in (np.asarray(ho_rows)[worst] + 1)))}


def _classify(g: _GapNumbers, texts: tuple[str, str, str], joints: Sequence[dict], use_sp: np.ndarray,
              ho_rows: np.ndarray, n_rows: int) -> tuple[str, str, dict]:
    """(classification, reason, poses to add) by the rules of the module docstring."""
    cov_txt, pred_txt, reg_txt = texts

    setup_gain = g.registered and g.unreg >= SETUP_GAIN_FACTOR * g.rms
    if setup_gain and g.rms <= SETUP_TRAIN_FACTOR * g.within:
        why = (f"re-registering the set-up removes most of the error ({_f3(g.unreg)} -> {_f3(g.rms)} mm, the training "
               f"session itself is modelled to {_f3(g.within)} mm); {cov_txt}; {pred_txt}")
        return "set-up change", why, {}
    if g.overall < EXTRAPOLATION_COVERAGE or (g.excess > 0 and g.sp_rms >= PREDICTED_SHARE * g.excess):
        what = ("validation configurations mostly outside the training coverage" if g.overall < EXTRAPOLATION_COVERAGE
                else "the parameters are poorly determined at the validation configurations")
        return "extrapolation", f"{what}: {cov_txt}; {pred_txt}{reg_txt}", gap_poses_to_add(joints, use_sp, ho_rows,
                                                                                         n_rows)
    why = (f"validation mostly inside the training coverage and the model is confident there, yet the error is "
           f"above the training fit: {cov_txt}; {pred_txt}{reg_txt}")
    return "unmodelled effect", why, {}


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
        sigma_pred: its predicted σ of the measured point at the held-out rows (n,) m (:func:`predicted_sigma`).
        floor_m: noise floor (3-D RMS, m).
        registered: the set-up was re-registered on rows of the validation session.
        final_R, final_sigma_pred, final_label: the same for the model with the selected effects
            (if any); the classification then uses it.
        within_rms_m: the within-session level (m) the set-up-change rule compares with (default
            the geometric training RMS).

    Returns:
        ``classification``, ``reason``, ``joints`` (per joint: train / validation ranges — wrapped for a periodic
        joint —, coverage, the uncovered validation range, its ``unit``), coverage numbers, RMS inside / outside, the
        predicted σ (RMS, max) vs the observed RMS, ``poses_to_add`` (extrapolation only).
    """
    robot = result.model.robot
    Qt, Qv, cov = _coverage(robot, train, ho_data)
    inside = np.all(cov, axis=1)
    use_R = R if final_R is None else final_R
    use_sp = sigma_pred if final_sigma_pred is None else final_sigma_pred
    e = np.linalg.norm(use_R, axis=1)
    rms = _rms(e)
    train_rms = float(result.rms_m)
    g = _GapNumbers(overall=float(inside.mean()), rms=rms, rms_in=_rms(e[inside]), rms_out=_rms(e[~inside]),
                    train_rms=train_rms, within=train_rms if within_rms_m is None else float(within_rms_m),
                    unreg=_unregistered_rms(result, ho_data, Qv) if registered else float("nan"),
                    sp_rms=_rms(use_sp), sp_in=_rms(use_sp[inside]), sp_out=_rms(use_sp[~inside]),
                    excess=float(np.sqrt(max(rms ** 2 - floor_m ** 2, 0.0))), floor_m=floor_m,
                    registered=bool(registered), track=not bool(np.all(robot.is_revolute)))
    joints = joint_ranges_of(robot.joint_names, Qt, Qv, cov, robot.periodic_joints, robot.joint_units)
    cls, why, poses = _classify(g, _gap_texts(g, final_label), joints, use_sp, ho_rows, len(ho_data))
    return {"classification": cls, "reason": why, "joints": joints, "coverage_tol_rad": COVERAGE_TOL_RAD,
            "coverage_per_joint": [float(c) for c in cov.mean(axis=0)], "coverage_all_joints": g.overall,
            "heldout_rms_m": rms, "heldout_rms_inside_m": g.rms_in, "heldout_rms_outside_m": g.rms_out,
            "heldout_rms_geometric_m": _rms(np.linalg.norm(R, axis=1)), "model": final_label or "geometry",
            "train_rms_m": train_rms, "within_session_rms_m": g.within, "rms_before_registration_m": g.unreg,
            "registered": bool(registered),
            "predicted_sigma_rms_m": g.sp_rms, "predicted_sigma_max_m": float(np.max(use_sp)) if use_sp.size else None,
            "predicted_sigma_inside_m": g.sp_in, "predicted_sigma_outside_m": g.sp_out,
            "noise_floor_m": floor_m, "observed_excess_m": g.excess,
            "poses_to_add": poses}
