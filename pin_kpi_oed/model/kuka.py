"""URDF generator for KUKA-like 6R arms in the classic 6R offset layout.

Every number in this module is a **documented stand-in** taken from public
third-party transcriptions of KUKA data (ROS-Industrial ``kuka_experimental``
URDFs, the ``robotkinematicscatalogue`` project, ARTE, a Corke-RTB KR 15 cell
model), gathered in ``shared/reference/kuka_kinematics.md``. None of it is a
KUKA datasheet, and the paper's own tables (DH/Hayati values, capsule sizes)
are not available to us. The inertias in particular are **plausible stand-ins,
not KUKA data**. All units are SI: metres, radians, kilograms, kg m^2,
rad/s and N m.

Layout
------
Six parameters describe the nominal geometry (all in metres):

* ``d1``: height of the A2 axis above the base plane,
* ``a1``: horizontal offset from the A1 axis to the A2 axis,
* ``a2``: upper arm, A2 -> A3 ("segment two"),
* ``a3``: offset of the A4 axis from the A3 axis, perpendicular to the
  forearm (positive = A4 axis above the A3 axis with the upper arm vertical
  and the forearm horizontal),
* ``d4``: forearm, A3 -> wrist centre along the forearm ("segment four"),
* ``d6``: wrist centre -> flange, along the A6 axis.

Joint frames follow the ROS-Industrial KUKA URDFs (``base_link``,
``link_1`` ... ``link_6``, ``tool0``); at the zero configuration every link
frame is parallel to ``base_link`` (x forward, z up)::

    joint      parent   origin xyz (in parent)   axis
    joint_a1   base     (0,  0, 0)                (0, 0, -1)
    joint_a2   link_1   (a1, 0, d1)               (0, 1, 0)
    joint_a3   link_2   (a2, 0, 0)                (0, 1, 0)
    joint_a4   link_3   (d4, 0, a3)               (-1, 0, 0)
    joint_a5   link_4   (0,  0, 0)                (0, 1, 0)
    joint_a6   link_5   (0,  0, 0)                (-1, 0, 0)
    joint_a6-tool0 (fixed) link_6  (d6, 0, 0), rpy (0, pi/2, 0)

so ``link_4``, ``link_5`` and ``link_6`` share the wrist centre as origin.
At ``q = 0`` the upper arm lies along +x and the forearm continues along +x:
the wrist centre is at ``(a1 + a2 + d4, 0, d1 + a3)`` and the flange at
``(a1 + a2 + d4 + d6, 0, d1 + a3)``. KUKA's HOME (A2 = -90 deg, A3 = +90 deg)
puts the upper arm vertical and the forearm horizontal, the flange facing +x;
A5 = +90 deg from there turns the flange down. A positive rotation about +y
takes +x towards -z, so the forearm segment A3 -> wrist centre, which is
``(d4, a3)`` in the (x, z) plane of ``link_3``, lies on the upper-arm line
when ``A3 = atan2(a3, d4)``; the largest distance of the wrist centre from
the A1 axis (A2 = 0, arm horizontal) is then the catalogue reach

    reach = a1 + a2 + sqrt(a3**2 + d4**2).

``tool0`` follows REP-199: its z axis points out of the flange, along the A6
axis and away from the wrist (``link_6`` +x), its x axis is ``link_6`` -z.

Geometry
--------
Visual and collision geometry are URDF cylinders; downstream code reads a
collision cylinder as a capsule of the same radius whose segment is the
cylinder axis. Segments, in each link's own frame (``r_k`` is the radius of
``capsule_radii[link_k]``):

* ``base_link``: (0, 0, 0) -> (0, 0, 0.3 d1), about z,
* ``link_1`` (shoulder): A1 origin (0, 0, 0) -> A2 origin (a1, 0, d1),
* ``link_2`` (upper arm): A2 origin -> A3 origin (a2, 0, 0),
* ``link_3`` (forearm root): A3 origin -> (0.25 d4, 0, a3), the elbow housing,
* ``link_4`` (forearm tube): (-0.75 d4, 0, 0) -> wrist centre, along A4,
* ``link_5`` (wrist): wrist centre -> (d6 - t6, 0, 0), along A6,
* ``link_6`` (flange): (d6 - t6, 0, 0) -> flange (d6, 0, 0),

with ``t6 = min(0.5 d6, max(0.02, 0.25 d6))`` the flange thickness. The
radii follow the enclosing-capsule table of the reference (KR 15: KR 16-2
column; KR 300: KR 300 R2500 ultra column; KR 500: KR 300 values scaled by
the ratio of the reaches). Being enclosing sizes, they make some capsules of
links that are not joint neighbours overlap even at HOME (base_link/link_2,
link_2/link_4 and link_4/link_6 for all three arms; link_1/link_3 and
link_3/link_5 too for KR 300 and KR 500): a self-collision check needs a list
of pairs to ignore.

Linear track
------------
:class:`LinearTrack` puts the arm on a linear track (KUKA's external axis E1): a fixed
``track_rail`` root link with the rail as one collision cylinder along its +y axis, and a
prismatic joint ``joint_e1`` (axis +y, limits in m, m/s and N) from the rail to ``base_link``,
whose origin is ``carriage_height_m`` above the rail frame (carriage and riser). Every other
joint, link and frame is the arm's. :data:`KR15_TRACK` (0 ... 6.4 m, 2 m/s, stand-in values)
gives the shipped ``urdf/kr15_track.urdf`` (``load_robot("kr15_track")``).

Inertias
--------
``total_mass_kg`` is split over ``link_1`` ... ``link_6`` in the proportions
of the ARTE KR 16-2 link masses (94, 47, 35.25, 23.5, 23.5, 11.75 kg); each
link is a solid cylinder of that mass spanning its capsule segment with the
capsule radius. ``base_link`` is fixed and carries no inertia. Velocity and
effort limits are plausible class values, also stand-ins.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from collections.abc import Sequence

import numpy as np

from pin_kpi_oed.errors import InputError

__all__ = [
    "JOINT_NAMES",
    "LINK_NAMES",
    "KukaGeometry",
    "KR15",
    "KR300",
    "KR500",
    "LinearTrack",
    "KR15_TRACK",
    "urdf_text",
    "write_urdf",
]

#: Names of the six revolute joints, base to flange.
JOINT_NAMES: tuple[str, ...] = tuple(f"joint_a{i}" for i in range(1, 7))
#: Names of the links carrying geometry, base to flange.
LINK_NAMES: tuple[str, ...] = ("base_link",) + tuple(f"link_{i}" for i in range(1, 7))

# ARTE KR 16-2 link masses (kg), link_1 ... link_6; used as proportions only.
_ARTE_KR16_MASSES = (94.0, 47.0, 35.25, 23.5, 23.5, 11.75)

# Fixed parts of the layout (see module docstring).
_BASE_HEIGHT_FRACTION = 0.3  # base cylinder height / d1
_FOREARM_ROOT_FRACTION = 0.25  # link_3 segment length / d4

# Plausible stand-in velocity (rad/s) and effort (N m) limits per class.
_VEL_KR15 = tuple(math.radians(v) for v in (156.0, 156.0, 156.0, 335.0, 355.0, 647.0))
_EFF_KR15 = (1500.0, 1500.0, 700.0, 150.0, 150.0, 80.0)
_VEL_KR300 = tuple(math.radians(v) for v in (105.0, 101.0, 107.0, 136.0, 129.0, 206.0))
_EFF_KR300 = (12000.0, 15000.0, 8000.0, 2000.0, 2000.0, 1000.0)
_VEL_KR500 = tuple(math.radians(v) for v in (68.0, 57.0, 57.0, 60.0, 60.0, 72.0))
_EFF_KR500 = (25000.0, 30000.0, 15000.0, 4000.0, 4000.0, 2000.0)


def _deg(values: Sequence[float]) -> tuple[float, ...]:
    return tuple(math.radians(v) for v in values)


@dataclass(frozen=True)
class KukaGeometry:
    """Nominal geometry of a KUKA-like 6R arm (classic 6R offset layout).

    All lengths are in metres, angles in radians, masses in kilograms. Every
    value is a documented stand-in (see the module docstring).

    Attributes:
        name: Robot name, written as the URDF ``<robot name>`` (XML-safe).
        d1: Height of the A2 axis above the base plane (m).
        a1: Horizontal offset A1 axis -> A2 axis (m).
        a2: Upper arm length A2 -> A3 (m).
        a3: Offset of the A4 axis from the A3 axis, perpendicular to the
            forearm (m, positive = A4 above A3 at HOME).
        d4: Forearm length A3 -> wrist centre (m).
        d6: Wrist centre -> flange (m).
        q_lower: Lower joint limits A1..A6 (rad).
        q_upper: Upper joint limits A1..A6 (rad).
        capsule_radii: Capsule radius (m) per link name, keys
            ``base_link``, ``link_1`` ... ``link_6``.
        total_mass_kg: Mass of the moving links ``link_1`` ... ``link_6`` (kg).
        velocity_limits: Joint speed limits A1..A6 (rad/s), stand-ins.
        effort_limits: Joint torque limits A1..A6 (N m), stand-ins.
    """

    name: str
    d1: float
    a1: float
    a2: float
    a3: float
    d4: float
    d6: float
    q_lower: tuple[float, ...]
    q_upper: tuple[float, ...]
    capsule_radii: dict[str, float] = field(hash=False)
    total_mass_kg: float
    velocity_limits: tuple[float, ...] = _VEL_KR15
    effort_limits: tuple[float, ...] = _EFF_KR15

    def __post_init__(self) -> None:
        if not self.name or any(c in self.name for c in "<>&\"' "):
            raise InputError(f"KukaGeometry.name must be a non-empty XML-safe token, got {self.name!r}")
        for attr in ("d1", "a1", "a2", "a3", "d4", "d6", "total_mass_kg"):
            value = getattr(self, attr)
            if not math.isfinite(value):
                raise InputError(f"KukaGeometry {self.name}: {attr} = {value!r} is not finite")
        for attr in ("d1", "a2", "d4", "d6", "total_mass_kg"):
            if getattr(self, attr) <= 0.0:
                raise InputError(f"KukaGeometry {self.name}: {attr} = {getattr(self, attr)!r} must be > 0")
        if self.a1 < 0.0:
            raise InputError(f"KukaGeometry {self.name}: a1 = {self.a1!r} must be >= 0")
        for attr in ("q_lower", "q_upper", "velocity_limits", "effort_limits"):
            value = tuple(float(v) for v in getattr(self, attr))
            if len(value) != 6 or not all(math.isfinite(v) for v in value):
                raise InputError(f"KukaGeometry {self.name}: {attr} must hold 6 finite values, got {value!r}")
            object.__setattr__(self, attr, value)
        for i, (lo, hi) in enumerate(zip(self.q_lower, self.q_upper), start=1):
            if not lo < hi:
                raise InputError(f"KukaGeometry {self.name}: A{i} limits [{lo}, {hi}] rad are empty")
        if any(v <= 0.0 for v in self.velocity_limits + self.effort_limits):
            raise InputError(f"KukaGeometry {self.name}: velocity and effort limits must be > 0")
        radii = dict(self.capsule_radii)
        if set(radii) != set(LINK_NAMES):
            raise InputError(
                f"KukaGeometry {self.name}: capsule_radii keys {sorted(radii)} != {sorted(LINK_NAMES)}"
            )
        for link, r in radii.items():
            if not (math.isfinite(r) and r > 0.0):
                raise InputError(f"KukaGeometry {self.name}: capsule radius of {link} = {r!r} must be > 0")
        object.__setattr__(self, "capsule_radii", radii)

    @property
    def reach_m(self) -> float:
        """Wrist-centre reach from the A1 axis, ``a1 + a2 + sqrt(a3^2 + d4^2)`` (m)."""
        return self.a1 + self.a2 + math.hypot(self.a3, self.d4)


# --- enclosing-capsule radii (m), reference table -----------------------------
_RADII_KR16 = {
    "base_link": 0.39,
    "link_1": 0.37,
    "link_2": 0.13,
    "link_3": 0.21,
    "link_4": 0.09,
    "link_5": 0.11,
    "link_6": 0.04,
}
_RADII_KR300 = {
    "base_link": 0.57,
    "link_1": 0.61,
    "link_2": 0.38,
    "link_3": 0.57,
    "link_4": 0.10,
    "link_5": 0.18,
    "link_6": 0.10,
}
# KR 500 R2830: no public collision geometry; KR 300 radii scaled by the reach ratio.
_REACH_KR300 = 0.350 + 1.150 + math.hypot(-0.041, 1.000)
_REACH_KR500 = 0.500 + 1.300 + math.hypot(-0.055, 1.025)
_RADII_KR500 = {k: v * _REACH_KR500 / _REACH_KR300 for k, v in _RADII_KR300.items()}

_LIMITS_KR16 = ((-185.0, -155.0, -130.0, -350.0, -130.0, -350.0), (185.0, 35.0, 154.0, 350.0, 130.0, 350.0))

#: KUKA KR 15/2 (Corke-RTB cell model; joint limits of the KR 16-2; 235 kg stand-in mass).
KR15 = KukaGeometry(
    name="kuka_kr15_2",
    d1=0.675,
    a1=0.300,
    a2=0.650,
    a3=0.150,
    d4=0.600,
    d6=0.140,
    q_lower=_deg(_LIMITS_KR16[0]),
    q_upper=_deg(_LIMITS_KR16[1]),
    capsule_radii=dict(_RADII_KR16),
    total_mass_kg=235.0,
    velocity_limits=_VEL_KR15,
    effort_limits=_EFF_KR15,
)

#: KUKA KR 300 R2500 ultra (1.1 t stand-in mass).
KR300 = KukaGeometry(
    name="kuka_kr300_r2500_ultra",
    d1=0.675,
    a1=0.350,
    a2=1.150,
    a3=-0.041,
    d4=1.000,
    d6=0.240,
    q_lower=_deg((-185.0, -140.0, -120.0, -350.0, -122.5, -350.0)),
    q_upper=_deg((185.0, -5.0, 155.0, 350.0, 122.5, 350.0)),
    capsule_radii=dict(_RADII_KR300),
    total_mass_kg=1100.0,
    velocity_limits=_VEL_KR300,
    effort_limits=_EFF_KR300,
)

#: KUKA KR 500 R2830 (= KR 500-3; 2.4 t stand-in mass).
KR500 = KukaGeometry(
    name="kuka_kr500_r2830",
    d1=1.045,
    a1=0.500,
    a2=1.300,
    a3=-0.055,
    d4=1.025,
    d6=0.290,
    q_lower=_deg((-185.0, -130.0, -100.0, -350.0, -120.0, -350.0)),
    q_upper=_deg((185.0, 20.0, 144.0, 350.0, 120.0, 350.0)),
    capsule_radii=dict(_RADII_KR500),
    total_mass_kg=2400.0,
    velocity_limits=_VEL_KR500,
    effort_limits=_EFF_KR500,
)



@dataclass(frozen=True)
class LinearTrack:
    """A linear track under the arm: a prismatic joint along the rail frame's +y axis (stand-in values).

    Attributes:
        lower_m: lower travel limit (m).
        upper_m: upper travel limit (m).
        velocity_m_s: speed limit (m/s).
        effort_n: force limit (N).
        carriage_height_m: height of the arm's base plane above the rail frame (carriage + riser, m).
        rail_radius_m: radius of the rail's collision capsule (m); its axis runs
            ``rail_radius_m`` above the rail frame's origin, from ``lower_m - overhang_m`` to
            ``upper_m + overhang_m`` along y.
        overhang_m: rail length beyond the travel limits at each end (m).
        carriage_mass_kg: mass of the carriage and the arm's base, carried by ``base_link`` (kg).
        joint_name: name of the prismatic joint.
        rail_link: name of the fixed root link carrying the rail.

    Raises:
        InputError: non-finite values, empty travel, or non-positive sizes / limits.
    """

    lower_m: float = 0.0
    upper_m: float = 6.4
    velocity_m_s: float = 2.0
    effort_n: float = 10000.0
    carriage_height_m: float = 0.7
    rail_radius_m: float = 0.15
    overhang_m: float = 0.5
    carriage_mass_kg: float = 250.0
    joint_name: str = "joint_e1"
    rail_link: str = "track_rail"

    def __post_init__(self) -> None:
        for attr in ("lower_m", "upper_m", "velocity_m_s", "effort_n", "carriage_height_m", "rail_radius_m",
                     "overhang_m", "carriage_mass_kg"):
            value = getattr(self, attr)
            if not (isinstance(value, (int, float)) and math.isfinite(value)):
                raise InputError(f"LinearTrack: {attr} = {value!r} is not a finite number")
        if not self.lower_m < self.upper_m:
            raise InputError(f"LinearTrack: travel lower_m..upper_m = [{self.lower_m}, {self.upper_m}] m is empty")
        for attr in ("velocity_m_s", "effort_n", "carriage_height_m", "rail_radius_m", "carriage_mass_kg"):
            if getattr(self, attr) <= 0.0:
                raise InputError(f"LinearTrack: {attr} = {getattr(self, attr)!r} must be > 0")
        if self.overhang_m < 0.0:
            raise InputError(f"LinearTrack: overhang_m = {self.overhang_m!r} must be >= 0")
        for attr in ("joint_name", "rail_link"):
            v = getattr(self, attr)
            if not v or any(c in v for c in "<>&\"' ") or v in JOINT_NAMES + LINK_NAMES + ("tool0",):
                raise InputError(f"LinearTrack: {attr} must be a new XML-safe name, got {v!r}")


#: The KR 15 on a 6.4 m track (0 ... 6.4 m, 2 m/s, 10 kN; 0.7 m carriage; stand-in values).
KR15_TRACK = LinearTrack()


# --- geometry helpers -----------------------------------------------------------
def _segments(geom: KukaGeometry) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Capsule segment end points of every link, in the link's own frame (m)."""
    t6 = min(0.5 * geom.d6, max(0.02, 0.25 * geom.d6))
    root = _FOREARM_ROOT_FRACTION * geom.d4
    z0 = np.zeros(3)
    return {
        "base_link": (z0, np.array([0.0, 0.0, _BASE_HEIGHT_FRACTION * geom.d1])),
        "link_1": (z0, np.array([geom.a1, 0.0, geom.d1])),
        "link_2": (z0, np.array([geom.a2, 0.0, 0.0])),
        "link_3": (z0, np.array([root, 0.0, geom.a3])),
        "link_4": (np.array([-(geom.d4 - root), 0.0, 0.0]), z0),
        "link_5": (z0, np.array([geom.d6 - t6, 0.0, 0.0])),
        "link_6": (np.array([geom.d6 - t6, 0.0, 0.0]), np.array([geom.d6, 0.0, 0.0])),
    }


