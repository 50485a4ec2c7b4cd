r"""Universal Robots kinematics files: the ``ur_description`` calibration layout, read and written.

Every UR arm leaves the factory with its own kinematic calibration; ``ur_calibration`` (UR ROS
driver) extracts it as a YAML file in ``ur_description``'s ``default_kinematics.yaml`` layout, which
the UR ROS drivers and MoveIt read::

    kinematics:
      shoulder:  {x, y, z, roll, pitch, yaw}     # placement of shoulder_pan_joint
      upper_arm: {...}                           # shoulder_lift_joint
      forearm:   {...}                           # elbow_joint
      wrist_1:   {...}   wrist_2: {...}   wrist_3: {...}
      hash: calib_<digits>

(one key per line, in this order; metres and radians). ``ur_description``'s macro builds the chain

    base_link ─Rz(π)→ base_link_inertia ─P_1─ q_1 ─P_2─ q_2 ⋯ ─P_6─ q_6 → wrist_3_link
        wrist_3_link ─rpy(0, −π/2, −π/2)→ flange ─rpy(π/2, 0, π/2)→ tool0

with P_k = T(x, y, z) · R_rpy(roll, pitch, yaw) the joint origin and every joint turning about its own
z axis. :func:`ur_urdf_text` writes that chain as a URDF (so :func:`~pin_kpi_oed.model.robot.load_robot`
takes a kinematics file as the nominal model, ``--robot ur10 --kinematics calib.yaml``); its
``base_link`` and ``tool0`` coincide with example-robot-data's UR URDFs at every configuration.

Writing a model in this layout (:func:`ur_values_of`) maps any 6R chain with joint placements M_k
(Pinocchio's, fixed joints folded in) and joint axes a_k onto it. With R_k a constant rotation that
takes e_z to a_k, the UR joint frame of joint k is the model's joint frame times R_k, so::

    P_1 = Rz(π)⁻¹ · M_1 · R_1,      P_k = R_{k−1}ᵀ · M_k · R_k      (k = 2..6)

and the tool: B = R_6ᵀ · M_tool · F⁻¹ (F = flange · tool0 above). The UR layout fixes
wrist_3 → tool0, so B must be a screw about the last joint's axis (a rotation about and a translation
along z, which commute with the joint's motion and are folded into P_6). Whatever of B is not such a
screw (a tool frame off the last joint's axis) cannot be represented: it is measured and the write is
refused beyond 1e-9 m / 1e-9 rad.

What the layout holds and what it loses. Each P_k is a full placement (6 numbers), so the 36
joint-placement parameters of the package map one to one: a rotation about a joint's own axis (a joint
zero offset) becomes part of that joint's roll / pitch / yaw — the ROS side applies it in the URDF
while the controller keeps reporting its raw joint angles, which is how ``ur_calibration`` carries the
controller's own Δθ. The layout has no place for the effects (joint-angle errors, compliance, thermal,
...), the discrepancy, the parameters' covariance, the stations' set-ups (tracker pose, reflector) or a
TCP: the model file keeps them, and ``predict`` / ``compensate`` use them.

The hash. ``ur_calibration`` writes the controller's calibration checksum, which the driver compares
with the connected robot's. A file written here carries ``calib_<digits>`` computed from its values (the
first 8 bytes of the SHA-256 of the 36 numbers as written); the driver therefore reports that the file
is not the controller's factory calibration, which is true: the robot controller still uses its own.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any
from collections.abc import Sequence

import numpy as np
import pinocchio as pin

from pin_kpi_oed.errors import InputError, RobotLoadError

__all__ = ["UR_SEGMENTS", "UR_KEYS", "UR_JOINTS", "UR_TYPES", "UR_KINEMATICS_DIR", "URKinematics",
           "read_ur_kinematics", "parse_ur_kinematics", "default_ur_kinematics", "ur_urdf_text", "ur_values_of",
           "placements_from_ur",
           "check_ur_type", "UR_FIXED_TOOL", "UR_BASE_INERTIA"]

#: The six joint placements of the layout, base to tip (the YAML keys, in the file's order).
UR_SEGMENTS = ("shoulder", "upper_arm", "forearm", "wrist_1", "wrist_2", "wrist_3")
#: The keys of one placement, in the file's order (m, m, m, rad, rad, rad).
UR_KEYS = ("x", "y", "z", "roll", "pitch", "yaw")
#: The joints the placements belong to (``ur_description``'s names).
UR_JOINTS = ("shoulder_pan_joint", "shoulder_lift_joint", "elbow_joint", "wrist_1_joint", "wrist_2_joint",
             "wrist_3_joint")
#: Folder of the shipped ``default_kinematics.yaml`` files (copied from ``ur_description``).
UR_KINEMATICS_DIR = Path(__file__).resolve().parents[2] / "urdf" / "ur"
#: UR types the package knows: joint speed limits (rad/s) from the maker's data as ``ur_description`` has them.
UR_TYPES: dict[str, tuple[float, ...]] = {
    "ur3": (3.15, 3.15, 3.15, 3.2, 3.2, 3.2), "ur5": (3.15,) * 6, "ur10": (2.16, 2.16, 3.15, 3.2, 3.2, 3.2),
    "ur3e": (np.pi, np.pi, np.pi, 2 * np.pi, 2 * np.pi, 2 * np.pi), "ur5e": (np.pi,) * 6,
    "ur10e": (2 * np.pi / 3, 2 * np.pi / 3, np.pi, np.pi, np.pi, np.pi),
    "ur16e": (2 * np.pi / 3, 2 * np.pi / 3, np.pi, np.pi, np.pi, np.pi),
}
#: Joint limits of ``ur_description`` (rad): ±2π, the elbow ±π.
_LIMITS = np.array([2 * np.pi, 2 * np.pi, np.pi, 2 * np.pi, 2 * np.pi, 2 * np.pi])
#: base_link → base_link_inertia (the controller's base frame has X+ backwards).
UR_BASE_INERTIA = pin.SE3(pin.rpy.rpyToMatrix(0.0, 0.0, np.pi), np.zeros(3))
#: wrist_3_link → tool0 (through ``flange``), fixed by the layout.
UR_FIXED_TOOL = (pin.SE3(pin.rpy.rpyToMatrix(0.0, -np.pi / 2, -np.pi / 2), np.zeros(3))
                 * pin.SE3(pin.rpy.rpyToMatrix(np.pi / 2, 0.0, np.pi / 2), np.zeros(3)))
#: Largest share of the tool placement that may be lost on writing (m and rad).
_TOOL_TOL = 1e-9
#: Largest tool0 distance (m) from the named type's default kinematics before a file counts as another robot's.
_TYPE_TOL_M = 0.03


def _num(v: float) -> str:
    v = float(v)
    return "0" if v == 0.0 else repr(v)


@dataclass(frozen=True, eq=False)
class URKinematics:
    """A UR robot's kinematic calibration in ``ur_description``'s layout.

    Attributes:
        values: (6, 6) per joint (rows in :data:`UR_SEGMENTS` order) x, y, z (m), roll, pitch, yaw (rad).
        hash: the file's ``hash`` (``calib_<digits>``).
        source: the file it was read from ("" if built in memory).
    """

    values: np.ndarray
    hash: str
    source: str = field(default="", compare=False)

    def __eq__(self, other: object) -> bool:
        return (isinstance(other, URKinematics) and self.hash == other.hash
                and np.array_equal(self.values, other.values))

    __hash__ = None

    def placements(self) -> list[pin.SE3]:
        """The joint origins P_k = T(x, y, z) · R_rpy(roll, pitch, yaw), base to tip."""
        return [pin.SE3(pin.rpy.rpyToMatrix(*row[3:]), np.array(row[:3], float)) for row in self.values]

    def layout(self) -> dict:
        """The file's content as a dict (``{"kinematics": {segment: {key: value}, ..., "hash": ...}}``)."""
        kin: dict[str, Any] = {seg: {k: float(v) for k, v in zip(UR_KEYS, row)}
                               for seg, row in zip(UR_SEGMENTS, self.values)}
        kin["hash"] = self.hash
        return {"kinematics": kin}

    def text(self, header: Sequence[str] = ()) -> str:
        """The YAML text in ``ur_description``'s key order (numbers with 17 significant digits), with
        ``header`` lines as leading comments."""
        lines = [f"# {h}" for h in header] + ["kinematics:"]
        for seg, row in zip(UR_SEGMENTS, self.values):
            lines.append(f"  {seg}:")
            lines += [f"    {k}: {_num(v)}" for k, v in zip(UR_KEYS, row)]
        lines.append(f"  hash: {self.hash}")
        return "\n".join(lines) + "\n"

    @staticmethod
    def content_hash(values: np.ndarray) -> str:
        """``calib_<digits>`` from the SHA-256 of the 36 values as written (first 8 bytes, decimal)."""
        import hashlib  # here, not at the top: OpenSSL's library is loaded only when a hash is asked for

        text = ",".join(_num(v) for v in np.asarray(values, float).ravel())
        return f"calib_{int.from_bytes(hashlib.sha256(text.encode()).digest()[:8], 'big')}"

    @classmethod
    def from_values(cls, values: np.ndarray, source: str = "") -> URKinematics:
        """Kinematics with the content hash of its values (:meth:`content_hash`)."""
        V = np.array(values, float).reshape(6, 6)
        return cls(V, cls.content_hash(V), source)


