"""Robot: a serial arm loaded from a URDF into Pinocchio, with a named tool frame.

A robot is the kinematic chain from the URDF root to the *tool frame*
(``tool0`` by default). Its forward kinematics is the product of joint
placements and joint motions (paper eq. 1)::

    oMtool(q) = M_1 exp(S_1 q_1) M_2 exp(S_2 q_2) ... M_k exp(S_k q_k) M_tool

where ``M_j = model.jointPlacements[j]`` is the URDF placement of joint j in
its parent joint frame, ``S_j`` its motion axis and ``M_tool`` the fixed
placement of the tool frame in the last joint frame. The geometric errors of
:mod:`pin_kpi_oed.model.parameters` perturb the ``M_j``.

Joints that hang off the end effector (gripper fingers, as on the Panda) and joints that branch off the
chain to the tool (Baxter's other arm and head, the legs of a legged base under an arm) are locked at their
neutral value clipped into their limits: their links stay in the model, and in its collision geometry, at that
posture. A continuous joint (a revolute joint without stops) is read as a revolute joint with limits ±2π rad
(:mod:`pin_kpi_oed.model.urdf_joints`). Both are said in :attr:`Robot.notes`.

Joints are revolute (values in rad) or prismatic (values in m, e.g. a linear track); the type
comes from Pinocchio (:func:`~pin_kpi_oed.model.kinematics.revolute_mask`). Limits, unit checks
and printed tables follow each joint's type: a revolute joint without finite limits falls back to ±2π rad,
a prismatic joint must have finite limits in the URDF (metres).

Robots are given either as a URDF path or as a name: ``kr15``, ``kr300``,
``kr500``, ``kr15_track`` (the KR 15 on a 6.4 m linear track; shipped in ``urdf/``) or an
``example-robot-data`` robot (``ur3``, ``ur5``, ``ur10``, ``panda``).
"""

from __future__ import annotations

import glob
import os
import site
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin

from pin_kpi_oed.errors import InputError, RobotLoadError
from pin_kpi_oed.model.kinematics import joint_unit, revolute_mask
from pin_kpi_oed.model.robot_cache import cached, keep, load_key
from pin_kpi_oed.model.urdf_joints import continuous_as_revolute, locked_posture, model_from_urdf_text
from pin_kpi_oed.model.robot_names import (ERD_ROBOTS, ROBOT_HELP, ROBOT_NAMES, SHIPPED_ROBOTS, TOOL_FRAME_HELP,  # noqa: F401
                                          TOOL_HELP, UR_E_SERIES, default_tool_frames)
from pin_kpi_oed.validation.robot_checks import captured_stderr, check_robot_scale, check_urdf_tree, xacro_refusal

#: Folder of the URDFs shipped with the package (KUKA arms).
URDF_DIR = Path(__file__).resolve().parents[2] / "urdf"

#: Joint values beyond these magnitudes are in the wrong unit: degrees (revolute) or mm (prismatic).
UNIT_GUARD = {"rad": 2.0 * np.pi + 0.1, "m": 100.0}
#: What a value beyond :data:`UNIT_GUARD` looks like, per unit.
_LOOKS_LIKE = {"rad": "degrees", "m": "mm"}


def is_robot_name(spec: str | os.PathLike) -> bool:
    """Whether ``spec`` is a robot name (shipped or example-robot-data) rather than a URDF path."""
    return str(spec).lower() in ROBOT_NAMES


def erd_root() -> Path:
    """Folder of example-robot-data's robots (``.../cmeel.prefix/share/example-robot-data/robots``).

    Raises:
        RobotLoadError: if example-robot-data is not installed.
    """
    candidates = list(site.getsitepackages()) + [site.getusersitepackages()] + sys.path
    for base in candidates:
        hits = glob.glob(os.path.join(base, "cmeel.prefix", "share", "example-robot-data", "robots"))
        if hits:
            return Path(hits[0])
    raise RobotLoadError("example-robot-data is not installed: run `make test` or `pip install example-robot-data`")


