r"""Calibrated URDF export: identified joint placements written back into the URDF.

Pinocchio folds the placements of the fixed joints that precede an actuated joint k
(e.g. ``world_joint`` before the first joint, or any fixed joint between two links)
into its joint placement::

    M_k = F_k · O_k,      F_k = O_{f1} · O_{f2} ⋯ (fixed joints between joint k's parent joint and joint k)

with O_k the ``<origin xyz rpy>`` of joint k in the URDF. The identified placement
M_k' = M_k · exp6(δ_k) is written back as the new origin of joint k, leaving every
fixed joint untouched::

    O_k' = F_k⁻¹ · M_k' = O_k · M_k⁻¹ · M_k'

so the reloaded model has exactly the identified forward kinematics. Rotations are written
as URDF roll-pitch-yaw (``pin.rpy.matrixToRpy``) and every number with 17 significant
digits (``repr``). Before anything is written, the text is reloaded with Pinocchio and its
tool-frame forward kinematics compared with the identified model at seeded random
configurations; the file is written atomically (:func:`pin_kpi_oed.data.atomic.atomic_write_text`)
only if the largest difference is ≤ ``tol_m`` (default 1e-9 m) and ≤ ``tol_m`` rad.
"""

from __future__ import annotations

import os
import re
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path
from collections.abc import Sequence

import numpy as np
import pinocchio as pin

from pin_kpi_oed.errors import InputError, RobotLoadError, SolverError
from pin_kpi_oed.data.atomic import atomic_write_text
from pin_kpi_oed.model.parameters import ParameterLayout
from pin_kpi_oed.model.robot import Robot, frame_id
from pin_kpi_oed.model.urdf_joints import locked_posture, model_from_urdf_text

__all__ = ["ROOT", "FixedFrame", "model_frames", "write_model_urdf", "URDF_LIMITS_NOTE", "calibrated_urdf_text",
           "check_urdf_fk", "write_calibrated_urdf", "export_result_urdf",
           "result_urdf_comment"]

#: What a calibrated URDF cannot carry; written as an XML comment into every exported URDF.
URDF_LIMITS_NOTE = ("This URDF carries the calibrated joint placements (geometry); the tracker pose and reflector "
                    "of each station only as fixed frames when exported with them (identify --urdf-frames). It "
                    "cannot carry the identified effects (joint-angle errors, compliance, thermal, ...): the model "
                    "file (pin-kpi-oed identify --model-out model.json) holds everything, and pin-kpi-oed predict "
                    "and compensate use it.")


def _fmt(v: float) -> str:
    v = float(v)
    return "0" if v == 0.0 else repr(v)


def _parse_origin(joint: ET.Element) -> pin.SE3:
    o = joint.find("origin")
    xyz = np.zeros(3)
    rpy = np.zeros(3)
    if o is not None:
        if o.get("xyz"):
            xyz = np.array([float(s) for s in o.get("xyz").split()])
        if o.get("rpy"):
            rpy = np.array([float(s) for s in o.get("rpy").split()])
    return pin.SE3(pin.rpy.rpyToMatrix(rpy), xyz)


def _absolutise_meshes(root: ET.Element, src_dir: Path, dst_dir: Path) -> None:
    """Relative mesh file names are resolved from the source URDF's folder (the copy lives elsewhere)."""
    if src_dir.resolve() == dst_dir.resolve():
        return
    for mesh in root.iter("mesh"):
        fn = mesh.get("filename")
        if fn and "://" not in fn and not os.path.isabs(fn):
            mesh.set("filename", str((src_dir / fn).resolve()))


#: Parent name of a :class:`FixedFrame` attached to the URDF's root link (the robot base frame).
ROOT = "<root>"


@dataclass(frozen=True)
class FixedFrame:
    """A fixed frame added to the calibrated URDF as a link with a fixed joint.

    Attributes:
        name: link name of the frame (the joint is ``<name>_joint``).
        parent: URDF link it hangs from (:data:`ROOT`: the root link, i.e. the robot base frame).
        placement: its pose in the parent link's frame (m, rad).
    """

    name: str
    parent: str
    placement: pin.SE3


def _safe(label: str) -> str:
    return re.sub(r"[^A-Za-z0-9_]", "_", str(label)) or "station"


