"""The design file a design run writes (``pin-kpi-oed design --json``, :func:`write_design`): the set-up (robot,
tracker, reflector, TCP, noise, prior), the full cell, every design with its configurations (rad), scores (SI:
m², m) and independent check, the certificate, the margins; the sections of the measured poses, the extended model
and the discrepancy when the run had them. :mod:`pin_kpi_oed.design.design_file` reads it back."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any
from collections.abc import Sequence

import numpy as np

from pin_kpi_oed.cell.cell import Cell

__all__ = ["design_document", "write_design"]


def design_document(cell: Cell, problem: Any, results: Sequence[Any], m: int, seed: int, collision: bool = True, *,
                    margins: tuple[float, float] = (0.0, 0.0), given_file: str | None = None,
                    pool_file: str | None = None, until: Any = None, true_checks: Sequence[Any] | None = None,
                    certificate: Any = None, extended_scores: Sequence[dict] | None = None,
                    model_file: str | None = None, prior: str | None = None) -> dict:
    """The design file's JSON document (what ``design --json`` writes and :func:`load_design` reads; SI units).

    Args:
        cell: the cell the designs are checked in (the untightened one).
        problem: the :class:`~pin_kpi_oed.design.optimize.DesignProblem` (model, identifiable set, constraints);
            with ``given_file`` a :class:`~pin_kpi_oed.design.sequential.SequentialProblem`.
        results: the designs (:class:`~pin_kpi_oed.design.optimize.DesignResult`); the ``kpi`` one (else the
            last) is the file's ``q_meas``.
        m: measurements per design; seed: the run's seed; collision: collision avoidance was on.
        margins: clearance (m) and incidence (deg) margins the optimiser designed with.
        given_file: the measured poses designed on top of (their C_s included in every design's ``cov_s_m2``).
        pool_file: the user pool the designs were selected from.
        until: the "how many more poses" answer (:func:`~pin_kpi_oed.design.sequential.poses_until`).
        true_checks: the independent check of every design in ``cell`` (pose clearances m, incidences deg).
        certificate: the optimality certificate (bound of tr(C_s), m²; every design's efficiency).
        extended_scores: per design, the extended-model score (``designs[i]["extended"]``); ``model_file``
            and ``prior`` name the model file and the prior they came from.

    Returns:
        The JSON-able dict.
    """
    from pin_kpi_oed.model.serialize import model_to_dict
    from pin_kpi_oed.oed.evaluate import score_design

    main = next((r for r in results if r.criterion == "kpi"), results[-1])
    doc = {
        **model_to_dict(problem.model),  # robot, tracker_T_base, reflector_m, tcp_m, noise (as `evaluate` reads them)
        "q_work": cell.q_work.tolist(), "joint_names": list(cell.robot.joint_names),
        "capsules": [c.to_dict() for c in cell.robot_capsules], "obstacles": [o.to_dict() for o in cell.obstacles],
        "half_spaces": [h.to_dict() for h in cell.half_spaces], "cell": cell.to_dict(), "measurements": m,
        "seed": seed, "collision_avoidance": collision, "identifiable": [problem.ident.names[i] for i in problem.base],
        "constraint_rows_per_configuration": problem.coll.info.count(),
        "designs": [{**r.to_dict(),
                     "cov_s_m2": score_design(problem.model, r.q_meas, cell.q_work, problem.ident).cov_s_m2.tolist()}
                    for r in results],
        "q_meas": main.q_meas.tolist(), "q_meas_criterion": main.criterion,
    }
    if extended_scores is not None:
        _add_extended(doc, problem, extended_scores, model_file, prior)
    doc["clearance_margin_m"], doc["incidence_margin_deg"] = margins
    if given_file:
        _add_given(doc, problem, results, given_file)
    if pool_file:
        doc["pool_file"] = str(pool_file)
    if until is not None:
        doc["poses_until"] = {**until.result_dict(), "target_sigma_m": until.target_sigma_m,
                              "n_more": until.n_more, "sigma_now_m": until.sigma_now_m,
                              "sigma_verified_m": until.sigma_verified_m, "q_added": until.Q_added.tolist()}
    if true_checks is not None:
        for d, rep in zip(doc["designs"], true_checks):
            d["pose_clearance_m"], d["pose_incidence_deg"] = rep.clearance_m.tolist(), rep.incidence_deg.tolist()
    if certificate is not None:
        doc["lower_bound_trace_cs_m2"] = certificate.lower_bound_trace_cs_m2
        doc["certificate"] = certificate.to_dict()
        for d, r in zip(doc["designs"], results):
            d["efficiency"] = certificate.efficiency(r.trace_cs_m2)
    return doc


def _add_extended(doc: dict, problem: Any, scores: Sequence[dict], model_file: str | None, prior: str | None) -> None:
    """``extended_model`` and every ``designs[i]["extended"]`` (``trace_cs_m2`` stays the geometric one)."""
    ext = problem.extended
    doc["extended_model"] = {"file": str(model_file), "prior": prior or "model", "n_geometric": ext.nb,
                             "n_effect": ext.k, "names": list(ext.names),
                             "note": "designs[i].extended: tr(C_s) of the extended model with the prior (the "
                                     "criterion designed for); designs[i].trace_cs_m2: geometric, no prior"}
    for d, e in zip(doc["designs"], scores):
        d["extended"] = e


def _add_given(doc: dict, problem: Any, results: Sequence[Any], given_file: str) -> None:
    """``given`` (the measured poses) and every design's C_s with them (and the prior), m²."""
    from pin_kpi_oed.oed.covariance import kpi_covariance

    doc["given"] = {"file": str(given_file), "q": problem.Q_given.tolist(), "tcp_sigma_m": problem.sigma_tcp(),
                    "prior_file": getattr(problem, "prior_file", None)}
    for d, r in zip(doc["designs"], results):
        F = problem.model.weighted_jacobian(problem.p0, r.q_meas)[:, :, problem.base].reshape(-1, problem.base.size)
        d["cov_s_m2"] = kpi_covariance(np.vstack([problem.F_given, F]), problem.E, problem.kpi_criterion.prior).tolist()


def write_design(path: str | os.PathLike, cell: Cell, problem: Any, results: Sequence[Any], m: int, seed: int,
                 collision: bool = True, **extras: Any) -> Path:
    """Write the design file (atomically) that ``view``, ``export``, ``evaluate`` and :func:`load_design` read.

    Args:
        path: the JSON file to write.
        cell, problem, results, m, seed, collision: as :func:`design_document`.
        **extras: the keyword arguments of :func:`design_document` (margins, given_file, certificate, ...).

    Returns:
        The path written.

    Raises:
        InputError: the path cannot be written (a folder, no such parent folder, not writable).
    """
    from pin_kpi_oed.data.atomic import atomic_write_json

    atomic_write_json(path, design_document(cell, problem, results, m, seed, collision, **extras))
    return Path(path)
