"""What the scene draws of the robot: Pinocchio geometry models of its URDF visuals, its capsules,
a stick figure (when the URDF has neither) and the reflector on its tool; the capsules' meshes."""

from __future__ import annotations

import functools
import re
import warnings
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin

from pin_kpi_oed.cell.cell import CapsuleSpec
from pin_kpi_oed.cell.meshes import build_geometry, package_dirs
from pin_kpi_oed.errors import RobotLoadError
from pin_kpi_oed.model.robot import Robot
from pin_kpi_oed.model.urdf_joints import locked_posture, model_from_urdf_text
from pin_kpi_oed.viz.recorder import import_meshcat
from pin_kpi_oed.viz.style import CAPSULE_RGBA, ROBOT_RGBA


def slug(name: str) -> str:
    """A scene-path-safe version of a name (``A on C_p`` -> ``A_on_C_p``)."""
    s = re.sub(r"[^A-Za-z0-9_.-]+", "_", str(name)).strip("_")
    return s or "design"


def visual_model(robot: Robot) -> tuple[pin.Model, pin.GeometryModel | None, list[str]]:
    """Pinocchio model of the serial chain (as the robot's) and its URDF visual geometry.

    The visual meshes are loaded once per process (:func:`~pin_kpi_oed.cell.meshes.build_geometry`); the model and
    the geometry model are new on every call (a scene adds its reflector to them and colours them).

    Args:
        robot: the robot (its URDF file and locked joints).

    Returns:
        (model, visual geometry or None when the URDF has none or its meshes are missing, notes).

    Raises:
        RobotLoadError: the reduced visual model does not have the robot's joints.
    """
    notes: list[str] = []
    full = model_from_urdf_text(Path(robot.urdf_path).read_text())[0]  # continuous joints revolute, as the robot's
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            visual = build_geometry(full, robot.urdf_path, pin.GeometryType.VISUAL, package_dirs(robot.urdf_path))
    except Exception as exc:  # missing mesh files etc.
        notes.append(f"URDF visuals not loaded ({str(exc).strip().splitlines()[0][:120] if str(exc).strip() else exc}):"
                     " drawing primitives")
        visual = None
    if visual is not None and len(visual.geometryObjects) == 0:
        notes.append("the URDF has no visual geometry: drawing primitives")
        visual = None
    locked = [full.getJointId(n) for n in robot.locked_joints]
    if locked:
        if visual is not None:
            model, visual = pin.buildReducedModel(full, visual, locked, locked_posture(full))
        else:
            model = pin.buildReducedModel(full, locked, locked_posture(full))
    else:
        model = full
    if model.nq != robot.nq:
        raise RobotLoadError(f"{robot.urdf_path}: visual model has {model.nq} joints, the robot {robot.nq}")
    return model, visual, notes


def capsule_geometry(model: pin.Model, capsules: Sequence[CapsuleSpec], prefix: str = "capsule") -> pin.GeometryModel:
    """Robot capsules attached to their link frames, as a Pinocchio geometry model."""
    import coal

    gm = pin.GeometryModel()
    for i, c in enumerate(capsules):
        fid = model.getFrameId(c.link, pin.FrameType.BODY)  # a fixed joint may share the link's name
        fr = model.frames[fid]
        d = c.b - c.a
        L = float(np.linalg.norm(d))
        R = pin.Quaternion.FromTwoVectors(np.array([0.0, 0.0, 1.0]), d / L).toRotationMatrix() if L > 1e-12 \
            else np.eye(3)
        local = pin.SE3(R, 0.5 * (c.a + c.b))
        go = pin.GeometryObject(f"{prefix}_{i}_{slug(c.name)}", int(fr.parentJoint), int(fid), fr.placement * local,
                                coal.Capsule(float(c.radius), max(L, 1e-6)))
        go.meshColor = CAPSULE_RGBA.copy()
        gm.addGeometryObject(go)
    return gm