def parse_ur_kinematics(doc: Any, where: str) -> URKinematics:
    """Check and convert a parsed kinematics document (``{"kinematics": {...}}``).

    Raises:
        InputError: a missing or non-numeric field (named), a translation beyond 5 m (looks like mm).
    """
    kin = doc.get("kinematics") if isinstance(doc, dict) else None
    if not isinstance(kin, dict):
        raise InputError(f"{where}: not a UR kinematics file (no top-level 'kinematics:' mapping)")
    V = np.zeros((6, 6))
    for i, seg in enumerate(UR_SEGMENTS):
        block = kin.get(seg)
        if not isinstance(block, dict):
            raise InputError(f"{where}: kinematics.{seg} is missing (expected {', '.join(UR_SEGMENTS)})")
        for j, key in enumerate(UR_KEYS):
            v = block.get(key)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not np.isfinite(v):
                raise InputError(f"{where}: kinematics.{seg}.{key} must be a finite number, got {v!r}")
            V[i, j] = float(v)
    big = np.abs(V[:, :3]) > 5.0
    if big.any():
        i, j = np.argwhere(big)[0]
        raise InputError(f"{where}: kinematics.{UR_SEGMENTS[i]}.{UR_KEYS[j]} = {V[i, j]:g} is beyond 5 m: "
                         "looks like mm; the file holds metres")
    h = kin.get("hash")
    if not isinstance(h, str) or not h:
        raise InputError(f"{where}: kinematics.hash is missing (expected 'calib_<digits>')")
    return URKinematics(V, h, where)