def _cylinder_pose(p0: np.ndarray, p1: np.ndarray) -> tuple[np.ndarray, tuple[float, float, float], float]:
    """Centre, URDF rpy and length of a cylinder whose axis (local z) is p0 -> p1.

    Segments in the x-z plane of the link use a rotation about y: R_y(pitch) maps z to
    (sin pitch, 0, cos pitch); a segment along +y (the track's rail) uses R_x(-π/2).
    """
    d = p1 - p0
    length = float(np.linalg.norm(d))
    if abs(d[0]) <= 1e-12 and abs(d[2]) <= 1e-12 and d[1] > 0.0:
        return 0.5 * (p0 + p1), (-math.pi / 2.0, 0.0, 0.0), length
    if abs(d[1]) > 1e-12:
        raise InputError("capsule segments must lie in the x-z plane of their link (or along +y)")
    pitch = math.atan2(d[0], d[2])
    return 0.5 * (p0 + p1), (0.0, pitch, 0.0), length


def _cylinder_inertia(mass: float, radius: float, p0: np.ndarray, p1: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """COM (m) and inertia tensor about the COM in the link frame (kg m^2) of a solid cylinder."""
    d = p1 - p0
    length = float(np.linalg.norm(d))
    u = d / length
    i_axial = 0.5 * mass * radius**2
    i_trans = mass * (3.0 * radius**2 + length**2) / 12.0
    inertia = i_trans * (np.eye(3) - np.outer(u, u)) + i_axial * np.outer(u, u)
    return 0.5 * (p0 + p1), inertia


def _f(x: float) -> str:
    """Shortest round-trip text of a float (exact when parsed back)."""
    x = float(x)
    if x == 0.0:
        return "0"
    return repr(x)


def _v(values: Sequence[float] | np.ndarray) -> str:
    return " ".join(_f(v) for v in values)


# --- public API ---------------------------------------------------------------------
def _link_text(name: str, p0: np.ndarray, p1: np.ndarray, radius: float, material: str,
               mass: float | None) -> list[str]:
    """A URDF link with one cylinder p0 -> p1 (visual and collision) and, with ``mass``, its inertia."""
    centre, rpy, length = _cylinder_pose(p0, p1)
    geometry = f'<cylinder radius="{_f(radius)}" length="{_f(length)}"/>'
    origin = f'<origin xyz="{_v(centre)}" rpy="{_v(rpy)}"/>'
    out = [f'  <link name="{name}">']
    if mass is not None:
        com, inertia = _cylinder_inertia(mass, radius, p0, p1)
        out += ["    <inertial>",
                f'      <origin xyz="{_v(com)}" rpy="0 0 0"/>',
                f'      <mass value="{_f(mass)}"/>',
                f'      <inertia ixx="{_f(inertia[0, 0])}" ixy="{_f(inertia[0, 1])}" ixz="{_f(inertia[0, 2])}" '
                f'iyy="{_f(inertia[1, 1])}" iyz="{_f(inertia[1, 2])}" izz="{_f(inertia[2, 2])}"/>',
                "    </inertial>"]
    out += ["    <visual>", f"      {origin}", f"      <geometry>{geometry}</geometry>",
            f'      <material name="{material}"/>', "    </visual>",
            "    <collision>", f"      {origin}", f"      <geometry>{geometry}</geometry>", "    </collision>",
            "  </link>"]
    return out


def urdf_text(geom: KukaGeometry, track: LinearTrack | None = None) -> str:
    """Return the URDF text of a KUKA-like 6R arm, optionally on a linear track.

    The text is deterministic (same geometry, same bytes). Joints are
    ``joint_a1`` ... ``joint_a6`` (revolute, limits in rad, rad/s, N m) plus
    the fixed ``joint_a6-tool0``; links are ``base_link``, ``link_1`` ...
    ``link_6`` and ``tool0``. Each link except ``tool0`` has one cylinder in
    ``<visual>`` and one in ``<collision>`` (read downstream as a capsule);
    inertias are stand-ins, not KUKA data. With ``track``, the root link is the
    rail (``track.rail_link``) and the prismatic ``track.joint_name`` (limits in
    m, m/s, N) carries ``base_link`` (module docstring, "Linear track").

    Args:
        geom: Arm geometry (m, rad, kg).
        track: the linear track under the arm, or None (arm on a fixed base).

    Returns:
        The URDF document as a string (UTF-8 compatible, ends with a newline).
    """
    out = _header_lines(geom, track) + _link_lines(geom, track) + _joint_lines(geom, track)
    out.append("</robot>")
    return "\n".join(out) + "\n"


def _header_lines(geom: KukaGeometry, track: LinearTrack | None) -> list[str]:
    """The URDF's opening lines: XML declaration, robot element, provenance comment, materials."""
    out: list[str] = []
    w = out.append
    w('<?xml version="1.0"?>')
    w(f'<robot name="{geom.name if track is None else geom.name + "_track"}">')
    w("  <!--")
    w("    Generated by pin_kpi_oed.model.kuka (do not edit; run urdf/regenerate.py).")
    w("    KUKA-like 6R arm, classic 6R offset layout, ROS-Industrial joint frames.")
    w(f"    d1={_f(geom.d1)} a1={_f(geom.a1)} a2={_f(geom.a2)} a3={_f(geom.a3)} "
      f"d4={_f(geom.d4)} d6={_f(geom.d6)} m; wrist-centre reach {geom.reach_m:.4f} m.")
    if track is not None:
        w(f"    On a linear track: prismatic {track.joint_name} along +y of {track.rail_link}, "
          f"{_f(track.lower_m)} ... {_f(track.upper_m)} m, {_f(track.velocity_m_s)} m/s; "
          f"base plane {_f(track.carriage_height_m)} m above the rail frame.")
    w("    All values are stand-ins from third-party public sources, not a KUKA datasheet.")
    w("    Inertias are plausible stand-ins (solid cylinders), NOT KUKA data.")
    w("    Collision cylinders are read as capsules of the same radius (segment = axis).")
    w("  -->")
    w('  <material name="kuka_orange"><color rgba="0.96 0.47 0.13 1"/></material>')
    w('  <material name="kuka_black"><color rgba="0.12 0.12 0.12 1"/></material>')
    return out


def _link_lines(geom: KukaGeometry, track: LinearTrack | None) -> list[str]:
    """The links: the rail (with a track), ``base_link`` ... ``link_6`` (cylinder visual and collision), ``tool0``."""
    seg = _segments(geom)
    masses = [geom.total_mass_kg * m / sum(_ARTE_KR16_MASSES) for m in _ARTE_KR16_MASSES]
    out: list[str] = []
    w = out.append
    if track is not None:
        z = track.rail_radius_m
        ends = (np.array([0.0, track.lower_m - track.overhang_m, z]),
                np.array([0.0, track.upper_m + track.overhang_m, z]))
        out += _link_text(track.rail_link, *ends, track.rail_radius_m, "kuka_black", None)
    for k, link in enumerate(LINK_NAMES):
        p0, p1 = seg[link]
        material = "kuka_black" if link in ("base_link", "link_6") else "kuka_orange"
        if k > 0:
            mass: float | None = masses[k - 1]
        else:
            mass = track.carriage_mass_kg if track is not None else None
        out += _link_text(link, p0, p1, geom.capsule_radii[link], material, mass)
    w('  <link name="tool0"/>')
    return out


def _joint_lines(geom: KukaGeometry, track: LinearTrack | None) -> list[str]:
    """The joints: the track's prismatic joint (with a track), ``joint_a1`` ... ``joint_a6``, ``joint_a6-tool0``."""
    out: list[str] = []
    w = out.append
    if track is not None:
        w(f'  <joint name="{track.joint_name}" type="prismatic">')
        w(f'    <origin xyz="0 0 {_f(track.carriage_height_m)}" rpy="0 0 0"/>')
        w(f'    <parent link="{track.rail_link}"/>')
        w(f'    <child link="{LINK_NAMES[0]}"/>')
        w('    <axis xyz="0 1 0"/>')
        w(f'    <limit lower="{_f(track.lower_m)}" upper="{_f(track.upper_m)}" '
          f'velocity="{_f(track.velocity_m_s)}" effort="{_f(track.effort_n)}"/>')
        w("  </joint>")

    joint_origins = (
        (0.0, 0.0, 0.0),
        (geom.a1, 0.0, geom.d1),
        (geom.a2, 0.0, 0.0),
        (geom.d4, 0.0, geom.a3),
        (0.0, 0.0, 0.0),
        (0.0, 0.0, 0.0),
    )
    axes = ("0 0 -1", "0 1 0", "0 1 0", "-1 0 0", "0 1 0", "-1 0 0")
    for i in range(6):
        w(f'  <joint name="{JOINT_NAMES[i]}" type="revolute">')
        w(f'    <origin xyz="{_v(joint_origins[i])}" rpy="0 0 0"/>')
        w(f'    <parent link="{LINK_NAMES[i]}"/>')
        w(f'    <child link="{LINK_NAMES[i + 1]}"/>')
        w(f'    <axis xyz="{axes[i]}"/>')
        w(
            f'    <limit lower="{_f(geom.q_lower[i])}" upper="{_f(geom.q_upper[i])}" '
            f'velocity="{_f(geom.velocity_limits[i])}" effort="{_f(geom.effort_limits[i])}"/>'
        )
        w("  </joint>")
    w('  <joint name="joint_a6-tool0" type="fixed">')
    w(f'    <origin xyz="{_f(geom.d6)} 0 0" rpy="0 {_f(math.pi / 2.0)} 0"/>')
    w('    <parent link="link_6"/>')
    w('    <child link="tool0"/>')
    w("  </joint>")
    return out


def write_urdf(geom: KukaGeometry, path: str | os.PathLike[str], track: LinearTrack | None = None) -> Path:
    """Write ``urdf_text(geom, track)`` to ``path`` atomically.

    The text goes to a temporary file in the target directory, is flushed and
    fsync'ed, then moved over ``path`` with :func:`os.replace`, so readers see
    either the old or the new file, never a partial one.

    Args:
        geom: Arm geometry (m, rad, kg).
        path: Destination file; its parent directory is created if missing.
        track: the linear track under the arm, or None.

    Returns:
        The destination path.
    """
    from pin_kpi_oed.data.atomic import atomic_write_text

    dest = Path(path)
    dest.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_text(dest, urdf_text(geom, track))
    return dest