def resolve_robot(spec: str) -> tuple[Path, str | None]:
    """Turn a robot name or URDF path into (URDF path, default tool frame or None)."""
    key = spec.lower()
    if key in SHIPPED_ROBOTS:
        return URDF_DIR / f"{key}.urdf", "tool0"
    if key in ERD_ROBOTS:
        rel, tool = ERD_ROBOTS[key]
        return erd_root() / rel, tool
    if key in UR_E_SERIES:  # the type's identity: its ur_description default kinematics (ur10e: none shipped)
        from pin_kpi_oed.model.ur_kinematics import UR_KINEMATICS_DIR

        return UR_KINEMATICS_DIR / f"{key}.yaml", "tool0"
    return Path(spec), None


def portable_spec(robot: Robot) -> str:
    """The robot's spec for files: its name when that name loads the same URDF, else the URDF path."""
    key = str(robot.name).lower()
    if getattr(robot, "kinematics", None) is not None:  # a UR name with its kinematics (stored beside it)
        return key
    if key in SHIPPED_ROBOTS or key in ERD_ROBOTS:
        try:
            if Path(resolve_robot(key)[0]).resolve() == Path(robot.urdf_path).resolve():
                return key
        except RobotLoadError:
            pass
    return str(robot.urdf_path)


def same_robot(spec_a: str, spec_b: str) -> bool:
    """Whether two robot specs (names or URDF paths) load the same URDF file."""
    def path(spec: str) -> Path:
        try:
            return Path(resolve_robot(str(spec))[0]).resolve()
        except RobotLoadError:
            return Path(str(spec)).resolve()
    return path(spec_a) == path(spec_b)


