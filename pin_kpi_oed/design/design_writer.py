"""The design file a design run writes (``pin-kpi-oed design --json``, :func:`write_design`): the set-up (robot,
tracker, reflector, TCP, noise, prior), the full cell, every design with its configurations (rad), scores (SI:
m², m) and independent check, the certificate, the margins; the sections of the measured poses, the extended model
and the discrepancy when the run had them. :mod:`pin_kpi_oed.design.design_file` reads it back."""

from __future__ import annotations

import os
from dataclasses import asdict
from pathlib import Path
from typing import Any
from collections.abc import Sequence

import numpy as np

from pin_kpi_oed.design.runner import DesignRun

__all__ = ["design_document", "write_design"]


def design_document(run: DesignRun) -> dict:
    """The design file's JSON document of one run (what :func:`write_design` and ``design --json`` write and
    :func:`~pin_kpi_oed.design.design_file.load_design` reads; SI units): the set-up, the cell, every design with
    its C_s (eq. 19; with measured poses their information included), the ``kpi`` design's (else the last one's)
    configurations as the file's ``q_meas``; the margins, measured poses, user pool, "how many more" answer,
    independent checks, certificate, extended model and discrepancy sections when the run has them.

    Args:
        run: the :class:`~pin_kpi_oed.design.runner.DesignRun`.

    Returns:
        The JSON-able dict.
    """
    cell, problem, results, m = run.cell, run.problem, run.results, run.m
    from pin_kpi_oed.model.serialize import model_to_dict
    from pin_kpi_oed.oed.evaluate import score_design

    main = next((r for r in results if r.criterion == "kpi"), results[-1])
    doc = {
        **model_to_dict(problem.model),  # robot, tracker_T_base, reflector_m, tcp_m, noise (as `evaluate` reads them)
        "q_work": cell.q_work.tolist(), "joint_names": list(cell.robot.joint_names),
        "capsules": [c.to_dict() for c in cell.robot_capsules], "obstacles": [o.to_dict() for o in cell.obstacles],
        "half_spaces": [h.to_dict() for h in cell.half_spaces], "cell": cell.to_dict(), "measurements": m,
        "seed": run.seed, "collision_avoidance": run.collision,
        "identifiable": [problem.ident.names[i] for i in problem.base],
        "constraint_rows_per_configuration": problem.coll.info.count(),
        "designs": [{**r.to_dict(),
                     "cov_s_m2": score_design(problem.model, r.q_meas, cell.q_work, problem.ident).cov_s_m2.tolist()}
                    for r in results],
        "q_meas": main.q_meas.tolist(), "q_meas_criterion": main.criterion,
    }
    for d, nd in zip(doc["designs"], run.nests or ()):
        if nd is None:  # poses that do not identify nest 0's parameters: no nest chosen, every pose at nest 0
            d["nest"] = [0] * len(d["q_meas"])
            continue
        d["nest"] = nd.nest.tolist()
        d["nests"] = {"line": nd.line(), "one": asdict(nd.one), "chosen": asdict(nd.chosen), "t": nd.t}
    if run.extended_scores is not None:
        _add_extended(doc, problem, run.extended_scores, run.model_file, run.prior)
    doc["clearance_margin_m"], doc["incidence_margin_deg"] = run.margins
    if run.path_profiles is not None:
        doc["path_profiles"] = run.path_profiles
    if run.given_file:
        _add_given(doc, problem, results, run.given_file)
    if run.pool_file:
        doc["pool_file"] = str(run.pool_file)
    until, certificate = run.until, run.certificate
    if until is not None:
        doc["poses_until"] = {**until.result_dict(), "target_sigma_m": until.target_sigma_m,
                              "n_more": until.n_more, "sigma_now_m": until.sigma_now_m,
                              "sigma_verified_m": until.sigma_verified_m, "q_added": until.Q_added.tolist()}
    if run.true_checks is not None:
        for d, rep in zip(doc["designs"], run.true_checks):
            d["pose_clearance_m"], d["pose_incidence_deg"] = rep.clearance_m.tolist(), rep.incidence_deg.tolist()
    if certificate is not None:
        doc["lower_bound_trace_cs_m2"] = certificate.lower_bound_trace_cs_m2
        doc["certificate"] = certificate.to_dict()
        for d, r in zip(doc["designs"], results):
            d["efficiency"] = certificate.efficiency(r.trace_cs_m2)
    if run.discrepancy_scores is not None:
        from pin_kpi_oed.design.scores import add_discrepancy_section

        add_discrepancy_section(doc, problem, list(run.discrepancy_scores), run.model_sigma_at_work)
    if run.poses_needed is not None:
        doc["poses_needed"] = run.poses_needed.to_dict()
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
                    "prior_file": problem.prior_file}
    for d, r in zip(doc["designs"], results):
        F = problem.model.weighted_jacobian(problem.p0, r.q_meas)[:, :, problem.base].reshape(-1, problem.base.size)
        d["cov_s_m2"] = kpi_covariance(np.vstack([problem.F_given, F]), problem.E, problem.kpi_criterion.prior).tolist()


def write_design(path: str | os.PathLike, run: DesignRun) -> Path:
    """Write the design file of a run (atomically) that ``view``, ``export``, ``evaluate`` and
    :func:`~pin_kpi_oed.design.design_file.load_design` read; ``design --json`` writes through this call.

    Args:
        path: the JSON file to write.
        run: the :class:`~pin_kpi_oed.design.runner.DesignRun` (:func:`~pin_kpi_oed.design.runner.design_run`).

    Returns:
        The path written.

    Raises:
        InputError: the path cannot be written (a folder, no such parent folder, not writable).
    """
    from pin_kpi_oed.data.atomic import atomic_write_json

    atomic_write_json(path, design_document(run))
    return Path(path)
