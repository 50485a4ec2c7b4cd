"""Order the poses of a design into a measurement program of least predicted cycle time.

:func:`plan_program` builds the program home → poses → home (home: the first working
configuration unless given):

1. every pose's representatives q + 2πk within the joint bounds
   (:func:`~pin_kpi_oed.program.transitions.equivalents`: the same link placements, so the same
   measurement; UR arms have ±360° joints) and the move times between every pair of them
   (:mod:`pin_kpi_oed.program.timing`: max_j |Δq_j| / v_j);
2. the order of least total time from OR-Tools' routing solver (a closed tour through home
   visiting exactly one representative of each pose — a disjunction per pose; guided local
   search, stopped by a solution count; a wall-clock cap far above it is a safety net only);
3. lazy collision checking (greedy descents from the previous tour while costs change, then guided
   local search, at most three times; :class:`~pin_kpi_oed.program.router.Router`): every move of the
   tour is checked densely (:class:`~pin_kpi_oed.program.transitions.TransitionChecker`); a colliding
   move is repaired through safe via pose(s), else along a path planned by OMPL's RRT-Connect, seeded
   per move (:meth:`~pin_kpi_oed.program.transitions.TransitionChecker.plan_route`), else through home,
   and its cost raised to the route's time, or, when an end has no route home, to a penalty (a pose
   none of whose representatives reached home on its own budget gets one planning problem from all of
   them); the tour is re-solved until every move of it has been checked (reordering around what
   collides), and again, guided local search, while the round limit left it with moves without a route;
4. the final program is re-checked move by move with no early stop (the independent figure).

The as-designed order (home → poses in the listed order and listed joint values → home, straight
moves) is timed and checked the same way for comparison.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from pin_kpi_oed.cell.cell import Cell
from pin_kpi_oed.errors import InputError, SolverError
from pin_kpi_oed.progress import progress
from pin_kpi_oed.program.router import Router
from pin_kpi_oed.program.timing import joint_speeds, path_time, time_matrix
from pin_kpi_oed.program.transitions import TransitionChecker, equivalents
from pin_kpi_oed.results import Result


@dataclass
class Waypoint:
    """One target of the program.

    Attributes:
        q: configuration (n,) rad (m for prismatic joints); for a ``measure`` waypoint the design's
            pose or a 2π-equivalent of it (the same link placements).
        kind: ``home``, ``measure`` or ``via``.
        pose: index of the pose in the design (``measure`` only, else -1).
    """

    q: np.ndarray
    kind: str
    pose: int = -1


@dataclass(kw_only=True)
class Program(Result):
    """An ordered measurement program (see the module docstring).

    Attributes:
        waypoints: home, measurement poses and via poses in execution order, home again.
        order: design indices of the poses in execution order.
        speeds: joint speed limits used (rad/s or m/s).
        cycle_time_s: predicted motion time of the program (s).
        as_designed_time_s: the same for the listed order with straight moves (s).
        n_moves: moves of the program.
        n_colliding: moves still colliding in the final dense check.
        n_repaired: moves routed through via poses.
        n_turned: poses measured at a 2π-equivalent of their listed joint values (same TCP, other turns).
        as_designed_colliding: moves of the listed order colliding in the dense check.
        min_move_clearance_m: smallest clearance along every move minus the cell's required clearance (m).
        margin_m: clearance margin every move must keep (m).
        n_rounds: tour solves.
        solver: routing solver used.
    """

    waypoints: list[Waypoint] = field(default_factory=list)
    order: list[int] = field(default_factory=list)
    speeds: np.ndarray = field(default_factory=lambda: np.zeros(0))
    cycle_time_s: float = 0.0
    as_designed_time_s: float = 0.0
    n_moves: int = 0
    n_colliding: int = 0
    n_repaired: int = 0
    n_turned: int = 0
    as_designed_colliding: int = 0
    min_move_clearance_m: float = float("inf")
    margin_m: float = 0.0
    n_rounds: int = 0
    solver: str = "ortools"

    @property
    def path(self) -> np.ndarray:
        """Every waypoint's configuration in order (k, n)."""
        return np.array([w.q for w in self.waypoints])

    @property
    def reduction(self) -> float:
        """Share of cycle time saved against the as-designed order (0…1)."""
        return 1.0 - self.cycle_time_s / self.as_designed_time_s if self.as_designed_time_s > 0 else 0.0

    def to_dict(self) -> dict:
        """JSON-ready dict (SI units)."""
        return {**self.result_dict(), "order": [int(i) for i in self.order],
                "waypoints": [{"q": w.q.tolist(), "kind": w.kind, "pose": int(w.pose)} for w in self.waypoints],
                "speeds": self.speeds.tolist(), "cycle_time_s": self.cycle_time_s,
                "as_designed_time_s": self.as_designed_time_s, "reduction": self.reduction,
                "n_moves": self.n_moves, "n_colliding": self.n_colliding, "n_repaired": self.n_repaired,
                "n_turned": self.n_turned,
                "as_designed_colliding": self.as_designed_colliding,
                "min_move_clearance_m": self.min_move_clearance_m, "margin_m": self.margin_m,
                "n_rounds": self.n_rounds, "solver": self.solver}

    def summary(self) -> str:
        """A readable line."""
        return (f"program: {len(self.order)} poses ({self.n_turned} at a 2pi-equivalent: same TCP), {self.n_moves} "
                f"moves ({self.n_repaired} via safe poses), "
                f"{self.n_colliding} colliding; cycle time {self.cycle_time_s:.1f} s vs "
                f"{self.as_designed_time_s:.1f} s "
                f"as designed ({100 * self.reduction:.1f} % shorter; as designed {self.as_designed_colliding} "
                f"colliding moves); min move clearance {self.min_move_clearance_m * 1e3:.1f} mm "
                f"(margin {self.margin_m * 1e3:.0f} mm)")


