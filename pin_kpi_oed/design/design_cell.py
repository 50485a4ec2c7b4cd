"""The set-up and cell of a design file (see :mod:`pin_kpi_oed.design.design_file`): a stored cell (``design --json``)
by the cell file's reader (:func:`read_stored_cell`); a hand-written or older file's read tolerantly: every field at
the top level, then under ``cell``; alias keys (``a``/``a_m``, ``radius``/``radius_m``, ...); what is assumed or
recomputed is said in the notes (one line each). Frames and units: SI; obstacles and half-spaces in the world frame,
robot capsules in their link frames."""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any
from collections.abc import Mapping

import numpy as np
import pinocchio as pin

from pin_kpi_oed.cell.cell import Cell, CapsuleSpec, HalfSpace, capsules_from_urdf, cell_from_dict
from pin_kpi_oed.cell.cell_model import DEFAULT_BEAM_RADIUS_M, DEFAULT_INCIDENCE_MAX_DEG
from pin_kpi_oed.cell.environment import environment_from_dicts
from pin_kpi_oed.cell.feasibility import FeasibilityChecker
from pin_kpi_oed.errors import InputError
from pin_kpi_oed.model.robot import Robot
from pin_kpi_oed.model.serialize import model_from_dict, se3_from_matrix
from pin_kpi_oed.model.tracker import TrackerModel

__all__ = ["Fields", "read_array", "read_json", "read_model", "read_q_work", "read_cell", "stored_cell",
           "cell_file_dict", "read_stored_cell", "check_stored_tracker", "skip_what_collides_at_work"]


def read_array(v: Any, shape: tuple[int, ...] | None, what: str) -> np.ndarray:
    """Finite numbers of the given shape (None: any)."""
    try:
        a = np.asarray(v, dtype=float)
    except (TypeError, ValueError):
        raise InputError(f"{what}: expected numbers, got {str(v)[:60]!r}") from None
    if shape is not None:
        if a.size != int(np.prod(shape)):
            raise InputError(f"{what}: expected shape {shape}, got {a.shape}")
        a = a.reshape(shape)
    if not np.all(np.isfinite(a)):
        raise InputError(f"{what}: contains NaN or inf")
    return a


def _first(d: Mapping, *keys: str, default: Any = None) -> Any:
    """The value of the first key present (and not null)."""
    for k in keys:
        if k in d and d[k] is not None:
            return d[k]
    return default


class Fields:
    """Look-up of a field at the top level of the file, then under ``cell``."""

    def __init__(self, d: Mapping):
        self.d = d
        self.cell = d.get("cell") if isinstance(d.get("cell"), Mapping) else {}

    def get(self, *keys: str, default: Any = None) -> Any:
        v = _first(self.d, *keys)
        return _first(self.cell, *keys, default=default) if v is None else v


# ============================================================================ reading steps
def read_json(source: str | os.PathLike | Mapping) -> tuple[dict, str, Path]:
    """(parsed dict, name for messages, folder for relative paths)."""
    if isinstance(source, Mapping):
        return dict(source), "<dict>", Path.cwd()
    p = Path(source)
    try:
        d = json.loads(p.read_text())
    except FileNotFoundError:
        raise InputError(f"{p}: no such file") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"{p}: cannot read ({exc})") from None
    except json.JSONDecodeError as exc:
        raise InputError(f"{p}: not valid JSON ({exc})") from None
    if not isinstance(d, Mapping):
        raise InputError(f"{p}: expected a JSON object at the top level")
    return dict(d), str(p), p.resolve().parent


def read_model(f: Fields, where: str, base_dir: Path, notes: list[str]) -> TrackerModel:
    """The measurement model; a moved ``robot.urdf_path`` falls back to ``robot.name``."""
    setup = {k: f.get(k) for k in ("robot", "tool_frame", "tracker_T_base", "reflector_m", "tcp_m", "noise",
                                   "fixed", "prior", "nests_m") if f.get(k) is not None}
    rob = setup.get("robot")
    if rob is None:
        raise InputError(f"{where}: missing field 'robot' (a name such as kr15, or {{urdf_path, tool_frame}})")
    if isinstance(rob, Mapping):
        rob = dict(rob)
        up = rob.get("urdf_path")
        if up and not Path(up).is_absolute() and (base_dir / up).exists():
            rob["urdf_path"] = str(base_dir / up)
        elif up and not Path(up).exists() and rob.get("name"):
            notes.append(f"robot.urdf_path {up} does not exist: loading robot '{rob['name']}' instead")
            rob["urdf_path"] = None
        setup["robot"] = rob
    if "tracker_T_base" not in setup:
        notes.append("no tracker_T_base: the tracker is drawn at the robot base")
    setup.setdefault("reflector_m", [0.0, 0.0, 0.0])
    if isinstance(setup.get("noise"), (int, float)):
        setup["noise"] = {"sigma_xyz_m": [float(setup["noise"])] * 3}
    return model_from_dict(setup, where)


