"""The ISO 9283 cube test planned in a cell: the test cube, its five positions, their poses.

ISO 9283 (§6) places a cube in the part of the workspace the robot is used in, its edges parallel to
the base frame, as large as the workspace allows; the test plane is the cube's diagonal plane
C1–C2–C7–C8 (here C1 = centre + a(−1, −1, −1), C2 = centre + a(1, 1, −1), C7 = centre + a(1, 1, 1),
C8 = centre + a(−1, −1, 1) in the base frame, a the half side), P1 its centre and P2–P5 on the plane's
diagonals at 10 % of the diagonal's length L = 2a√3 from the corners C1, C2, C7, C8. Each position
is taken with a tool orientation of its own, chosen among :data:`N_ORIENTATIONS` candidates (the first working
configuration's orientation turned towards the tracker until the incidence at the cube centre is half the cell's
limit, since the tracker must see every position, and then about that axis by :data:`N_TURNS` angles: the
reflector's incidence does not change; the candidates whose centre pose lies farthest inside the joint bounds); the
standard commands one pose per position, the same in every cycle, not one orientation for every position. A test
cycle visits P1, P5, P4, P3, P2 (the standard's order) and the test runs :data:`N_CYCLES` of them.

The standard wants the cube in the part of the workspace the robot is used in, as large as it fits. Its centre
starts at the working configurations' mean TCP position and moves by a pattern search (steps along the base axes
from :data:`SHIFT_STEP_M`, halved down to :data:`SHIFT_TOL_M`) to where a larger cube fits, at most
:data:`MAX_SHIFT_M` from that mean; at each centre the side is found by bisection: a size is accepted when its eight
corners and five test positions are each reached by the package's inverse kinematics
(:func:`~pin_kpi_oed.cell.working_targets.solve_tcp_target`, one of the candidate orientations, within the joint
bounds) in a configuration the independent check (:class:`~pin_kpi_oed.cell.feasibility.FeasibilityChecker`: every
pair clear of the cell's clearance, the beam free, the incidence within the limit) accepts. The largest accepted size
is the cube ("largest" up to the bisection's resolution :data:`SIDE_TOL_M`, and among the centres the search visits).
"""

from __future__ import annotations

