"""The ISO 9283 cube test planned in a cell: the test cube, its five positions, their poses.

ISO 9283 (§6) places a cube in the part of the workspace the robot is used in, its edges parallel to
the base frame, as large as the workspace allows; the test plane is the cube's diagonal plane
C1–C2–C7–C8 (here C1 = centre + a(−1, −1, −1), C2 = centre + a(1, 1, −1), C7 = centre + a(1, 1, 1),
C8 = centre + a(−1, −1, 1) in the base frame, a the half side), P1 its centre and P2–P5 on the plane's
diagonals at 10 % of the diagonal's length L = 2a√3 from the corners C1, C2, C7, C8. Every position
is taken with one tool orientation (the first working configuration's, turned towards the tracker
until the incidence at the cube centre is half the cell's limit, since the tracker must see every
position, and about that axis so that the centre's pose lies farthest inside the joint bounds). A test
cycle visits P1, P5, P4, P3, P2 (the standard's order) and the test runs :data:`N_CYCLES` of them.

The cube is centred on the working configurations' mean TCP position and sized by bisection on its
half side: a size is accepted when its eight corners and five test positions are each reached by the
package's inverse kinematics (:func:`~pin_kpi_oed.cell.working_targets.solve_tcp_target`, the one
orientation, within the joint bounds) in a configuration the independent check
(:class:`~pin_kpi_oed.cell.feasibility.FeasibilityChecker`: every pair clear of the cell's clearance,
the beam free, the incidence within the limit) accepts. The largest accepted size is the cube
("largest" up to the bisection's resolution :data:`SIDE_TOL_M`, and among cubes on that centre).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from pin_kpi_oed.cell.feasibility import FeasibilityChecker
from pin_kpi_oed.cell.working_targets import IK_TOL_M, IK_TOL_RAD, solve_tcp_target, track_target
from pin_kpi_oed.errors import InputError

#: test cycles of the standard's pose accuracy and repeatability test
N_CYCLES = 30
#: distance of P2–P5 from their corners, as a fraction of the test plane's diagonal
CORNER_FRACTION = 0.1
#: the smallest cube side tried (m) and the resolution of the largest side (m)
MIN_SIDE_M = 0.05
SIDE_TOL_M = 0.01
#: the continuation's step from the cube centre to a point (m)
STEP_M = 0.02
#: turns of the test orientation about the tool's z axis tried
N_TURNS = 12
#: the test orientation's incidence at the cube centre, as a fraction of the cell's limit (the rest: the wrist's)
KEEP_FRACTION = 0.5
#: the corners C1, C2, C7, C8 of the test plane (units of the half side, base frame)
PLANE_CORNERS = np.array([[-1.0, -1.0, -1.0], [1.0, 1.0, -1.0], [1.0, 1.0, 1.0], [-1.0, -1.0, 1.0]])
#: the order of a test cycle (indices of P1..P5)
CYCLE_ORDER = (0, 4, 3, 2, 1)


@dataclass
class IsoCubeTest:
    """The planned ISO 9283 cube test.

    Attributes:
        centre_m: cube centre in the cell frame (3,) m.
        side_m: cube side (m).
        positions_m: P1..P5 in the cell frame (5, 3) m.
        corners_m: the test plane's corners C1, C2, C7, C8 in the cell frame (4, 3) m.
        rotation: the tool-frame orientation every position is taken with, in the cell frame (3, 3): the first
            working configuration's, its z axis turned towards the tracker.
        q: the poses of P1..P5 (5, n) rad / m.
        clearance_m: per pose, the independent check's smallest clearance beyond the cell's (5,) m.
    """

    centre_m: np.ndarray
    side_m: float
    positions_m: np.ndarray
    corners_m: np.ndarray
    rotation: np.ndarray
    q: np.ndarray
    clearance_m: np.ndarray

    def cycle_poses(self, n_cycles: int = N_CYCLES) -> tuple[np.ndarray, list[int]]:
        """The test's pose sequence: ``n_cycles`` cycles P1, P5, P4, P3, P2.

        Returns:
            (configurations (5·n_cycles, n) rad / m, index 0..4 of the position of each).
        """
        idx = list(CYCLE_ORDER) * int(n_cycles)
        return self.q[idx], idx


def iso_test_plane(centre_m: np.ndarray, side_m: float, R_base: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The test plane's corners and the five test positions of a cube.

    Args:
        centre_m: cube centre (3,) m, cell frame.
        side_m: cube side (m).
        R_base: the robot base's orientation in the cell frame (3, 3): the cube's edges follow its axes.

    Returns:
        (corners C1, C2, C7, C8 (4, 3) m, positions P1..P5 (5, 3) m), cell frame; P2..P5 belong to C1, C2, C7, C8.
    """
    c = np.asarray(centre_m, float)
    corners = c + (0.5 * side_m * PLANE_CORNERS) @ np.asarray(R_base, float).T
    opposite = corners[[2, 3, 0, 1]]
    near = corners + CORNER_FRACTION * (opposite - corners)
    return corners, np.vstack([c, near])