def read_q_work(f: Fields, robot: Robot, where: str, notes: list[str]) -> np.ndarray:
    """Working configurations (t, n) rad; default the neutral configuration."""
    qw = f.get("q_work")
    if qw is None:
        notes.append("no q_work: the working configuration is the robot's neutral one")
        return robot.neutral()[None]
    q_work = np.atleast_2d(read_array(qw, None, f"{where}: q_work"))
    if q_work.shape[1] != robot.nq:
        raise InputError(f"{where}: q_work has {q_work.shape[1]} joint values per configuration, "
                         f"{robot.name} has {robot.nq}")
    return q_work


def _parse_capsules(items: Any, where: str) -> list[CapsuleSpec]:
    """Robot capsules: a list of {link, a, b, radius} or {link: [{a, b, radius}, ...]}."""
    out: list[CapsuleSpec] = []
    if isinstance(items, Mapping):
        items = [dict(c, link=link) for link, cs in items.items() for c in (cs if isinstance(cs, list) else [cs])]
    for i, c in enumerate(items or []):
        w = f"{where}[{i}]"
        if not isinstance(c, Mapping):
            raise InputError(f"{w}: expected an object with link, a, b, radius")
        a = read_array(_first(c, "a_m", "a", "p0", "start"), (3,), f"{w}.a_m")
        b = read_array(_first(c, "b_m", "b", "p1", "end", default=a), (3,), f"{w}.b_m")
        r = float(read_array(_first(c, "radius_m", "radius", "r"), (1,), f"{w}.radius_m")[0])
        link = _first(c, "link", "frame", "parent")
        out.append(CapsuleSpec(str(_first(c, "name", default=f"{link or 'capsule'}_{i}")), a, b, r,
                               str(link) if link is not None else None))
    return out


def _read_robot_capsules(f: Fields, robot: Robot, where: str, notes: list[str]) -> list[CapsuleSpec]:
    """Robot capsules (link frames): the file's, else the URDF's collision cylinders, else none."""
    raw = f.get("capsules", "robot_capsules")
    if raw is None or isinstance(raw, str):  # absent, or "urdf" as in a cell file
        try:
            capsules = capsules_from_urdf(robot, f"{where}: capsules")
        except InputError as exc:
            notes.append(f"no robot capsules ({exc})")
            return []
        notes.append("no capsules in the file: robot capsules taken from the URDF's collision cylinders")
        return capsules
    capsules = _parse_capsules(raw, f"{where}: capsules")
    for c in capsules:
        if c.link is None or not robot.model.existFrame(c.link, pin.FrameType.BODY):
            raise InputError(f"{where}: capsule '{c.name}' is attached to unknown link '{c.link}'")
    return capsules


def _parse_obstacles(items: Any, where: str) -> list[CapsuleSpec]:
    """Obstacles (world frame): capsules ``{a, b, radius}`` and spheres ``{center, radius}`` (capsules of length 0)."""
    out: list[CapsuleSpec] = []
    for i, o in enumerate(items or []):
        w = f"{where}[{i}]"
        if not isinstance(o, Mapping):
            raise InputError(f"{w}: expected an object (capsule: a, b, radius; sphere: center, radius)")
        kind = str(_first(o, "type", "kind", "shape", default="")).lower()
        if not kind:
            kind = "capsule" if ("a" in o or "a_m" in o or "p0" in o) else "sphere"
        name = str(_first(o, "name", default=f"{kind}_{i}"))
        r = float(read_array(_first(o, "radius_m", "radius", "r", default=0.0), (1,), f"{w}.radius_m")[0])
        if kind in ("capsule", "cylinder", "segment"):
            a = read_array(_first(o, "a_m", "a", "p0", "start"), (3,), f"{w}.a_m")
            b = read_array(_first(o, "b_m", "b", "p1", "end", default=a), (3,), f"{w}.b_m")
        elif kind in ("sphere", "point"):
            a = b = read_array(_first(o, "center_m", "center", "centre", "c", "a_m", "a"), (3,), f"{w}.center")
        else:
            raise InputError(f"{w}: unknown obstacle type '{kind}' (capsule, sphere: the shapes of the cell model)")
        out.append(CapsuleSpec(name, a, b.copy(), r))
    return out


