"""Measurement cells: the robot, its tracker and its surroundings, read from YAML.

A *cell* is everything the design optimiser needs besides the criterion
(paper sections 2.2 and 3.2): the robot and its tool frame, the reflector and
the KPI point on the tool, the laser tracker's pose and noise, the joint
bounds, the robot's capsules, the obstacles, the laser beam, the incidence
limit (eq. 4, default 30°) and the working configurations q_work (the KPIs).

:class:`Cell` is the one cell model of the package: the optimiser's constraints
(:mod:`pin_kpi_oed.cell.collision`), the independent check
(:mod:`pin_kpi_oed.cell.feasibility`) and the design files the viewer shows
(:mod:`pin_kpi_oed.design.design_file`) all use it.

Frames. Obstacles, half-spaces, the robot base and the tracker are given in
one *cell* (world) frame W; the robot's capsules in their link frames. The
measurement model needs the pose of the robot base in the tracker frame,

    tracker_T_base = (W_T_tracker)⁻¹ · W_T_base .

Capsules (eq. 20–21). A capsule is a segment [a, b] with a radius r: the set of
points within r of the segment. Robot capsules default to the URDF's collision
cylinders read as capsules of the same radius along the cylinder axis
(``robot_capsules: urdf``); the KUKA URDFs of ``urdf/`` have one per link. Mesh and box
collision geometry (e.g. the UR10's) becomes the enclosing capsule fitted to its vertices
(:mod:`pin_kpi_oed.cell.meshes`); ``robot_capsules: urdf_visual`` fits the visual meshes instead.
A half-space ``{x : n·x ≥ offset}`` is the free side of a plane (wall, floor).

Schema (SI units; angles may be given in degrees with a ``_deg`` key instead of
``_rad``)::

    name: kr15_fms
    robot: kr15                      # shipped name or URDF path (relative to this file)
    tool_frame: tool0
    base:    {xyz_m: [x, y, z], rpy_rad: [r, p, y]}      # robot base in the cell frame
    tracker: {xyz_m: [...], rpy_deg: [...]}              # tracker frame in the cell frame
    reflector_m: [x, y, z]           # reflector in the tool frame
    nests_m: [[x, y, z], ...]        # optional: the reflector nests on the tool (tool frame), nest 0 = reflector_m;
                                     # design then chooses each pose's nest (pin_kpi_oed.model.nests)
    tcp_m: [x, y, z]                 # KPI point (TCP) in the tool frame
    noise: {sigma_xyz_m: [sx, sy, sz]}                   # or {range_a_m: a, range_b: b}; identify --cell takes it
                                                         # for the tracker's noise when the data have no sigma columns
    joint_bounds: {lower_deg: [...], upper_deg: [...]}   # optional override of the URDF limits
    robot_capsules: urdf             # or urdf_visual, or a list of {name, link, a_m, b_m, radius_m} (link frame)
    extra_capsules: []               # more robot capsules, same fields (e.g. a tool)
    obstacles:
      capsules:    [{name, a_m, b_m, radius_m}]          # cell frame
      half_spaces: [{name, normal, offset_m}]            # free side n·x >= offset
    environment:                     # obstacles from files (pin_kpi_oed.cell.environment), relative paths
      - {name: table, urdf: table.urdf, pose: {xyz_m: [...], rpy_deg: [...]}, max_radius_m: 0.1}
      - {name: fixture, mesh: fixture.stl, scale: 0.001, pose: {...}}
    skip_pairs: [[base_link, link_2], [link_1, pedestal]]   # capsule/link/obstacle/environment names
    beam: {radius_m: 0.005, skip: []}                    # laser beam capsule tracker -> reflector
    incidence_max_deg: 30            # largest angle between the tool frame's z axis (the reflector's axis:
                                     # mount the reflector facing along tool z) and the beam to the tracker (eq. 4)
    clearance_m: 0.0                 # required distance between any two capsules
    working_configurations_deg: [[a1, ..., a6]]
    working_targets:                 # and/or TCP targets (cell frame), solved by IK (pin_kpi_oed.cell.working_targets)
      - {xyz_m: [x, y, z], rpy_deg: [r, p, y], seed_deg: [a1, ..., a6]}   # rpy and seed optional
    working_paths:                   # and/or paths the TCP follows (pin_kpi_oed.cell.paths): the path KPI
      - {name: seam, waypoints: [{xyz_m: [...], rpy_deg: [...]}, ...], step_m: 0.005}
    camera: {...}                    # a camera instead of the tracker, with its board (pin_kpi_oed.cell.camera_setup)
    board: {...}
    orientation_length_m: 0.2        # the 6-D KPI's weight of the tool orientation (position + L x rotation)
    measurements: 60
    max_random_tries: 200000         # rejection-sampling budget of the heuristic design

Names in ``skip_pairs`` and ``beam.skip`` may be capsule names, link names
(every capsule of that link), obstacle or half-space names; ``beam.skip`` is meant for a tool
capsule that carries the reflector (the beam starts inside it). Adjacent links (a joint's
parent and child) are skipped automatically; the skip list is for pairs that
are adjacent *by construction* (enclosing capsules that overlap in every
configuration, a robot mounted on its pedestal).
"""