def _cube_points(centre: np.ndarray, side: float, R_base: np.ndarray) -> np.ndarray:
    """The eight cube corners, then P1..P5 (13, 3) m."""
    signs = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], float)
    cube = centre + (0.5 * side * signs) @ R_base.T
    return np.vstack([cube, iso_test_plane(centre, side, R_base)[1]])


class _Solver:
    """IK of cube points with the independent check as acceptance: the cube centre by the multi-start IK, every
    other point by continuation from the centre's pose along the straight line (steps of :data:`STEP_M`, one
    branch: the cube's poses are then neighbours), the multi-start IK where the continuation fails."""

    def __init__(self, cell, rotation: np.ndarray, centre: np.ndarray, n_random: int):
        self.cell, self.R, self.n_random = cell, rotation, n_random
        self.chk = FeasibilityChecker(cell)
        self.last = ""
        self.centre = centre
        self.q_centre = self._multi_start(centre, list(np.atleast_2d(cell.q_work)), 0)

    def accept(self, q: np.ndarray) -> str:
        rep = self.chk.check(q[None])
        if rep.feasible[0]:
            return ""
        if not rep.within_bounds[0]:
            return "beyond a joint bound"
        if rep.collision_free[0] and rep.clearance_m[0] >= 0:
            return f"incidence {rep.incidence_deg[0]:.1f} deg above the limit {self.cell.incidence_max_deg:g}"
        return f"{rep.worst[0]} at {rep.clearance_m[0] * 1e3:.1f} mm"

    def _multi_start(self, p: np.ndarray, seeds: list, seed: int) -> np.ndarray | None:
        res = solve_tcp_target(self.cell.robot, self.cell.W_T_base, self.cell.tcp_m, p, self.R, seeds=seeds,
                               accept=self.accept, n_random=self.n_random, seed=seed)
        if not res.success:
            self.last = (f"point ({', '.join(f'{v:.3f}' for v in p)}) m: "
                         + (res.message or "unreachable with the test orientation"))
            return None
        return res.q

    def _follow(self, p: np.ndarray) -> np.ndarray | None:
        if self.q_centre is None:
            return None
        c = self.cell
        n = max(1, int(np.ceil(np.linalg.norm(p - self.centre) / STEP_M)))
        q = self.q_centre
        for t in np.linspace(0.0, 1.0, n + 1)[1:]:
            q, e_m, e_rad = track_target(c.robot, c.W_T_base, c.tcp_m, self.centre + t * (p - self.centre), self.R, q)
            if e_m > 1e-4 or e_rad > 1e-3:
                return None
        q, e_m, e_rad = track_target(c.robot, c.W_T_base, c.tcp_m, p, self.R, q, max_iter=200)
        ok = e_m <= IK_TOL_M and e_rad <= IK_TOL_RAD and not self.accept(q)
        return q if ok else None

    def solve(self, points: np.ndarray) -> np.ndarray | None:
        if self.q_centre is None:
            return None
        out: list[np.ndarray] = []
        for i, p in enumerate(points):
            q = self._follow(p)
            if q is None:
                q = self._multi_start(p, [self.q_centre] + out, i + 1)
            if q is None:
                return None
            out.append(q)
        return np.array(out)


def _orientation(cell) -> tuple[np.ndarray, np.ndarray]:
    """The working configurations' mean TCP position (cell frame, m) and the test orientation (3, 3)."""
    Q = np.atleast_2d(np.asarray(cell.q_work, float))
    if Q.size == 0:
        raise InputError(f"cell {cell.name}: the ISO 9283 cube is placed around the working configurations; "
                         f"give q_work or working_targets in the cell file")
    rb = cell.robot
    pts, rot = [], None
    for q in Q:
        pin.framesForwardKinematics(rb.model, rb.data, q)
        M = cell.W_T_base * rb.data.oMf[rb.tool_frame_id]
        pts.append(M.act(np.asarray(cell.tcp_m, float)))
        rot = M.rotation.copy() if rot is None else rot
    centre = np.mean(pts, axis=0)
    keep = np.radians(KEEP_FRACTION * cell.incidence_max_deg)
    return centre, facing_tracker(np.asarray(rot), cell.W_T_tracker.translation - centre, keep)