def solve_tour(cost_s: np.ndarray, time_limit_s: float = 2.0, solution_limit: int = 100, fast: bool = False,
               groups: list[list[int]] | None = None, initial: list[int] | None = None) -> list[int]:
    """Closed tour of least total cost through every node, starting and ending at node 0 (OR-Tools routing).

    Args:
        cost_s: (k, k) move costs (s), rounded to ms for the solver.
        groups: alternatives: the tour visits exactly one node of each group (an OR-Tools disjunction
            without penalty); nodes in no group are visited. None: every node is visited.
        time_limit_s: wall-clock cap of the search (s).
        solution_limit: cap on the solutions the guided local search visits (keeps the result
            reproducible when the time limit is not reached).
        fast: greedy descent from the cheapest-arc start instead of guided local search (a local
            optimum in ~0.2 s for 60 poses; used while the lazy collision checks still change costs).
        initial: a tour (starting with 0) to start the local search from instead of the cheapest-arc
            construction (the previous round's tour: most costs are unchanged).

    Returns:
        Node order starting with 0 (length k).

    Raises:
        SolverError: no tour found.
    """
    from ortools.constraint_solver import pywrapcp, routing_enums_pb2

    k = cost_s.shape[0]
    if k <= 2 and not any(len(g) > 1 for g in groups or []):
        return list(range(k))
    C = np.rint(np.asarray(cost_s) * 1e3).astype(np.int64)  # ms
    manager = pywrapcp.RoutingIndexManager(k, 1, 0)
    routing = pywrapcp.RoutingModel(manager)
    cb = routing.RegisterTransitMatrix(C.tolist())
    routing.SetArcCostEvaluatorOfAllVehicles(cb)
    for g in groups or []:
        if len(g) > 1:
            routing.AddDisjunction([manager.NodeToIndex(int(i)) for i in g])  # no penalty: exactly one
    params = pywrapcp.DefaultRoutingSearchParameters()
    params.first_solution_strategy = routing_enums_pb2.FirstSolutionStrategy.PATH_CHEAPEST_ARC
    meta = routing_enums_pb2.LocalSearchMetaheuristic
    params.local_search_metaheuristic = meta.GREEDY_DESCENT if fast else meta.GUIDED_LOCAL_SEARCH
    params.time_limit.FromMilliseconds(int(max(time_limit_s, 0.01) * 1e3))
    if not fast:
        params.solution_limit = int(solution_limit)
    if initial is not None and len(initial) > 1:
        routing.CloseModelWithParameters(params)
        start = routing.ReadAssignmentFromRoutes([[manager.NodeToIndex(int(i)) for i in initial[1:]]], True)
        sol = routing.SolveFromAssignmentWithParameters(start, params) if start is not None else None
        if sol is None:
            sol = routing.SolveWithParameters(params)
    else:
        sol = routing.SolveWithParameters(params)
    if sol is None:
        raise SolverError("ordering: OR-Tools found no tour")
    idx, out = routing.Start(0), []
    while not routing.IsEnd(idx):
        out.append(manager.IndexToNode(idx))
        idx = sol.Value(routing.NextVar(idx))
    return out