from __future__ import annotations

import math
from collections import OrderedDict
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin

from pin_kpi_oed.cell.camera_setup import CameraSetup, read_camera_setup
from pin_kpi_oed.cell.cell_model import DEFAULT_BEAM_RADIUS_M, DEFAULT_INCIDENCE_MAX_DEG, CapsuleSpec, Cell, HalfSpace
from pin_kpi_oed.cell.fields import read_angles as angles_of
from pin_kpi_oed.cell.fields import read_pose as pose_of
from pin_kpi_oed.cell.fields import read_vec as vec_of
from pin_kpi_oed.cell.fields import where as at
from pin_kpi_oed.errors import InputError, RobotLoadError
from pin_kpi_oed.model.nests import check_nests
from pin_kpi_oed.model.noise import NoiseModel
from pin_kpi_oed.model.robot import Robot, is_robot_name, load_robot
from pin_kpi_oed.validation.schema import validate_cell_dict

#: Folder of the cells shipped with the package.
CELL_DIR = Path(__file__).resolve().parent / "cells"
SHIPPED_CELLS = ("kr15", "kr15_seam", "kr300", "kr500", "ur10")


def _capsule(d: Any, what: str, need_link: bool) -> CapsuleSpec:
    if not isinstance(d, dict):
        raise InputError(f"{what}: expected a mapping with name, a_m, b_m, radius_m, got {d!r}")
    for key in ("name", "a_m", "b_m", "radius_m") + (("link",) if need_link else ()):
        if key not in d:
            raise InputError(f"{what}: missing field '{key}'")
    r = float(d["radius_m"])
    if not (math.isfinite(r) and r >= 0):
        raise InputError(f"{what}.radius_m: must be a finite number >= 0, got {d['radius_m']!r}")
    return CapsuleSpec(str(d["name"]), vec_of(d["a_m"], 3, f"{what}.a_m"), vec_of(d["b_m"], 3, f"{what}.b_m"), r,
                       str(d["link"]) if need_link else None)


def capsules_from_urdf(robot: Robot, where: str = "robot_capsules", kind: str = "collision") -> list[CapsuleSpec]:
    """Robot capsules from the URDF's collision (or visual) geometry, in link frames.

    A cylinder of radius r and length l becomes the capsule of radius r whose segment is the
    cylinder axis (length l); a sphere a capsule of length 0; a capsule stays a capsule; a mesh or
    a box becomes the enclosing capsule fitted to its vertices (:mod:`pin_kpi_oed.cell.meshes`).

    Args:
        robot: the robot.
        where: field name for messages.
        kind: ``collision`` or ``visual`` geometry.

    Raises:
        InputError: unreadable geometry or no geometry at all, naming the URDF.
    """
    from pin_kpi_oed.cell.meshes import capsule_of, geometry_model

    try:
        gm = geometry_model(robot, kind)
    except InputError as exc:
        raise InputError(f"{where}: {str(exc).split(': ', 1)[-1]}") from None
    out: list[CapsuleSpec] = []
    count: dict[str, int] = {}
    for go in gm.geometryObjects:
        link = robot.model.frames[go.parentFrame].name
        a, b, r = capsule_of(robot, go)
        k = count.get(link, 0)
        count[link] = k + 1
        out.append(CapsuleSpec(link if k == 0 else f"{link}_{k}", a, b, r, link))
    if not out:
        raise InputError(f"{where}: {robot.urdf_path} has no {kind} geometry; list the robot capsules "
                         "explicitly in the cell file")
    return out


