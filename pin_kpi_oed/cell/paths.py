r"""Working paths: curves the TCP follows (a weld seam, a sealing bead), sampled densely and solved by IK.

The cell file may state working paths besides the working configurations (SI units, cell frame)::

    working_paths:
      - name: seam                                   # a poly-line of TCP poses
        waypoints:
          - {xyz_m: [1.0, -0.4, 1.2], rpy_deg: [180, 0, 0]}
          - {xyz_m: [1.0,  0.4, 1.2], rpy_deg: [180, 0, 0]}
        step_m: 0.005                                # or samples: 200 (over the whole path)
        seed_deg: [0, -70, 65, 0, 95, 0]             # optional start of the first sample's IK
      - name: corner                                 # a circular arc through three TCP positions
        arc: {start: {xyz_m: [...], rpy_deg: [...]}, via_m: [x, y, z], end: {xyz_m: [...], rpy_deg: [...]}}
        samples: 100
      - name: program                                # a joint-space program (CSV, pin_kpi_oed.data.targets)
        program: weld_program.csv
        samples: 200                                 # optional: linear in joint space between its rows

Positions are interpolated linearly along a poly-line (on the circle of an arc), orientations by the geodesic
R(τ) = R_a exp(τ log(R_aᵀ R_b)) between consecutive waypoints (proportional to arc length). A waypoint without
``rpy`` leaves the orientation free along its segments (position-only IK). Each sample is solved by damped least
squares warm-started from the previous sample's solution (:func:`~pin_kpi_oed.cell.working_targets.track_target`;
the first sample by the multi-start :func:`~pin_kpi_oed.cell.working_targets.solve_tcp_target`), so the path stays
on one branch. A sample is refused, naming it and the fix, when

* it is not reached from the previous one (out of reach, or a singularity the warm start cannot cross),
* a joint moves more than ``max_joint_step_rad`` (default 0.2 rad) from the previous sample (a branch change:
  a wrist flip, an elbow switch), or
* a capsule pair is closer than the cell's clearance (the collision check of the working configurations; a
  working path is not measured, so the laser beam and the incidence are not checked).

The samples Q_path (S, n) are the KPI configurations of the path criteria (:mod:`pin_kpi_oed.oed.path_kpi`).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin

from pin_kpi_oed.cell.fields import read_angles, read_vec
from pin_kpi_oed.errors import InputError

__all__ = ["WorkingPath", "read_working_paths", "solve_path", "check_clear", "MAX_JOINT_STEP_RAD", "MAX_SAMPLES"]

#: largest joint move (rad; m for prismatic joints) between consecutive samples before it counts as a branch change
MAX_JOINT_STEP_RAD = 0.2
#: most samples of one path
MAX_SAMPLES = 5000
_KEYS = {"name", "waypoints", "arc", "program", "step_m", "samples", "seed_rad", "seed_deg", "max_joint_step_rad"}


@dataclass
class WorkingPath:
    """A working path solved into joint space.

    Attributes:
        name: the path's name.
        Q: joint values of the samples, (S, n) rad / m.
        xyz_W: TCP positions of the samples in the cell frame, (S, 3) m.
        R_W: tool-frame orientations of the samples in the cell frame, (S, 3, 3).
        s_m: arc length of every sample along the TCP's path, (S,) m.
    """

    name: str
    Q: np.ndarray
    xyz_W: np.ndarray
    R_W: np.ndarray
    s_m: np.ndarray

    def to_dict(self) -> dict:
        """Plain numbers (m, rad)."""
        return {"name": self.name, "q_rad": self.Q.tolist(), "xyz_m": self.xyz_W.tolist(), "s_m": self.s_m.tolist()}


def _slerp(Ra: np.ndarray, Rb: np.ndarray, tau: np.ndarray) -> np.ndarray:
    w = pin.log3(Ra.T @ Rb)
    return np.array([Ra @ pin.exp3(t * w) for t in tau])


def _arc_points(a: np.ndarray, v: np.ndarray, b: np.ndarray, n: int, what: str) -> np.ndarray:
    """n points on the circle through a, v, b from a to b (passing v)."""
    u, w = v - a, b - a
    nrm = np.cross(u, w)
    if np.linalg.norm(nrm) < 1e-9 * max(np.linalg.norm(u) * np.linalg.norm(w), 1e-12):
        raise InputError(f"{what}.arc: start, via_m and end are collinear; give a poly-line or move via_m")
    # circumcentre
    c = a + (np.dot(w, w) * np.cross(nrm, u) + np.dot(u, u) * np.cross(w, nrm)) / (2.0 * np.dot(nrm, nrm))
    e1, ez = (a - c) / np.linalg.norm(a - c), nrm / np.linalg.norm(nrm)
    e2 = np.cross(ez, e1)
    r = np.linalg.norm(a - c)

    def ang(p: np.ndarray) -> float:
        return float(np.arctan2((p - c) @ e2, (p - c) @ e1) % (2 * np.pi))

    t = np.linspace(0.0, ang(b), n)
    return c + r * (np.cos(t)[:, None] * e1 + np.sin(t)[:, None] * e2)


def _waypoints(entry: dict, what: str) -> tuple[np.ndarray, list[np.ndarray | None]]:
    """Positions (k, 3) m and orientations (or None) of a poly-line's or an arc's key poses."""
    def pose(p: Any, w: str) -> tuple[np.ndarray, np.ndarray | None]:
        if not isinstance(p, dict) or "xyz_m" not in p:
            raise InputError(f"{w}: expected a mapping with xyz_m (and optional rpy_rad / rpy_deg)")
        rpy = read_angles(p, "rpy", 3, w, required=False)
        return read_vec(p["xyz_m"], 3, f"{w}.xyz_m"), None if rpy is None else pin.rpy.rpyToMatrix(*rpy)

    if "waypoints" in entry:
        wps = entry["waypoints"]
        if not isinstance(wps, list) or len(wps) < 2:
            raise InputError(f"{what}.waypoints: expected a list of at least 2 TCP poses")
        poses = [pose(p, f"{what}.waypoints[{i}]") for i, p in enumerate(wps)]
        return np.array([p for p, _ in poses]), [R for _, R in poses]
    arc = entry["arc"]
    if not isinstance(arc, dict) or not {"start", "via_m", "end"} <= set(arc):
        raise InputError(f"{what}.arc: expected a mapping with start, via_m and end")
    (a, Ra), (b, Rb) = pose(arc["start"], f"{what}.arc.start"), pose(arc["end"], f"{what}.arc.end")
    return np.array([a, read_vec(arc["via_m"], 3, f"{what}.arc.via_m"), b]), [Ra, None, Rb]


def _sample_cartesian(entry: dict, what: str) -> tuple[np.ndarray, np.ndarray | None]:
    """Dense TCP positions (S, 3) m and orientations (S, 3, 3) or None (orientation free)."""
    P, Rs = _waypoints(entry, what)
    if "arc" in entry:
        chord = np.linalg.norm(P[1] - P[0]) + np.linalg.norm(P[2] - P[1])
        n = _count(entry, chord, what)
        X = _arc_points(P[0], P[1], P[2], n, what)
        Rs = [Rs[0], Rs[2]]
        P = np.array([P[0], P[2]])
        seg = np.linalg.norm(np.diff(X, axis=0), axis=1)
        s = np.concatenate([[0.0], np.cumsum(seg)])
        tau_all = s / s[-1]
        seg_of = np.zeros(n, dtype=int)
        taus = [tau_all]
    else:
        seg = np.linalg.norm(np.diff(P, axis=0), axis=1)
        if np.any(seg < 1e-9):
            k = int(np.argmin(seg))
            raise InputError(f"{what}.waypoints[{k + 1}]: repeats the previous waypoint; remove it")
        s_way = np.concatenate([[0.0], np.cumsum(seg)])
        n = _count(entry, float(s_way[-1]), what)
        s = np.linspace(0.0, s_way[-1], n)
        seg_of = np.minimum(np.searchsorted(s_way, s, side="right") - 1, len(seg) - 1)
        tau_all = (s - s_way[seg_of]) / seg[seg_of]
        X = P[seg_of] + tau_all[:, None] * (P[seg_of + 1] - P[seg_of])
        taus = None
    if all(R is None for R in Rs):
        return X, None
    if any(R is None for R in Rs):
        raise InputError(f"{what}: give rpy at every waypoint or at none (orientation along the path)")
    R = np.empty((len(X), 3, 3))
    for k in range(len(Rs) - 1):
        idx = np.flatnonzero(seg_of == k)
        R[idx] = _slerp(Rs[k], Rs[k + 1], (taus[0] if taus else tau_all)[idx])
    return X, R


def _count(entry: dict, length_m: float, what: str) -> int:
    """Number of samples from ``samples`` or ``step_m`` (default 5 mm)."""
    if "samples" in entry and "step_m" in entry:
        raise InputError(f"{what}: give either samples or step_m, not both")
    if "samples" in entry:
        n = entry["samples"]
        if not isinstance(n, int) or isinstance(n, bool) or not 2 <= n <= MAX_SAMPLES:
            raise InputError(f"{what}.samples: expected an integer in [2, {MAX_SAMPLES}], got {n!r}")
        return n
    step = float(read_vec(entry.get("step_m", 0.005), 1, f"{what}.step_m")[0])
    if not step > 0:
        raise InputError(f"{what}.step_m: expected a positive length in m, got {step:g}")
    n = int(np.ceil(length_m / step)) + 1
    if n > MAX_SAMPLES:
        raise InputError(f"{what}.step_m: {step:g} m gives {n} samples over {length_m:.3f} m (at most "
                         f"{MAX_SAMPLES}); a step in mm? give step_m in m, e.g. 0.005")
    return max(n, 2)


def check_clear(chk: Any, cell: Any, q: np.ndarray, what: str) -> None:
    """Refuse a sample whose closest capsule pair is nearer than the cell's clearance (no beam: not measured).

    Raises:
        InputError: naming ``what``, the pair and its distance (mm).
    """
    d = chk.pair_distances(q) - cell.clearance_m
    k = int(np.argmin(d)) if d.size else -1
    if k >= 0 and d[k] < -1e-9:
        raise InputError(f"{what}: {chk.names[k]} at {d[k] * 1e3:.1f} mm (clearance "
                         f"{cell.clearance_m * 1e3:g} mm); move the path or the tool orientation clear")


def solve_path(cell: Any, X: np.ndarray, R: np.ndarray | None, what: str, seeds: list[np.ndarray],
               max_step: float = MAX_JOINT_STEP_RAD) -> np.ndarray:
    """Joint values (S, n) of TCP samples along a path: one branch, warm-started, collision-checked.

    Args:
        cell: the cell (robot, base, TCP, capsules, clearance).
        X: TCP positions (S, 3) m, cell frame; R: orientations (S, 3, 3) or None (free).
        what: the path's name in messages.
        seeds: starts of the first sample's multi-start IK.
        max_step: largest joint move between consecutive samples (rad / m).

    Raises:
        InputError: the first sample refused, naming it, its position (m) and the fix.
    """
    from pin_kpi_oed.cell.feasibility import FeasibilityChecker
    from pin_kpi_oed.cell.working_targets import IK_TOL_M, IK_TOL_RAD, solve_tcp_target, track_target

    robot = cell.robot
    chk = FeasibilityChecker(dataclasses.replace(cell, environment=[]))

    def where(i: int) -> str:
        return f"{what}: sample {i} at ({X[i, 0]:.3f}, {X[i, 1]:.3f}, {X[i, 2]:.3f}) m"

    def collides(i: int, q: np.ndarray) -> None:
        check_clear(chk, cell, q, where(i))

    def accept(q: np.ndarray) -> str:
        try:
            check_clear(chk, cell, q, "")
        except InputError as exc:
            return str(exc).split(": ", 1)[-1].split(";")[0]
        return ""

    first = solve_tcp_target(robot, cell.W_T_base, cell.tcp_m, X[0], None if R is None else R[0], seeds=seeds,
                             accept=accept)
    if not first.success:
        what0 = (f"every solution within the joint bounds collides ({first.message})" if first.message
                 else "unreachable within the joint bounds")
        raise InputError(f"{where(0)}: {what0} (best residual {first.residual_m * 1e3:.3f} mm); move the path into "
                         f"reach or clear of the obstacles, or give seed_deg")
    Q = np.empty((len(X), robot.nq))
    Q[0] = first.q
    collides(0, Q[0])
    for i in range(1, len(X)):
        q, ep, er = track_target(robot, cell.W_T_base, cell.tcp_m, X[i], None if R is None else R[i], Q[i - 1])
        if ep > IK_TOL_M or er > IK_TOL_RAD:
            raise InputError(f"{where(i)}: not reached from sample {i - 1} (residual {ep * 1e3:.3f} mm, "
                             f"{np.degrees(er):.3f} deg): out of reach or at a singularity; shorten the path, move "
                             f"it into reach or change the tool orientation")
        step = np.abs(q - Q[i - 1])
        j = int(np.argmax(step))
        if step[j] > max_step:
            raise InputError(f"{where(i)}: joint {robot.joint_names[j]} moves {step[j]:.3f} rad from sample {i - 1} "
                             f"(a branch change, limit {max_step:g} rad); sample the path more densely (step_m) or "
                             f"move it away from the singularity")
        Q[i] = q
        collides(i, q)
    return Q


def _program_samples(cell: Any, entry: dict, what: str, base_dir: Path | None) -> np.ndarray:
    """Joint values of a joint-space program file, linearly densified to ``samples`` if given."""
    from pin_kpi_oed.data.targets import read_targets

    path = Path(str(entry["program"]))
    if base_dir is not None and not path.is_absolute():
        path = base_dir / path
    ts = read_targets(path, cell.robot.joint_names, program=True)
    Qp = np.asarray(ts.q, float)
    if len(Qp) < 2:
        raise InputError(f"{what}.program: {path} has {len(Qp)} row(s); a path needs at least 2")
    cell.robot.check_q(Qp, f"{what}.program")
    if "samples" not in entry:
        return Qp
    n = _count(entry, 0.0, what)
    t = np.linspace(0.0, len(Qp) - 1.0, n)
    k = np.minimum(t.astype(int), len(Qp) - 2)
    return Qp[k] + (t - k)[:, None] * (Qp[k + 1] - Qp[k])


def _poses(cell: Any, Q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """TCP positions (S, 3) m and tool orientations (S, 3, 3) in the cell frame."""
    robot = cell.robot
    data = robot.model.createData()
    X, R = np.empty((len(Q), 3)), np.empty((len(Q), 3, 3))
    for i, q in enumerate(Q):
        pin.framesForwardKinematics(robot.model, data, q)
        M = cell.W_T_base * data.oMf[robot.tool_frame_id]
        X[i], R[i] = M.act(np.asarray(cell.tcp_m, float)), M.rotation
    return X, R


def read_working_paths(cell: Any, entries: Any, source: str = "", base_dir: Path | None = None) -> list[WorkingPath]:
    """The cell file's ``working_paths`` solved into joint space (see the module docstring).

    Raises:
        InputError: a malformed entry, or a sample that cannot be followed, naming the path, the sample and the fix.
    """
    pre = f"{source}: " if source else ""
    if not isinstance(entries, list):
        raise InputError(f"{pre}working_paths: expected a list of paths")
    out: list[WorkingPath] = []
    for i, e in enumerate(entries):
        w = f"{pre}working_paths[{i}]"
        if not isinstance(e, dict) or sum(k in e for k in ("waypoints", "arc", "program")) != 1:
            raise InputError(f"{w}: expected a mapping with exactly one of waypoints, arc or program")
        unknown = set(e) - _KEYS
        if unknown:
            raise InputError(f"{w}: unknown field(s) {', '.join(sorted(unknown))} (known: {', '.join(sorted(_KEYS))})")
        name = str(e.get("name", f"path{i}"))
        w = f"{w} '{name}'"
        max_step = float(read_vec(e.get("max_joint_step_rad", MAX_JOINT_STEP_RAD), 1, f"{w}.max_joint_step_rad")[0])
        if not 0 < max_step <= np.pi:
            raise InputError(f"{w}.max_joint_step_rad: expected a value in (0, pi] rad, got {max_step:g}")
        if "program" in e:
            Q = _program_samples(cell, e, w, base_dir)
            step = np.abs(np.diff(Q, axis=0)).max(axis=1)
            if step.size and step.max() > max_step:
                k = int(np.argmax(step)) + 1
                raise InputError(f"{w}: sample {k} moves a joint {step[k - 1]:.3f} rad from sample {k - 1} (limit "
                                 f"{max_step:g} rad); give more samples")
            X, R = _poses(cell, Q)
            from pin_kpi_oed.cell.feasibility import FeasibilityChecker

            chk = FeasibilityChecker(dataclasses.replace(cell, environment=[]))
            for k, q in enumerate(Q):
                check_clear(chk, cell, q, f"{w}: sample {k} at ({X[k, 0]:.3f}, {X[k, 1]:.3f}, {X[k, 2]:.3f}) m")
        else:
            X, R_t = _sample_cartesian(e, w)
            seed_q = read_angles(e, "seed", cell.robot.nq, w, required=False)
            seeds = ([seed_q] if seed_q is not None else []) + list(np.atleast_2d(cell.q_work))
            Q = solve_path(cell, X, R_t, w, seeds, max_step)
            X, R = _poses(cell, Q)
        s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(X, axis=0), axis=1))])
        out.append(WorkingPath(name, Q, X, R, s))
    return out
