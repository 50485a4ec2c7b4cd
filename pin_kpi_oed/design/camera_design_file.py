"""The design file of a camera design (``design --cell CAMERA_CELL --json``): the tracker design file's layout
(:mod:`pin_kpi_oed.design.design_writer`, read by :func:`~pin_kpi_oed.design.design_file.load_design`) with the
camera as its device.

The file holds the set-up in the tracker file's fields (``tracker_T_base``: the device frame — the board
eye-in-hand, the camera eye-to-hand — and ``reflector_m``: the origin of what rides on the tool), so that
``export`` (which plans the program and cares about the cell alone) reads it like any design file, and says
``"device": "camera"`` with the camera, its board and its view limits in the stored cell (``cell.camera``,
``cell.board``: the cell file's syntax), from which :func:`load_camera_design` rebuilds the camera cell for
``simulate --design`` and ``view``. The design ``kpi`` holds the poses (rad), tr C_s over the identified
parameters, the held part at nominal (m²), the TCP σ (m), its C_s at the working configurations (3t × 3t, m²), the
certificate's efficiency and the independent check. SI units throughout.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from pin_kpi_oed.cell.camera_setup import read_camera_setup
from pin_kpi_oed.cell.cell_model import Cell
from pin_kpi_oed.errors import InputError

__all__ = ["camera_design_document", "is_camera_design", "load_camera_design", "CameraDesignFile", "DEVICE"]

#: the ``device`` field of a camera's design file
DEVICE = "camera"


def camera_design_document(cell: Cell, problem: Any, design: Any, held: Any, seed: int) -> dict:
    """The design file's document of a camera design (module docstring; SI units).

    Args:
        cell: the camera cell; problem: its :class:`~pin_kpi_oed.design.camera_design.CameraDesignProblem`;
        design: the :class:`~pin_kpi_oed.design.camera_design.CameraDesign`; held: the held parameters' share
        (:class:`~pin_kpi_oed.oed.held.HeldShare`) of the design; seed: the pool's seed.

    Returns:
        The JSON-able dict.
    """
    from pin_kpi_oed.model.serialize import model_to_dict
    from pin_kpi_oed.oed.evaluate import score_design

    t = cell.q_work.shape[0]
    score = score_design(problem.model, design.Q, cell.q_work, problem.ident)
    chk, cert = design.check, design.certificate
    entry = {"criterion": "kpi", "label": "KPI (camera)", "q_meas": design.Q.tolist(),
             "trace_cs_m2": design.trace_cs_m2, "held_trace_m2": held.trace_m2,
             "tcp_sigma_m": float(np.sqrt((design.trace_cs_m2 + held.trace_m2) / t)),
             "held": {"names": list(held.names), "contrib_m": np.asarray(held.contrib_m).tolist()},
             "cov_s_m2": score.cov_s_m2.tolist(), "efficiency": design.stated_efficiency, "source": design.source,
             "q_selection": design.Q_selection.tolist(), "selection_trace_cs_m2": design.selection_trace_cs_m2,
             "nit": design.nit, "time_s": design.time_s, "feasible": bool(design.success),
             "check": {"ok": chk.ok.tolist(), "corners_inside": chk.corners_inside.tolist(),
                       "n_corners": int(chk.n_corners), "depth_m": chk.depth_m.tolist(),
                       "angle_deg": chk.angle_deg.tolist(),
                       "ray_clearance_m": [float(x) if np.isfinite(x) else None for x in chk.ray_clearance_m]}}
    return {**model_to_dict(cell.tracker_model()), "device": DEVICE,
            "q_work": cell.q_work.tolist(), "joint_names": list(cell.robot.joint_names),
            "capsules": [c.to_dict() for c in cell.robot_capsules], "obstacles": [o.to_dict() for o in cell.obstacles],
            "half_spaces": [h.to_dict() for h in cell.half_spaces], "cell": cell.to_dict(),
            "measurements": int(design.Q.shape[0]), "seed": int(seed), "collision_avoidance": True,
            "identifiable": [problem.ident.names[i] for i in problem.base],
            "designs": [entry], "q_meas": entry["q_meas"], "q_meas_criterion": "kpi",
            "lower_bound_trace_cs_m2": cert.lower_bound_trace_cs_m2, "certificate": cert.to_dict(),
            "clearance_margin_m": 0.0, "incidence_margin_deg": 0.0}


def _document(source: str | os.PathLike | dict) -> dict:
    if isinstance(source, dict):
        return source
    try:
        with open(source, encoding="utf-8") as f:
            doc = json.load(f)
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise InputError(f"{source}: not a readable design JSON ({exc})") from None
    if not isinstance(doc, dict):
        raise InputError(f"{source}: not a design JSON (expected a mapping)")
    return doc


def is_camera_design(source: str | os.PathLike | dict) -> bool:
    """Whether a design file (or its document) is a camera's (``"device": "camera"``); False for a file that cannot
    be read, which the tracker's reader then names.

    Args:
        source: the file or its parsed document.

    Returns:
        True for a camera's design file.
    """
    try:
        return _document(source).get("device") == DEVICE
    except InputError:
        return False


@dataclass
class CameraDesignFile:
    """A camera design read back.

    Attributes:
        cell: the camera cell the design was made in (camera, board and view limits included).
        Q: the design's poses (m, n) rad; criterion: its name; raw: the file's document.
    """

    cell: Cell
    Q: np.ndarray
    criterion: str
    raw: dict


def load_camera_design(path: str | os.PathLike, criterion: str | None = None) -> CameraDesignFile:
    """Read a camera's design file (module docstring): the tracker design file's checks
    (:func:`~pin_kpi_oed.design.design_file.load_design`), then the camera of its stored cell.

    Args:
        path: the design JSON; criterion: the design (default the file's ``q_meas`` design).

    Returns:
        The :class:`CameraDesignFile`.

    Raises:
        InputError: not a camera's design file, a damaged field (named), no such design.
    """
    from pin_kpi_oed.design.design_file import load_design

    doc = _document(path)
    if doc.get("device") != DEVICE:
        raise InputError(f"{path}: not a camera's design file (no \"device\": \"camera\")")
    df = load_design(doc, compute_missing=False)
    entry = df.design(criterion or df.default_criterion)
    stored = doc.get("cell")
    cell = df.cell
    cell.camera = read_camera_setup(stored if isinstance(stored, dict) else {}, f"{Path(path).name}: cell")
    if cell.camera is None:
        raise InputError(f"{path}: cell.camera: missing field (a camera's design file stores its camera and board)")
    return CameraDesignFile(cell, np.asarray(entry.q_meas, float), entry.criterion, doc)