@dataclass
class Robot:
    """A serial arm with a tool frame.

    Attributes:
        model: Pinocchio model of the serial chain (extra branches locked).
        data: Pinocchio data of ``model``.
        urdf_path: URDF file the model comes from.
        name: short name (robot name or file stem).
        tool_frame: name of the tool frame.
        tool_frame_id: its Pinocchio frame index.
        joint_ids: Pinocchio joint indices of the actuated joints, base to tip.
        joint_names: their URDF names.
        q_lower: lower joint limits (rad for revolute, m for prismatic joints), shape (n,).
        q_upper: upper joint limits (rad or m), shape (n,).
        locked_joints: names of joints locked at neutral (beyond the tool, or branching off the chain to it).
        revolute: revolute (True) / prismatic (False) mask of the joints; computed from the model if None.
        kinematics: the UR kinematics file the nominal model comes from
            (:class:`~pin_kpi_oed.model.ur_kinematics.URKinematics`), or None (the URDF's own).
        urdf_text: the URDF text the model was built from when it is not the file at ``urdf_path``
            (a UR kinematics file's chain), else None.
        notes: what the loader made of the URDF that the user must be told (one line each): the continuous
            joints taken as revolute of ±2π rad, the joints branching off the chain locked at neutral.
    """

    model: pin.Model
    data: pin.Data
    urdf_path: str
    name: str
    tool_frame: str
    tool_frame_id: int
    joint_ids: list[int]
    joint_names: list[str]
    q_lower: np.ndarray
    q_upper: np.ndarray
    locked_joints: list[str] = field(default_factory=list)
    revolute: np.ndarray | None = field(default=None, repr=False, compare=False)
    kinematics: Any = field(default=None, repr=False, compare=False)
    urdf_text: str | None = field(default=None, repr=False, compare=False)
    notes: list[str] = field(default_factory=list, repr=False, compare=False)

    def read_urdf_text(self) -> str:
        """The URDF text of the model: :attr:`urdf_text`, else the file at :attr:`urdf_path`."""
        return self.urdf_text if self.urdf_text is not None else Path(self.urdf_path).read_text()

    @property
    def nq(self) -> int:
        """Number of actuated joints."""
        return len(self.joint_ids)

    @property
    def parents(self) -> list[int]:
        """Parent joint index of each actuated joint (0 = universe)."""
        return [int(self.model.parents[j]) for j in self.joint_ids]

    @property
    def is_revolute(self) -> np.ndarray:
        """Boolean mask of revolute joints (the others are prismatic)."""
        if self.revolute is None:
            self.revolute = revolute_mask(self.model, self.joint_ids)
        return self.revolute.copy()

    @property
    def periodic_joints(self) -> np.ndarray:
        """Boolean mask of the joints whose values are compared modulo 2π: revolute joints whose limits span at
        least 2π (q and q + 2π both reachable, the same link pose). Prismatic joints (m) and revolute joints with a
        narrower range are compared linearly: their ends are far apart, not neighbours."""
        span = np.asarray(self.q_upper, float) - np.asarray(self.q_lower, float)
        return self.is_revolute & (span >= 2.0 * np.pi - 1e-9)

    @property
    def joint_units(self) -> list[str]:
        """SI unit of each joint value: ``"rad"`` (revolute) or ``"m"`` (prismatic)."""
        return [joint_unit(bool(r)) for r in self.is_revolute]

    def reach(self) -> float:
        """Rough reach (m): sum of joint-placement and tool offsets along the chain, plus the travel of
        prismatic joints (largest |limit|)."""
        total = sum(float(np.linalg.norm(self.model.jointPlacements[j].translation)) for j in self.joint_ids[1:])
        travel = sum(max(abs(float(lo)), abs(float(hi)))
                     for lo, hi, r in zip(self.q_lower, self.q_upper, self.is_revolute) if not r)
        return total + travel + float(np.linalg.norm(self.model.frames[self.tool_frame_id].placement.translation))

    def neutral(self) -> np.ndarray:
        """A configuration inside the limits: neutral clipped to the bounds (rad / m)."""
        return np.clip(pin.neutral(self.model), self.q_lower, self.q_upper)

    def random_q(self, rng: np.random.Generator, n: int = 1) -> np.ndarray:
        """``n`` configurations drawn uniformly within the joint limits, shape (n, nq)."""
        return rng.uniform(self.q_lower, self.q_upper, size=(n, self.nq))

    def oMtool(self, q: np.ndarray) -> pin.SE3:
        """Pose of the tool frame in the base frame at configuration ``q``."""
        pin.framesForwardKinematics(self.model, self.data, np.asarray(q, dtype=float))
        return self.data.oMf[self.tool_frame_id].copy()

    def check_q(self, q: np.ndarray, what: str = "q", tol: float = 1e-9, line_of: Any = None) -> np.ndarray:
        """Validate configurations: shape (m, nq) or (nq,), finite, in SI units, within the joint limits.

        Args:
            q: joint values (rad for revolute, m for prismatic joints).
            what: name used in error messages (e.g. the file or field).
            tol: tolerance on the limits (rad or m).
            line_of: ``line_of(i)`` -> the file line number of row i (0-based), for messages; None: rows are
                counted from 1 without line numbers.

        Returns:
            The configurations as a float array of shape (m, nq).

        Raises:
            InputError: wrong shape, NaN/inf, a value beyond :data:`UNIT_GUARD` for its joint type
                ("looks like degrees" / "looks like mm"), or a value outside the joint limits (named,
                with the joint's unit).
        """
        Q = np.atleast_2d(np.asarray(q, dtype=float))
        if Q.ndim != 2 or Q.shape[1] != self.nq:
            raise InputError(f"{what}: expected {self.nq} joint values per configuration "
                             f"({', '.join(self.joint_names)}), got shape {np.shape(q)}")
        def row(i: int) -> str:
            return f"row {i + 1} (line {line_of(i)})" if line_of is not None else f"configuration {i + 1} (from 1)"

        bad = ~np.isfinite(Q)
        if bad.any():
            i, j = np.argwhere(bad)[0]
            raise InputError(f"{what}: {row(int(i))}, joint {self.joint_names[j]} is {Q[i, j]} (not finite)")
        units = self.joint_units
        lo = Q < self.q_lower - tol
        hi = Q > self.q_upper + tol
        if lo.any() or hi.any():
            i, j = np.argwhere(lo | hi)[0]
            u = units[j]
            raise InputError(
                f"{what}: {row(int(i))}, joint {self.joint_names[j]} = {Q[i, j]:.6g} {u} is outside its limits "
                f"[{self.q_lower[j]:.6g}, {self.q_upper[j]:.6g}] {u}")
        return Q

    @property
    def unit_guard(self) -> np.ndarray:
        """Per joint, the largest magnitude of a value in its unit (rad / m): :data:`UNIT_GUARD`, or the joint's own
        limit + 0.1 when larger, up to two turns (a wrist of ±400°, a URDF's own limit, is no degree value)."""
        own = np.nan_to_num(np.maximum(np.abs(self.q_lower), np.abs(self.q_upper)) + 0.1, posinf=0.0)
        return np.maximum(np.array([UNIT_GUARD[u] for u in self.joint_units]), np.minimum(own, 4 * np.pi + 0.1))

    def check_units(self, q: np.ndarray, what: str = "q", first_row: int = 0) -> None:
        """Reject joint values in the wrong unit: beyond 2π + 0.1 rad (revolute: degrees) or 100 m (prismatic: mm),
        or the joint's own limit + 0.1 if larger (:attr:`unit_guard`). For data read from files, before :meth:`check_q`.

        Args:
            q: joint values, (m, nq) (rad / m).
            what: name used in error messages (e.g. the file).
            first_row: number of the first row in messages (1 for "measurement 1").

        Raises:
            InputError: naming the measurement, joint, value and what it looks like.
        """
        Q = np.atleast_2d(np.asarray(q, dtype=float))
        units = self.joint_units
        guard = self.unit_guard
        big = np.abs(Q) > guard
        if big.any():
            i, j = np.argwhere(big)[0]
            u = units[j]
            raise InputError(f"{what}: joint {self.joint_names[j]} of measurement {i + first_row} is {Q[i, j]:.6g}, "
                             f"beyond {guard[j]:.4g} {u}: looks like {_LOOKS_LIKE[u]}; convert to {u}")

    def limits_table(self) -> list[str]:
        """The joint limits as printable lines, each in its joint's display unit (deg for revolute, m for
        prismatic joints), with a header line."""
        lines = [f"{'joint':<22}{'type':<11}{'lower':>10}{'upper':>10}  unit"]
        for n, lo, hi, r in zip(self.joint_names, self.q_lower, self.q_upper, self.is_revolute):
            if r:
                lines.append(f"{n:<22}{'revolute':<11}{np.degrees(lo):>10.1f}{np.degrees(hi):>10.1f}  deg")
            else:
                lines.append(f"{n:<22}{'prismatic':<11}{lo:>10.3f}{hi:>10.3f}  m")
        return lines

    def summary(self) -> dict:
        """Plain-number description (joints with type and SI limits, tool frame) for printing or JSON.

        Each joint has ``type`` (``revolute``/``prismatic``), ``unit`` and its limits as
        ``lower_rad``/``upper_rad`` (revolute) or ``lower_m``/``upper_m`` (prismatic).
        """
        joints = []
        for n, lo, hi, u in zip(self.joint_names, self.q_lower, self.q_upper, self.joint_units):
            joints.append({"name": n, "type": "revolute" if u == "rad" else "prismatic", "unit": u,
                           f"lower_{u}": float(lo), f"upper_{u}": float(hi)})
        return {
            "name": self.name,
            "urdf_path": self.urdf_path,
            "tool_frame": self.tool_frame,
            "joints": joints,
            "locked_joints": list(self.locked_joints),
            "notes": list(self.notes),
        }


