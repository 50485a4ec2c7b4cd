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


#: The capsule mesh's resolution: Pinocchio's ``createCapsule`` defaults (segments around, quarter-circle steps).
CAPSULE_RADIAL, CAPSULE_CAP = 30, 10


@functools.lru_cache(maxsize=1)
def _capsule_parts() -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(cos θ_i, sin θ_i, cos φ_j, sin φ_j, faces) of Pinocchio's capsule mesh: the angles' cosines and sines by
    the same scalar calls as ``createCapsule``, and its triangles (vertex indices as floats, as it builds them)."""
    n0, n1 = CAPSULE_RADIAL, CAPSULE_CAP
    theta = [(np.pi / 2 * i) / n1 for i in range(n1)]
    phi = [(2 * np.pi * j) / n0 for j in range(n0)]
    ct, st = np.array([np.cos(t) for t in theta]), np.array([np.sin(t) for t in theta])
    cp, sp = np.array([np.cos(f) for f in phi]), np.array([np.sin(f) for f in phi])
    stride, last = 2 * n1, n0 * 2 * n1 + 1
    j = np.arange(n0)[:, None]
    jn = (j + 1) % n0
    i = np.arange(n1 - 1)[None, :]
    ends = np.stack([np.hstack([jn * stride + n1, jn * stride, j * stride]),
                     np.hstack([j * stride + n1, jn * stride + n1, j * stride]),
                     np.hstack([j * stride + n1 - 1, jn * stride + n1 - 1, np.full_like(j, last - 1)]),
                     np.hstack([jn * stride + 2 * n1 - 1, j * stride + 2 * n1 - 1, np.full_like(j, last)])], axis=1)
    sides = np.stack([np.stack([jn * stride + i, jn * stride + i + 1, j * stride + i], axis=-1),
                      np.stack([jn * stride + i + 1, j * stride + i + 1, j * stride + i], axis=-1),
                      np.stack([jn * stride + n1 + i + 1, jn * stride + n1 + i, j * stride + n1 + i], axis=-1),
                      np.stack([jn * stride + n1 + i + 1, j * stride + n1 + i, j * stride + n1 + i + 1], axis=-1)],
                     axis=2).reshape(n0, 4 * (n1 - 1), 3)
    faces = np.concatenate([ends, sides], axis=1).reshape(-1, 3).astype(float)
    return ct, st, cp, sp, faces


def capsule_arrays(length: float, radius: float) -> tuple[np.ndarray, np.ndarray]:
    """The vertices and triangles of Pinocchio's capsule mesh (``createCapsule(length, radius)`` of
    ``pinocchio.visualize.meshcat_visualizer``, whose Python loops took 7 ms a capsule), bit for bit, by array
    operations.

    Args:
        length: the length of the capsule's segment (m); radius: its radius (m).

    Returns:
        (vertices (2·30·10 + 2, 3) m, triangles (30·(4·9 + 4), 3) vertex indices as floats).
    """
    ct, st, cp, sp, faces = _capsule_parts()
    h, r = length, radius
    V = np.empty((CAPSULE_RADIAL, 2, CAPSULE_CAP, 3))
    V[:, :, :, 0] = (ct[None, :] * cp[:, None] * r)[:, None, :]
    V[:, :, :, 1] = (ct[None, :] * sp[:, None] * r)[:, None, :]
    V[:, 0, :, 2] = -h / 2 - st * r
    V[:, 1, :, 2] = h / 2 + st * r
    vertices = np.vstack([V.reshape(-1, 3), [[0.0, 0.0, -h / 2 - r], [0.0, 0.0, h / 2 + r]]])
    return vertices, faces.copy()


def capsule_mesh(length: float, radius: float) -> Any:
    """Pinocchio's capsule mesh as a meshcat geometry (:func:`capsule_arrays`).

    Args:
        length: the length of the capsule's segment (m); radius: its radius (m).

    Returns:
        A ``meshcat.geometry.TriangularMeshGeometry``.
    """
    import meshcat.geometry as mg

    return mg.TriangularMeshGeometry(*capsule_arrays(length, radius))


@functools.lru_cache(maxsize=1)
def meshcat_visualizer() -> type:
    """Pinocchio's ``MeshcatVisualizer`` drawing Coal capsules with :func:`capsule_mesh` (the same mesh; a scene's
    ghosts draw every capsule of the robot once per pose), every other geometry as Pinocchio draws it.

    Returns:
        The visualiser class (a subclass of ``pinocchio.visualize.MeshcatVisualizer``).
    """
    import coal
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
