"""Robot: a serial arm loaded from a URDF into Pinocchio, with a named tool frame.

A robot is the kinematic chain from the URDF root to the *tool frame*
(``tool0`` by default). Its forward kinematics is the product of joint
placements and joint motions (paper eq. 1)::

    oMtool(q) = M_1 exp(S_1 q_1) M_2 exp(S_2 q_2) ... M_k exp(S_k q_k) M_tool

where ``M_j = model.jointPlacements[j]`` is the URDF placement of joint j in
its parent joint frame, ``S_j`` its motion axis and ``M_tool`` the fixed
placement of the tool frame in the last joint frame. The geometric errors of
:mod:`pin_kpi_oed.model.parameters` perturb the ``M_j``.

Joints that hang off the end effector (gripper fingers, as on the Panda) are
locked at their neutral value; any other branch makes the model non-serial
and is refused with :class:`~pin_kpi_oed.errors.RobotLoadError`.

Robots are given either as a URDF path or as a name: ``kr15``, ``kr300``,
``kr500`` (shipped in ``urdf/``) or an ``example-robot-data`` robot
(``ur3``, ``ur5``, ``ur10``, ``panda``).
"""

from __future__ import annotations

import glob
import os
import site
import sys
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pinocchio as pin

from pin_kpi_oed.errors import InputError, RobotLoadError

#: Folder of the URDFs shipped with the package (KUKA arms).
URDF_DIR = Path(__file__).resolve().parents[2] / "urdf"

#: example-robot-data names -> (relative URDF path, default tool frame).
ERD_ROBOTS: dict[str, tuple[str, str]] = {
    "ur3": ("ur_description/urdf/ur3_robot.urdf", "tool0"),
    "ur5": ("ur_description/urdf/ur5_robot.urdf", "tool0"),
    "ur10": ("ur_description/urdf/ur10_robot.urdf", "tool0"),
    "panda": ("panda_description/urdf/panda.urdf", "panda_hand_tcp"),
}