@dataclass
class ProgramOptions:
    """Knobs of :func:`plan_program`.

    Attributes:
        margin_m: clearance every move keeps on top of the cell's (m).
        home: home configuration (default the cell's first working configuration).
        speed_override: share of the URDF speed limits (0, 1].
        step_deg: dense-check step (deg, ≤ 1).
        via_pool: safe configurations sampled for repairs.
        seed: seed of the via pool and of the route planner (see
            :meth:`~pin_kpi_oed.program.transitions.TransitionChecker.plan_route`).
        time_limit_s: wall-clock cap of a routing solve (s): a safety net well above what a solve takes (a cap that
            binds would make the program depend on the machine's load).
        solutions: solutions a guided local search visits (its stopping rule: the same costs give the same tour).
        max_rounds: tour solves of the lazy checks at most (every move of the last tour is checked and routed
            whatever the limit, the tour re-solved while one has no route; rounds beyond it mostly trade
            colliding moves for routes of similar cost).
        plan_checks: route-planning budget per colliding move while ordering (configurations
            checked); half of it for a pose's route home, four times it in the last attempt on
            the final tour.
        equivalents: choose among each pose's 2π-equivalent representatives (else the listed values).
        home_window_rad: representatives turn every revolute joint at most this far from home (rad; all of a
            pose's when none does; None: no limit). A representative beyond it turns a joint more than three
            quarters of a turn away from home and back, and every representative is a node of each tour solve
            (a UR5 with five ±360° joints: 32 per pose, 1,280 for 40 poses, where the window keeps 164).
    """

    margin_m: float = 0.0
    home: np.ndarray | None = None
    speed_override: float = 1.0
    step_deg: float = 1.0
    via_pool: int = 300
    seed: int = 0
    time_limit_s: float = 20.0
    solutions: int = 30
    max_rounds: int = 20
    plan_checks: int = 15_000
    equivalents: bool = True
    home_window_rad: float | None = 1.5 * np.pi


