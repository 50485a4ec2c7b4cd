"""Measurement set-up description: robot + tracker + reflector + noise as plain numbers.

The same dictionary shape is read by ``pin-kpi-oed evaluate`` and written into
design and identification JSON files::

    {"robot": "kr15" | {"urdf_path": ..., "tool_frame": ...},
     "tool_frame": "tool0",                 # optional
     "tracker_T_base": 4x4 (m),             # pose of the robot base in the tracker frame
     "reflector_m": [x, y, z],              # reflector offset in the tool frame (m)
     "nests_m": [[x, y, z], ...],           # optional: the reflector nests (tool frame, m), nest 0 = reflector_m
     "tcp_m": [x, y, z],                    # KPI point in the tool frame (m), default origin
     "noise": {"sigma_xyz_m": [...], "range_a_m": null, "range_b": 0},
     "fixed": ["tracker.*", ...],           # known parameters (optional)
     "prior": {"joint_*.t*": 1e-4}}         # prior sigma per pattern (optional)
"""

from __future__ import annotations

from typing import Any

import numpy as np

from pin_kpi_oed.errors import InputError
from pin_kpi_oed.model.kinematics import se3_from_matrix
from pin_kpi_oed.model.nests import check_nests
from pin_kpi_oed.model.noise import NoiseModel
from pin_kpi_oed.model.robot import load_robot
from pin_kpi_oed.model.tracker import TrackerModel

__all__ = ["model_from_dict", "model_to_dict", "se3_from_matrix"]


def _vec(d: dict, key: str, n: int, default: Any = None, where: str = "set-up") -> np.ndarray:
    v = d.get(key, default)
    if v is None:
        raise InputError(f"{where}: missing field '{key}'")
    a = np.asarray(v, dtype=float)
    if a.size != n or not np.all(np.isfinite(a)):
        raise InputError(f"{where}: field '{key}' must be {n} finite numbers, got {v!r}")
    return a.reshape(-1)


def model_from_dict(d: dict, where: str = "set-up") -> TrackerModel:
    """Build a :class:`TrackerModel` from the plain-number description above.

    Raises:
        InputError / RobotLoadError: a missing or invalid field, named.
    """
    rob = d.get("robot")
    if rob is None:
        raise InputError(f"{where}: missing field 'robot'")
    if isinstance(rob, dict):
        spec, tool = rob.get("urdf_path") or rob.get("name"), rob.get("tool_frame")
    else:
        spec, tool = rob, None
    tool = d.get("tool_frame", tool)
    robot = load_robot(spec, tool)
    T = se3_from_matrix(d.get("tracker_T_base", np.eye(4)), f"{where}: tracker_T_base")
    noise = NoiseModel.from_dict(d.get("noise", {}))
    model = TrackerModel(robot, tracker_T_base=T, reflector_m=_vec(d, "reflector_m", 3, where=where),
                         tcp_m=_vec(d, "tcp_m", 3, default=[0.0, 0.0, 0.0], where=where), noise=noise,
                         nests_m=check_nests(_vec(d, "reflector_m", 3, where=where), d.get("nests_m"),
                                             f"{where}: nests_m"))
    if d.get("fixed"):
        model.layout.fix(d["fixed"])
    for pat, sig in (d.get("prior") or {}).items():
        model.layout.set_prior(pat, float(sig))
    return model


def model_to_dict(model: TrackerModel) -> dict:
    """Inverse of :func:`model_from_dict` (plain numbers, SI units)."""
    return {
        "robot": {"name": model.robot.name, "urdf_path": model.robot.urdf_path, "tool_frame": model.robot.tool_frame},
        "tracker_T_base": model.tracker_T_base.homogeneous.tolist(),
        "reflector_m": model.reflector_m.tolist(),
        "tcp_m": model.tcp_m.tolist(),
        "noise": model.noise.to_dict(),
        "fixed": [n for n, f in zip(model.layout.names, model.layout.fixed) if f],
        **({"nests_m": model.nests_m.tolist()} if model.n_nests > 1 else {}),
    }
