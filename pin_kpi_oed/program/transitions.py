"""Dense collision checks of the joint-space moves between poses, and their repair through via poses.

A move between two configurations is the straight line in joint space (what ``movej`` / ``PTP`` /
``MoveAbsJ`` execute). :class:`TransitionChecker` samples it at joint steps of at most
``step_rad`` (default 1°) for revolute and ``step_m`` (default 5 mm) for prismatic joints, end
points included, and evaluates every capsule / half-space pair of the cell with the independent
checker (:meth:`~pin_kpi_oed.cell.feasibility.FeasibilityChecker.pair_distances`: Pinocchio + Coal,
the same capsules as the design, no pruning). A move is *clear* when every sample keeps
``cell.clearance_m + margin_m``, or — when an end pose is itself closer than that (a design made
without the margin) — never comes closer than its closer end pose; a move from a colliding pose
is never clear. The beam and the incidence angle are not checked along a move:
the tracker measures at the poses only.

A colliding move is repaired by :meth:`TransitionChecker.repair`: through one safe intermediate
pose (wrist-first / arm-first splits of the move, the home pose, retracted variants of the end
poses, then a seeded pool of collision-free configurations; cheapest first), else through two
(every leg densely checked); when neither works, :meth:`TransitionChecker.plan_route` plans a
path with OMPL's RRT-Connect in joint space (validity: the same pair distances and margin; every
tree edge a dense move check), simplified by OMPL's path simplifier, and every leg of the result
densely re-checked by :meth:`TransitionChecker.check`. OMPL's random numbers are seeded per call
(from the seed and the move): the same design gives the same program in one process or two.

:func:`equivalents` lists the configurations q + 2πk of a pose inside the joint bounds (UR arms have
±360° joints): the same link placements, so the same measurement, clearance and incidence; the
ordering picks the representative per pose that makes the moves short and safe.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import numpy as np

from pin_kpi_oed.cell.cell import Cell
from pin_kpi_oed.cell.feasibility import FeasibilityChecker
from pin_kpi_oed.errors import InputError
from pin_kpi_oed.program.move_bound import MoveBound

#: how far above a decision's threshold (m) the move-check bound may use a segment pair's enclosing balls instead
#: of its closest points (:meth:`~pin_kpi_oed.program.move_bound.MoveBound.pairs`; :func:`ball_cap`): the same
#: decisions, cheaper. A segment pair's closest points are never nearer than its balls, so a row the balls keep
#: above the threshold is not the one that puts a sample below it: the samples below it keep their bound bit for
#: bit, those above it stay above it (and are never evaluated)
BALL_CAP_M = 1e-6

#: the margin of a cap that is not positive (:func:`ball_cap`): such a cap keeps the balls per segment pair over
#: all configurations (:meth:`~pin_kpi_oed.program.move_bound.MoveBound.pairs`), so it is left where it was
BALL_CAP_WIDE_M = 0.05


def ball_cap(threshold_m: float) -> float:
    """The cap of the move-check bound for a decision at ``threshold_m`` (m, the cell's clearance included).

    Args:
        threshold_m: the smallest pair distance (m) that decides (a sample bounded at or above it is not evaluated).

    Returns:
        ``threshold_m + BALL_CAP_M``, at least ``BALL_CAP_M`` (m); ``threshold_m + BALL_CAP_WIDE_M`` when that is not
        positive (a colliding move checked without early stop): the caps whose decisions, and exact evaluations,
        are those of the closest points everywhere.
    """
    wide = threshold_m + BALL_CAP_WIDE_M
    return wide if wide <= 0 else max(threshold_m + BALL_CAP_M, BALL_CAP_M)

#: RRT-Connect's step, as a share of the joint space's extent (OMPL's default is 0.2: long edges that mostly
#: collide in a cell, each a dense check of hundreds of samples; 0.05 plans the UR10 cell's routes in fewer checks)
ROUTE_RANGE = 0.05


def equivalents(q: np.ndarray, lower: np.ndarray, upper: np.ndarray, revolute: np.ndarray,
                max_count: int = 64) -> np.ndarray:
    """The configurations q + 2πk (k integer per revolute joint) within the bounds; q itself first.

    A revolute joint turned by a full turn places every link exactly as before, so each returned
    configuration gives the same tool pose (the same measurement), clearance and incidence.

    Args:
        q: configuration (n,) rad (m for prismatic joints, never shifted).
        lower, upper: joint bounds (n,).
        revolute: (n,) bool, which joints are revolute.
        max_count: at most this many configurations (q first, then by fewer shifted joints).

    Returns:
        (k ≥ 1, n) configurations; row 0 is q.
    """
    q = np.asarray(q, float)
    choices = []
    for j in range(q.size):
        ks = [0]
        if revolute[j]:
            kmax = int(math.floor((upper[j] - q[j]) / (2 * math.pi) + 1e-12))
            kmin = int(math.ceil((lower[j] - q[j]) / (2 * math.pi) - 1e-12))
            ks += [k for k in range(kmin, kmax + 1) if k != 0]
        choices.append(ks)
    combos = sorted(itertools.product(*choices), key=lambda ks: sum(k != 0 for k in ks))[:max_count]
    # exactly q + 2πk, never clipped: a clipped value would be another pose (issue: a joint beyond its limit
    # was exported at the limit); rows other than q are within the bounds by construction
    return q[None, :] + 2 * math.pi * np.array(combos, float)


@dataclass
class MoveCheck:
    """Dense check of one joint-space move.

    Attributes:
        clear: every sample keeps the required clearance (the margin, or the end poses' if smaller).
        min_clearance_m: smallest pair distance along the move minus the cell's required clearance (m).
        n_samples: configurations evaluated.
        worst_fraction: where along the move (0…1) the smallest clearance is.
    """

    clear: bool
    min_clearance_m: float
    n_samples: int
    worst_fraction: float


class TransitionChecker:
    """Dense checks of joint-space moves in a cell (see the module docstring).

    Args:
        cell: the cell (its capsules, obstacles, half-spaces, skip pairs and required clearance).
        margin_m: extra clearance every move must keep (m), on top of ``cell.clearance_m``.
        step_rad: largest revolute joint step between samples (rad); at most 1° is the contract of the program check.
        step_m: largest prismatic joint step between samples (m).
        checker: an existing :class:`FeasibilityChecker` of the cell (built if None).
        use_bound: let a verified cheap lower bound of the pair distances
        (:class:`~pin_kpi_oed.program.move_bound.MoveBound`) clear the
            samples it proves clear; the others, the end poses and every sample that decides a result are
            checked exactly (Coal). The decisions and the smallest clearances are those of the exact check.

    Raises:
        InputError: negative margin or non-positive steps.
    """

    def __init__(self, cell: Cell, margin_m: float = 0.0, step_rad: float = math.radians(1.0),
                 step_m: float = 0.005, checker: FeasibilityChecker | None = None, use_bound: bool = True):
        if not (margin_m >= 0 and step_rad > 0 and step_m > 0):
            raise InputError(f"transition check: margin >= 0 and steps > 0 required, got margin {margin_m} m, "
                             f"steps {step_rad} rad / {step_m} m")
        self.cell = cell
        self.margin_m = float(margin_m)
        self.checker = checker or FeasibilityChecker(cell)
        self.required_m = float(cell.clearance_m) + self.margin_m
        rev = np.asarray(cell.robot.is_revolute, bool)
        self.steps = np.where(rev, float(step_rad), float(step_m))
        self.n_evaluations = 0
        self._cache: dict[tuple[bytes, bytes, bool], MoveCheck] = {}
        self._clearances: dict[bytes, float] = {}
        bound = MoveBound(self.checker) if use_bound else None
        #: the cheap lower bound deciding the samples it clears (None: every sample checked exactly)
        self.bound = bound if bound is not None and bound.ok else None

    def samples(self, qa: np.ndarray, qb: np.ndarray) -> np.ndarray:
        """Configurations along the straight joint move qa → qb, end points included, steps ≤ the limits."""
        qa, qb = np.asarray(qa, float), np.asarray(qb, float)
        k = max(1, int(math.ceil(float(np.max(np.abs(qb - qa) / self.steps)) - 1e-12)))
        s = np.linspace(0.0, 1.0, k + 1)[:, None]
        return qa + s * (qb - qa)

    def clearance(self, q: np.ndarray) -> float:
        """Smallest pair distance at q minus the cell's required clearance (m); ``inf`` with no pairs.

        Remembered per configuration (the end poses of moves are asked again and again); only new
        configurations count in :attr:`n_evaluations`.
        """
        key = np.asarray(q, float).tobytes()
        hit = self._clearances.get(key)
        if hit is not None:
            return hit
        self.n_evaluations += 1
        out = self.checker.min_pair_distance(q) - self.cell.clearance_m
        if len(self._clearances) >= 200_000:
            self._clearances.clear()
        self._clearances[key] = out
        return out

    def check(self, qa: np.ndarray, qb: np.ndarray, stop_early: bool = True) -> MoveCheck:
        """Densely check the move qa → qb.

        Args:
            qa, qb: end configurations (n,).
            stop_early: stop at the first sample below the required clearance.

        Returns:
            The :class:`MoveCheck` (``min_clearance_m`` over the samples evaluated).
        """
        qa, qb = np.asarray(qa, float), np.asarray(qb, float)
        key = (qa.tobytes(), qb.tobytes(), stop_early)
        hit = self._cache.get(key) or self._cache.get((qb.tobytes(), qa.tobytes(), stop_early))
        if hit is not None:
            return hit
        S = self.samples(qa, qb)
        ends = [self.clearance(S[0]), self.clearance(S[-1])]
        need = min(self.margin_m, min(ends)) - 1e-9  # never closer than the margin or than the end poses are
        k = int(np.argmin(ends))
        best, where, n = ends[k], float(k), 2
        if min(ends) < -1e-9:
            need = math.inf  # an end pose itself collides: the move cannot be clear
        inner = list(range(1, len(S) - 1))
        if self.bound is not None and stop_early and len(inner) > 8 and best >= need:
            for i in (len(S) // 2, len(S) // 4, (3 * len(S)) // 4):  # a colliding move is usually caught here
                c = self.clearance(S[i])
                n += 1
                if c < best:
                    best, where = c, i / (len(S) - 1)
                if best < need:
                    break
        if self.bound is not None and inner and not (stop_early and best < need):
            # exact checks only where the bound cannot decide, lowest bound first: the result (clear or not,
            # and without early stop the smallest clearance) is the exact check's
            # the balls stand in for closest points only far above what can decide: the margin (early stop), else
            # the smallest clearance so far (samples bounded above it are never evaluated)
            cap = ball_cap(self.cell.clearance_m + (max(need, self.margin_m) if stop_early else best))
            lb = self.bound(S[1:-1], cap) - self.cell.clearance_m
            order = np.argsort(lb, kind="stable")
            for o in order:
                if (stop_early and (best < need or lb[o] >= need)) or (not stop_early and lb[o] >= best):
                    break
                c = self.clearance(S[o + 1])
                n += 1
                if c < best:
                    best, where = c, (o + 1) / (len(S) - 1)
            inner = []
        for i in sorted(inner, key=lambda i: abs(i - len(S) / 2)):  # middle outwards
            if stop_early and best < need:
                break
            c = self.clearance(S[i])
            n += 1
            if c < best:
                best, where = c, i / (len(S) - 1)
        self._cache[key] = out = MoveCheck(bool(best >= need), best, n, where)
        return out

    def path_check(self, path: np.ndarray) -> MoveCheck:
        """Densely check a sequence of moves through the rows of ``path`` (no early stop)."""
        path = np.atleast_2d(path)
        checks = [self.check(a, b, stop_early=False) for a, b in zip(path[:-1], path[1:])]
        if not checks:
            return MoveCheck(True, math.inf, 0, 0.0)
        k = int(np.argmin([c.min_clearance_m for c in checks]))
        return MoveCheck(all(c.clear for c in checks), checks[k].min_clearance_m,
                         sum(c.n_samples for c in checks), (k + checks[k].worst_fraction) / len(checks))

    def safe_pool(self, n: int, seed: int = 0, max_tries: int | None = None) -> np.ndarray:
        """Seeded collision-free configurations (clearance ≥ 2 × the move margin) to route through.

        Args:
            n: configurations wanted.
            seed: seed of the uniform sampling within the cell's joint bounds.
            max_tries: sampling budget (default 50 n).

        Returns:
            (k ≤ n, joints) configurations.
        """
        rng = np.random.default_rng(seed)
        lo, hi = self.cell.q_lower, self.cell.q_upper
        out: list[np.ndarray] = []
        tries = max_tries or 50 * n
        thr = 2.0 * self.margin_m + 0.01
        while tries > 0 and len(out) < n:  # the same draws, in the same order, as one at a time
            X = lo + rng.random((min(64, tries), lo.size)) * (hi - lo)
            tries -= len(X)
            ok = self.at_least(X, thr, stop_after=n - len(out))
            out += [x for x in X[ok]]
        return np.array(out[:n]).reshape(-1, lo.size)

    def at_least(self, X: np.ndarray, threshold: float, stop_after: int | None = None) -> np.ndarray:
        """Which configurations keep ``clearance(q) >= threshold`` (the bound decides the clear ones).

        Args:
            X: configurations (k, n).
            threshold: required clearance (m, on top of the cell's).
            stop_after: stop once this many are found (the rest are False).

        Returns:
            (k,) bool.
        """
        X = np.atleast_2d(np.asarray(X, float))
        cap = ball_cap(self.cell.clearance_m + threshold)
        lb = ((self.bound(X, cap) - self.cell.clearance_m) if self.bound is not None and len(X)
              else np.full(len(X), -np.inf))
        out = np.zeros(len(X), bool)
        found = 0
        for i, x in enumerate(X):
            out[i] = lb[i] >= threshold or self.clearance(x) >= threshold
            found += out[i]
            if stop_after is not None and found >= stop_after:
                break
        return out

    def structured_vias(self, qa: np.ndarray, qb: np.ndarray, home: np.ndarray | None = None) -> np.ndarray:
        """Via candidates a programmer would try first for the move qa → qb.

        Wrist first (qa's arm, qb's wrist) and arm first (qb's arm, qa's wrist); the home pose; and
        qa, qb and their midpoint with the arm (the first three revolute joints after the first:
        shoulder and elbow) of the home pose, i.e. retracted. Non-revolute joints keep qa's values
        in the retracted candidates.

        Returns:
            (k, n) candidate configurations (not yet checked).
        """
        qa, qb = np.asarray(qa, float), np.asarray(qb, float)
        rev = np.flatnonzero(self.cell.robot.is_revolute)
        arm, wrist = rev[:3], rev[3:]
        out = []
        for x, y in ((qa, qb), (qb, qa)):
            v = x.copy()
            v[wrist] = y[wrist]
            out.append(v)
        if home is not None:
            home = np.asarray(home, float)
            out.append(home.copy())
            for base in (qa, qb, 0.5 * (qa + qb)):
                v = base.copy()
                v[arm[1:]] = home[arm[1:]]
                out.append(v)
        return np.array(out)

    def repair(self, qa: np.ndarray, qb: np.ndarray, vias: np.ndarray, speeds: np.ndarray, max_one: int = 24,
               max_legs: int = 6, safe: np.ndarray | None = None) -> list[np.ndarray] | None:
        """A collision-free route qa → via(s) → qb through candidate via poses, cheapest first.

        Args:
            qa, qb: end configurations.
            vias: candidate intermediate configurations (k, n) (:meth:`structured_vias`); candidates outside
                the joint bounds or too close to an obstacle are skipped.
            speeds: joint speed limits (n,): a move's cost is its time max_j |Δq_j| / v_j (s).
            max_one: one-via candidates checked (cheapest first).
            max_legs: candidates per side of the two-via search.
            safe: candidates known to be within the bounds and to keep the margin (a :meth:`safe_pool`),
                after ``vias``.

        Returns:
            The intermediate configurations (one or two), or None when no route was found.
        """
        vias = np.atleast_2d(vias)
        lo, hi = self.cell.q_lower, self.cell.q_upper
        if vias.size:
            vias = vias[np.all((vias >= lo) & (vias <= hi), axis=1)]
            vias = vias[self.at_least(vias, self.margin_m)]
        if safe is not None and len(safe):
            vias = np.vstack([vias.reshape(-1, lo.size), safe])
        if len(vias) == 0:
            return None
        speeds = np.asarray(speeds, float)
        ca = np.max(np.abs(vias - qa) / speeds, axis=1)
        cb = np.max(np.abs(qb - vias) / speeds, axis=1)
        for k in np.argsort(ca + cb)[:max_one]:
            if self.check(qa, vias[k]).clear and self.check(vias[k], qb).clear:
                return [vias[k]]
        A = [k for k in np.argsort(ca)[:3 * max_legs] if self.check(qa, vias[k]).clear][:max_legs]
        B = [k for k in np.argsort(cb)[:3 * max_legs] if self.check(vias[k], qb).clear][:max_legs]
        legs = sorted((ca[i] + float(np.max(np.abs(vias[j] - vias[i]) / speeds)) + cb[j], i, j)
                      for i in A for j in B if i != j)
        for _, i, j in legs:
            if self.check(vias[i], vias[j]).clear:
                return [vias[i], vias[j]]
        return None

    def plan_route(self, qa: np.ndarray, qb: np.ndarray, seed: int = 0, max_checks: int = 20_000
                   ) -> list[np.ndarray] | None:
        """A collision-free route qa → qb from OMPL's RRT-Connect in joint space, simplified and re-checked.

        OMPL plans in joint coordinates scaled by the dense steps (one unit = one step), with steps of
        :data:`ROUTE_RANGE` of the space's extent. A state is valid when its clearance keeps what :meth:`check`
        requires of the route (the margin, or the end poses' clearance if smaller); a motion is valid when both
        its states are and :meth:`check` clears it (every sample at the dense steps, the verified bound sparing
        the exact evaluations it can). The path found is simplified by OMPL's ``PathSimplifier`` (vertex
        reduction, partial shortcuts, vertex reduction again), then every leg is densely checked once more.

        OMPL's random numbers are seeded per call: ``ompl.util.RNG.setSeed`` with a seed drawn from ``seed``
        and the two end configurations, right before the space, planner and simplifier (whose generators OMPL
        seeds from it) are built. The same move gives the same route in one process or two, whatever was
        planned before.

        Args:
            qa, qb: end configurations (n,).
            seed: seed of the planner's random numbers.
            max_checks: planning budget in configurations checked (a count, not a time: the result does
                not depend on the machine's load).

        Returns:
            The intermediate configurations (empty when the straight move is clear), or None when an
            end pose collides or no route was found within the budget.
        """
        qa, qb = np.asarray(qa, float), np.asarray(qb, float)
        if min(self.clearance(qa), self.clearance(qb)) < 0.0:
            return None
        if self.check(qa, qb).clear:
            return []
        found = self.plan_route_from(qa[None], qb, seed=seed, max_checks=max_checks)
        return None if found is None else found[1]

    def plan_route_from(self, starts: np.ndarray, qb: np.ndarray, seed: int = 0, max_checks: int = 20_000
                        ) -> tuple[int, list[np.ndarray]] | None:
        """A collision-free route to qb from whichever of several start configurations reaches it (RRT-Connect).

        One OMPL problem with every start as a start state (RRT-Connect grows its start tree from all of them):
        starts in a pocket of the free space share one budget with the others instead of each exhausting its
        own, and the first start connected to the goal wins.
        Planned, simplified and re-checked as :meth:`plan_route` (OMPL seeded from ``seed``, the starts and qb).

        Args:
            starts: (k, n) alternative start configurations (e.g. a pose's 2π-equivalents); colliding ones
                are left out.
            qb: goal configuration (n,).
            seed: seed of the planner's random numbers.
            max_checks: planning budget in configurations checked.

        Returns:
            (index of the start the route leaves from, its intermediate configurations), or None when qb
            collides, every start collides or no route was found within the budget.
        """
        starts, qb = np.atleast_2d(np.asarray(starts, float)), np.asarray(qb, float)
        ok = [i for i, q in enumerate(starts) if self.clearance(q) >= 0.0]
        if not ok or self.clearance(qb) < 0.0:
            return None
        need = min(self.margin_m, self.clearance(qb), *(self.clearance(starts[i]) for i in ok)) - 1e-9
        pts = self._ompl_path(starts[ok], qb, need, _call_seed(seed, *starts[ok], qb), max(int(max_checks), 1))
        if pts is None:
            return None
        k = ok[int(np.argmin(np.abs(starts[ok] - pts[0]).max(axis=1)))]
        pts[0], pts[-1] = starts[k], qb
        if not all(self.check(u, v).clear for u, v in zip(pts[:-1], pts[1:])):
            return None
        return k, [p.copy() for p in pts[1:-1]]

    def _ompl_path(self, starts: np.ndarray, qb: np.ndarray, need: float, seed: int, budget: int
                   ) -> np.ndarray | None:
        """OMPL's RRT-Connect (every row of ``starts`` a start state) and path simplifier for :meth:`plan_route_from`:
        the path's configurations (its first one of the starts), or None."""
        from ompl import base as ob
        from ompl import geometric as og
        from ompl import util as ou

        n, scale = qb.size, self.steps
        counts = {"motions": 0}

        def vec(state) -> np.ndarray:
            return np.fromiter((state[j] for j in range(n)), float, n) * scale

        def valid(state) -> bool:
            return bool(self.clearance(vec(state)) >= need)

        def motion(s1, s2) -> bool:
            counts["motions"] += 1
            a, b = vec(s1), vec(s2)
            return bool(self.clearance(a) >= need and self.clearance(b) >= need and self.check(a, b).clear)

        def until(checks: int):
            stop_at, motions_at = self.n_evaluations + checks, counts["motions"] + checks
            return ob.PlannerTerminationCondition(
                lambda: self.n_evaluations >= stop_at or counts["motions"] >= motions_at)

        ou.noOutputHandler()  # OMPL logs every re-seed after its first numbers; re-seeding per call is the intent
        try:
            ou.RNG.setSeed(seed)
            space = ob.RealVectorStateSpace(n)
            bounds = ob.RealVectorBounds(n)
            for j in range(n):
                bounds.setLow(j, float(self.cell.q_lower[j] / scale[j]))
                bounds.setHigh(j, float(self.cell.q_upper[j] / scale[j]))
            space.setBounds(bounds)
            si = ob.SpaceInformation(space)
            si.setStateValidityChecker(valid)
            si.setMotionValidator(_DenseMotions(si, motion))
            si.setup()
            pdef = ob.ProblemDefinition(si)
            for qa in starts:
                start = space.allocState()
                for j in range(n):
                    start[j] = float(qa[j] / scale[j])
                pdef.addStartState(start)
            goal = space.allocState()
            for j in range(n):
                goal[j] = float(qb[j] / scale[j])
            pdef.setGoalState(goal)
            planner = og.RRTConnect(si)
            planner.setRange(ROUTE_RANGE * space.getMaximumExtent())
            planner.setProblemDefinition(pdef)
            planner.setup()
            planner.solve(until(budget))
            if not pdef.hasExactSolution():
                return None
            path = pdef.getSolutionPath()
            simplifier = og.PathSimplifier(si)
            simplifier.reduceVertices(path)
            simplifier.partialShortcutPath(path)
            simplifier.reduceVertices(path)
            return np.array([vec(path.getState(i)) for i in range(path.getStateCount())])
        finally:
            ou.restorePreviousOutputHandler()


def _call_seed(seed: int, *ends: np.ndarray) -> int:
    """OMPL's seed of one planning call (1 … 2³¹ − 1): drawn from ``seed`` and the end configurations."""
    words = np.frombuffer(np.concatenate(ends).astype(float).tobytes(), np.uint32)
    state = np.random.SeedSequence([int(seed) & 0xFFFFFFFF, *map(int, words)]).generate_state(1)[0]
    return int(state) % (2 ** 31 - 1) + 1


def _DenseMotions(si, motion):
    """An OMPL motion validator (``ompl.base.MotionValidator``) answering with ``motion(s1, s2)``."""
    from ompl import base as ob

    class DenseMotions(ob.MotionValidator):
        def checkMotion(self, s1, s2, *last_valid) -> bool:  # noqa: N802 (OMPL's name)
            return motion(s1, s2)

    return DenseMotions(si)
