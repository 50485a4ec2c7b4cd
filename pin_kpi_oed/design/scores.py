"""What a design run scores besides the criteria: the extended model's tr(C_s) and TCP σ (eq. 19 over geometry and
effects, with the prior), the honest TCP σ with the discrepancy (universal kriging, over the working configurations
and the working region) and the discrepancy section of the design file. SI units (m², m)."""

from __future__ import annotations

import math
from typing import Any

import numpy as np


__all__ = ["extended_scores", "discrepancy_scores", "sigma_given", "add_discrepancy_section"]


def extended_scores(problem: Any, results: list, q_work: np.ndarray) -> list[dict] | None:
    """Extended-model scores of every design (``--model``), or None without an extended model.

    C = (FᵀF + Σ₀⁻¹)⁻¹ over geometry + the model file's effects with the chosen prior, C_s = E C Eᵀ
    (eq. 19, extended; :meth:`~pin_kpi_oed.oed.extended.ExtendedModel.covariances`).

    Args:
        problem: the design problem (its ``extended`` model, or None).
        results: the designs (``q_meas``, rad).
        q_work: working configurations (rad).

    Returns:
        Per design {"trace_cs_m2", "tcp_sigma_m" = sqrt((tr(C_s) + held_trace_m2)/t), "cov_s_m2", "held_trace_m2"}
        (m², m, m², m²): the TCP σ as the geometric design states it, with the design's held parameters (the joint
        placements no measurement of the reflector determines, which the extended model holds as well); NaN where
        the design with the prior does not determine the parameters.
    """
    from pin_kpi_oed.errors import IdentifiabilityError

    ext = problem.extended
    if ext is None:
        return None
    t = np.atleast_2d(q_work).shape[0]
    out = []
    for r in results:
        held = float(getattr(r, "held_trace_m2", 0.0) or 0.0)
        try:
            Cs = ext.covariances(r.q_meas, q_work)[1]
            tr = float(np.trace(Cs))
            out.append({"trace_cs_m2": tr, "tcp_sigma_m": math.sqrt((tr + held) / t), "cov_s_m2": Cs.tolist(),
                        "held_trace_m2": held})
        except (IdentifiabilityError, ValueError):
            out.append({"trace_cs_m2": float("nan"), "tcp_sigma_m": float("nan"), "cov_s_m2": None,
                        "held_trace_m2": held})
    return out


def discrepancy_scores(problem: Any, results: list) -> list[dict]:
    """Honest TCP scores of every design with the problem's discrepancy (universal-kriging C_s, base frame).

    Returns:
        Per design {"trace_cs_m2", "tcp_sigma_m" = sqrt((tr(C_s) + held_trace_m2)/t), "cov_s_m2",
        "held_trace_m2"} (m², m, m², m²) at the working configurations W (``trace_cs_m2`` and ``cov_s_m2`` the
        identified part; the TCP σ with the joint-placement parameters held at nominal, the design's
        ``held_trace_m2``) and, with a working region, {"trace_cs_region_m2", "held_trace_region_m2",
        "tcp_sigma_region_m"} over W plus the region's configurations (sqrt((tr(C_s) + held)/(t + k)), the held
        parameters' G Σ_N Gᵀ at the region's configurations included like every TCP σ); ``cov_s_m2`` is the full
        universal-kriging C_s (3t × 3t) rotated to the tracker frame, like the design's own ``cov_s_m2`` (the trace
        is the base frame's); NaN / None where the design does not identify the parameters.
    """
    from pin_kpi_oed.errors import IdentifiabilityError

    crit = problem.gp_criterion(region=False)
    reg = problem.gp_criterion() if problem.region is not None and problem.region.kept else None
    t = problem.cell.q_work.shape[0]
    R = np.kron(np.eye(t), crit.model.tracker_pose(crit.p).rotation)  # base -> tracker frame, per working configuration
    out = []
    for r in results:
        try:
            tr = float(crit.value(r.q_meas))
            C = R @ crit.covariance(r.q_meas) @ R.T
            cov = (0.5 * (C + C.T)).tolist()
        except IdentifiabilityError:
            tr, cov = float("nan"), None
        held = float(getattr(r, "held_trace_m2", 0.0))
        out.append({"trace_cs_m2": tr, "tcp_sigma_m": math.sqrt((tr + held) / t) if tr == tr else float("nan"),
                    "cov_s_m2": cov, "held_trace_m2": held})
        if reg is not None:
            out[-1].update(_region_scores(problem, reg, r.q_meas))
    return out