def plan_program(cell: Cell, Q: np.ndarray, options: ProgramOptions | None = None) -> Program:
    """Order, check and repair the moves of a design (see the module docstring).

    Args:
        cell: the cell.
        Q: measurement configurations (m, n) rad.
        options: :class:`ProgramOptions`.

    Returns:
        The :class:`Program` (``success``: every move clear in the final dense check).

    Raises:
        InputError: wrong shape of Q, a step above 1°, bad margin or speed override.
    """
    o = options or ProgramOptions()
    t0 = time.perf_counter()
    Q = np.atleast_2d(np.asarray(Q, float))
    n = cell.robot.nq
    if Q.shape[1] != n or Q.shape[0] < 1:
        raise InputError(f"program: expected configurations of {n} joints, got shape {Q.shape}")
    if not (0 < o.step_deg <= 1.0):
        raise InputError(f"program: dense-check step must be in (0, 1] deg, got {o.step_deg}")
    speeds = joint_speeds(cell.robot, o.speed_override)
    home = np.asarray(o.home if o.home is not None else (cell.q_work[0] if len(cell.q_work) else cell.robot.neutral),
                      float)
    rev = np.asarray(cell.robot.is_revolute, bool)
    reps = [_near(_within(equivalents(q, cell.q_lower, cell.q_upper, rev), cell), home, rev, o.home_window_rad)
            if o.equivalents else q[None] for q in Q]
    nodes = np.vstack([home, *reps])
    pose_of = np.concatenate([[-1], *[np.full(len(r), i) for i, r in enumerate(reps)]]).astype(int)
    groups = [[int(k) for k in np.flatnonzero(pose_of == i)] for i in range(len(Q))]
    tc = TransitionChecker(cell, o.margin_m, step_rad=np.radians(o.step_deg))
    cost = time_matrix(nodes, speeds)
    router = Router(nodes, groups, tc, speeds, cost, seed=o.seed, plan_checks=o.plan_checks, via_pool=o.via_pool)
    tour, rounds, fast, n_gls = [0], 0, True, 0
    # a bar on a terminal (silent in pipes and tests): rounds of ordering + dense move checks, then the last checks
    with progress(total=o.max_rounds + 2, desc="program: order + check moves", unit="round") as bar:
        for rounds in range(1, o.max_rounds + 1):
            tour = solve_tour(cost, o.time_limit_s, o.solutions, fast=fast, groups=groups,
                              initial=tour if rounds > 1 else None)
            n_gls += not fast
            changed = router.check_tour(tour)
            bar.update()
            bar.set_postfix(checks=tc.n_evaluations)
            if not changed and not fast or n_gls >= 3:
                break
            fast = changed  # costs settled: a guided local search; it found unchecked moves: greedy rounds again
        bar.total = rounds + 2
        for _ in range(10):  # the round limit hit with moves left without a route: the tour around them
            if router.routed(tour):
                break
            tour = solve_tour(cost, o.time_limit_s, o.solutions, groups=groups, initial=tour)
            if not router.check_tour(tour):
                break
        bar.update()
        router.check_tour(tour, plan_checks=4 * o.plan_checks)  # last attempt on moves still without a route
        bar.update()
    edges = router.edges
    prog = _assemble(nodes, tour, edges, pose_of)
    path = np.array([w.q for w in prog])
    per_move = [tc.check(a, b, stop_early=False) for a, b in zip(path[:-1], path[1:])]
    designed = np.vstack([home, Q, home])
    as_designed = [tc.check(a, b) for a, b in zip(designed[:-1], designed[1:])]
    n_col = int(sum(not m.clear for m in per_move))
    return Program(success=n_col == 0, status="clear" if n_col == 0 else "colliding",
                   message="" if n_col == 0 else f"{n_col} move(s) collide and found no safe via route",
                   nit=rounds, nfev=tc.n_evaluations, time_s=time.perf_counter() - t0,
                   waypoints=prog, order=[w.pose for w in prog if w.kind == "measure"], speeds=speeds,
                   cycle_time_s=path_time(path, speeds), as_designed_time_s=path_time(designed, speeds),
                   n_moves=len(per_move), n_colliding=n_col,
                   n_turned=int(sum(w.kind == "measure" and not np.array_equal(w.q, Q[w.pose]) for w in prog)),
                   n_repaired=int(sum(1 for a, b in zip(tour, tour[1:] + tour[:1])
                                      if edges.get((min(a, b), max(a, b))))),
                   as_designed_colliding=int(sum(not m.clear for m in as_designed)),
                   min_move_clearance_m=min((m.min_clearance_m for m in per_move), default=float("inf")),
                   margin_m=o.margin_m, n_rounds=rounds)


def _near(reps: np.ndarray, home: np.ndarray, revolute: np.ndarray, window: float | None) -> np.ndarray:
    """The representatives whose revolute joints are within ``window`` (rad) of home (all of them when none is)."""
    if window is None:
        return reps
    ok = np.all(np.abs(reps[:, revolute] - home[revolute]) <= window, axis=1)
    return reps[ok] if ok.any() else reps


def _within(reps: np.ndarray, cell: Cell) -> np.ndarray:
    """The representatives within the joint bounds (all of them, q first, when none is)."""
    ok = np.all((reps >= cell.q_lower - 1e-9) & (reps <= cell.q_upper + 1e-9), axis=1)
    return reps[ok] if ok.any() else reps


def _assemble(nodes: np.ndarray, tour: list[int], edges: dict, pose_of: np.ndarray) -> list[Waypoint]:
    """Waypoints of a tour: home, poses (their chosen representatives) and vias (in travel direction), home."""
    out: list[Waypoint] = []
    for a, b in zip(tour, tour[1:] + tour[:1]):
        out.append(Waypoint(nodes[a].copy(), "home" if a == 0 else "measure", int(pose_of[a])))
        route = edges.get((min(a, b), max(a, b))) or []
        if a > b:
            route = route[::-1]
        out.extend(Waypoint(np.asarray(v, float).copy(), "via") for v in route)
    out.append(Waypoint(nodes[0].copy(), "home"))
    return out