def read_ur_kinematics(path: str | os.PathLike) -> URKinematics:
    """Read a ``default_kinematics.yaml``-layout file.

    Raises:
        InputError: unreadable file, YAML error, or a field as in :func:`parse_ur_kinematics`.
    """
    import yaml

    p = Path(path)
    try:
        doc = yaml.safe_load(p.read_text())
    except OSError as exc:
        raise InputError(f"{p}: cannot read the kinematics file ({exc.strerror or exc})") from None
    except yaml.YAMLError as exc:
        raise InputError(f"{p}: not valid YAML ({str(exc).splitlines()[0]})") from None
    return parse_ur_kinematics(doc, str(p))


def default_ur_kinematics(name: str) -> URKinematics | None:
    """The shipped ``ur_description`` default kinematics of a UR type, or None where none is shipped."""
    path = UR_KINEMATICS_DIR / f"{name.lower()}.yaml"
    return read_ur_kinematics(path) if path.exists() else None


def _origin(M: pin.SE3) -> str:
    return (f'<origin xyz="{" ".join(_num(v) for v in M.translation)}" '
            f'rpy="{" ".join(_num(v) for v in pin.rpy.matrixToRpy(M.rotation))}"/>')


def ur_urdf_text(kin: URKinematics, name: str) -> str:
    """A URDF of the ``ur_description`` chain with these kinematics (no meshes; limits of ``ur_description``).

    Args:
        kin: the kinematics.
        name: the UR type (a key of :data:`UR_TYPES`), for the joint speed limits and the robot name.

    Returns:
        The URDF text (links base_link, base_link_inertia, shoulder_link ... wrist_3_link, flange, tool0, base).
    """
    speeds = UR_TYPES[name.lower()]
    links = ["base_link_inertia", "shoulder_link", "upper_arm_link", "forearm_link", "wrist_1_link",
             "wrist_2_link", "wrist_3_link"]
    out = [f'<robot name="{name}">', f"  <!-- {name}: ur_description's chain with the kinematics {kin.hash} -->",
           '  <link name="base_link"/>'] + [f'  <link name="{ln}"/>' for ln in links]
    out += ['  <link name="flange"/>', '  <link name="tool0"/>', '  <link name="base"/>',
            '  <joint name="base_link-base_link_inertia" type="fixed"><parent link="base_link"/>'
            f'<child link="base_link_inertia"/>{_origin(UR_BASE_INERTIA)}</joint>']
    for k, (joint, P) in enumerate(zip(UR_JOINTS, kin.placements())):
        out.append(f'  <joint name="{joint}" type="revolute"><parent link="{links[k]}"/>'
                   f'<child link="{links[k + 1]}"/>{_origin(P)}<axis xyz="0 0 1"/>'
                   f'<limit lower="{_num(-_LIMITS[k])}" upper="{_num(_LIMITS[k])}" effort="100" '
                   f'velocity="{_num(speeds[k])}"/>'
                   "</joint>")
    out += ['  <joint name="base_link-base_fixed_joint" type="fixed"><parent link="base_link"/><child link="base"/>'
            f"{_origin(UR_BASE_INERTIA)}</joint>",
            '  <joint name="wrist_3-flange" type="fixed"><parent link="wrist_3_link"/><child link="flange"/>'
            f'{_origin(pin.SE3(pin.rpy.rpyToMatrix(0.0, -np.pi / 2, -np.pi / 2), np.zeros(3)))}</joint>',
            '  <joint name="flange-tool0" type="fixed"><parent link="flange"/><child link="tool0"/>'
            f'{_origin(pin.SE3(pin.rpy.rpyToMatrix(np.pi / 2, 0.0, np.pi / 2), np.zeros(3)))}</joint>', "</robot>"]
    return "\n".join(out) + "\n"


