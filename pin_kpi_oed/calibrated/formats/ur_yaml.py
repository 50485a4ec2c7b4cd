"""A UR robot's kinematics file (``export-model --format ur-yaml``): ``ur_description``'s layout.

The calibrated joint placements M_k · exp6(δ_k) are mapped onto the layout by
:func:`~pin_kpi_oed.model.ur_kinematics.ur_values_of` following the link frames of the robot's nominal
kinematics (its own kinematics file, else the type's default), so the values stay next to
``ur_description``'s and its meshes hang where they belong. The file is read back
(:func:`~pin_kpi_oed.model.robot.load_robot` with the new kinematics) and its tool0 compared with the
calibrated model's at seeded configurations; it is written only within 1e-9 m. Every joint placement
parameter is carried (a rotation about a joint's axis becomes part of that joint's roll / pitch / yaw);
effects, discrepancy, set-ups, TCP and covariance are not
(:func:`~pin_kpi_oed.calibrated.formats.base.lost_parts`).
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from pin_kpi_oed.data.atomic import atomic_write_text
from pin_kpi_oed.errors import InputError, SolverError
from pin_kpi_oed.calibrated.formats.base import (ExportReport, ModelFormat, calibrated_placements,
                                                            lost_parts)

__all__ = ["UrYamlFormat", "ur_kinematics_of", "CHECK_TOL_M"]

#: Largest tool0 difference (m) between the file read back and the calibrated model.
CHECK_TOL_M = 1e-9


def ur_kinematics_of(cm, source: str = ""):
    """The :class:`~pin_kpi_oed.model.ur_kinematics.URKinematics` of a calibrated model's geometry.

    Raises:
        InputError: the robot is not a UR type, or its tool frame cannot be carried.
    """
    from pin_kpi_oed.model.ur_kinematics import UR_JOINTS, UR_TYPES, URKinematics, default_ur_kinematics, ur_values_of

    rb = cm.robot
    key = str(rb.name).lower()
    if key not in UR_TYPES or tuple(rb.joint_names) != UR_JOINTS:
        raise InputError(f"robot '{rb.name}' is not a Universal Robots arm ({', '.join(UR_TYPES)}): the UR "
                         "kinematics layout is for UR arms; write model_format='urdf'")
    reference = rb.kinematics if rb.kinematics is not None else default_ur_kinematics(key)
    V = ur_values_of(rb.model, rb.joint_ids, rb.tool_frame_id, calibrated_placements(cm), reference=reference)
    return URKinematics.from_values(V, source)


def check_ur_kinematics(cm, kin, n: int = 200, seed: int = 0) -> float:
    """Largest tool0 position difference (m) between ``kin`` loaded as the robot and the calibrated model."""
    import pinocchio as pin

    from pin_kpi_oed.model.robot import load_robot

    rb = cm.robot
    back = load_robot(rb.name, rb.tool_frame, kinematics=kin)
    ref = rb.model.copy()
    for j, M in zip(rb.joint_ids, calibrated_placements(cm)):
        ref.jointPlacements[j] = M
    d_ref = ref.createData()
    Q = np.vstack([rb.neutral(), rb.random_q(np.random.default_rng(seed), n)])
    gap = 0.0
    for q in Q:
        pin.framesForwardKinematics(ref, d_ref, q)
        gap = max(gap, float(np.linalg.norm(d_ref.oMf[rb.tool_frame_id].translation - back.oMtool(q).translation)))
    return gap


class UrYamlFormat(ModelFormat):
    """``ur_description``'s ``default_kinematics.yaml`` layout (UR ROS drivers, MoveIt)."""

    name = "ur-yaml"
    suffix = ".yaml"
    description = "UR kinematics file (ur_description default_kinematics.yaml layout) for the UR ROS drivers"

    def write(self, cm, path: str | os.PathLike, *, tcp_m: np.ndarray | None = None, frames: bool = True,
              source: str = "") -> ExportReport:
        target = Path(path)
        kin = ur_kinematics_of(cm, str(target))
        gap = check_ur_kinematics(cm, kin)
        if gap > CHECK_TOL_M:
            raise SolverError(f"the UR kinematics reproduce the calibrated tool0 only to {gap:.3g} m "
                              f"(> {CHECK_TOL_M:g} m); nothing written to {target}")
        nominal = cm.robot.kinematics.hash if cm.robot.kinematics is not None else f"the {cm.robot.name} URDF"
        lost = lost_parts(cm)
        header = [f"{cm.robot.name} kinematics calibrated by pin_kpi_oed{' from ' + source if source else ''}",
                  f"nominal: {nominal}; hash below: SHA-256 of these values (not the controller's checksum)",
                  "not in this file: " + "; ".join(lost)]
        atomic_write_text(target, kin.text(header))
        return ExportReport(str(target), self.name, gap, lost)