def _parse_half_spaces(items: Any, where: str) -> list[HalfSpace]:
    """Half-spaces: {normal, offset} (free where normal·x >= offset), {normal, point}, or [nx, ny, nz, offset]."""
    out: list[HalfSpace] = []
    for i, h in enumerate(items or []):
        w = f"{where}[{i}]"
        name = None
        if isinstance(h, Mapping):
            n = read_array(_first(h, "normal", "n"), (3,), f"{w}.normal")
            if "point" in h:
                d = float(n @ read_array(h["point"], (3,), f"{w}.point"))
            else:
                d = float(read_array(_first(h, "offset", "d", "offset_m", default=0.0), (1,), f"{w}.offset")[0])
            name = _first(h, "name")
        else:
            a = read_array(h, (4,), w)
            n, d = a[:3], float(a[3])
        nn = float(np.linalg.norm(n))
        if nn < 1e-12:
            raise InputError(f"{w}.normal: zero vector")
        n, d = n / nn, d / nn
        if name is None:
            name = "floor" if n[2] > 0.9 else ("ceiling" if n[2] < -0.9 else f"wall_{i}")
        out.append(HalfSpace(str(name), n, d))
    return out


def _read_obstacles(f: Fields, where: str) -> tuple[list[CapsuleSpec], list[HalfSpace]]:
    """Obstacle capsules and half-spaces (a list each, or a cell's ``{capsules, half_spaces}``)."""
    obs_raw, hs_raw = f.get("obstacles"), f.get("half_spaces", "halfspaces", "planes")
    if isinstance(obs_raw, Mapping):
        hs_raw = hs_raw if hs_raw is not None else obs_raw.get("half_spaces")
        obs_raw = obs_raw.get("capsules")
    return _parse_obstacles(obs_raw, f"{where}: obstacles"), _parse_half_spaces(hs_raw, f"{where}: half_spaces")


def _read_joint_bounds(f: Fields, robot: Robot, where: str) -> tuple[np.ndarray, np.ndarray]:
    """The cell's joint bounds (rad), default the robot's."""
    lo = f.get("q_lower_rad", default=robot.q_lower)
    hi = f.get("q_upper_rad", default=robot.q_upper)
    return read_array(lo, (robot.nq,), f"{where}: q_lower_rad"), read_array(hi, (robot.nq,), f"{where}: q_upper_rad")


def read_cell(f: Fields, model: TrackerModel, where: str, notes: list[str]) -> Cell:
    """The cell of the design: model + world placement + geometry + limits + working configurations."""
    robot = model.robot
    W_T_base = se3_from_matrix(f.get("world_T_base", "W_T_base", default=np.eye(4)), f"{where}: world_T_base")
    q_lower, q_upper = _read_joint_bounds(f, robot, where)
    capsules = _read_robot_capsules(f, robot, where, notes)
    obstacles, half_spaces = _read_obstacles(f, where)
    skip = [(str(p[0]), str(p[1])) for p in (f.get("skip_pairs", "pairs_to_skip", "ignore_pairs") or [])
            if isinstance(p, (list, tuple)) and len(p) >= 2]
    beam = f.get("beam", default={})
    beam = beam if isinstance(beam, Mapping) else {}
    return Cell(name=str(f.get("name", default=robot.name)), source=where, robot=robot, W_T_base=W_T_base,
                W_T_tracker=W_T_base * model.tracker_T_base.inverse(), reflector_m=model.reflector_m,
                tcp_m=model.tcp_m, noise=model.noise, q_lower=q_lower, q_upper=q_upper, robot_capsules=capsules,
                obstacles=obstacles, half_spaces=half_spaces, skip_pairs=skip,
                beam_radius_m=float(beam.get("radius_m", DEFAULT_BEAM_RADIUS_M)),
                beam_skip=[str(x) for x in beam.get("skip") or []],
                incidence_max_deg=float(f.get("incidence_limit_deg", "incidence_max_deg",
                                              default=DEFAULT_INCIDENCE_MAX_DEG)),
                clearance_m=float(f.get("clearance_m", default=0.0)),
                q_work=read_q_work(f, robot, where, notes),
                environment=environment_from_dicts(f.get("environment"), obstacles, where, notes),
                nests_m=model.nests_m.copy() if model.n_nests > 1 else None)