def model_frames(cm, tcp_m: np.ndarray | None = None, stations: Sequence[str] | None = None) -> list[FixedFrame]:
    """The set-up frames of a calibrated model as fixed URDF frames (so ROS tools see the whole chain).

    Per station s: ``tracker_<s>`` (the tracker / cell frame, child of the root link, placed at
    tracker_T_base⁻¹) and ``reflector_<s>`` (child of the tool link at the reflector offset, rotated by
    the probe orientation for a 6-D probe); and ``tcp`` (child of the tool link at ``tcp_m``, default
    the model's ``tcp_m``) when it is not the tool frame itself.

    Args:
        cm: a :class:`~pin_kpi_oed.calibrated.model_file.CalibratedModel`.
        tcp_m: TCP point in the tool frame (m).
        stations: the stations to include (default all).

    Returns:
        The frames, in order.
    """
    tool = cm.robot.tool_frame
    out = []
    for lab in (stations if stations is not None else cm.stations):
        st = cm.setups[cm.station(lab)]
        out.append(FixedFrame(f"tracker_{_safe(lab)}", ROOT, pin.SE3(st.tracker_T_base).inverse()))
        R = np.eye(3) if st.probe_R is None else np.asarray(st.probe_R)
        out.append(FixedFrame(f"reflector_{_safe(lab)}", tool, pin.SE3(R, np.asarray(st.reflector_m, float))))
    tcp = np.asarray(cm.tcp_m if tcp_m is None else tcp_m, float).reshape(3)
    if np.any(tcp != 0) or tcp_m is not None:
        out.append(FixedFrame("tcp", tool, pin.SE3(np.eye(3), tcp)))
    return out


def _add_frames(root: ET.Element, frames: Sequence[FixedFrame], path: Path) -> None:
    links = [ln.get("name") for ln in root.findall("link")]
    children = {j.find("child").get("link") for j in root.findall("joint") if j.find("child") is not None}
    roots = [ln for ln in links if ln not in children]
    if len(roots) != 1:
        raise RobotLoadError(f"{path}: cannot add frames, the URDF has {len(roots)} root links")
    taken = set(links) | {j.get("name") for j in root.findall("joint")}
    for fr in frames:
        parent = roots[0] if fr.parent == ROOT else fr.parent
        if parent not in links:
            raise RobotLoadError(f"{path}: cannot hang frame '{fr.name}' from '{parent}': no such link in the URDF")
        if fr.name in taken or f"{fr.name}_joint" in taken:
            raise InputError(f"{path}: frame name '{fr.name}' is already used in the URDF")
        taken |= {fr.name, f"{fr.name}_joint"}
        ET.SubElement(root, "link", name=fr.name)
        j = ET.SubElement(root, "joint", name=f"{fr.name}_joint", type="fixed")
        ET.SubElement(j, "parent", link=parent)
        ET.SubElement(j, "child", link=fr.name)
        M = pin.SE3(fr.placement)
        ET.SubElement(j, "origin", xyz=" ".join(_fmt(v) for v in M.translation),
                      rpy=" ".join(_fmt(v) for v in pin.rpy.matrixToRpy(M.rotation)))
        links.append(fr.name)