def _chain_to_frame(model: pin.Model, frame_id: int) -> list[int]:
    chain = []
    j = int(model.frames[frame_id].parentJoint)
    while j > 0:
        chain.append(j)
        j = int(model.parents[j])
    return chain[::-1]


def _subtree(model: pin.Model, root: int) -> set[int]:
    out = {root}
    for j in range(1, model.njoints):
        k = j
        while k > 0:
            if k == root:
                out.add(j)
                break
            k = int(model.parents[k])
    return out


def load_robot(spec: str | os.PathLike, tool_frame: str | None = None, kinematics: Any = None) -> Robot:
    """Load a serial arm from a URDF path or a robot name.

    Args:
        spec: URDF path, a shipped name (``kr15``, ``kr300``, ``kr500``, ``kr15_track``) or an
            example-robot-data name (``ur3``, ``ur5``, ``ur10``, ``panda``).
        tool_frame: tool frame name; default ``tool0`` where the URDF has one
            (``panda_hand_tcp`` for the Panda).
        kinematics: a UR kinematics file (path, a loaded
            :class:`~pin_kpi_oed.model.ur_kinematics.URKinematics`, or the file's layout as a dict) as the nominal
            model of a UR name
            (``ur3``, ``ur5``, ``ur10``, ``ur3e``, ``ur5e``, ``ur10e``, ``ur16e``); the e-series names load
            ``ur_description``'s default kinematics without it (``ur10e`` needs the file).

    Returns:
        The :class:`Robot`: a copy of its own of a robot loaded before from the same file's bytes with the same
        options (:mod:`pin_kpi_oed.model.robot_cache`; not with ``kinematics``).

    Raises:
        RobotLoadError: missing or malformed URDF, unknown tool frame, a
            multi-DoF joint on the chain (a free-flyer), a joint that is neither
            revolute nor prismatic, or a prismatic joint without finite limits (m).
    """
    key = load_key(spec, tool_frame, resolve_robot(str(spec))[0]) if kinematics is None else None
    hit = cached(key)  # the same file loaded before in this process: a copy of its robot
    if hit is not None:
        return hit
    kin = _ur_kinematics(str(spec), kinematics)
    text = None
    if kin is None or str(spec).lower() in ERD_ROBOTS:
        path, default_tool = resolve_robot(str(spec))
        full, continuous = _build_full_model(path)
    else:
        from pin_kpi_oed.model.ur_kinematics import ur_urdf_text

        text = ur_urdf_text(kin, str(spec).lower())
        path, default_tool = resolve_robot(str(spec))  # the type's file: one identity whatever kinematics
        full, continuous = model_from_urdf_text(text)
    tool = _tool_frame(full, path, tool_frame, default_tool)
    model, locked, branches = _serial_chain_model(full, path, tool)

    joint_ids = list(range(1, model.njoints))
    try:
        revolute = revolute_mask(model, joint_ids)
    except RobotLoadError as exc:
        raise RobotLoadError(f"{path}: {exc}") from None
    lower, upper = _joint_limits(model, joint_ids, revolute, path)
    name = str(spec) if is_robot_name(spec) else path.stem
    robot = Robot(
        model=model,
        data=model.createData(),
        urdf_path=str(path),
        name=name,
        tool_frame=tool,
        tool_frame_id=frame_id(model, tool),
        joint_ids=joint_ids,
        joint_names=[model.names[j] for j in joint_ids],
        q_lower=lower,
        q_upper=upper,
        locked_joints=locked,
        revolute=revolute,
        kinematics=kin,
        urdf_text=text,
        notes=_load_notes(model, continuous, branches, tool),
    )
    if kin is not None and text is None:
        _take_ur_kinematics(robot, kin)
    check_robot_scale(robot.reach(), path)
    keep(key, robot)
    return robot