def stored_cell(d: Mapping) -> Mapping | None:
    """The cell block ``design --json`` writes (:meth:`~pin_kpi_oed.cell.cell_model.Cell.to_dict`), or None for a
    hand-written or older file without one."""
    c = d.get("cell")
    return c if isinstance(c, Mapping) and STORED_CELL_KEYS <= set(c) else None


#: the fields by which :func:`stored_cell` recognises a cell block written by ``design --json``
STORED_CELL_KEYS = {"W_T_base", "W_T_tracker", "robot_capsules", "q_lower_rad", "q_upper_rad", "beam"}


def _pose(M: Any, what: str) -> dict:
    """A 4×4 homogeneous matrix as the cell file's ``{xyz_m, rpy_rad}``."""
    T = se3_from_matrix(M, what)
    return {"xyz_m": T.translation.tolist(), "rpy_rad": pin.rpy.matrixToRpy(T.rotation).tolist()}


def cell_file_dict(f: Fields, stored: Mapping, robot: Robot, where: str) -> dict:
    """The cell file's mapping (:func:`~pin_kpi_oed.cell.cell.cell_from_dict`) of a design file's stored cell, the
    viewer's copies at the top level first (``capsules``, ``obstacles``, ``half_spaces``, ``q_work``). The
    environment files' capsules stay obstacles (the files are read again by the caller); names of environment
    objects leave the skip lists, whose capsule pairs they hold."""
    env_names = {str(e.get("name")) for e in stored.get("environment") or [] if isinstance(e, Mapping)}
    obstacles = f.get("obstacles")
    if isinstance(obstacles, Mapping):
        obstacles, halfs = obstacles.get("capsules"), obstacles.get("half_spaces")
    else:
        halfs = f.get("half_spaces")
    beam = stored.get("beam") if isinstance(stored.get("beam"), Mapping) else {}
    out = {"name": str(stored.get("name") or robot.name), "robot": robot.name,
           "base": _pose(stored["W_T_base"], f"{where}: cell.W_T_base"),
           "tracker": _pose(stored["W_T_tracker"], f"{where}: cell.W_T_tracker"),
           "reflector_m": stored.get("reflector_m"), "tcp_m": stored.get("tcp_m", [0.0, 0.0, 0.0]),
           **({"nests_m": stored["nests_m"]} if stored.get("nests_m") is not None else {}),
           "noise": {k: v for k, v in (stored.get("noise") or {}).items() if v is not None},
           "joint_bounds": {"lower_rad": stored["q_lower_rad"], "upper_rad": stored["q_upper_rad"]},
           "robot_capsules": f.get("capsules", "robot_capsules"),
           "obstacles": {"capsules": obstacles or [], "half_spaces": halfs or []},
           "skip_pairs": [list(p) for p in stored.get("skip_pairs") or [] if not env_names & {str(x) for x in p}],
           "beam": {"radius_m": beam.get("radius_m", DEFAULT_BEAM_RADIUS_M),
                    "skip": [x for x in beam.get("skip") or [] if str(x) not in env_names]},
           "incidence_max_deg": f.get("incidence_limit_deg", "incidence_max_deg", default=DEFAULT_INCIDENCE_MAX_DEG),
           "clearance_m": stored.get("clearance_m", 0.0),
           "working_configurations_rad": f.get("q_work")}
    for key in ("measurements", "max_random_tries", "orientation_length_m"):
        if stored.get(key) is not None:
            out[key] = stored[key]
    return out


def read_stored_cell(f: Fields, stored: Mapping, model: TrackerModel, where: str, notes: list[str]) -> Cell:
    """The cell of a design file that stores it: the cell file's reader
    (:func:`~pin_kpi_oed.cell.cell.cell_from_dict`, the same checks as ``load_cell``) on :func:`cell_file_dict`,
    with the set-up's robot; the environment files read again (:func:`environment_from_dicts`)."""
    cell = cell_from_dict(cell_file_dict(f, stored, model.robot, where), f"{where}: cell", robot=model.robot)
    check_stored_tracker(f.d, stored, cell, where)
    cell.environment = environment_from_dicts(stored.get("environment"), cell.obstacles, where, notes)
    return cell