def stick_geometry(model: pin.Model, tool_frame_id: int, reach: float) -> pin.GeometryModel:
    """A stick figure: a cylinder from each joint to the next (and to the tool frame)."""
    import coal

    gm = pin.GeometryModel()
    r = max(0.02, 0.03 * reach)
    ends = [(j, model.jointPlacements[j].translation, model.parents[j]) for j in range(2, model.njoints)]
    tf = model.frames[tool_frame_id]
    ends.append((None, tf.placement.translation, tf.parentJoint))
    for k, (_, t, parent) in enumerate(ends):
        L = float(np.linalg.norm(t))
        if L < 1e-6:
            continue
        R = pin.Quaternion.FromTwoVectors(np.array([0.0, 0.0, 1.0]), t / L).toRotationMatrix()
        go = pin.GeometryObject(f"stick_{k}", int(parent), pin.SE3(R, 0.5 * t), coal.Cylinder(r, L))
        go.meshColor = ROBOT_RGBA.copy()
        gm.addGeometryObject(go)
    return gm


def add_reflector(model: pin.Model, visual: pin.GeometryModel, robot: Robot, reflector_m: np.ndarray) -> None:
    """The reflector (a small silver sphere at ``reflector_m`` in the tool frame), part of the robot's visuals."""
    import coal

    tf = model.frames[robot.tool_frame_id]
    at = pin.SE3(np.eye(3), tf.placement.act(reflector_m))
    go = pin.GeometryObject("reflector", int(tf.parentJoint), at, coal.Sphere(max(0.012, 0.008 * robot.reach())))
    go.meshColor = np.array([0.85, 0.85, 0.9, 1.0])
    visual.addGeometryObject(go)


def is_primitive(visual: pin.GeometryModel) -> bool:
    """Whether every visual is a Coal primitive (cheap to draw many times), no mesh."""
    import coal

    return all(isinstance(g.geometry, coal.ShapeBase) and not str(g.meshPath).lower().endswith((".dae", ".stl", ".obj"))
               for g in visual.geometryObjects)


@functools.lru_cache(maxsize=64)
def _capsule_arrays(length: float, radius: float) -> tuple[np.ndarray, np.ndarray]:
    """The vertices and triangles of Pinocchio's ``createCapsule(length, radius)`` mesh as meshcat stores them
    (float32, uint32), read-only: its Python loops take about 7 ms a capsule, and a scene draws the robot's capsules
    once per pose it shows."""
    from pinocchio.visualize.meshcat_visualizer import createCapsule

    mesh = createCapsule(length, radius)
    V, F = np.array(mesh.vertices), np.array(mesh.faces)
    V.flags.writeable = F.flags.writeable = False
    return V, F


def capsule_mesh(length: float, radius: float) -> Any:
    """Pinocchio's capsule mesh (``createCapsule``) as a new meshcat geometry, its arrays made once per size.

    Args:
        length: the length of the capsule's segment (m); radius: its radius (m).

    Returns:
        A ``meshcat.geometry.TriangularMeshGeometry`` of its own (its own uuid), sharing the read-only arrays.
    """
    import meshcat.geometry as mg

    return mg.TriangularMeshGeometry(*_capsule_arrays(float(length), float(radius)))


@functools.lru_cache(maxsize=1)
def meshcat_visualizer() -> type:
    """Pinocchio's ``MeshcatVisualizer`` drawing Coal capsules with :func:`capsule_mesh` (Pinocchio's mesh, made
    once per size: a scene's ghosts draw every capsule of the robot once per pose), every other geometry as
    Pinocchio draws it.

    Returns:
        The visualiser class (a subclass of ``pinocchio.visualize.MeshcatVisualizer``).
    """
    import coal

    import_meshcat()  # before Pinocchio's visualiser imports it (pyzmq's DeprecationWarning left unsaid)
    import meshcat.geometry as mg
    from pinocchio.visualize import MeshcatVisualizer

    class CapsuleMeshcatVisualizer(MeshcatVisualizer):
        """``MeshcatVisualizer`` whose capsules are :func:`capsule_mesh`."""

        def loadPrimitive(self, geometry_object: Any) -> Any:  # noqa: N802 - Pinocchio's name
            geom = geometry_object.geometry
            if isinstance(geom, coal.Capsule) and hasattr(mg, "TriangularMeshGeometry"):
                return capsule_mesh(2.0 * geom.halfLength, geom.radius)
            return super().loadPrimitive(geometry_object)

    return CapsuleMeshcatVisualizer