def _region_scores(problem: Any, reg: Any, Q_meas: np.ndarray) -> dict:
    """The honest scores over the working region (W plus the region's configurations, n of them): the
    universal-kriging tr(C_s) and the held parameters' tr(G Σ_N Gᵀ) there
    (:func:`~pin_kpi_oed.oed.held.design_held`, as every other TCP σ), and the TCP σ sqrt((both)/n), m², m² and m;
    NaN where the design does not identify the parameters."""
    from pin_kpi_oed.errors import IdentifiabilityError
    from pin_kpi_oed.oed.held import design_held

    Q_region = reg.Q_work
    try:
        tr_r = float(reg.value(Q_meas))
        held_r = design_held(problem.model, problem.base, Q_meas, Q_region, p=problem.p0).trace_m2
    except IdentifiabilityError:
        tr_r = held_r = float("nan")
    return {"trace_cs_region_m2": tr_r, "held_trace_region_m2": held_r,
            "tcp_sigma_region_m": math.sqrt((tr_r + held_r) / Q_region.shape[0])}


def sigma_given(problem: Any) -> float:
    """Predicted TCP σ (m) at the working configurations of the measured poses alone, discrepancy and the
    joint-placement parameters held at nominal included (as every design's)."""
    from pin_kpi_oed.errors import IdentifiabilityError
    from pin_kpi_oed.oed.held import design_held

    crit = problem.gp_criterion(region=False)
    try:
        held = (design_held(problem.model, problem.base, problem.Q_given, problem.cell.q_work, p=problem.p0).trace_m2
                if problem.Q_given is not None else 0.0)
        return math.sqrt((crit.value(np.zeros((0, problem.n))) + held) / problem.cell.q_work.shape[0])
    except IdentifiabilityError:
        return float("inf")


def add_discrepancy_section(doc: dict, problem: Any, gp_scores: list[dict], model_sigma: dict | None = None) -> None:
    """Add the discrepancy (source, S, white level, kernel), the model file's own σ at the working configurations
    (``model_sigma``, as predict gives it) and every design's honest scores to the JSON (SI)."""
    from pin_kpi_oed.discrepancy.lever_arm import lever_arm_m, lever_arm_sigma_m

    d = problem.discrepancy_prior()
    arm = lever_arm_m(problem.model.tcp_m, problem.model.reflector_m)
    doc["discrepancy"] = {"source": d.source, "scale_m": d.scale_m.tolist(), "noise": d.noise,
                          "white_sigma_m": (d.scale_m * math.sqrt(d.noise)).tolist(),
                          "delta_sigma_m": d.delta_sigma_m.tolist(),
                          "kernel": None if d.kernel is None else d.kernel.to_dict(),
                          "certificate": "none exists for the discrepancy-aware criteria (kpi_gp, D_gp, ...)",
                          "tcp_from_reflector_m": arm, "lever_arm_sigma_per_rad_m": lever_arm_sigma_m(arm, 1.0),
                          "note": "designs[i].discrepancy: universal-kriging tr(C_s) and TCP sigma at the working "
                                  "configurations, discrepancy included, and its C_s (3t x 3t, m^2) in the tracker "
                                  "frame like designs[i].cov_s_m2 (pin-kpi-oed view draws it); "
                                  "designs[i].trace_cs_m2 / tcp_sigma_m / cov_s_m2: the paper's, tracker noise only; "
                                  "the discrepancy is learnt at the reflector: a flange rotation of s rad per axis "
                                  "adds lever_arm_sigma_per_rad_m * s (3-D RMS, in quadrature) at the TCP, which "
                                  "no sigma here includes"}
    if model_sigma is not None:
        doc["discrepancy"]["model_sigma_at_work"] = model_sigma
    region = problem.region
    doc["working_region"] = None if region is None else {
        **region.to_dict(), "note": "kpi_gp's KPI is tr(C_s) over the working configurations and these; "
                                    "designs[i].discrepancy.tcp_sigma_region_m is "
                                    "sqrt((tr(C_s) + held_trace_region_m2)/(t + kept)) over them, the parameters "
                                    "held at nominal included"}
    for dd, sc in zip(doc["designs"], gp_scores):
        dd["discrepancy"] = sc