#: largest disagreement (m, rad) between a stored cell's ``tracker_T_base`` and its world frames: rounding in a file
#: is far below it, a hand edit far above
TRACKER_TOL = 1e-6


def check_stored_tracker(d: Mapping, stored: Mapping, cell: Cell, where: str) -> None:
    """The ``tracker_T_base`` of a design file that stores its cell (at the top level and under ``cell``) checked as
    a model file checks it (a rigid transform) and against the cell's world frames it is derived from
    (``W_T_tracker⁻¹ · W_T_base``, what the design used): an edit of it alone is refused, not drawn or ignored.

    Args:
        d: the design file's document.
        stored: its stored cell (``cell``).
        cell: the cell read from it.
        where: the file (for messages).

    Raises:
        InputError: not a rigid transform, or disagreeing with the world frames (field named, by how much).
    """
    for field, M in (("tracker_T_base", d.get("tracker_T_base")),
                     ("cell.tracker_T_base", stored.get("tracker_T_base"))):
        if M is None:
            continue
        T = se3_from_matrix(M, f"{where}: {field}")
        v = pin.log6(T.inverse() * cell.tracker_T_base).vector
        gap_m, gap_rad = float(np.linalg.norm(v[:3])), float(np.linalg.norm(v[3:]))
        if gap_m > TRACKER_TOL or gap_rad > TRACKER_TOL:
            raise InputError(f"{where}: {field} disagrees with cell.W_T_tracker^-1 * cell.W_T_base (by "
                             f"{gap_m * 1e3:.3g} mm, {gap_rad:.3g} rad); the tracker is placed by the cell's world "
                             f"frames: edit cell.W_T_tracker / cell.W_T_base (or delete {field})")


#: share of seeded random configurations in which a pair must collide to count as overlapping by construction
_BY_CONSTRUCTION_SHARE = 0.5


def skip_what_collides_at_work(cell: Cell, notes: list[str], has_skip_lists: bool) -> list[str]:
    """Skip what overlaps *by construction* (files without skip lists); report what collides at work.

    Loading a design never widens what is allowed: a file that carries its skip lists (``design --json``
    writes them) gets nothing added. A file without them gets a pair (or beam target) added only when it
    collides at every working configuration *and* in at least half of 64 seeded random configurations
    within the joint bounds (enclosing capsules of adjacent links, a robot standing on its floor); a pair
    that collides at a working configuration otherwise (a working configuration edited into a wall) is
    kept in the check and returned.

    Returns:
        One line per working configuration in collision (``working configuration #k: a|b 205.3 mm inside``).
    """
    chk = FeasibilityChecker(cell)
    D = chk.distances(cell.q_work)
    always = np.all(D < 0, axis=0)
    if always.any() and not has_skip_lists:
        rng = np.random.default_rng(0)
        Qr = cell.q_lower + rng.random((64, cell.q_lower.size)) * (cell.q_upper - cell.q_lower)
        cols = np.flatnonzero(always)
        Dr = chk.distances(Qr)[:, cols]
        by_construction = np.zeros_like(always)
        by_construction[cols] = np.mean(Dr < 0, axis=0) >= _BY_CONSTRUCTION_SHARE
        pairs = [chk.pair_names[k] for k in np.flatnonzero(by_construction[:chk.n_pairs])]
        beam = [chk.beam_names[k] for k in np.flatnonzero(by_construction[chk.n_pairs:])]
        if pairs:
            cell.skip_pairs.extend(pairs)
            notes.append("in collision at every working configuration and by construction, not checked "
                         "(skip_pairs): " + ", ".join(f"{a}|{b}" for a, b in pairs))
        if beam:
            cell.beam_skip.extend(beam)
            notes.append("blocking the beam at every working configuration and by construction, not checked "
                         "against the beam: " + ", ".join(beam))
        if pairs or beam:
            chk = FeasibilityChecker(cell)
            D = chk.distances(cell.q_work)
    problems = []
    for k, d in enumerate(D[:, :chk.n_pairs] - cell.clearance_m):
        if d.size and d.min() < -1e-7:
            j = int(np.argmin(d))
            problems.append(f"working configuration #{k}{' (home)' if k == 0 else ''} collides: {chk.names[j]} "
                            f"{-d[j] * 1e3:.1f} mm inside")
    if problems:
        notes.append("; ".join(problems))
    return problems