SHIPPED_ROBOTS = ("kr15", "kr300", "kr500")


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
    return Path(spec), None


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
        q_lower: lower joint limits (rad or m), shape (n,).
        q_upper: upper joint limits (rad or m), shape (n,).
        locked_joints: names of joints locked at neutral (end-effector branches).
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
        return np.array([self.model.joints[j].shortname().startswith("JointModelR") for j in self.joint_ids])

    def reach(self) -> float:
        """Rough reach (m): sum of joint-placement and tool offsets along the chain."""
        total = sum(float(np.linalg.norm(self.model.jointPlacements[j].translation)) for j in self.joint_ids[1:])
        return total + float(np.linalg.norm(self.model.frames[self.tool_frame_id].placement.translation))

    def neutral(self) -> np.ndarray:
        """A configuration inside the limits: neutral clipped to the bounds (rad)."""
        return np.clip(pin.neutral(self.model), self.q_lower, self.q_upper)

    def random_q(self, rng: np.random.Generator, n: int = 1) -> np.ndarray:
        """``n`` configurations drawn uniformly within the joint limits, shape (n, nq)."""
        return rng.uniform(self.q_lower, self.q_upper, size=(n, self.nq))

    def oMtool(self, q: np.ndarray) -> pin.SE3:
        """Pose of the tool frame in the base frame at configuration ``q``."""
        pin.framesForwardKinematics(self.model, self.data, np.asarray(q, dtype=float))
        return self.data.oMf[self.tool_frame_id].copy()

    def check_q(self, q: np.ndarray, what: str = "q", tol: float = 1e-9) -> np.ndarray:
        """Validate configurations: shape (m, nq) or (nq,), finite, within the joint limits.

        Args:
            q: joint values (rad for revolute, m for prismatic joints).
            what: name used in error messages (e.g. the file or field).
            tol: tolerance on the limits (rad).

        Returns:
            The configurations as a float array of shape (m, nq).

        Raises:
            InputError: wrong shape, NaN/inf, or a value outside the joint limits (named).
        """
        Q = np.atleast_2d(np.asarray(q, dtype=float))
        if Q.ndim != 2 or Q.shape[1] != self.nq:
            raise InputError(f"{what}: expected {self.nq} joint values per configuration "
                             f"({', '.join(self.joint_names)}), got shape {np.shape(q)}")
        bad = ~np.isfinite(Q)
        if bad.any():
            i, j = np.argwhere(bad)[0]
            raise InputError(f"{what}: configuration {i}, joint {self.joint_names[j]} is {Q[i, j]} (not finite)")
        lo = Q < self.q_lower - tol
        hi = Q > self.q_upper + tol
        if lo.any() or hi.any():
            i, j = np.argwhere(lo | hi)[0]
            raise InputError(
                f"{what}: configuration {i}, joint {self.joint_names[j]} = {Q[i, j]:.6g} rad is outside its limits "
                f"[{self.q_lower[j]:.6g}, {self.q_upper[j]:.6g}] rad")
        return Q

    def summary(self) -> dict:
        """Plain-number description (joints, limits in rad, tool frame) for printing or JSON."""
        return {
            "name": self.name,
            "urdf_path": self.urdf_path,
            "tool_frame": self.tool_frame,
            "joints": [
                {"name": n, "lower_rad": float(lo), "upper_rad": float(hi)}
                for n, lo, hi in zip(self.joint_names, self.q_lower, self.q_upper)
            ],
            "locked_joints": list(self.locked_joints),
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


def load_robot(spec: str | os.PathLike, tool_frame: str | None = None) -> Robot:
    """Load a serial arm from a URDF path or a robot name.

    Args:
        spec: URDF path, a shipped name (``kr15``, ``kr300``, ``kr500``) or an
            example-robot-data name (``ur3``, ``ur5``, ``ur10``, ``panda``).
        tool_frame: tool frame name; default ``tool0`` where the URDF has one
            (``panda_hand_tcp`` for the Panda).

    Returns:
        The :class:`Robot`.

    Raises:
        RobotLoadError: missing or malformed URDF, unknown tool frame, or a
            non-serial model (free-flyer, multi-DoF joint, branch).
    """
    path, default_tool = resolve_robot(str(spec))
    if not path.exists():
        known = ", ".join(SHIPPED_ROBOTS + tuple(ERD_ROBOTS))
        raise RobotLoadError(f"{path}: no such URDF file (robot names known: {known})")
    try:
        text = path.read_text()
    except (OSError, UnicodeDecodeError) as exc:
        raise RobotLoadError(f"{path}: cannot read URDF ({exc})") from None
    import xml.etree.ElementTree as ET

    try:
        root = ET.fromstring(text)
    except ET.ParseError as exc:
        raise RobotLoadError(f"{path}: malformed URDF (XML error: {exc})") from None
    if root.tag != "robot":
        raise RobotLoadError(f"{path}: not a URDF file (root element <{root.tag}>, expected <robot>)")
    try:
        full = pin.buildModelFromUrdf(str(path))
    except Exception as exc:  # Pinocchio raises ValueError/RuntimeError with long texts
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise RobotLoadError(f"{path}: malformed URDF ({first})") from None

    tool = tool_frame or default_tool or ("tool0" if full.existFrame("tool0") else None)
    if tool is None:
        raise RobotLoadError(f"{path}: no tool frame given and the URDF has no 'tool0' frame: pass --tool FRAME")
    if not full.existFrame(tool):
        names = [f.name for f in full.frames if f.type in (pin.FrameType.BODY, pin.FrameType.OP_FRAME)]
        raise RobotLoadError(f"{path}: unknown tool frame '{tool}' (frames: {', '.join(names[-8:])} ...)")

    chain = _chain_to_frame(full, full.getFrameId(tool))
    if not chain:
        raise RobotLoadError(f"{path}: tool frame '{tool}' is not moved by any joint")
    for j in chain:
        if full.joints[j].nq != 1 or full.joints[j].nv != 1:
            raise RobotLoadError(f"{path}: joint '{full.names[j]}' has {full.joints[j].nq} DoF: "
                                 "not a serial arm of 1-DoF joints")
    tip_subtree = _subtree(full, chain[-1])
    extra = [j for j in range(1, full.njoints) if j not in chain]
    branches = [j for j in extra if j not in tip_subtree]
    if branches:
        raise RobotLoadError(f"{path}: not a serial arm: joints {', '.join(full.names[j] for j in branches)} "
                             f"branch off the chain to '{tool}'")
    locked = [full.names[j] for j in extra]
    model = pin.buildReducedModel(full, extra, pin.neutral(full)) if extra else full

    joint_ids = list(range(1, model.njoints))
    lower = np.array(model.lowerPositionLimit, dtype=float)
    upper = np.array(model.upperPositionLimit, dtype=float)
    # continuous joints or absurd limits: fall back to +-2 pi
    lower = np.where(np.isfinite(lower) & (lower > -1e3), lower, -2 * np.pi)
    upper = np.where(np.isfinite(upper) & (upper < 1e3), upper, 2 * np.pi)
    name = str(spec) if str(spec).lower() in SHIPPED_ROBOTS + tuple(ERD_ROBOTS) else path.stem
    return Robot(
        model=model,
        data=model.createData(),
        urdf_path=str(path),
        name=name,
        tool_frame=tool,
        tool_frame_id=model.getFrameId(tool),
        joint_ids=joint_ids,
        joint_names=[model.names[j] for j in joint_ids],
        q_lower=lower,
        q_upper=upper,
        locked_joints=locked,
    )