_KNOWN_KEYS = {"name", "description", "robot", "tool_frame", "base", "tracker", "reflector_m", "tcp_m", "noise",
               "nests_m", "joint_bounds", "robot_capsules", "extra_capsules", "obstacles", "skip_pairs", "beam",
               "incidence_max_deg", "clearance_m", "working_configurations_rad", "working_configurations_deg",
               "measurements", "max_random_tries", "environment", "working_targets", "kinematics",
               "working_paths", "orientation_length_m", "camera", "board"}


def _did_you_mean(unknown: set, known: set[str]) -> str:
    """"; did you mean 'tool_frame' (for 'tool_fram')?" for the unknown keys close to a known one (difflib), else
    the known keys listed."""
    import difflib

    names = sorted(known)
    close = {u: difflib.get_close_matches(u, names, n=1, cutoff=0.6) for u in sorted(map(str, unknown))}
    hints = [f"'{m[0]}' (for '{u}')" for u, m in close.items() if m]
    if hints:
        return "; did you mean " + ", ".join(hints) + "?"
    return f" (known: {', '.join(sorted(known))})"


def _check_top_level(d: Any, source: str) -> None:
    """The file is a mapping of known fields naming a robot."""
    if not isinstance(d, dict):
        raise InputError(f"{source or 'cell'}: expected a YAML mapping at the top level")
    unknown = set(d) - _KNOWN_KEYS
    if unknown:
        raise InputError(f"{at(source, 'cell')}: unknown field(s) {', '.join(sorted(map(str, unknown)))}"
                         + _did_you_mean(unknown, _KNOWN_KEYS))
    if "robot" not in d:
        raise InputError(f"{at(source, 'robot')}: missing field (shipped name or URDF path)")


def _read_robot(d: dict, source: str, base_dir: Path | None) -> Robot:
    """The robot: a shipped name or a URDF path (relative to ``base_dir``)."""
    spec = str(d["robot"])
    if base_dir is not None and not is_robot_name(spec):
        p = Path(spec)
        if not p.is_absolute():
            spec = str((base_dir / p).resolve())
    kin = d.get("kinematics")
    if kin is not None and base_dir is not None and not Path(str(kin)).is_absolute():
        kin = str((base_dir / str(kin)).resolve())
    try:
        return load_robot(spec, d.get("tool_frame"), kinematics=kin)
    except RobotLoadError as exc:
        raise RobotLoadError(f"{at(source, 'robot')}: {exc}") from None


def _read_tracker_setup(d: dict, source: str, camera: CameraSetup | None = None
                        ) -> tuple[pin.SE3, pin.SE3, np.ndarray, np.ndarray, NoiseModel]:
    """(W_T_base, W_T_tracker, reflector in the tool frame (m), TCP in the tool frame (m), noise); with a camera the
    device frame (board or camera) stands for the tracker and the tool-mounted part's origin for the reflector."""
    W_T_base = pose_of(d.get("base"), at(source, "base"))
    if camera is not None:
        for key in ("tracker", "reflector_m", "nests_m"):
            if key in d:
                raise InputError(f"{at(source, key)}: a camera cell has no {key} (the camera and its board are the "
                                 "measuring device)")
        W_T_tracker, reflector = camera.device_in_cell(), camera.tool_mounted().translation.copy()
    else:
        if "tracker" not in d:
            raise InputError(f"{at(source, 'tracker')}: missing field (tracker pose xyz_m, rpy_rad)")
        W_T_tracker = pose_of(d["tracker"], at(source, "tracker"))
        if "reflector_m" not in d:
            raise InputError(f"{at(source, 'reflector_m')}: missing field (reflector in the tool frame, m)")
        reflector = vec_of(d["reflector_m"], 3, at(source, "reflector_m"))
    tcp = vec_of(d.get("tcp_m", [0.0, 0.0, 0.0]), 3, at(source, "tcp_m"))
    try:
        noise = NoiseModel.from_dict(d.get("noise") or {})
    except InputError as exc:
        raise InputError(f"{at(source, 'noise')}: {exc}") from None
    return W_T_base, W_T_tracker, reflector, tcp, noise