def _take_ur_kinematics(robot: Robot, kin: Any) -> None:
    """Replace the joint placements of a shipped UR robot by those of a kinematics file, keeping its URDF's
    link frames (meshes, collision geometry, tool0): :func:`~pin_kpi_oed.model.ur_kinematics.placements_from_ur`.

    Raises:
        RobotLoadError: a tool frame the UR layout does not describe (not tool0 on the last joint's axis).
    """
    from pin_kpi_oed.model.ur_kinematics import default_ur_kinematics, placements_from_ur

    try:
        M = placements_from_ur(robot.model, robot.joint_ids, robot.model.getFrameId("tool0"), kin,
                               reference=default_ur_kinematics(robot.name.lower()))
    except InputError as exc:
        raise RobotLoadError(f"{robot.urdf_path}: {exc}") from None
    for j, Mk in zip(robot.joint_ids, M):
        robot.model.jointPlacements[j] = Mk
    robot.data = robot.model.createData()


def _ur_kinematics(spec: str, kinematics: Any) -> Any:
    """The UR kinematics of ``spec`` (given, or the shipped default of an e-series name), checked to be that
    type's, or None (the robot's URDF holds its kinematics).

    Raises:
        RobotLoadError: a kinematics file for a robot that is not a UR type, or of another UR type.
        InputError: an unreadable or malformed kinematics file.
    """
    from pin_kpi_oed.model.ur_kinematics import (UR_TYPES, URKinematics, check_ur_type, default_ur_kinematics,
                                                 parse_ur_kinematics, read_ur_kinematics)

    key = spec.lower()
    if kinematics is None:
        if key in UR_TYPES and key not in ERD_ROBOTS:
            kin = default_ur_kinematics(key)
            if kin is None:
                raise RobotLoadError(f"{spec}: no default kinematics shipped: pass its kinematics file "
                                     "(kinematics='calib.yaml', from ur_calibration)")
            return kin
        return None
    if key not in UR_TYPES:
        raise RobotLoadError(f"a UR kinematics file is the nominal model of a UR robot ({', '.join(UR_TYPES)}), "
                             f"not of '{spec}'")
    if isinstance(kinematics, dict):  # the file's layout, as a model file stores it
        kin = parse_ur_kinematics(kinematics, "robot.kinematics")
    else:
        kin = kinematics if isinstance(kinematics, URKinematics) else read_ur_kinematics(kinematics)
    check_ur_type(kin, key)
    return kin