def _z_to(axis: np.ndarray) -> np.ndarray:
    """A rotation R with R · e_z = axis (the identity when the axis is e_z)."""
    a = np.asarray(axis, float) / np.linalg.norm(axis)
    if np.allclose(a, [0.0, 0.0, 1.0], atol=0.0, rtol=0.0):
        return np.eye(3)
    if np.allclose(a, [0.0, 0.0, -1.0], atol=1e-15):
        return pin.rpy.rpyToMatrix(np.pi, 0.0, 0.0)
    return pin.Quaternion.FromTwoVectors(np.array([0.0, 0.0, 1.0]), a).matrix()


def _ur_frames(kin: URKinematics) -> list[pin.SE3]:
    """The UR joint frames of ``kin`` in base_link at q = 0 (U_k = Rz(π) · P_1 ⋯ P_k)."""
    out, T = [], UR_BASE_INERTIA
    for P in kin.placements():
        T = T * P
        out.append(T)
    return out


def _joint_screws(model: pin.Model, joint_ids: Sequence[int], axes: np.ndarray,
                  reference: URKinematics | None) -> list[pin.SE3]:
    """S_k = T(t_k a_k) · R_k with R_k e_z = a_k: the UR frame of joint k in the model's joint frame.

    Without a reference R_k is the smallest rotation and t_k = 0. With one (the type's default kinematics),
    the rotation about the axis and the slide along it are those that bring the frame closest to the
    reference's at q = 0, so the values follow ``ur_description``'s link frames (its meshes hang on them).
    """
    if reference is None:
        return [pin.SE3(_z_to(a), np.zeros(3)) for a in axes]
    data = model.createData()
    pin.forwardKinematics(model, data, pin.neutral(model))
    out = []
    for j, a, W in zip(joint_ids, axes, _ur_frames(reference)):
        D = data.oMi[j].inverse() * W
        R0 = _z_to(a)
        G = R0.T @ D.rotation
        R = R0 @ pin.rpy.rpyToMatrix(0.0, 0.0, float(np.arctan2(G[1, 0], G[0, 0])))
        out.append(pin.SE3(R, float(a @ D.translation) * a))
    return out


def _ur_map(model: pin.Model, joint_ids: Sequence[int], tool_frame_id: int,
            reference: URKinematics | None) -> tuple[list[pin.SE3], pin.SE3]:
    """(S_k per joint, the tool screw folded into P_6) of a 6R chain (module docstring).

    Raises:
        InputError: not six revolute joints, or a tool frame the layout cannot carry (off the last axis).
    """
    from pin_kpi_oed.model.kinematics import joint_motion_axes, revolute_mask

    if len(joint_ids) != 6:
        raise InputError(f"the UR kinematics layout holds 6 joints, the robot has {len(joint_ids)}")
    if not np.all(revolute_mask(model, joint_ids)):
        raise InputError("the UR kinematics layout holds revolute joints only")
    S = _joint_screws(model, joint_ids, joint_motion_axes(model, joint_ids)[1], reference)
    frame = model.frames[tool_frame_id]
    if int(frame.parentJoint) != int(joint_ids[-1]):
        raise InputError(f"tool frame '{frame.name}' is not carried by the last joint: the UR layout fixes "
                         "wrist_3 → tool0")
    B = S[5].inverse() * frame.placement * UR_FIXED_TOOL.inverse()
    yaw = float(np.arctan2(B.rotation[1, 0], B.rotation[0, 0]))
    screw = pin.SE3(pin.rpy.rpyToMatrix(0.0, 0.0, yaw), np.array([0.0, 0.0, B.translation[2]]))
    rest = screw.inverse() * B
    lost_m, lost_rad = float(np.linalg.norm(rest.translation)), float(np.linalg.norm(pin.log3(rest.rotation)))
    if lost_m > _TOOL_TOL or lost_rad > _TOOL_TOL:
        raise InputError(f"tool frame '{frame.name}' lies {lost_m:.3g} m / {lost_rad:.3g} rad off the last joint's "
                         "axis: the UR layout fixes wrist_3 → tool0 and cannot carry it (export with "
                         "tool_frame='tool0')")
    return S, screw