def _read_joint_bounds(d: dict, robot: Robot, source: str) -> tuple[np.ndarray, np.ndarray]:
    """Joint bounds of the design (rad): the URDF's, or the cell's ``joint_bounds`` override."""
    lo, hi = robot.q_lower.copy(), robot.q_upper.copy()
    jb = d.get("joint_bounds")
    if jb is None:
        return lo, hi
    w = at(source, "joint_bounds")
    if not isinstance(jb, dict):
        raise InputError(f"{w}: expected a mapping with lower_rad/upper_rad (or _deg)")
    lo2 = angles_of(jb, "lower", robot.nq, w, required=False)
    hi2 = angles_of(jb, "upper", robot.nq, w, required=False)
    lo = lo if lo2 is None else lo2
    hi = hi if hi2 is None else hi2
    bad = np.flatnonzero(~(lo < hi))
    if bad.size:
        j = bad[0]
        raise InputError(f"{w}: joint {robot.joint_names[j]} bounds [{lo[j]:.4g}, {hi[j]:.4g}] rad are empty")
    return lo, hi


def _read_robot_capsules(d: dict, robot: Robot, source: str) -> list[CapsuleSpec]:
    """Robot capsules (link frames): the URDF's collision cylinders or a list, plus ``extra_capsules``."""
    rc = d.get("robot_capsules", "urdf")
    if rc == "urdf" or rc is None:
        caps = capsules_from_urdf(robot, at(source, "robot_capsules"))
    elif rc == "urdf_visual":
        caps = capsules_from_urdf(robot, at(source, "robot_capsules"), kind="visual")
    elif isinstance(rc, list):
        caps = [_capsule(c, at(source, f"robot_capsules[{i}]"), True) for i, c in enumerate(rc)]
    else:
        raise InputError(f"{at(source, 'robot_capsules')}: expected 'urdf', 'urdf_visual' or a list of capsules, "
                         f"got {rc!r}")
    caps += [_capsule(c, at(source, f"extra_capsules[{i}]"), True)
             for i, c in enumerate(d.get("extra_capsules") or [])]
    links = body_names(robot)
    for c in caps:
        if c.link not in links:
            raise InputError(f"{at(source, 'robot_capsules')}: capsule '{c.name}' is on unknown link '{c.link}' "
                             f"(links of {robot.name}: {', '.join(sorted(links))})")
    return caps


def _read_obstacles(d: dict, source: str) -> tuple[list[CapsuleSpec], list[HalfSpace]]:
    """Obstacle capsules and half-spaces (cell frame)."""
    obs = d.get("obstacles") or {}
    if not isinstance(obs, dict):
        raise InputError(f"{at(source, 'obstacles')}: expected a mapping with 'capsules' and 'half_spaces'")
    unknown = set(obs) - {"capsules", "half_spaces"}
    if unknown:
        raise InputError(f"{at(source, 'obstacles')}: unknown field(s) {', '.join(sorted(map(str, unknown)))}"
                         + _did_you_mean(unknown, {"capsules", "half_spaces"}))
    obstacles = [_capsule(c, at(source, f"obstacles.capsules[{i}]"), False)
                 for i, c in enumerate(obs.get("capsules") or [])]
    halfs = []
    for i, h in enumerate(obs.get("half_spaces") or []):
        w = at(source, f"obstacles.half_spaces[{i}]")
        if not isinstance(h, dict) or not {"name", "normal", "offset_m"} <= set(h):
            raise InputError(f"{w}: expected a mapping with name, normal, offset_m")
        nrm = vec_of(h["normal"], 3, f"{w}.normal")
        if np.linalg.norm(nrm) < 1e-9:
            raise InputError(f"{w}.normal: must not be zero")
        halfs.append(HalfSpace(str(h["name"]), nrm / np.linalg.norm(nrm), float(h["offset_m"])))
    return obstacles, halfs


