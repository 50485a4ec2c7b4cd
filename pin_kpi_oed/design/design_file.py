"""Design files: the JSON a design run writes (``pin-kpi-oed design --json``), read tolerantly.

:func:`load_design` turns a design JSON (or its dict) into a :class:`DesignFile`: the measurement
model of the set-up (robot, tracker, reflector, TCP, noise, fixed parameters and prior, as
:mod:`pin_kpi_oed.model.serialize` reads them), the :class:`~pin_kpi_oed.cell.cell.Cell` it was
designed in (the same cell model the optimiser and the independent check use), and the designs.
The viewer, the report figures and ``pin-kpi-oed view`` read designs through it.

Tolerant reading: hand-written or older files may leave out most of the cell. Every field is
looked up at the top level, then under ``cell`` (where ``design --json`` writes the full cell);
alias keys are accepted (``a``/``a_m``, ``radius``/``radius_m``, ...); what is assumed or
recomputed is said in :attr:`DesignFile.notes` (one line each):

* no ``tracker_T_base``: the tracker sits at the robot base;
* no ``q_work``: the robot's neutral configuration;
* no robot capsules: the URDF's collision cylinders (:func:`~pin_kpi_oed.cell.cell.capsules_from_urdf`);
* a file without skip lists: capsule pairs in collision at *every* working configuration *and* in most
  random configurations (enclosing capsules that overlap by construction, a robot standing on its floor)
  are added to ``skip_pairs``, and such beam blockers to the beam's skip list; a file with skip lists
  gets nothing added. A working configuration that collides otherwise is never skipped: it is noted and
  kept in :attr:`DesignFile.work_collisions` (``export`` refuses it unless ``--force``);
* a stored ``cov_s_m2`` is checked against the one its ``q_meas`` give (the file's numbers are not
  trusted; a mismatch is noted and the recomputed one used, a singular design gets NaN); a missing or
  mis-shaped ``cov_s_m2`` is recomputed with :func:`pin_kpi_oed.oed.evaluate.score_design`
  (the same C_s as ``design --json`` and ``evaluate`` write, eq. 19, with the file's prior).

Frames and units: SI. ``world_T_base`` (default identity) places the robot base in the world
(cell) frame, ``tracker_T_base`` the base in the tracker frame. Obstacles and half-spaces are in
the world frame, robot capsules in their link frames; a half-space ``{"normal": n, "offset": d}``
is the free region ``n·x >= d`` (or ``{"normal": n, "point": p}``: ``n·(x - p) >= 0``).
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Any
from collections.abc import Mapping, Sequence

import numpy as np
import pinocchio as pin

from pin_kpi_oed.cell.cell import Cell, CapsuleSpec, HalfSpace, capsules_from_urdf
from pin_kpi_oed.cell.environment import environment_from_dicts
from pin_kpi_oed.cell.feasibility import FeasibilityChecker
from pin_kpi_oed.errors import InputError, PinKpiOedError
from pin_kpi_oed.model.tracker import TrackerModel
from pin_kpi_oed.model.robot import Robot
from pin_kpi_oed.model.serialize import model_from_dict, se3_from_matrix
from pin_kpi_oed.validation.schema import validate_design_dict

def design_document(cell: Cell, problem: Any, results: Sequence[Any], m: int, seed: int, collision: bool = True, *,
                    margins: tuple[float, float] = (0.0, 0.0), given_file: str | None = None,
                    pool_file: str | None = None, until: Any = None, true_checks: Sequence[Any] | None = None,
                    certificate: Any = None, extended_scores: Sequence[dict] | None = None,
                    model_file: str | None = None, prior: str | None = None) -> dict:
    """The design file's JSON document (what ``design --json`` writes and :func:`load_design` reads; SI units).

    Args:
        cell: the cell the designs are checked in (the untightened one).
        problem: the :class:`~pin_kpi_oed.design.optimize.DesignProblem` (model, identifiable set, constraints);
            with ``given_file`` a :class:`~pin_kpi_oed.design.sequential.SequentialProblem`.
        results: the designs (:class:`~pin_kpi_oed.design.optimize.DesignResult`); the ``kpi`` one (else the
            last) is the file's ``q_meas``.
        m: measurements per design; seed: the run's seed; collision: collision avoidance was on.
        margins: clearance (m) and incidence (deg) margins the optimiser designed with.
        given_file: the measured poses designed on top of (their C_s included in every design's ``cov_s_m2``).
        pool_file: the user pool the designs were selected from.
        until: the "how many more poses" answer (:func:`~pin_kpi_oed.design.sequential.poses_until`).
        true_checks: the independent check of every design in ``cell`` (pose clearances m, incidences deg).
        certificate: the optimality certificate (bound of tr(C_s), m²; every design's efficiency).
        extended_scores: per design, the extended-model score (``designs[i]["extended"]``); ``model_file``
            and ``prior`` name the model file and the prior they came from.

    Returns:
        The JSON-able dict.
    """
    from pin_kpi_oed.model.serialize import model_to_dict
    from pin_kpi_oed.oed.evaluate import score_design

    main = next((r for r in results if r.criterion == "kpi"), results[-1])
    doc = {
        **model_to_dict(problem.model),  # robot, tracker_T_base, reflector_m, tcp_m, noise (as `evaluate` reads them)
        "q_work": cell.q_work.tolist(), "joint_names": list(cell.robot.joint_names),
        "capsules": [c.to_dict() for c in cell.robot_capsules], "obstacles": [o.to_dict() for o in cell.obstacles],
        "half_spaces": [h.to_dict() for h in cell.half_spaces], "cell": cell.to_dict(), "measurements": m,
        "seed": seed, "collision_avoidance": collision, "identifiable": [problem.ident.names[i] for i in problem.base],
        "constraint_rows_per_configuration": problem.coll.info.count(),
        "designs": [{**r.to_dict(),
                     "cov_s_m2": score_design(problem.model, r.q_meas, cell.q_work, problem.ident).cov_s_m2.tolist()}
                    for r in results],
        "q_meas": main.q_meas.tolist(), "q_meas_criterion": main.criterion,
    }
    if extended_scores is not None:
        _add_extended(doc, problem, extended_scores, model_file, prior)
    doc["clearance_margin_m"], doc["incidence_margin_deg"] = margins
    if given_file:
        _add_given(doc, problem, results, given_file)
    if pool_file:
        doc["pool_file"] = str(pool_file)
    if until is not None:
        doc["poses_until"] = {**until.result_dict(), "target_sigma_m": until.target_sigma_m,
                              "n_more": until.n_more, "sigma_now_m": until.sigma_now_m,
                              "sigma_verified_m": until.sigma_verified_m, "q_added": until.Q_added.tolist()}
    if true_checks is not None:
        for d, rep in zip(doc["designs"], true_checks):
            d["pose_clearance_m"], d["pose_incidence_deg"] = rep.clearance_m.tolist(), rep.incidence_deg.tolist()
    if certificate is not None:
        doc["lower_bound_trace_cs_m2"] = certificate.lower_bound_trace_cs_m2
        doc["certificate"] = certificate.to_dict()
        for d, r in zip(doc["designs"], results):
            d["efficiency"] = certificate.efficiency(r.trace_cs_m2)
    return doc


def _add_extended(doc: dict, problem: Any, scores: Sequence[dict], model_file: str | None, prior: str | None) -> None:
    """``extended_model`` and every ``designs[i]["extended"]`` (``trace_cs_m2`` stays the geometric one)."""
    ext = problem.extended
    doc["extended_model"] = {"file": str(model_file), "prior": prior or "model", "n_geometric": ext.nb,
                             "n_effect": ext.k, "names": list(ext.names),
                             "note": "designs[i].extended: tr(C_s) of the extended model with the prior (the "
                                     "criterion designed for); designs[i].trace_cs_m2: geometric, no prior"}
    for d, e in zip(doc["designs"], scores):
        d["extended"] = e


def _add_given(doc: dict, problem: Any, results: Sequence[Any], given_file: str) -> None:
    """``given`` (the measured poses) and every design's C_s with them (and the prior), m²."""
    from pin_kpi_oed.oed.covariance import kpi_covariance

    doc["given"] = {"file": str(given_file), "q": problem.Q_given.tolist(), "tcp_sigma_m": problem.sigma_tcp(),
                    "prior_file": getattr(problem, "prior_file", None)}
    for d, r in zip(doc["designs"], results):
        F = problem.model.weighted_jacobian(problem.p0, r.q_meas)[:, :, problem.base].reshape(-1, problem.base.size)
        d["cov_s_m2"] = kpi_covariance(np.vstack([problem.F_given, F]), problem.E, problem.kpi_criterion.prior).tolist()


def write_design(path: str | os.PathLike, cell: Cell, problem: Any, results: Sequence[Any], m: int, seed: int,
                 collision: bool = True, **extras: Any) -> Path:
    """Write the design file (atomically) that ``view``, ``export``, ``evaluate`` and :func:`load_design` read.

    Args:
        path: the JSON file to write.
        cell, problem, results, m, seed, collision: as :func:`design_document`.
        **extras: the keyword arguments of :func:`design_document` (margins, given_file, certificate, ...).

    Returns:
        The path written.

    Raises:
        InputError: the path cannot be written (a folder, no such parent folder, not writable).
    """
    from pin_kpi_oed.data.atomic import atomic_write_json

    atomic_write_json(path, design_document(cell, problem, results, m, seed, collision, **extras))
    return Path(path)


#: Readable names of the usual criteria (a design entry's own ``label`` wins).
DESIGN_LABELS: dict[str, str] = {"random": "heuristic", "param": "A on C_p", "kpi": "KPI (A on C_s)"}


@dataclass
class DesignEntry:
    """One design of a design file.

    Attributes:
        criterion: criterion name as in the file (``random``, ``param``, ``kpi``, ...).
        label: readable name.
        q_meas: measurement configurations (m, n) rad.
        cov_s_m2: TCP covariance C_s (3t, 3t) m², tracker frame.
        trace_cs_m2: tr(C_s) (m²).
        cov_source: ``file`` or ``computed`` (recomputed because the file has none).
        info: every other field of the design entry, as read.
        cov_s_honest_m2: the honest C_s (3t, 3t) m², tracker frame like ``cov_s_m2``: the universal-kriging
            covariance with the model discrepancy included (``designs[i].discrepancy.cov_s_m2``, written by
            ``design --model``), or None (older files, no discrepancy).
    """

    criterion: str
    label: str
    q_meas: np.ndarray
    cov_s_m2: np.ndarray
    trace_cs_m2: float
    cov_source: str
    info: dict = field(default_factory=dict)
    cov_s_honest_m2: np.ndarray | None = None

    def covariance(self, honest: bool) -> np.ndarray:
        """C_s (3t, 3t) m², tracker frame: the honest one (discrepancy included) when asked and present, else the
        paper's (tracker noise only)."""
        return self.cov_s_honest_m2 if honest and self.cov_s_honest_m2 is not None else self.cov_s_m2


@dataclass
class DesignFile:
    """A design JSON, parsed tolerantly (see :func:`load_design`).

    Attributes:
        model: the tracker measurement model (robot, tracker_T_base, reflector, TCP, noise, prior).
        cell: the cell the designs live in (robot capsules, obstacles, half-spaces, skip lists,
            beam, incidence limit, clearance, joint bounds, working configurations).
        designs: the designs.
        notes: what was assumed or recomputed (one line each).
        source: file name (or ``<dict>``).
        raw: the parsed JSON.
        work_collisions: working configurations in collision (one line each; never skipped: ``export``
            refuses them unless ``--force``).
    """

    model: TrackerModel
    cell: Cell
    designs: list[DesignEntry]
    notes: list[str] = field(default_factory=list)
    source: str = "<dict>"
    raw: dict = field(default_factory=dict)
    work_collisions: list[str] = field(default_factory=list)

    @property
    def robot(self) -> Robot:
        """The robot."""
        return self.model.robot

    @property
    def world_T_base(self) -> pin.SE3:
        """Pose of the robot base in the world (cell) frame."""
        return self.cell.W_T_base

    @property
    def world_T_tracker(self) -> pin.SE3:
        """Pose of the tracker in the world frame."""
        return self.cell.W_T_tracker

    @property
    def q_work(self) -> np.ndarray:
        """Working configurations (t, n) rad."""
        return self.cell.q_work

    @property
    def capsules(self) -> list[CapsuleSpec]:
        """Robot capsules (link frames)."""
        return self.cell.robot_capsules

    @property
    def obstacles(self) -> list[CapsuleSpec]:
        """Obstacle capsules (world frame)."""
        return self.cell.obstacles

    @property
    def half_spaces(self) -> list[HalfSpace]:
        """Half-spaces (world frame)."""
        return self.cell.half_spaces

    @property
    def incidence_limit_deg(self) -> float:
        """Laser incidence limit (deg, eq. 4)."""
        return self.cell.incidence_max_deg

    @cached_property
    def checker(self) -> FeasibilityChecker:
        """The independent dense check of the cell (Pinocchio + Coal)."""
        return FeasibilityChecker(self.cell)

    def pose_clearance(self, Q: np.ndarray) -> np.ndarray:
        """Smallest clearance (m) of each configuration over every checked pair, the beam included.

        The same value as the design table's ``min clr`` (:class:`FeasibilityChecker`): robot capsules
        against each other (non-adjacent links), obstacles and half-spaces, the beam against all of them,
        minus the cell's required clearance. Negative = penetration; ``inf`` when nothing is checked.
        """
        return self.checker.check(Q).clearance_m

    def to_world(self, Y_tracker: np.ndarray) -> np.ndarray:
        """Points (k, 3) from the tracker frame to the world frame (m)."""
        T = self.world_T_tracker
        return np.atleast_2d(Y_tracker) @ T.rotation.T + T.translation

    def tcp_world(self, Q: np.ndarray | None = None) -> np.ndarray:
        """TCP positions (k, 3) in the world frame at configurations Q (default the working ones), m."""
        Q = self.q_work if Q is None else Q
        return self.to_world(self.model.kpi(np.zeros(self.model.n_params), Q))

    def reflector_world(self, Q: np.ndarray) -> np.ndarray:
        """Reflector positions (k, 3) in the world frame (m)."""
        return self.to_world(self.model.predict(np.zeros(self.model.n_params), Q)[:, :3])

    def incidence_deg(self, Q: np.ndarray) -> np.ndarray:
        """Laser incidence angle of every configuration (deg, eq. 4)."""
        c = self.model.incidence_cos(np.zeros(self.model.n_params), Q)
        return np.degrees(np.arccos(np.clip(c, -1.0, 1.0)))

    def design(self, criterion: str) -> DesignEntry:
        """The design of a criterion.

        Raises:
            InputError: no such design (the known ones are listed).
        """
        for d in self.designs:
            if d.criterion == criterion:
                return d
        raise InputError(f"{self.source}: no design '{criterion}' (designs: "
                         f"{', '.join(d.criterion for d in self.designs)})")


# ============================================================================ tolerant field access
def _arr(v: Any, shape: tuple[int, ...] | None, what: str) -> np.ndarray:
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


class _Fields:
    """Look-up of a field at the top level of the file, then under ``cell``."""

    def __init__(self, d: Mapping):
        self.d = d
        self.cell = d.get("cell") if isinstance(d.get("cell"), Mapping) else {}

    def get(self, *keys: str, default: Any = None) -> Any:
        v = _first(self.d, *keys)
        return _first(self.cell, *keys, default=default) if v is None else v


# ============================================================================ reading steps
def _read_json(source: str | os.PathLike | Mapping) -> tuple[dict, str, Path]:
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


def _read_model(f: _Fields, where: str, base_dir: Path, notes: list[str]) -> TrackerModel:
    """The measurement model; a moved ``robot.urdf_path`` falls back to ``robot.name``."""
    setup = {k: f.get(k) for k in ("robot", "tool_frame", "tracker_T_base", "reflector_m", "tcp_m", "noise",
                                   "fixed", "prior") if f.get(k) is not None}
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


def _read_q_work(f: _Fields, robot: Robot, where: str, notes: list[str]) -> np.ndarray:
    """Working configurations (t, n) rad; default the neutral configuration."""
    qw = f.get("q_work")
    if qw is None:
        notes.append("no q_work: the working configuration is the robot's neutral one")
        return robot.neutral()[None]
    q_work = np.atleast_2d(_arr(qw, None, f"{where}: q_work"))
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
        a = _arr(_first(c, "a_m", "a", "p0", "start"), (3,), f"{w}.a_m")
        b = _arr(_first(c, "b_m", "b", "p1", "end", default=a), (3,), f"{w}.b_m")
        r = float(_arr(_first(c, "radius_m", "radius", "r"), (1,), f"{w}.radius_m")[0])
        link = _first(c, "link", "frame", "parent")
        out.append(CapsuleSpec(str(_first(c, "name", default=f"{link or 'capsule'}_{i}")), a, b, r,
                               str(link) if link is not None else None))
    return out


def _read_robot_capsules(f: _Fields, robot: Robot, where: str, notes: list[str]) -> list[CapsuleSpec]:
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
        r = float(_arr(_first(o, "radius_m", "radius", "r", default=0.0), (1,), f"{w}.radius_m")[0])
        if kind in ("capsule", "cylinder", "segment"):
            a = _arr(_first(o, "a_m", "a", "p0", "start"), (3,), f"{w}.a_m")
            b = _arr(_first(o, "b_m", "b", "p1", "end", default=a), (3,), f"{w}.b_m")
        elif kind in ("sphere", "point"):
            a = b = _arr(_first(o, "center_m", "center", "centre", "c", "a_m", "a"), (3,), f"{w}.center")
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
            n = _arr(_first(h, "normal", "n"), (3,), f"{w}.normal")
            if "point" in h:
                d = float(n @ _arr(h["point"], (3,), f"{w}.point"))
            else:
                d = float(_arr(_first(h, "offset", "d", "offset_m", default=0.0), (1,), f"{w}.offset")[0])
            name = _first(h, "name")
        else:
            a = _arr(h, (4,), w)
            n, d = a[:3], float(a[3])
        nn = float(np.linalg.norm(n))
        if nn < 1e-12:
            raise InputError(f"{w}.normal: zero vector")
        n, d = n / nn, d / nn
        if name is None:
            name = "floor" if n[2] > 0.9 else ("ceiling" if n[2] < -0.9 else f"wall_{i}")
        out.append(HalfSpace(str(name), n, d))
    return out


def _read_obstacles(f: _Fields, where: str) -> tuple[list[CapsuleSpec], list[HalfSpace]]:
    """Obstacle capsules and half-spaces (a list each, or a cell's ``{capsules, half_spaces}``)."""
    obs_raw, hs_raw = f.get("obstacles"), f.get("half_spaces", "halfspaces", "planes")
    if isinstance(obs_raw, Mapping):
        hs_raw = hs_raw if hs_raw is not None else obs_raw.get("half_spaces")
        obs_raw = obs_raw.get("capsules")
    return _parse_obstacles(obs_raw, f"{where}: obstacles"), _parse_half_spaces(hs_raw, f"{where}: half_spaces")


def _read_joint_bounds(f: _Fields, robot: Robot, where: str) -> tuple[np.ndarray, np.ndarray]:
    """The cell's joint bounds (rad), default the robot's."""
    lo = f.get("q_lower_rad", default=robot.q_lower)
    hi = f.get("q_upper_rad", default=robot.q_upper)
    return _arr(lo, (robot.nq,), f"{where}: q_lower_rad"), _arr(hi, (robot.nq,), f"{where}: q_upper_rad")


def _read_cell(f: _Fields, model: TrackerModel, where: str, notes: list[str]) -> Cell:
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
                beam_radius_m=float(beam.get("radius_m", 0.005)), beam_skip=[str(x) for x in beam.get("skip") or []],
                incidence_max_deg=float(f.get("incidence_limit_deg", "incidence_max_deg", default=30.0)),
                clearance_m=float(f.get("clearance_m", default=0.0)),
                q_work=_read_q_work(f, robot, where, notes),
                environment=environment_from_dicts(f.get("environment"), obstacles, where, notes))


#: share of seeded random configurations in which a pair must collide to count as overlapping by construction
_BY_CONSTRUCTION_SHARE = 0.5


def _skip_what_collides_at_work(cell: Cell, notes: list[str], has_skip_lists: bool) -> list[str]:
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


def _raw_designs(d: Mapping, where: str) -> list:
    """The design entries: ``designs`` (a list or {criterion: entry}) or a top-level ``q_meas``."""
    raw = d.get("designs")
    if raw is None and "q_meas" in d:
        raw = [{"criterion": d.get("criterion", "design"),
                **{k: d[k] for k in d if k in ("q_meas", "cov_s_m2", "trace_cs_m2")}}]
    if not raw:
        raise InputError(f"{where}: no designs (field 'designs': list of {{criterion, q_meas, ...}})")
    if isinstance(raw, Mapping):
        raw = [dict(v, criterion=v.get("criterion", k)) for k, v in raw.items()]
    return list(raw)


class _Covariances:
    """C_s of designs whose file has none: :func:`~pin_kpi_oed.oed.evaluate.score_design` (one identifiability
    analysis)."""

    def __init__(self, model: TrackerModel, q_work: np.ndarray):
        self.model, self.q_work = model, q_work
        self.ident: Any = None

    def __call__(self, Q: np.ndarray) -> np.ndarray:
        from pin_kpi_oed.oed.evaluate import score_design
        from pin_kpi_oed.oed.identifiability import analyse

        self.ident = analyse(self.model) if self.ident is None else self.ident
        return score_design(self.model, Q, self.q_work, self.ident).cov_s_m2


def _read_design(e: Mapping, crit: str, w: str, cell: Cell, covariances: _Covariances, compute_missing: bool,
                 notes: list[str]) -> DesignEntry:
    """One design entry: configurations (checked against the cell's bounds), C_s (read or recomputed)."""
    robot, t = cell.robot, cell.q_work.shape[0]
    if e.get("q_meas") is None:
        raise InputError(f"{w} ({crit}): missing field 'q_meas' (m x {robot.nq} joint values, rad)")
    Q = np.atleast_2d(_arr(e["q_meas"], None, f"{w}.q_meas"))
    if Q.shape[1] != robot.nq:
        raise InputError(f"{w}.q_meas: {Q.shape[1]} joint values per configuration, {robot.name} has {robot.nq}")
    out = (Q < cell.q_lower - 1e-9) | (Q > cell.q_upper + 1e-9)
    if out.any():
        k, j = np.argwhere(out)[0]
        notes.append(f"design {crit}: {int(out.any(axis=1).sum())} configuration(s) outside the joint "
                     f"limits (first: #{k}, {robot.joint_names[j]} = {Q[k, j]:.4g} rad)")
    C, source = e.get("cov_s_m2"), "file"
    if C is not None:
        C = np.asarray(C, dtype=float)
        if C.shape != (3 * t, 3 * t):
            notes.append(f"design {crit}: cov_s_m2 has shape {C.shape}, expected {(3 * t, 3 * t)}: recomputed")
            C = None
        elif not np.all(np.isfinite(C)):
            notes.append(f"design {crit}: cov_s_m2 contains NaN or inf: recomputed")
            C = None
    stored = C
    if C is None or compute_missing:  # never trust stored numbers the file's poses do not give
        if C is None and not compute_missing:
            raise InputError(f"{w} ({crit}): missing field 'cov_s_m2' (3t x 3t TCP covariance, m^2)")
        try:
            C = covariances(Q)
        except PinKpiOedError as exc:
            if stored is None:
                raise type(exc)(f"{w} ({crit}): {exc}") from None
            notes.append(f"design {crit}: its q_meas do not determine C_s ({exc}); the stored cov_s_m2 is not "
                         "shown")
            C = np.full_like(stored, np.nan)
        source = "computed"
        if stored is not None and np.all(np.isfinite(C)):
            gap = float(np.max(np.abs(stored - C))) / max(float(np.max(np.abs(C))), 1e-300)
            if gap > 1e-6:
                notes.append(f"design {crit}: stored cov_s_m2 differs from the one its q_meas give (relative "
                             f"{gap:.2g}): the recomputed one is shown")
            else:
                source = "file"
    elif stored is not None:
        sym = 0.5 * (C + C.T)
        if np.max(np.abs(C - C.T)) > 1e-9 * max(np.max(np.abs(C)), 1e-300) or np.linalg.eigvalsh(sym)[0] < \
                -1e-9 * max(np.max(np.abs(C)), 1e-300):
            raise InputError(f"{w} ({crit}).cov_s_m2: not a covariance (not symmetric positive semi-definite)")
    tr = e.get("trace_cs_m2")
    tr = float(tr) if (source == "file" and isinstance(tr, (int, float)) and np.isfinite(tr)) else float(np.trace(C))
    info = {k: v for k, v in e.items() if k not in ("q_meas", "cov_s_m2")}
    return DesignEntry(crit, str(e.get("label") or DESIGN_LABELS.get(crit, crit)), Q, C, tr, source, info,
                       _honest_covariance(e, crit, t, notes))


def _honest_covariance(e: Mapping, crit: str, t: int, notes: list[str]) -> np.ndarray | None:
    """``discrepancy.cov_s_m2`` of a design entry (3t × 3t m², tracker frame), or None (absent, or unusable: noted)."""
    disc = e.get("discrepancy")
    if not isinstance(disc, Mapping) or disc.get("cov_s_m2") is None:
        return None
    try:
        C = np.asarray(disc["cov_s_m2"], dtype=float)
    except (TypeError, ValueError):
        C = np.zeros(0)
    if C.shape != (3 * t, 3 * t) or not np.all(np.isfinite(C)):
        notes.append(f"design {crit}: discrepancy.cov_s_m2 is not a finite {3 * t} x {3 * t} matrix: the paper's "
                     "C_s is shown")
        return None
    big = max(float(np.max(np.abs(C))), 1e-300)
    if np.max(np.abs(C - C.T)) > 1e-9 * big or np.linalg.eigvalsh(0.5 * (C + C.T))[0] < -1e-9 * big:
        notes.append(f"design {crit}: discrepancy.cov_s_m2 is not symmetric positive semi-definite: the paper's "
                     "C_s is shown")
        return None
    return C


def _read_designs(d: Mapping, cell: Cell, model: TrackerModel, where: str, criteria: Sequence[str] | None,
                  compute_missing: bool, notes: list[str]) -> list[DesignEntry]:
    """The designs kept (``criteria``: only these, in this order)."""
    raw = _raw_designs(d, where)
    covariances = _Covariances(model, cell.q_work)
    designs = []
    for i, e in enumerate(raw):
        w = f"{where}: designs[{i}]"
        if not isinstance(e, Mapping):
            raise InputError(f"{w}: expected an object with criterion and q_meas")
        crit = str(e.get("criterion") or e.get("name") or f"design{i}")
        if not criteria or crit in criteria:
            designs.append(_read_design(e, crit, w, cell, covariances, compute_missing, notes))
    if criteria:
        missing = [c for c in criteria if c not in {dv.criterion for dv in designs}]
        if missing:
            raise InputError(f"{where}: no design '{missing[0]}' (designs: "
                             f"{', '.join(str(e.get('criterion')) for e in raw if isinstance(e, Mapping))})")
        designs.sort(key=lambda dv: list(criteria).index(dv.criterion))
    computed = [dv.criterion for dv in designs if dv.cov_source == "computed"]
    if computed:
        notes.append("C_s recomputed with pin_kpi_oed for: " + ", ".join(computed))
    return designs


def load_design(source: str | os.PathLike | Mapping, criteria: Sequence[str] | None = None,
                compute_missing: bool = True) -> DesignFile:
    """Read a design JSON (or dict) tolerantly (see the module docstring).

    Fields read (anything else is ignored; ``cell.<field>`` is looked up too):

    * ``robot``: a name or ``{"urdf_path", "tool_frame", "name"}``; a ``urdf_path`` that does not exist
      (file moved) falls back to ``name``;
    * ``tracker_T_base`` (4×4, m), ``world_T_base`` / ``W_T_base`` (4×4, default identity), ``reflector_m``,
      ``tcp_m``, ``noise``, ``fixed``, ``prior`` (as :mod:`pin_kpi_oed.model.serialize`);
    * ``q_work`` (t × n, rad; default the robot's neutral configuration), ``q_lower_rad`` / ``q_upper_rad``;
    * ``capsules`` (robot, per link: ``link``, ``a``, ``b``, ``radius``; default from the URDF's collision
      cylinders), ``obstacles`` (capsules / spheres), ``half_spaces``, ``skip_pairs``, ``beam``
      (``radius_m``, ``skip``), ``incidence_limit_deg`` / ``incidence_max_deg`` (default 30), ``clearance_m``;
    * ``designs``: list of ``{criterion, q_meas (m × n rad), cov_s_m2 (3t × 3t m², tracker frame),
      trace_cs_m2, label, discrepancy, ...}``, or a single design given by a top-level ``q_meas``; optional
      ``discrepancy.cov_s_m2`` (3t × 3t m², tracker frame, written by ``design --model``): the honest C_s, model
      discrepancy included (:attr:`DesignEntry.cov_s_honest_m2`; unusable ones are noted and ignored).

    Args:
        source: path of the JSON file, or the parsed dict.
        criteria: keep only these designs (by criterion name), in this order.
        compute_missing: recompute a missing C_s (else a missing ``cov_s_m2`` is an error).

    Returns:
        The :class:`DesignFile`.

    Raises:
        InputError: unreadable file, or a missing / invalid field (named with the file).
        RobotLoadError: the robot cannot be loaded.
        IdentifiabilityError: a C_s to recompute is not determined by the design's measurements.
    """
    d, where, base_dir = _read_json(source)
    validate_design_dict(d, where)
    f = _Fields(d)
    notes: list[str] = []
    model = _read_model(f, where, base_dir, notes)
    cell = _read_cell(f, model, where, notes)
    has_skips = any(k in d or k in (d.get("cell") if isinstance(d.get("cell"), Mapping) else {})
                    for k in ("skip_pairs", "pairs_to_skip", "ignore_pairs"))
    work_collisions = _skip_what_collides_at_work(cell, notes, has_skips)
    designs = _read_designs(d, cell, model, where, criteria, compute_missing, notes)
    return DesignFile(model, cell, designs, notes, where, d, work_collisions)