from collections.abc import Callable
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
#: the candidate orientations kept (those whose centre pose lies farthest inside the joint bounds)
N_ORIENTATIONS = 4
#: the test orientation's incidence at the cube centre, as a fraction of the cell's limit (the rest: the wrist's)
KEEP_FRACTION = 0.5
#: the centre search: largest shift from the working configurations' mean TCP, first step, resolution (m)
MAX_SHIFT_M = 0.3
SHIFT_STEP_M = 0.1
SHIFT_TOL_M = 0.025
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
        rotations: the tool-frame orientation of each of P1..P5 in the cell frame (5, 3, 3): one of the candidates
            (the first working configuration's, its z axis turned towards the tracker, turned about it).
        q: the poses of P1..P5 (5, n) rad / m.
        clearance_m: per pose, the independent check's smallest clearance beyond the cell's (5,) m.
        shift_m: the centre's distance from the working configurations' mean TCP (m).
        side_at_mean_m: the largest side that fits on that mean (m; None when a side was given and fits there).
    """

    centre_m: np.ndarray
    side_m: float
    positions_m: np.ndarray
    corners_m: np.ndarray
    rotations: np.ndarray
    q: np.ndarray
    clearance_m: np.ndarray
    shift_m: float = 0.0
    side_at_mean_m: float | None = None

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
    """IK of cube points with one orientation and the independent check as acceptance: the cube centre by the
    multi-start IK, every other point by continuation from the centre's pose along the straight line (steps of
    :data:`STEP_M`, one branch: the cube's poses are then neighbours), the multi-start IK where it fails."""

    def __init__(self, cell, rotation: np.ndarray, centre: np.ndarray, n_random: int):
        self.cell, self.R, self.n_random = cell, rotation, n_random
        self.chk = FeasibilityChecker(cell)
        self.last = ""
        self.centre = centre
        self.q_centre = self.multi_start(centre, list(np.atleast_2d(cell.q_work)), 0)

    def accept(self, q: np.ndarray) -> str:
        rep = self.chk.check(q[None])
        if rep.feasible[0]:
            return ""
        if not rep.within_bounds[0]:
            return "beyond a joint bound"
        if rep.collision_free[0] and rep.clearance_m[0] >= 0:
            return f"incidence {rep.incidence_deg[0]:.1f} deg above the limit {self.cell.incidence_max_deg:g}"
        return f"{rep.worst[0]} at {rep.clearance_m[0] * 1e3:.1f} mm"

    def margin(self) -> float:
        """The centre pose's smallest distance to a joint bound (rad / m; −inf when the centre is not reached)."""
        if self.q_centre is None:
            return -np.inf
        c = self.cell
        return float(np.min(np.minimum(self.q_centre - c.q_lower, c.q_upper - self.q_centre)))

    def multi_start(self, p: np.ndarray, seeds: list, seed: int) -> np.ndarray | None:
        res = solve_tcp_target(self.cell.robot, self.cell.W_T_base, self.cell.tcp_m, p, self.R, seeds=seeds,
                               accept=self.accept, n_random=self.n_random, seed=seed)
        if not res.success:
            self.last = (f"point ({', '.join(f'{v:.3f}' for v in p)}) m: "
                         + (res.message or "unreachable with the test orientations"))
            return None
        return res.q

    def follow(self, p: np.ndarray) -> np.ndarray | None:
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


class _Candidates:
    """The candidate orientations at one cube centre (module docstring): each point is solved with the first
    that reaches it, by continuation first, then by the multi-start IK."""

    def __init__(self, cell, R: np.ndarray, centre: np.ndarray, n_random: int):
        turns = [_Solver(cell, R @ pin.exp3(np.array([0.0, 0.0, psi])), centre, n_random)
                 for psi in np.arange(N_TURNS) * (2.0 * np.pi / N_TURNS)]
        turns.sort(key=lambda s: -s.margin())
        self.solvers = [s for s in turns[:N_ORIENTATIONS] if s.q_centre is not None] or turns[:1]
        self.centre = centre
        self.last = self.solvers[0].last

    def solve(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
        """(poses (k, n) rad / m, orientations (k, 3, 3)) of the points, or None (``last`` says why): every point
        by continuation first, then the multi-start IK for the points it missed (the first it cannot reach ends
        the search)."""
        if self.solvers[0].q_centre is None:
            self.last = self.solvers[0].last
            return None
        hits: list = [next(((q, s.R) for s in self.solvers if (q := s.follow(p)) is not None), None) for p in points]
        for i in (i for i, h in enumerate(hits) if h is None):
            for s in self.solvers:
                q = s.multi_start(points[i], [s.q_centre] + [h[0] for h in hits if h is not None and h[1] is s.R],
                                  i + 1)
                if q is not None:
                    hits[i] = (q, s.R)
                    break
            else:
                self.last = self.solvers[0].last
                return None
        return np.array([h[0] for h in hits]), np.array([h[1] for h in hits])


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


def plan_iso_cube(cell, side_m: float | None = None, n_random: int = 6, max_shift_m: float = MAX_SHIFT_M,
                  moves: Callable[[np.ndarray], str] | None = None) -> IsoCubeTest:
    """Plan the ISO 9283 cube test in a cell (see the module docstring).

    Args:
        cell: the cell (robot, base, TCP, working configurations, obstacles, tracker).
        side_m: cube side (m); None: the largest that fits (centre search and bisection to :data:`SIDE_TOL_M`).
            A given side is placed on the working configurations' mean TCP when it fits there, else on the
            searched centre.
        n_random: random IK starts per point after the seeds (seeded).
        max_shift_m: the largest shift of the centre from the working configurations' mean TCP (m; 0: the mean).
        moves: the check of a cycle's moves (P1..P5 poses (5, n) rad / m -> "" when every move P1, P5, P4, P3, P2,
            P1 is clear, else why not), part of a size's acceptance; None: the poses only.

    Returns:
        The :class:`IsoCubeTest`.

    Raises:
        InputError: no working configurations, a non-positive side, or a cube that does not fit (naming the
            largest side that fits, or the point no collision-free pose reaches and what to change).
    """
    if side_m is not None and not (np.isfinite(side_m) and side_m > 0):
        raise InputError(f"ISO 9283 cube side: must be a finite number > 0 m, got {side_m}")
    mean, R = _orientation(cell)
    R_base = cell.W_T_base.rotation
    search = _CentreSearch(cell, R, mean, n_random, max(0.0, float(max_shift_m)), moves)
    at_mean = search.largest(mean, 0.0, side_m)
    centre, side = mean, at_mean
    if side_m is None or at_mean < side_m:
        centre, side = search.run(at_mean, side_m)
    if side_m is not None:
        if side < side_m:
            raise InputError(f"ISO 9283 cube of side {side_m:g} m does not fit in cell {cell.name}: the largest that "
                             f"fits is {side:.3f} m (centre within {search.max_shift:g} m of the working "
                             f"configurations' mean TCP); give a smaller side")
        side = float(side_m)
    key = (tuple(np.round(centre, 9)), side)
    if key not in search.solved and not search.fits(centre, side):  # accepted sizes were solved before
        raise InputError(f"ISO 9283 cube of side {side:g} m: {search.candidates(centre).last}")
    q, rot = search.solved[key]
    rep = FeasibilityChecker(cell).check(q)
    corners, positions = iso_test_plane(centre, side, R_base)
    return IsoCubeTest(centre, side, positions, corners, rot, q, rep.clearance_m,
                       float(np.linalg.norm(centre - mean)), at_mean if side_m is None else None)


class _CentreSearch:
    """The largest cube side per centre (bisection) and the pattern search of the centre (module docstring)."""

    def __init__(self, cell, R: np.ndarray, mean: np.ndarray, n_random: int, max_shift_m: float,
                 moves: Callable[[np.ndarray], str] | None):
        self.cell, self.R, self.mean, self.n_random, self.max_shift = cell, R, mean, n_random, max_shift_m
        self.moves = moves
        self.R_base = cell.W_T_base.rotation
        self.hi = 2.0 * float(np.linalg.norm(mean - cell.W_T_base.translation)) + 2.0
        self._cand: dict[tuple, _Candidates] = {}
        self.solved: dict[tuple, tuple[np.ndarray, np.ndarray]] = {}

    def candidates(self, centre: np.ndarray) -> _Candidates:
        key = tuple(np.round(centre, 9))
        if key not in self._cand:
            self._cand[key] = _Candidates(self.cell, self.R, centre, self.n_random)
        return self._cand[key]

    def fits(self, centre: np.ndarray, side: float) -> bool:
        cand = self.candidates(centre)
        sol = cand.solve(_cube_points(centre, side, self.R_base))
        if sol is not None and self.moves is not None and (why := self.moves(sol[0][8:])):
            cand.last, sol = why, None
        if sol is not None:
            self.solved[(tuple(np.round(centre, 9)), side)] = (sol[0][8:], sol[1][8:])
        return sol is not None

    def largest(self, centre: np.ndarray, above: float, enough: float | None = None, step: float | None = None
                ) -> float:
        """The largest side (m) at ``centre`` by bisection, if larger than ``above`` (else ``above``, or 0 when
        not even :data:`MIN_SIDE_M` fits); ``enough`` (m): stop once a side that large fits; ``step`` (m): the
        centre lies that far from one where ``above`` was the largest, so the side grows by at most 2·step (the
        cube of side s + 2·step there holds the one of side s here)."""
        lo = max(above + SIDE_TOL_M, MIN_SIDE_M)
        if not self.fits(centre, lo):
            return above
        if enough is not None and self.fits(centre, max(enough, lo)):
            return max(enough, lo)
        if step is None:  # doubling to the first side that does not fit
            hi = 2.0 * lo
            while hi < self.hi and self.fits(centre, hi):
                lo, hi = hi, 2.0 * hi
        else:
            hi = above + 2.0 * step + 2.0 * SIDE_TOL_M
        while hi - lo > SIDE_TOL_M:
            mid = 0.5 * (lo + hi)
            lo, hi = (mid, hi) if self.fits(centre, mid) else (lo, mid)
        return lo

    def run(self, side: float, enough: float | None = None) -> tuple[np.ndarray, float]:
        """(centre (3,) m, side m): the pattern search from the mean, where ``side`` (m) fits (module docstring);
        refuses when no cube of :data:`MIN_SIDE_M` fits anywhere it looks."""
        centre = self.mean
        step = SHIFT_STEP_M
        while step >= SHIFT_TOL_M - 1e-12 and (enough is None or side < enough):
            moved = False
            for d in np.vstack([np.eye(3), -np.eye(3)]) @ self.R_base.T * step:
                c = centre + d
                if np.linalg.norm(c - self.mean) > self.max_shift + 1e-9:
                    continue
                s = self.largest(c, side, enough, step)
                if s > side:
                    centre, side, moved = c, s, True
            step = step if moved else 0.5 * step
        if side <= 0.0:
            raise InputError(f"cell {self.cell.name}: not even an ISO 9283 cube of side {MIN_SIDE_M:g} m fits within "
                             f"{self.max_shift:g} m of the working configurations' mean TCP "
                             f"({', '.join(f'{v:.3f}' for v in self.mean)}) m with the test orientations: "
                             f"{self.candidates(self.mean).last}; move the working configurations into open "
                             f"workspace (away from obstacles, joint limits and the beam's blockers)")
        return centre, side