def _read_environment(d: dict, source: str, base_dir: Path | None) -> list:
    """Obstacles from mesh / URDF files (:mod:`pin_kpi_oed.cell.environment`), paths relative to the cell file."""
    from pin_kpi_oed.cell.environment import load_environment_object

    return [load_environment_object(e, i, base_dir, source, pose_of) for i, e in enumerate(d.get("environment") or [])]


class _Names:
    """The names ``skip_pairs`` and ``beam.skip`` may use: capsules, their links, obstacles, half-spaces,
    environment objects (standing for all their capsules and solids)."""

    def __init__(self, caps: list[CapsuleSpec], obstacles: list[CapsuleSpec], halfs: list[HalfSpace],
                 links: set[str], source: str, environment: list | None = None):
        env = list(environment or [])
        names = [c.name for c in caps] + [o.name for o in obstacles] + [h.name for h in halfs] + [e.name for e in env]
        dup = sorted({x for x in names if names.count(x) > 1})
        if dup:
            raise InputError(f"{at(source, 'cell')}: duplicate capsule/obstacle name(s) {', '.join(dup)}")
        self.known = set(names) | {c.link for c in caps}
        self.links = links
        #: environment object name -> its capsule names (what the optimiser's skip lists must hold)
        self.groups = {e.name: [c.name for c in e.capsules] for e in env}

    def expand(self, x: str) -> list[str]:
        """``x`` and, for an environment object, the names of its capsules."""
        return [x] + self.groups.get(x, [])

    def check(self, x: Any, what: str) -> str:
        """``x`` as a known name.

        Raises:
            InputError: an unknown name (or a link without capsules), naming ``what``.
        """
        x = str(x)
        if x not in self.known:
            kind = "link or obstacle" if x not in self.links else "link without capsules"
            raise InputError(f"{what}: unknown {kind} name '{x}' (known: {', '.join(sorted(self.known))})")
        return x


def _read_skip_pairs(d: dict, names: _Names, source: str) -> list[tuple[str, str]]:
    """Pairs of names never checked against each other."""
    skips = []
    for i, pr in enumerate(d.get("skip_pairs") or []):
        w = at(source, f"skip_pairs[{i}]")
        if not isinstance(pr, (list, tuple)) or len(pr) != 2:
            raise InputError(f"{w}: expected a pair of names, got {pr!r}")
        a, b = names.check(pr[0], w), names.check(pr[1], w)
        skips += [(x, y) for x in names.expand(a) for y in names.expand(b)]
    return skips


def _read_beam(d: dict, names: _Names, source: str) -> tuple[float, list[str]]:
    """(beam radius (m), names the beam is not checked against)."""
    beam = d.get("beam") or {}
    if not isinstance(beam, dict):
        raise InputError(f"{at(source, 'beam')}: expected a mapping with radius_m and skip")
    beam_r = float(beam.get("radius_m", DEFAULT_BEAM_RADIUS_M))
    if not (math.isfinite(beam_r) and beam_r >= 0):
        raise InputError(f"{at(source, 'beam.radius_m')}: must be >= 0, got {beam.get('radius_m')!r}")
    skip_where = at(source, "beam.skip")
    return beam_r, [y for x in beam.get("skip") or [] for y in names.expand(names.check(x, skip_where))]


def _read_limits(d: dict, source: str) -> tuple[float, float, int, int]:
    """(incidence limit (deg), clearance (m), measurements, random-design budget)."""
    inc = float(d.get("incidence_max_deg", DEFAULT_INCIDENCE_MAX_DEG))
    if not (0 < inc <= 180):
        raise InputError(f"{at(source, 'incidence_max_deg')}: must be in (0, 180] deg, got {inc}")
    clr = float(d.get("clearance_m", 0.0))
    if not (math.isfinite(clr) and clr >= 0):
        raise InputError(f"{at(source, 'clearance_m')}: must be >= 0 m, got {clr}")
    m = int(d.get("measurements", 60))
    tries = int(d.get("max_random_tries", 200_000))
    if m < 1 or tries < 1:
        raise InputError(f"{at(source, 'measurements')}: measurements and max_random_tries must be >= 1")
    return inc, clr, m, tries