def calibrated_urdf_text(robot: Robot, placements: Sequence[pin.SE3], comment: str | None = None,
                         out_dir: str | os.PathLike | None = None, frames: Sequence[FixedFrame] = ()) -> str:
    """URDF text of ``robot`` with the actuated joints' placements replaced.

    Args:
        robot: the robot (its URDF file is the template; its model gives the nominal M_k).
        placements: identified joint placements M_k', one per actuated joint, base to tip
            (e.g. :meth:`TrackerModel.joint_placements`).
        comment: optional text put in an XML comment at the top of the robot element.
        out_dir: folder the file will live in (relative mesh paths are made absolute).
        frames: fixed frames to add (e.g. :func:`model_frames`: tracker / cell frame, reflector, TCP).

    Returns:
        The URDF text.

    Raises:
        RobotLoadError: the URDF cannot be parsed or lacks an actuated joint.
        InputError: wrong number of placements.
    """
    if len(placements) != robot.nq:
        raise InputError(f"expected {robot.nq} joint placements, got {len(placements)}")
    path = Path(robot.urdf_path)
    try:
        parser = ET.XMLParser(target=ET.TreeBuilder(insert_comments=True))
        root = ET.fromstring(robot.read_urdf_text(), parser=parser)
    except (OSError, ET.ParseError) as exc:
        raise RobotLoadError(f"{path}: cannot parse the URDF for export ({exc})") from None
    joints = {j.get("name"): j for j in root.findall("joint")}
    # the template's own placements (a kinematics file may have replaced the robot's): F_k = M_k O_k^-1
    template = (robot.model if robot.kinematics is None
                else _reduced(model_from_urdf_text(robot.read_urdf_text())[0], robot))
    for k, (name, jid) in enumerate(zip(robot.joint_names, robot.joint_ids)):
        el = joints.get(name)
        if el is None:
            raise RobotLoadError(f"{path}: joint '{name}' not found in the URDF")
        O_k = _parse_origin(el)
        M_nom = template.jointPlacements[jid]
        new = O_k * M_nom.inverse() * pin.SE3(placements[k])  # O_k' = F_k^-1 M_k'
        R = new.rotation
        U, _, Vt = np.linalg.svd(R)
        new = pin.SE3(U @ Vt, new.translation)
        rpy = pin.rpy.matrixToRpy(new.rotation)
        o = el.find("origin")
        if o is None:
            o = ET.SubElement(el, "origin")
        o.set("xyz", " ".join(_fmt(v) for v in new.translation))
        o.set("rpy", " ".join(_fmt(v) for v in rpy))
    if frames:
        _add_frames(root, frames, path)
    if out_dir is not None:
        _absolutise_meshes(root, path.parent, Path(out_dir))
    if comment:
        root.insert(0, ET.Comment(" " + comment.replace("--", "- -") + " "))
    return '<?xml version="1.0"?>\n' + ET.tostring(root, encoding="unicode") + "\n"


def _reduced(model: pin.Model, robot: Robot) -> pin.Model:
    if not robot.locked_joints:
        return model
    ids = [model.getJointId(n) for n in robot.locked_joints if model.existJointName(n)]
    return pin.buildReducedModel(model, ids, locked_posture(model)) if ids else model


def check_urdf_fk(text: str, robot: Robot, placements: Sequence[pin.SE3], n: int = 50, seed: int = 0
                  ) -> tuple[float, float]:
    """Largest tool-frame FK difference between a URDF text and ``robot`` with ``placements``.

    Args:
        text: URDF text.
        robot: the reference robot.
        placements: its joint placements to compare against.
        n: number of seeded random configurations (plus the neutral one).
        seed: seed of the configurations.

    Returns:
        (max position difference (m), max rotation difference (rad)).

    Raises:
        RobotLoadError: Pinocchio cannot load the text or the tool frame / joints differ.
    """
    try:
        full = model_from_urdf_text(text)[0]  # the file keeps a continuous joint's type: read as the robot's
    except Exception as exc:  # Pinocchio raises various types with long texts
        raise RobotLoadError(f"the calibrated URDF does not load in Pinocchio ({str(exc).splitlines()[0]})") from None
    new = _reduced(full, robot)
    if not new.existFrame(robot.tool_frame):
        raise RobotLoadError(f"the calibrated URDF lacks the tool frame '{robot.tool_frame}'")
    names = [new.names[j] for j in range(1, new.njoints)]
    if names != list(robot.joint_names):
        raise RobotLoadError(f"the calibrated URDF has joints {names}, expected {robot.joint_names}")
    ref = robot.model.copy()
    for k, j in enumerate(robot.joint_ids):
        ref.jointPlacements[j] = pin.SE3(placements[k])
    d_ref, d_new = ref.createData(), new.createData()
    f_ref, f_new = robot.tool_frame_id, frame_id(new, robot.tool_frame)
    Q = np.vstack([robot.neutral(), robot.random_q(np.random.default_rng(seed), n)])
    dp = dr = 0.0
    for q in Q:
        pin.framesForwardKinematics(ref, d_ref, q)
        pin.framesForwardKinematics(new, d_new, q)
        A, B = d_ref.oMf[f_ref], d_new.oMf[f_new]
        dp = max(dp, float(np.linalg.norm(A.translation - B.translation)))
        dr = max(dr, float(np.linalg.norm(pin.log3(A.rotation.T @ B.rotation))))
    return dp, dr


