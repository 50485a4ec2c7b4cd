"""Lazy move checks and repairs of a program's tours: the state :func:`~pin_kpi_oed.program.ordering.plan_program`
keeps across its rounds.

The nodes are home (node 0) and every representative (2π-equivalent) of every pose; a group holds one pose's
representatives, the tour visits one of each. A move of a tour is checked densely the first time a tour takes
it (:class:`~pin_kpi_oed.program.transitions.TransitionChecker`); its cost c(a, b) becomes what the program will
execute:

- clear: the straight move's time;
- colliding, both ends reaching home: the cheapest safe via pose(s) found (structured candidates, then the seeded
  pool), else a route planned by RRT-Connect
  (:meth:`~pin_kpi_oed.program.transitions.TransitionChecker.plan_route`), else the route through home,
  a → … → home → … → b, safe by construction;
- an end without a route home: the penalty :data:`PENALTY_S` (the tour takes another representative).

A node's route home is found once: straight, straight to a node reaching home, through via poses, or planned within
a sixteenth of the budget; a straight clear move to a node without one puts it in the same pocket of the free space.
When every representative of a pose has failed, one RRT-Connect problem starts from all of them at once with the
full budget (:meth:`~pin_kpi_oed.program.transitions.TransitionChecker.plan_route_from`): representatives in a
pocket (a wrist folded between its bound and the forearm) share it with the free ones, and a pose no longer loses
every route home because each representative's small budget ran out (which a design moved by 1e-9 rad could
decide). A pose none of whose representatives reaches home within it is reported by the program as colliding.
"""

from __future__ import annotations

import numpy as np

from pin_kpi_oed.program.timing import move_time
from pin_kpi_oed.program.transitions import TransitionChecker

__all__ = ["PENALTY_S", "Router"]

#: cost (s) of a move that collides and could not be repaired
PENALTY_S = 1.0e4