def _load_notes(model: pin.Model, continuous: list[str], branches: list[str], tool: str) -> list[str]:
    """The loader's note lines: continuous joints of the chain taken as revolute, branches locked at neutral."""
    notes = []
    on_chain = [n for n in continuous if model.existJointName(n)]
    if on_chain:
        notes.append(f"continuous joint(s) {', '.join(on_chain)} taken as revolute with limits ±2π rad "
                     "(one turn either way)")
    if branches:
        notes.append(f"joint(s) {', '.join(branches)} branch off the chain to '{tool}': locked at neutral, "
                     "clipped into their limits (their links stay in the model and its collision geometry at that "
                     "posture)")
    return notes


def _build_full_model(path: Path) -> tuple[pin.Model, list[str]]:
    """Read, parse and check the URDF at ``path`` and build its full Pinocchio model, its continuous joints
    revolute of ±2π rad (:func:`~pin_kpi_oed.model.urdf_joints.continuous_as_revolute`).

    Returns:
        (the full model, the names of the joints taken from continuous to revolute).

    Raises:
        RobotLoadError: missing, unreadable or malformed URDF (one line naming the file).
    """
    if not path.exists():
        known = ", ".join(ROBOT_NAMES)
        raise RobotLoadError(f"{path}: no such URDF file (robot names known: {known})")
    try:
        text = path.read_text()
    except (OSError, UnicodeDecodeError) as exc:
        raise RobotLoadError(f"{path}: cannot read URDF ({exc})") from None
    import xml.etree.ElementTree as ET

    try:
        root = ET.fromstring(text)
    except ET.ParseError as exc:
        if "unbound prefix" in str(exc) and "<xacro:" in text:  # xacro elements without the xmlns:xacro declaration
            raise xacro_refusal(path, f"xacro element without its namespace declaration, {exc}") from None
        raise RobotLoadError(f"{path}: malformed URDF (XML error: {exc})") from None
    if root.tag != "robot":
        raise RobotLoadError(f"{path}: not a URDF file (root element <{root.tag}>, expected <robot>)")
    check_urdf_tree(root, path, text)
    continuous = continuous_as_revolute(root)
    try:
        with captured_stderr() as cap:  # urdfdom prints its reasons on fd 2: put them in the one line
            full = (pin.buildModelFromXML(ET.tostring(root, encoding="unicode")) if continuous
                    else pin.buildModelFromUrdf(str(path)))
    except Exception as exc:  # Pinocchio raises ValueError/RuntimeError with long texts
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        why = cap.first_line()
        raise RobotLoadError(f"{path}: malformed URDF ({why.split('  ')[0] if why else first})") from None
    return full, continuous


def _tool_frame(full: pin.Model, path: Path, tool_frame: str | None, default_tool: str | None) -> str:
    """The tool frame: given, the robot name's default, or ``tool0``; raises RobotLoadError if absent."""
    tool = tool_frame or default_tool or ("tool0" if full.existFrame("tool0") else None)
    if tool is None:
        raise RobotLoadError(f"{path}: no tool frame given and the URDF has no 'tool0' frame: pass tool_frame='FRAME'")
    if not full.existFrame(tool):
        names = [f.name for f in full.frames if f.type in (pin.FrameType.BODY, pin.FrameType.OP_FRAME)]
        raise RobotLoadError(f"{path}: unknown tool frame '{tool}' (frames: {', '.join(names[-8:])} ...)")
    return tool