def _read_working_configurations(d: dict, robot: Robot, source: str) -> np.ndarray:
    """Working configurations (t, n) rad, within the joint bounds (none if only ``working_targets`` are given)."""
    qw = angles_of(d, "working_configurations", robot.nq, at(source, "cell"),
                 required=not (d.get("working_targets") or d.get("working_paths")))
    if qw is None:
        return np.zeros((0, robot.nq))
    qw = np.atleast_2d(qw)
    robot.check_q(qw, at(source, "working_configurations"))
    return qw


def body_names(robot: Robot) -> set[str]:
    """Names of the robot's links (Pinocchio BODY frames): where capsules can be attached."""
    return {f.name for f in robot.model.frames if f.type == pin.FrameType.BODY}


def cell_from_dict(d: dict, source: str = "", base_dir: Path | None = None, robot: Robot | None = None) -> Cell:
    """Build a :class:`Cell` from the parsed YAML mapping (see the module docstring).

    Args:
        d: the mapping.
        source: file name used in error messages.
        base_dir: folder for relative URDF paths.
        robot: the robot already loaded (a design file's set-up), or None to load the one ``d`` names.

    Returns:
        The cell (names validated against the robot). The robot's joint bounds are set to the cell's.

    Raises:
        InputError: a missing, unknown or invalid field, or an unknown link/obstacle name (named).
        RobotLoadError: the robot cannot be loaded.
    """
    _check_top_level(d, source)
    validate_cell_dict(d, source)
    robot = _read_robot(d, source, base_dir) if robot is None else robot
    camera = read_camera_setup(d, source)
    W_T_base, W_T_tracker, reflector, tcp, noise = _read_tracker_setup(d, source, camera)
    lo, hi = _read_joint_bounds(d, robot, source)
    robot.q_lower, robot.q_upper = lo.copy(), hi.copy()
    caps = _read_robot_capsules(d, robot, source)
    obstacles, halfs = _read_obstacles(d, source)
    env = _read_environment(d, source, base_dir)
    obstacles += [c for e in env for c in e.capsules]
    names = _Names(caps, obstacles, halfs, body_names(robot), source, env)
    skips = _read_skip_pairs(d, names, source)
    beam_r, beam_skip = _read_beam(d, names, source)
    inc, clr, m, tries = _read_limits(d, source)
    qw = _read_working_configurations(d, robot, source)
    cell = Cell(name=str(d.get("name", Path(source).stem if source else "cell")), source=source, robot=robot,
                W_T_base=W_T_base, W_T_tracker=W_T_tracker, reflector_m=reflector, tcp_m=tcp, noise=noise,
                q_lower=lo, q_upper=hi, robot_capsules=caps, obstacles=obstacles, half_spaces=halfs,
                skip_pairs=skips, beam_radius_m=beam_r, beam_skip=beam_skip, incidence_max_deg=inc,
                clearance_m=clr, q_work=qw, measurements=m, max_random_tries=tries, environment=env,
                noise_stated=bool(d.get("noise")), camera=camera)
    if d.get("nests_m") is not None:
        cell.nests_m = check_nests(reflector, d["nests_m"], at(source, "nests_m"))
    if d.get("working_targets"):
        from pin_kpi_oed.cell.working_targets import solve_working_targets

        cell.q_work = np.vstack([qw, solve_working_targets(cell, d["working_targets"], source)])
    cell.orientation_length_m = _read_orientation_length(d, source)
    if d.get("working_paths"):
        from pin_kpi_oed.cell.paths import read_working_paths

        cell.paths = read_working_paths(cell, d["working_paths"], source, base_dir)
        if cell.q_work.shape[0] == 0:  # the point KPI of a cell with paths only: every path's end points
            cell.q_work = np.vstack([np.vstack([p.Q[0], p.Q[-1]]) for p in cell.paths])
    return cell


