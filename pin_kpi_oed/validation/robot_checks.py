"""Plausibility checks of a URDF before and after Pinocchio reads it (shared by every command).

Before: a joint axis of zero length, a ``<limit>`` with lower > upper, an un-expanded xacro file (xacro elements
or ``${...}`` / ``$(...)`` in attribute values; comments and element text do not count).
After: a robot whose reach is kilometres (a URDF written in mm).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from pin_kpi_oed.errors import InputError, RobotLoadError

__all__ = ["check_urdf_tree", "xacro_construct", "xacro_refusal", "check_robot_scale", "MAX_REACH_M",
           "kinematic_difference", "check_same_robot"]

#: the largest plausible reach of an arm (m); a URDF in mm gives ~1000x its real reach
MAX_REACH_M = 100.0


#: the xacro namespace; an element in it (``<xacro:include>``, ``<xacro:macro>``, ...) is un-expanded xacro
XACRO_NS = "http://www.ros.org/wiki/xacro"


def xacro_construct(root: Any) -> str | None:
    """The first un-expanded xacro construct of a parsed URDF, in words, or None for plain URDF.

    Only what xacro itself would expand counts: an element in the xacro namespace, or an attribute value
    with a property ``${...}`` or a substitution ``$(...)``. XML comments (which the parser drops) and element
    text are never expanded by xacro, so a ``${prefix}`` or ``<xacro:...>`` left in a comment of a file that
    xacro generated, or the ``xmlns:xacro`` declaration it keeps, does not make the file a xacro file.

    Args:
        root: the ``xml.etree`` root element.

    Returns:
        e.g. ``"element <xacro:include>"`` or ``"joint 'j1': origin rpy='${pi/2} 0 0'"``, or None.
    """
    for el in root.iter():
        tag = el.tag if isinstance(el.tag, str) else ""
        if tag.startswith("{" + XACRO_NS + "}"):
            return f"element <xacro:{tag.split('}', 1)[1]}>"
        for key, val in el.attrib.items():
            if "${" in val or "$(" in val:
                return f"<{tag}> {key}='{val}'"
    return None


def xacro_refusal(path: Any, what: str) -> RobotLoadError:
    """The one refusal of an un-expanded xacro file: the file, what was found and the command that expands it."""
    return RobotLoadError(f"{path}: a xacro file, not plain URDF ({what}): expand it first "
                          f"('xacro {path} > robot.urdf') and pass the .urdf")


def check_urdf_tree(root: Any, path: Any, text: str = "") -> None:
    """Check the parsed URDF XML (``xml.etree`` root) of ``path``.

    Args:
        root: the parsed XML (comments dropped by the parser).
        path: the file, for messages.
        text: the file's text (unused; kept for callers that pass it).

    Raises:
        RobotLoadError: naming the file, the joint and the value: a xacro file (:func:`xacro_construct`),
            a zero joint axis, reversed limits.
    """
    found = xacro_construct(root)
    if found is not None:
        raise xacro_refusal(path, found)
    for j in root.iter("joint"):
        name, kind = j.get("name", "?"), j.get("type", "")
        if kind not in ("revolute", "continuous", "prismatic"):
            continue
        ax = j.find("axis")
        if ax is not None and ax.get("xyz") is not None:
            try:
                v = np.array([float(x) for x in ax.get("xyz").split()], float)
            except ValueError:
                raise RobotLoadError(f"{path}: joint '{name}': axis xyz='{ax.get('xyz')}' is not 3 numbers") from None
            if v.size != 3 or not np.all(np.isfinite(v)) or np.linalg.norm(v) < 1e-12:
                raise RobotLoadError(f"{path}: joint '{name}': axis xyz='{ax.get('xyz')}' has zero length (or is not "
                                     "3 finite numbers); give the unit direction of the joint axis")
        lim = j.find("limit")
        if lim is not None and kind != "continuous" and lim.get("lower") is not None and lim.get("upper") is not None:
            try:
                lo, hi = float(lim.get("lower")), float(lim.get("upper"))
            except ValueError:
                raise RobotLoadError(f"{path}: joint '{name}': limit lower/upper are not numbers") from None
            if lo > hi:
                unit = "m" if kind == "prismatic" else "rad"
                raise RobotLoadError(f"{path}: joint '{name}': limit lower={lo:g} > upper={hi:g} {unit} (reversed)")


def check_robot_scale(reach_m: float, path: Any) -> None:
    """Refuse a robot whose reach (m) is implausible for an arm (a URDF in mm).

    Raises:
        RobotLoadError: naming the file and the reach.
    """
    if not math.isfinite(reach_m) or reach_m > MAX_REACH_M:
        raise RobotLoadError(f"{path}: the robot reaches {reach_m:.4g} m, more than {MAX_REACH_M:g} m: the URDF looks "
                             "like mm (URDF lengths are in m)")


class captured_stderr:
    """Capture what C/C++ code writes to file descriptor 2 (urdfdom's parser) instead of printing it.

    Usage: ``with captured_stderr() as cap: ...``; then ``cap.text`` holds the captured text and
    ``cap.first_line()`` its first meaningful line (e.g. urdfdom's reason for a refusal).
    """

    def __enter__(self) -> captured_stderr:
        import os
        import sys

        self.text = ""
        try:
            sys.stderr.flush()
            self._fd = sys.stderr.fileno() if hasattr(sys.stderr, "fileno") else 2
        except (OSError, ValueError, AttributeError):
            self._fd = 2
        memfd = getattr(os, "memfd_create", None)  # Linux: an anonymous file without loading tempfile
        if memfd is not None:
            self._tmp = os.fdopen(memfd("captured_stderr"), "w+b")
        else:  # pragma: no cover - other systems
            import tempfile

            self._tmp = tempfile.TemporaryFile()
        try:
            self._saved = os.dup(2)
            os.dup2(self._tmp.fileno(), 2)
        except OSError:  # pragma: no cover - no fd 2
            self._saved = None
        return self

    def __exit__(self, *exc: Any) -> None:
        import os

        if self._saved is not None:
            os.dup2(self._saved, 2)
            os.close(self._saved)
        self._tmp.seek(0)
        self.text = self._tmp.read().decode(errors="replace")
        self._tmp.close()

    def first_line(self) -> str:
        """The first non-empty captured line without urdfdom's ``Error:`` prefix ('' when none)."""
        for ln in self.text.splitlines():
            ln = ln.strip()
            if ln:
                return ln.removeprefix("Error:").strip()
        return ""


#: accepted ratio of the measured points' spread to the spread the joint values give (reflector offsets and
#: real errors move it by far less than a unit mistake: 10 (cm), 25.4 (in), 1000 (mm / m), 57.3 (deg / rad))
SPREAD_RATIO = 3.0


def _spread_ratio(robot: Any, Q: np.ndarray, P: np.ndarray) -> float:
    """Median pairwise distance of the points over that of the tool-frame origins the joint values give
    (independent of the unknown tracker pose)."""
    import pinocchio as pin

    k = min(len(Q), 120)
    idx = np.linspace(0, len(Q) - 1, k).round().astype(int)
    T = np.empty((k, 3))
    for r, i in enumerate(idx):
        pin.framesForwardKinematics(robot.model, robot.data, np.asarray(Q[i], float))
        T[r] = robot.data.oMf[robot.tool_frame_id].translation
    a, b = np.triu_indices(k, 1)
    dT, dP = np.linalg.norm(T[a] - T[b], axis=1), np.linalg.norm(P[idx][a] - P[idx][b], axis=1)
    ok = dT > 0.02 * max(float(dT.max(initial=0.0)), 1e-12)
    if ok.sum() < 1:
        return float("nan")
    return float(np.median(dP[ok]) / np.median(dT[ok]))


def check_points_against_joints(robot: Any, Q: np.ndarray, P: np.ndarray, points: str, joints: str,
                                length_unit: str = "m", angle_unit: str = "rad", angle_scale: float = 1.0,
                                options: str = "tracker") -> float:
    """Do measured positions and joint values agree in scale? (units of a tracker export and a joint log)

    The distances between measured points do not depend on where the tracker stands; the distances
    between the tool-frame origins the joint values give (nominal kinematics) differ from them only by
    the reflector offset and the robot's errors. A median ratio beyond :data:`SPREAD_RATIO` either way
    is a unit mistake: the points' length unit, or the joint log's angle unit (tried: the other one).

    Args:
        robot: the robot.
        Q: joint values as read (rad / m), (m, n).
        P: measured positions as read (m), (m, 3).
        points, joints: the files, for messages.
        length_unit: the unit the points were read in; angle_unit: the joint log's (``deg`` / ``rad``).
        angle_scale: the factor that converted the joint log's revolute values to rad.
        options: the unit parameters the advice names: ``tracker`` (a tracker export and its joint log:
            ``angle_unit``, a 'Units:' comment or ``units``) or ``table`` (a measurement CSV: ``units``, e.g.
            ``mm,deg``); the command line says its options (``--angle-unit``, ``--units``).

    Returns:
        The ratio (about 1).

    Raises:
        InputError: naming both files, the ratio and the likely unit mistake.
    """

    Q, P = np.atleast_2d(np.asarray(Q, float)), np.atleast_2d(np.asarray(P, float))
    if len(Q) < 5:  # too few points for a scale (a handful of pairs)
        return float("nan")
    ratio = _spread_ratio(robot, Q, P)
    if not np.isfinite(ratio) or 1 / SPREAD_RATIO <= ratio <= SPREAD_RATIO:
        return ratio
    rev = np.asarray(robot.is_revolute, bool)
    other = "rad" if angle_unit == "deg" else "deg"
    Q2 = Q.copy()
    f = (math.pi / 180.0) if other == "deg" else 1.0
    Q2[:, rev] = Q[:, rev] / angle_scale * f
    ratio2 = _spread_ratio(robot, Q2, P) if np.all(np.isfinite(Q2)) else float("nan")
    head = (f"{points} ({length_unit}) and {joints} ({angle_unit}): the measured points spread {ratio:.3g}x as far as "
            f"the joint values move the tool ({robot.name}, reach {robot.reach():.2f} m)")
    table = options == "table"
    if np.isfinite(ratio2) and 1 / SPREAD_RATIO <= ratio2 <= SPREAD_RATIO:
        fix = (f"give units='{other}'" if other == "deg" else "give the joints in rad (drop deg from parameter "
               "'units')") if table else f"give angle_unit='{other}'"
        raise InputError(f"{head}: the joint {'values look' if table else 'log looks'} like {other}, not {angle_unit}; "
                         f"{fix}")
    units = {"m": 1.0, "cm": 1e-2, "mm": 1e-3, "in": 0.0254, "um": 1e-6}
    here = units.get(length_unit, 1.0)
    true = min(units, key=lambda u: abs(math.log(ratio * units[u] / here)) if ratio > 0 else 0.0)
    declare = f"units='{true}'" if table else f"a 'Units: {true}' comment or units='{true}'"
    hint = (f"the points look like {true}, not {length_unit} (declare it with {declare})"
            if abs(math.log(ratio * units[true] / here)) < math.log(SPREAD_RATIO) and true != length_unit
            else ("check the length and angle units of the file (parameter 'units', e.g. mm,deg)" if table else
                  "check the length unit of the points ('Units:' comment, parameter 'units') and the joint log's "
                  "angle unit (parameter 'angle_unit')"))
    raise InputError(f"{head}; {hint}")


#: a calibration corrects joint placements by millimetres and milliradians; a difference beyond these is another arm
SAME_ROBOT_TOL_M, SAME_ROBOT_TOL_RAD = 0.02, 0.05


def kinematic_difference(a: Any, b: Any) -> str | None:
    """How the kinematic structure of two robots differs (joint names, types, axes, placements), None when the same.

    Args:
        a, b: robots (``model.robot.Robot``: a Pinocchio ``model``, ``joint_ids``, ``joint_names``).

    Returns:
        The first difference in words (joint and values in m / rad), or None. Joint placements within
        :data:`SAME_ROBOT_TOL_M` / :data:`SAME_ROBOT_TOL_RAD` are the same arm (what a calibration changes).
    """
    if list(a.joint_names) != list(b.joint_names):
        return f"joints {list(a.joint_names)} against {list(b.joint_names)}"
    for name, ja, jb in zip(a.joint_names, a.joint_ids, b.joint_ids):
        if a.model.joints[ja].shortname() != b.model.joints[jb].shortname():
            return f"joint {name} is {a.model.joints[ja].shortname()} against {b.model.joints[jb].shortname()}"
        Ma, Mb = a.model.jointPlacements[ja], b.model.jointPlacements[jb]
        dt = float(np.linalg.norm(Ma.translation - Mb.translation))
        if dt > SAME_ROBOT_TOL_M:
            return (f"joint {name} sits {dt * 1e3:.0f} mm apart (placement {_xyz(Ma.translation)} against "
                    f"{_xyz(Mb.translation)} m)")
        R = Ma.rotation.T @ Mb.rotation
        ang = math.acos(max(-1.0, min(1.0, (float(np.trace(R)) - 1.0) / 2.0)))
        if ang > SAME_ROBOT_TOL_RAD:
            return f"joint {name} is turned {math.degrees(ang):.1f}° against the other"
    return None


def _xyz(v: Any) -> str:
    return ", ".join(f"{float(x):.3f}" for x in v)


def check_same_robot(model_robot: Any, cell_robot: Any, what: str) -> None:
    """Refuse a calibration of another arm (a UR5's model file for a UR10 cell has the same joint names).

    Raises:
        InputError: naming ``what`` (option and file), both robots and the first difference.
    """

    diff = kinematic_difference(model_robot, cell_robot)
    if diff is not None:
        raise InputError(f"{what}: calibrates the robot '{model_robot.name}', not the cell's '{cell_robot.name}' "
                         f"({diff}); use a model file identified on this robot")