def frame_id(model: pin.Model, name: str) -> int:
    """The id of frame ``name``: the link's (BODY) frame where a joint or another frame bears the same name (the
    SO-100's ``gripper`` is a link and a joint), else the first frame of that name.

    Raises:
        RobotLoadError: no frame of that name.
    """
    for kind in (pin.FrameType.BODY, pin.FrameType.OP_FRAME, pin.FrameType.FIXED_JOINT, pin.FrameType.JOINT):
        if model.existFrame(name, kind):
            return int(model.getFrameId(name, kind))
    for k, f in enumerate(model.frames):
        if f.name == name:
            return k
    raise RobotLoadError(f"no frame '{name}'")


def _serial_chain_model(full: pin.Model, path: Path, tool: str) -> tuple[pin.Model, list[str], list[str]]:
    """(model reduced to the serial chain moving ``tool``, names of the locked joints, the names of those among
    them that branch off the chain rather than hang beyond the tool). Every joint off the chain is locked at its
    neutral value clipped into its limits (:func:`locked_posture`, :func:`pinocchio.buildReducedModel`): a joint
    off the chain moves no link of the chain, so the
    chain's kinematics is the same at any of its values; its links stay as fixed bodies at that posture.

    Raises:
        RobotLoadError: the tool is not moved by any joint, or a multi-DoF joint on the chain.
    """
    chain = _chain_to_frame(full, frame_id(full, tool))
    if not chain:
        raise RobotLoadError(f"{path}: tool frame '{tool}' is not moved by any joint")
    for j in chain:
        if full.joints[j].nq != 1 or full.joints[j].nv != 1:
            raise RobotLoadError(f"{path}: joint '{full.names[j]}' has {full.joints[j].nv} DoF: "
                                 "not a serial arm of 1-DoF joints")
    tip_subtree = _subtree(full, chain[-1])
    extra = [j for j in range(1, full.njoints) if j not in chain]
    branches = [full.names[j] for j in extra if j not in tip_subtree]
    locked = [full.names[j] for j in extra]
    if extra:
        _rename_shadowed_joints(full, extra)
    model = pin.buildReducedModel(full, extra, locked_posture(full)) if extra else full
    return model, locked, branches


def _rename_shadowed_joints(full: pin.Model, locked: list[int]) -> None:
    """Rename (in ``full``) each joint to be locked that bears a link's name (the SO-100's joint and link
    ``gripper``) to ``NAME__joint``: Pinocchio's reduction makes the locked joint a frame and refuses two frames of
    one name; the link keeps its name (it may be the tool frame)."""
    for j in locked:
        name = full.names[j]
        if not full.existFrame(name, pin.FrameType.BODY):
            continue
        full.names[j] = f"{name}__joint"
        for k, f in enumerate(full.frames):
            if f.name == name and f.type == pin.FrameType.JOINT:
                f.name = f"{name}__joint"
                full.frames[k] = f


def _joint_limits(model: pin.Model, joint_ids: list[int], revolute: np.ndarray, path: Path
                  ) -> tuple[np.ndarray, np.ndarray]:
    """Joint limits per type: revolute in rad (continuous / absurd limits -> ±2π), prismatic in m (finite).

    Raises:
        RobotLoadError: a prismatic joint without finite limits, or with lower >= upper.
    """
    lower = np.array([model.lowerPositionLimit[model.joints[j].idx_q] for j in joint_ids], dtype=float)
    upper = np.array([model.upperPositionLimit[model.joints[j].idx_q] for j in joint_ids], dtype=float)
    # continuous revolute joints or absurd limits: fall back to +-2 pi
    lo_bad = ~np.isfinite(lower) | (lower <= -1e3)
    hi_bad = ~np.isfinite(upper) | (upper >= 1e3)
    for k in np.flatnonzero(~revolute & (lo_bad | hi_bad | ~(lower < upper))):
        raise RobotLoadError(f"{path}: prismatic joint '{model.names[joint_ids[k]]}' needs finite limits in m "
                             f"(<limit lower=... upper=...>), got [{lower[k]:.6g}, {upper[k]:.6g}]")
    lower = np.where(revolute & lo_bad, -2 * np.pi, lower)
    upper = np.where(revolute & hi_bad, 2 * np.pi, upper)
    return lower, upper