class Router:
    """Lazy move checks, repairs and routes home of a program's nodes (see the module docstring).

    Args:
        nodes: (k, n) configurations; node 0 is home.
        groups: per pose, its nodes (representatives).
        tc: the dense move checker.
        speeds: joint speed limits (rad/s or m/s).
        cost: (k, k) move costs (s), straight move times at first; changed in place as moves are checked.
        seed: seed of the via pool and of the route planner.
        plan_checks: route-planning budget per move (configurations checked).
        via_pool: safe configurations sampled for repairs.

    Attributes:
        edges: (a, b) with a < b → the move's intermediate configurations ([] straight), None when it has no route.
        home_route: node → its route home (intermediate configurations), None when none was found.
    """

    def __init__(self, nodes: np.ndarray, groups: list[list[int]], tc: TransitionChecker, speeds: np.ndarray,
                 cost: np.ndarray, *, seed: int = 0, plan_checks: int = 15_000, via_pool: int = 300):
        self.nodes, self.groups, self.tc, self.speeds, self.cost = nodes, groups, tc, speeds, cost
        self.seed, self.plan_checks, self.via_pool = int(seed), int(plan_checks), int(via_pool)
        self.straight = cost.copy()
        self.group_of = {j: g for g, group in enumerate(groups) for j in group}
        self.edges: dict[tuple[int, int], list | None] = {}
        self.home_route: dict[int, list | None] = {0: []}
        self._pool: np.ndarray | None = None

    def c(self, qa: np.ndarray, qb: np.ndarray) -> float:
        """Move time (s)."""
        return move_time(qa, qb, self.speeds)

    def pool(self) -> np.ndarray:
        """The seeded safe via pool (sampled at first use)."""
        if self._pool is None:
            self._pool = self.tc.safe_pool(self.via_pool, seed=self.seed)
        return self._pool

    def repair(self, qa: np.ndarray, qb: np.ndarray) -> list | None:
        """One or two safe via poses for the move qa → qb (structured candidates, then the pool), None if none."""
        tc = self.tc
        return tc.repair(qa, qb, tc.structured_vias(qa, qb, self.nodes[0]), self.speeds, safe=self.pool())

    def route(self, qa: np.ndarray, qb: np.ndarray, plan_checks: int) -> list | None:
        """Intermediate configurations of a safe route qa → qb (via poses, else RRT-Connect), None if none found."""
        if self.tc.check(qa, qb).clear:
            return []
        r = self.repair(qa, qb)
        return self.tc.plan_route(qa, qb, seed=self.seed, max_checks=plan_checks) if r is None else r

    def reach_home(self, i: int) -> bool:
        """Whether node i has a safe route to home (computed once; see the module docstring)."""
        if i not in self.home_route:
            q = self.nodes[i]
            near = sorted((j for j in self.home_route if j != 0), key=lambda j: self.c(q, self.nodes[j]))
            known = [j for j in near if self.home_route[j] is not None][:8]
            trapped = [j for j in near if self.home_route[j] is None][:8]
            hop = next((j for j in known if self.tc.check(q, self.nodes[j]).clear), None)
            if self.tc.check(q, self.nodes[0]).clear:
                self.home_route[i] = []
            elif hop is not None:  # straight to a node reaching home
                self.home_route[i] = [self.nodes[hop], *self.home_route[hop]]
            elif any(self.tc.check(q, self.nodes[j]).clear for j in trapped):
                self.home_route[i] = None
            else:
                self.home_route[i] = self.route(q, self.nodes[0], self.plan_checks // 16)
            if self.home_route[i] is None:
                self.cost[i, :] = self.cost[:, i] = PENALTY_S
                self.cost[i, i] = 0.0
                self.rescue(self.group_of.get(i, -1))
        return self.home_route[i] is not None

    def rescue(self, g: int) -> None:
        """When every representative of pose g has failed to reach home: one RRT-Connect problem from all of them
        (full budget); the representative it connects gets its route home and its moves back."""
        group = self.groups[g] if g >= 0 else []
        if not group or any(self.home_route.get(j, 0) is not None for j in group):
            return  # one reaches home, or one is still untried
        found = self.tc.plan_route_from(self.nodes[group], self.nodes[0], seed=self.seed,
                                        max_checks=self.plan_checks)
        if found is None:
            return
        j = group[found[0]]
        self.home_route[j] = found[1]
        self.cost[j, :], self.cost[:, j] = self.straight[j, :], self.straight[:, j]
        for x, r in self.home_route.items():
            if r is None:  # moves to nodes still without a route home stay penalised
                self.cost[j, x] = self.cost[x, j] = PENALTY_S
        for key in [key for key in self.edges if j in key]:
            r = self.edges.pop(key)
            if r is not None:
                self.set_route(key, r)  # a clear move stays clear; unrouted ones are checked again

    def set_route(self, key: tuple[int, int], route: list | None) -> None:
        """Store the route of a move and its cost (the route's time, or the penalty)."""
        a, b = key
        self.edges[key] = route
        if route is None:
            self.cost[a, b] = self.cost[b, a] = PENALTY_S
        else:
            pts = [self.nodes[a], *route, self.nodes[b]]
            self.cost[a, b] = self.cost[b, a] = sum(self.c(p, q) for p, q in zip(pts[:-1], pts[1:]))

    def through_home(self, key: tuple[int, int]) -> list | None:
        """The route a → home → b from the two routes home (None unless both exist)."""
        ra, rb = self.home_route.get(key[0]), self.home_route.get(key[1])
        if ra is None or rb is None:
            return None
        return [*ra, self.nodes[0], *rb[::-1]] if key[0] and key[1] else ra + rb[::-1]

    def routed(self, tour: list[int]) -> bool:
        """Whether every move of a tour has a route."""
        return all(self.edges.get((min(a, b), max(a, b))) is not None for a, b in zip(tour, tour[1:] + tour[:1]))

    def check_tour(self, tour: list[int], plan_checks: int | None = None) -> bool:
        """Check the unchecked moves of a tour; route the colliding ones, or penalise them.

        Args:
            tour: node order starting with 0 (closed).
            plan_checks: the last attempt: moves still without a route (an end without a route home) are
                planned with this budget, ends without a route home included.

        Returns:
            Whether any move was new.
        """
        new, seen = False, set()
        for a, b in zip(tour, tour[1:] + tour[:1]):
            key = (min(a, b), max(a, b))
            if key in seen or key in self.edges and (plan_checks is None or self.edges[key] is not None):
                continue
            seen.add(key)
            new = True
            qa, qb = self.nodes[key[0]], self.nodes[key[1]]
            if self.tc.check(qa, qb).clear:
                self.set_route(key, [])
                continue
            if plan_checks is not None:  # the last attempt plans even from nodes without a route home
                r = self.route(qa, qb, plan_checks)
                self.set_route(key, r if r is not None else self.through_home(key))
                continue
            if not (self.reach_home(key[0]) & self.reach_home(key[1])):
                self.set_route(key, None)
                continue
            r = self.route(qa, qb, self.plan_checks)
            self.set_route(key, r if r is not None else self.through_home(key))
        return new