def write_calibrated_urdf(robot: Robot, placements: Sequence[pin.SE3], path: str | os.PathLike,
                          comment: str | None = None, tol_m: float = 1e-9) -> float:
    """Write the calibrated URDF atomically after checking it reproduces the identified FK.

    Args:
        robot: the robot whose URDF is the template.
        placements: identified joint placements, base to tip.
        path: output file.
        comment: optional XML comment (e.g. tracker pose and reflector).
        tol_m: largest accepted FK difference (m; also used in rad for the orientation).

    Returns:
        The largest tool-frame position difference found (m).

    Raises:
        SolverError: the reloaded URDF differs by more than ``tol_m`` (nothing is written).
        InputError: the output directory does not exist.
    """
    target = Path(path)
    text = calibrated_urdf_text(robot, placements, comment, out_dir=target.parent if str(target.parent) else ".")
    return _write_checked(target, text, robot, placements, tol_m)


def _write_checked(target: Path, text: str, robot: Robot, placements: Sequence[pin.SE3], tol_m: float) -> float:
    """Write ``text`` atomically after checking that it reproduces the identified FK; returns the position gap (m).

    Raises:
        SolverError: the reloaded URDF differs by more than ``tol_m`` (nothing is written).
    """
    dp, dr = check_urdf_fk(text, robot, placements)
    if dp > tol_m or dr > tol_m:
        raise SolverError(f"the calibrated URDF reproduces the identified FK only to {dp:.3g} m / {dr:.3g} rad "
                          f"(> {tol_m:g}); nothing written to {target}")
    atomic_write_text(target, text)
    return dp


def result_urdf_comment(result, source: str | None = None) -> str:
    """XML comment of a calibrated URDF: where it comes from, the first station's set-up, and
    :data:`URDF_LIMITS_NOTE` (what the file cannot carry)."""
    T = np.asarray(result.tracker_T_base)
    stations = list(getattr(result, "stations", []) or [])
    return (f"calibrated by pin_kpi_oed from {source or result.n_measurements} "
            f"({result.n_measurements} measurements{', stations ' + ', '.join(stations) if len(stations) > 1 else ''}"
            f"); tool frame {result.model.robot.tool_frame}; reflector_m "
            f"{np.array2string(np.asarray(result.reflector_m), precision=9)}; tracker_T_base translation "
            f"{np.array2string(T[:3, 3], precision=9)} m{f' (station {stations[0]})' if len(stations) > 1 else ''}. "
            + URDF_LIMITS_NOTE)


def export_result_urdf(result, path: str | os.PathLike, tol_m: float = 1e-9) -> float:
    """Write the calibrated URDF of an :class:`~pin_kpi_oed.identification.identify.IdentificationResult`.

    The tracker pose and reflector offset go into an XML comment (they are not part of the
    robot), with what the URDF cannot carry (:data:`URDF_LIMITS_NOTE`); the model file holds them.

    Returns:
        The largest tool-frame position difference of the check (m).
    """
    model = result.model
    return write_calibrated_urdf(model.robot, model.joint_placements(result.p), path,
                                 comment=result_urdf_comment(result), tol_m=tol_m)


def write_model_urdf(cm, path: str | os.PathLike, frames: bool = True, tcp_m: np.ndarray | None = None,
                     tol_m: float = 1e-9) -> float:
    """Write the calibrated URDF of a model file's :class:`CalibratedModel`, with its set-up frames.

    Args:
        cm: the calibrated model.
        path: output file (written atomically after the FK check).
        frames: add :func:`model_frames` (tracker / cell frame and reflector per station, TCP).
        tcp_m: TCP point in the tool frame (m) for the ``tcp`` frame.
        tol_m: largest accepted FK difference of the check (m, and rad).

    Returns:
        The largest tool-frame position difference of the check (m).

    Raises:
        SolverError: the reloaded URDF does not reproduce the calibrated FK (nothing written).
    """
    rb = cm.robot
    L = ParameterLayout(list(rb.joint_names))
    placements = [rb.model.jointPlacements[j] * pin.exp6(cm.joint_p[L.joint_slice(k)])
                  for k, j in enumerate(rb.joint_ids)]
    target = Path(path)
    comment = ("calibrated by pin_kpi_oed (model file); frames tracker_<station> (tracker / cell frame), "
               "reflector_<station>, tcp are fixed frames of the set-up. " + URDF_LIMITS_NOTE) if frames else None
    text = calibrated_urdf_text(rb, placements, comment, out_dir=target.parent if str(target.parent) else ".",
                                frames=model_frames(cm, tcp_m) if frames else ())
    return _write_checked(target, text, rb, placements, tol_m)