def facing_tracker(R: np.ndarray, g: np.ndarray, keep_rad: float = 0.0) -> np.ndarray:
    """The orientation R turned by the smallest rotation that brings its z axis within ``keep_rad`` of g (the
    reflector faces the tracker: incidence at most ``keep_rad`` at the cube centre; R itself when it is).

    Args:
        R: a tool-frame orientation (3, 3); g: the direction to the tracker (3,) (any length > 0).
        keep_rad: the angle between the turned z axis and g (rad) when R's is larger.

    Returns:
        The turned orientation (3, 3).
    """
    z, u = R[:, 2], np.asarray(g, float) / np.linalg.norm(g)
    axis, c = np.cross(z, u), float(np.clip(z @ u, -1.0, 1.0))
    s = float(np.linalg.norm(axis))
    if s < 1e-12:  # aligned, or opposite: turn half a turn about the tool's x axis
        return R if c > 0 else R @ pin.exp3(np.array([np.pi, 0.0, 0.0]))
    return pin.exp3(axis / s * max(0.0, float(np.arctan2(s, c)) - keep_rad)) @ R


def plan_iso_cube(cell, side_m: float | None = None, n_random: int = 6) -> IsoCubeTest:
    """Plan the ISO 9283 cube test in a cell (see the module docstring).

    Args:
        cell: the cell (robot, base, TCP, working configurations, obstacles, tracker).
        side_m: cube side (m); None: the largest that fits (bisection between :data:`MIN_SIDE_M` and the
            robot's reach, to :data:`SIDE_TOL_M`).
        n_random: random IK starts per point after the seeds (seeded).

    Returns:
        The :class:`IsoCubeTest`.

    Raises:
        InputError: no working configurations, a non-positive side, or a cube that does not fit (naming the
            point no collision-free pose reaches and what to change).
    """
    centre, R = _orientation(cell)
    R_base = cell.W_T_base.rotation
    solver = _best_solver(cell, R, centre, n_random)
    if side_m is not None:
        if not (np.isfinite(side_m) and side_m > 0):
            raise InputError(f"ISO 9283 cube side: must be a finite number > 0 m, got {side_m}")
        side = float(side_m)
        if solver.solve(_cube_points(centre, side, R_base)) is None:
            raise InputError(f"ISO 9283 cube of side {side:g} m around ({', '.join(f'{v:.3f}' for v in centre)}) m "
                             f"does not fit: {solver.last}; give a smaller side or move the working "
                             f"configurations into open workspace")
    else:
        side = _largest_side(solver, centre, R_base, cell)
    positions = _cube_points(centre, side, R_base)[8:]
    q = solver.solve(positions)
    if q is None:  # accepted sizes were solved before; reached only if the seeds changed the outcome
        raise InputError(f"ISO 9283 cube of side {side:g} m: {solver.last}")
    rep = FeasibilityChecker(cell).check(q)
    corners, _ = iso_test_plane(centre, side, R_base)
    return IsoCubeTest(centre, side, positions, corners, solver.R, q, rep.clearance_m)


def _best_solver(cell, R: np.ndarray, centre: np.ndarray, n_random: int) -> _Solver:
    """The solver of the test orientation, among R turned about its z axis by :data:`N_TURNS` angles (the
    reflector's incidence does not change), whose centre pose lies farthest inside the joint bounds (rad / m)."""
    best, margin = None, -np.inf
    for psi in np.arange(N_TURNS) * (2.0 * np.pi / N_TURNS):
        solver = _Solver(cell, R @ pin.exp3(np.array([0.0, 0.0, psi])), centre, n_random)
        q = solver.q_centre
        if q is None:
            best = best or solver
            continue
        m = float(np.min(np.minimum(q - cell.q_lower, cell.q_upper - q)))
        if m > margin:
            best, margin = solver, m
    assert best is not None
    return best


def _largest_side(solver: _Solver, centre: np.ndarray, R_base: np.ndarray, cell) -> float:
    """The largest side (m) whose cube points all solve, by bisection; refuses when the smallest does not."""
    if solver.solve(_cube_points(centre, MIN_SIDE_M, R_base)) is None:
        raise InputError(f"cell {cell.name}: not even an ISO 9283 cube of side {MIN_SIDE_M:g} m fits around the "
                         f"working configurations' mean TCP ({', '.join(f'{v:.3f}' for v in centre)}) m with the "
                         f"test orientation: {solver.last}; move the working configurations into open "
                         f"workspace (away from obstacles, joint limits and the beam's blockers)")
    reach = 2.0 * float(np.linalg.norm(centre - cell.W_T_base.translation)) + 2.0
    lo, hi = MIN_SIDE_M, reach
    while hi - lo > SIDE_TOL_M:
        mid = 0.5 * (lo + hi)
        if solver.solve(_cube_points(centre, mid, R_base)) is None:
            hi = mid
        else:
            lo = mid
    return lo