def _read_orientation_length(d: dict, source: str) -> float:
    """``orientation_length_m``: the length weighting the tool's orientation in the 6-D KPI (m, default 0.2)."""
    v = d.get("orientation_length_m", 0.2)
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v <= 0:
        raise InputError(f"{at(source, 'orientation_length_m')}: expected a positive length in m, got {v!r}")
    if v > 5.0:
        raise InputError(f"{at(source, 'orientation_length_m')}: {v:g} m is longer than any tool; the value looks "
                         f"like mm: give it in m (e.g. 0.2 for 200 mm)")
    return float(v)


def resolve_cell(spec: str | Path) -> Path:
    """Path of a cell: a shipped name (``kr15``, ``kr300``, ``kr500``, ``ur10``) or a YAML path."""
    key = str(spec)
    if key.lower() in SHIPPED_CELLS:
        return CELL_DIR / f"{key.lower()}.yaml"
    return Path(key)


def load_cell(spec: str | Path) -> Cell:
    """Load a cell from a shipped name or a YAML file.

    Args:
        spec: ``kr15``, ``kr300``, ``kr500`` or a path to a YAML cell file.

    Returns:
        The :class:`Cell`.

    Raises:
        InputError: missing/unreadable file, invalid YAML, or an invalid field (named with the file).
        RobotLoadError: the robot of the cell cannot be loaded.
    """
    path = resolve_cell(spec)
    if not path.exists():
        raise InputError(f"{path}: no such cell file (shipped cells: {', '.join(SHIPPED_CELLS)})")
    try:
        text = path.read_text()
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"{path}: cannot read the cell file ({exc})") from None
    return cell_from_dict(parse_cell_text(text, path), str(path), path.resolve().parent)


#: parsed cell files by their text, most recent last: a text parsed before in this process is not parsed again
_PARSED: OrderedDict[str, Any] = OrderedDict()
_PARSED_SIZE = 32
_PLAIN = (str, int, float, bool, type(None))


def _plain_copy(x: Any) -> Any:
    """A copy of parsed YAML of mappings, lists and scalars: new mappings and lists, the (immutable) scalars shared."""
    if type(x) is dict:
        return {k: _plain_copy(v) for k, v in x.items()}
    if type(x) is list:
        return [_plain_copy(v) for v in x]
    return x


def _is_plain(x: Any) -> bool:
    """Whether ``x`` holds only mappings (scalar keys), lists and scalars: what :func:`_plain_copy` copies whole."""
    if type(x) is dict:
        return all(type(k) in _PLAIN and _is_plain(v) for k, v in x.items())
    if type(x) is list:
        return all(map(_is_plain, x))
    return type(x) in _PLAIN


def parse_cell_text(text: str, path: Path) -> Any:
    """A cell file's text parsed (YAML), a text parsed before given as a copy of that parse (mappings and lists
    new: the caller may change them).

    Args:
        text: the file's text.
        path: the file, for the message.

    Returns:
        The parsed document (a mapping for a cell file; whatever the YAML holds otherwise).

    Raises:
        InputError: invalid YAML (PyYAML's message, first line).
    """
    import yaml

    hit = _PARSED.get(text)
    if hit is not None:
        try:
            _PARSED.move_to_end(text)
        except KeyError:  # dropped by another thread meanwhile: the parse in hand is still this text's
            pass
        return _plain_copy(hit)
    try:
        # libyaml's parser where PyYAML has it (a shipped cell: 1 ms instead of 11 ms; the same constructor, so the
        # same values); a file it refuses is parsed again by PyYAML's own, whose message the refusal quotes as before
        d = yaml.load(text, Loader=getattr(yaml, "CSafeLoader", yaml.SafeLoader))
    except yaml.YAMLError:
        try:
            d = yaml.safe_load(text)
        except yaml.YAMLError as exc:
            first = str(exc).strip().splitlines()[0]
            raise InputError(f"{path}: invalid YAML ({first})") from None
    try:
        plain = _is_plain(d)
    except RecursionError:  # an alias holding itself
        plain = False
    if plain and d is not None:
        _PARSED[text] = _plain_copy(d)
        while len(_PARSED) > _PARSED_SIZE:
            try:
                _PARSED.popitem(last=False)
            except KeyError:  # emptied by another thread meanwhile
                break
    return d