def ur_values_of(model: pin.Model, joint_ids: Sequence[int], tool_frame_id: int,
                 placements: Sequence[pin.SE3] | None = None, reference: URKinematics | None = None) -> np.ndarray:
    """The UR-layout values of a 6R chain (module docstring: P_k = S_{k−1}⁻¹ M_k S_k, tool screw folded in).

    Args:
        model: Pinocchio model of the nominal chain (root = base_link).
        joint_ids: its six revolute joints, base to tip.
        tool_frame_id: the tool frame (tool0), carried by the last joint.
        placements: joint placements M_k to write instead of the model's (e.g. identified ones).
        reference: kinematics whose link frames the values follow (the type's default), or None.

    Returns:
        (6, 6) values: per joint x, y, z (m), roll, pitch, yaw (rad).

    Raises:
        InputError: not six revolute joints, or a tool frame the layout cannot carry (off the last axis).
    """
    S, screw = _ur_map(model, joint_ids, tool_frame_id, reference)
    M = ([pin.SE3(model.jointPlacements[j]) for j in joint_ids] if placements is None
         else [pin.SE3(P) for P in placements])
    P = [UR_BASE_INERTIA.inverse() * M[0] * S[0]] + [S[k - 1].inverse() * M[k] * S[k] for k in range(1, 6)]
    P[5] = P[5] * screw
    return np.array([np.r_[Pk.translation, pin.rpy.matrixToRpy(Pk.rotation)] for Pk in P])


def placements_from_ur(model: pin.Model, joint_ids: Sequence[int], tool_frame_id: int, kin: URKinematics,
                       reference: URKinematics | None = None) -> list[pin.SE3]:
    """The inverse of :func:`ur_values_of`: joint placements M_k of ``model``'s chain (its own link frames,
    joint axes and tool placement) that give ``kin``'s forward kinematics.

    Args:
        model: Pinocchio model of the nominal chain (its link frames are kept).
        joint_ids: its six revolute joints; tool_frame_id: tool0.
        kin: the kinematics to take.
        reference: the link-frame convention (as for :func:`ur_values_of`).
    """
    S, screw = _ur_map(model, joint_ids, tool_frame_id, reference)
    P = kin.placements()
    P[5] = P[5] * screw.inverse()
    return [UR_BASE_INERTIA * P[0] * S[0].inverse()] + [S[k - 1] * P[k] * S[k].inverse() for k in range(1, 6)]


def check_ur_type(kin: URKinematics, name: str) -> None:
    """Refuse a kinematics file of another UR type: tool0 of the file and of ``name``'s default kinematics
    farther apart than 30 mm at seeded configurations (a calibration moves it by a few mm at most).

    Raises:
        RobotLoadError: naming the file, the type and the closest shipped type.
    """
    ref = default_ur_kinematics(name)
    if ref is None:
        return
    rng = np.random.default_rng(0)
    Q = rng.uniform(-np.pi, np.pi, size=(20, 6))

    def tool0(k: URKinematics) -> np.ndarray:
        Ps = k.placements()
        out = []
        for q in Q:
            T = UR_BASE_INERTIA
            for P, qk in zip(Ps, q):
                T = T * P * pin.SE3(pin.rpy.rpyToMatrix(0.0, 0.0, qk), np.zeros(3))
            out.append(T.translation)
        return np.array(out)

    here = tool0(kin)
    gap = float(np.max(np.linalg.norm(here - tool0(ref), axis=1)))
    if gap > _TYPE_TOL_M:
        gaps = {t: float(np.max(np.linalg.norm(here - tool0(k), axis=1)))
                for t in UR_TYPES if (k := default_ur_kinematics(t)) is not None}
        best = min(gaps, key=gaps.get)
        raise RobotLoadError(f"{kin.source or 'kinematics'}: not a {name}'s kinematics (tool0 up to "
                             f"{gap * 1e3:.0f} mm from the {name}'s default; closest: {best}, "
                             f"{gaps[best] * 1e3:.1f} mm)")
