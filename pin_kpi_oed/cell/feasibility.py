"""Independent dense feasibility check of a design (Pinocchio forward kinematics + Coal).

:class:`FeasibilityChecker` re-evaluates configurations of a :class:`~pin_kpi_oed.cell.cell.Cell`
densely — every capsule pair, no pruning, no batching — with Pinocchio's forward kinematics, a
``pin.GeometryModel`` of Coal capsules and half-spaces (``pin.computeDistances``), per-pose Coal
capsules for the laser beam and the incidence angle (eq. 4) from ``oMf[tool]``: none of the
optimiser's code path (:mod:`pin_kpi_oed.cell.collision`). The design optimiser reports its
designs through it, and the viewer's clearances are its distances.

Pairs checked: robot capsules of non-adjacent joints (a joint's parent and child are adjacent),
every robot capsule against every obstacle capsule and half-space, and the beam (tracker →
reflector) against every robot capsule, obstacle and half-space; the cell's ``skip_pairs`` and
``beam_skip`` are honoured (by capsule, link, obstacle or half-space name). Obstacles from environment
files (:mod:`pin_kpi_oed.cell.environment`) are checked as their geometry (Coal boxes, cylinders,
spheres, convex or BVH meshes), not as the optimiser's enclosing capsules. Distances are signed
(negative = penetration depth), in metres, for the capsules as solids (radii subtracted).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from operator import attrgetter

import numpy as np
import pinocchio as pin

from pin_kpi_oed.cell.cell_model import Cell

_MIN_DISTANCE = attrgetter("min_distance")
_Z_AXIS = np.array([0.0, 0.0, 1.0])
_Z_AXIS.flags.writeable = False


def coal_capsule(a: np.ndarray, b: np.ndarray, radius: float):
    """A Coal capsule whose segment is [a, b] (m), and its transform (local z along b − a).

    Args:
        a, b: end points of the segment (m).
        radius: radius (m).

    Returns:
        (coal.Capsule, coal.Transform3s).
    """
    import coal

    a, b = np.asarray(a, float), np.asarray(b, float)
    d = b - a
    L = math.sqrt(d.dot(d))  # what np.linalg.norm computes for a vector, without its overhead
    R = pin.Quaternion.FromTwoVectors(_Z_AXIS, d / L).matrix() if L > 1e-12 else np.eye(3)
    T = coal.Transform3s(R, 0.5 * (a + b))
    return coal.Capsule(float(radius), L), T


@dataclass
class FeasibilityReport:
    """Dense, independent feasibility check of a design.

    Attributes:
        collision_free: per pose, every capsule pair and half-space clear (m,).
        visible: per pose, laser beam unobstructed and incidence within the limit (m,).
        within_bounds: per pose, joint values within the cell's bounds (m,).
        clearance_m: per pose, smallest clearance over every checked pair (incl. the beam) minus the
            cell's required clearance (m,) m; ``inf`` when nothing is checked.
        incidence_deg: per pose, incidence angle (m,) deg.
        worst: per pose, name of the pair with the smallest clearance.
        n_pairs: pairs checked per pose (robot–robot, robot–obstacle, robot–half-space, beam).
    """

    collision_free: np.ndarray
    visible: np.ndarray
    within_bounds: np.ndarray
    clearance_m: np.ndarray
    incidence_deg: np.ndarray
    worst: list[str]
    n_pairs: int

    @property
    def feasible(self) -> np.ndarray:
        """Per pose: collision-free, visible and within bounds."""
        return self.collision_free & self.visible & self.within_bounds

    @property
    def all_feasible(self) -> bool:
        """Whether every pose is feasible."""
        return bool(np.all(self.feasible))

    @property
    def share_colliding(self) -> float:
        """Share of poses in collision (capsules or half-spaces), 0…1."""
        return float(np.mean(~self.collision_free)) if self.collision_free.size else 0.0

    @property
    def share_infeasible(self) -> float:
        """Share of poses failing any check, 0…1."""
        return float(np.mean(~self.feasible)) if self.collision_free.size else 0.0

    @property
    def min_clearance_m(self) -> float:
        """Smallest clearance of the design (m)."""
        return float(self.clearance_m.min()) if self.clearance_m.size else float("inf")

    @property
    def max_incidence_deg(self) -> float:
        """Largest incidence angle of the design (deg)."""
        return float(self.incidence_deg.max()) if self.incidence_deg.size else 0.0

    def violations(self, limit: int = 5) -> list[str]:
        """Readable descriptions of the first infeasible poses."""
        out = []
        for i in np.flatnonzero(~self.feasible)[:limit]:
            why = []
            if not self.within_bounds[i]:
                why.append("outside the joint bounds")
            if not self.collision_free[i] or self.clearance_m[i] < 0:
                why.append(f"{self.worst[i]} at {self.clearance_m[i] * 1e3:.1f} mm")
            if not self.visible[i] and self.clearance_m[i] >= 0:
                why.append(f"incidence {self.incidence_deg[i]:.1f} deg")
            out.append(f"pose {i}: " + ", ".join(why))
        return out

    def to_dict(self) -> dict:
        """Plain numbers."""
        return {"all_feasible": self.all_feasible, "n_poses": int(self.collision_free.size),
                "n_colliding": int(np.sum(~self.collision_free)), "n_invisible": int(np.sum(~self.visible)),
                "n_out_of_bounds": int(np.sum(~self.within_bounds)), "share_colliding": self.share_colliding,
                "min_clearance_m": self.min_clearance_m, "max_incidence_deg": self.max_incidence_deg,
                "pairs_per_pose": self.n_pairs, "violations": self.violations()}


class FeasibilityChecker:
    """Independent dense check: Pinocchio FK + Coal on a ``pin.GeometryModel``, every pair.

    Args:
        cell: the measurement cell.

    Attributes:
        pair_names: (name, name) of every checked capsule / half-space pair.
        beam_names: name of every capsule / half-space the beam is checked against.
        names: ``a|b`` for every pair, then ``beam|x`` for every beam target: the columns of
            :meth:`distances`.
        n_pairs: number of capsule / half-space pairs (the first columns of :meth:`distances`).
    """

    def __init__(self, cell: Cell):
        self.cell = cell
        rb = cell.robot
        self.model = rb.model
        self.data = rb.model.createData()
        self.gm = pin.GeometryModel()
        self.labels: list[tuple[str, str | None]] = []  # (name, link) of every geometry object
        self.robot_ids, self.robot_joint = self._add_robot_capsules()
        self.obst_ids, self.half_ids = self._add_obstacles()
        env_ids, self.mesh_ids = add_environment_solids(self)  # environment meshes themselves
        self.obst_ids += env_ids
        self.pairs = self._collision_pairs()
        #: pairs with a non-convex mesh (Coal BVH), whose near-zero distances :func:`mesh_penetration` re-tests
        self.mesh_pairs = [p for p, (i, k) in enumerate(self.pairs) if i in self.mesh_ids or k in self.mesh_ids]
        for i, k in self.pairs:
            self.gm.addCollisionPair(pin.CollisionPair(i, k))
        self.gd = pin.GeometryData(self.gm)
        #: the boxes around the non-convex meshes that let :meth:`min_pair_distance` leave out far mesh pairs
        self.mesh_boxes = mesh_boxes(self) if self.mesh_pairs else None
        self._mesh_active = True  # the mesh pairs active in ``gd`` (all but inside min_pair_distance)
        # references into GeometryData's result vector, made once: iterating or indexing the vector's property wraps
        # every result anew (several times Coal's own work); the references read the results of every later call
        self._results = list(self.gd.distanceResults)
        self.beam_targets = [i for i in self.robot_ids + self.obst_ids + self.half_ids
                             if not any(x in self._keys(i) for x in cell.beam_skip)]
        # the beam targets' shapes read once; the placements of the fixed ones (on the universe joint) made into
        # Coal transforms once, at the first pose (the same numbers at every pose)
        self._beam_shapes = [self.gm.geometryObjects[i].geometry for i in self.beam_targets]
        self._beam_fixed = [self.gm.geometryObjects[i].parentJoint == 0 for i in self.beam_targets]
        self._beam_T: list = []
        self._distance_request = None
        self.tool_id = rb.tool_frame_id
        self.tracker = cell.tracker_in_base
        self.reflector = np.asarray(cell.reflector_m, float)
        go = self.gm.geometryObjects
        self.n_pairs = len(self.pairs)
        self.pair_names = [(go[a].name, go[b].name) for a, b in self.pairs]
        self.beam_names = [go[i].name for i in self.beam_targets]
        self.names = [f"{a}|{b}" for a, b in self.pair_names] + [f"beam|{x}" for x in self.beam_names]

    # ------------------------------------------------------------------ set-up
    def _add_robot_capsules(self) -> tuple[list[int], list[int]]:
        """Robot capsules as geometry objects on their joints; returns (geometry ids, joint ids)."""
        ids, joints = [], []
        model = self.model
        for c in self.cell.robot_capsules:
            fid = model.getFrameId(c.link, pin.FrameType.BODY)
            fr = model.frames[fid]
            shape, T = coal_capsule(fr.placement.act(c.a), fr.placement.act(c.b), c.radius)
            go = pin.GeometryObject(c.name, int(fr.parentJoint), fid, pin.SE3(T.getRotation(), T.getTranslation()),
                                    shape)
            ids.append(self.gm.addGeometryObject(go))
            joints.append(int(fr.parentJoint))
            self.labels.append((c.name, c.link))
        return ids, joints

    def _add_obstacles(self) -> tuple[list[int], list[int]]:
        """Obstacle capsules and half-spaces, fixed in the base frame; returns their geometry ids."""
        import coal

        base_T_W = self.cell.W_T_base.inverse()
        obst, half = [], []
        for o in self.cell.obstacles:
            if o.name in self.cell.environment_capsule_names:
                continue  # the optimiser's capsules of an environment file: checked as the meshes themselves
            shape, T = coal_capsule(base_T_W.act(o.a), base_T_W.act(o.b), o.radius)
            go = pin.GeometryObject(o.name, 0, 0, pin.SE3(T.getRotation(), T.getTranslation()), shape)
            obst.append(self.gm.addGeometryObject(go))
            self.labels.append((o.name, None))
        for h in self.cell.half_spaces:
            # coal.Halfspace(n, d) is the solid {x : n·x <= d}; the free side is n·x >= offset
            go = pin.GeometryObject(h.name, 0, 0, pin.SE3(base_T_W), coal.Halfspace(h.normal, h.offset))
            half.append(self.gm.addGeometryObject(go))
            self.labels.append((h.name, None))
        return obst, half

    def _keys(self, i: int) -> set[str]:
        """Names a skip entry may use for geometry object i (its own name, its link)."""
        return {x for x in self.labels[i] if x}

    def _skipped(self, a: set[str], b: set[str]) -> bool:
        """Whether a skip pair of the cell names two objects whose names are ``a`` and ``b``."""
        return any((x in a and y in b) or (x in b and y in a) for x, y in self.cell.skip_pairs)

    def _collision_pairs(self) -> list[tuple[int, int]]:
        """Non-adjacent robot capsule pairs, robot capsules against obstacles and half-spaces, minus skips."""
        parents = [int(p) for p in self.model.parents]

        def adjacent(j1: int, j2: int) -> bool:
            return j1 == j2 or parents[j1] == j2 or parents[j2] == j1

        keys = [self._keys(i) for i in range(len(self.labels))]  # every object's names, made once
        pairs = []
        for x, i in enumerate(self.robot_ids):
            for y, k in enumerate(self.robot_ids):
                if y > x and not adjacent(self.robot_joint[x], self.robot_joint[y]) and \
                        not self._skipped(keys[i], keys[k]):
                    pairs.append((i, k))
            for k in self.obst_ids + self.half_ids:
                if not self._skipped(keys[i], keys[k]):
                    pairs.append((i, k))
        return pairs

    # ------------------------------------------------------------------ evaluation
    def _pose(self, q: np.ndarray) -> tuple[np.ndarray, float]:
        """Signed distances (m, radii subtracted) of every pair and beam target at q, and cos(incidence)."""
        import coal

        d = np.empty(len(self.names))
        d[:self.n_pairs] = self.pair_distances(q)
        oMt = self.data.oMf[self.tool_id]
        refl = oMt.act(self.reflector)
        beam, Tb = coal_capsule(self.tracker, refl, self.cell.beam_radius_m)
        req = self._distance_request
        if req is None:
            req = self._distance_request = coal.DistanceRequest()
        for k, T in enumerate(self._beam_transforms()):
            d[self.n_pairs + k] = coal.distance(beam, Tb, self._beam_shapes[k], T, req, coal.DistanceResult())
        if self.mesh_ids:
            beam_mesh_penetration(self, beam, Tb, d)
        g = self.tracker - refl
        return d, float(oMt.rotation[:, 2] @ g / np.linalg.norm(g))

    def _beam_transforms(self) -> list:
        """Coal transforms of the beam targets at the current placements (``gd.oMg``): the fixed ones' made once."""
        import coal

        oMg = self.gd.oMg
        if not self._beam_T:
            self._beam_T = [None] * len(self.beam_targets)
            for k, gid in enumerate(self.beam_targets):
                if self._beam_fixed[k]:
                    self._beam_T[k] = coal.Transform3s(oMg[gid].rotation, oMg[gid].translation)
        out = list(self._beam_T)
        for k, gid in enumerate(self.beam_targets):
            if out[k] is None:
                Mg = oMg[gid]
                out[k] = coal.Transform3s(Mg.rotation, Mg.translation)
        return out

    def pair_distances(self, q: np.ndarray) -> np.ndarray:
        """Signed distances (m, radii subtracted) of the capsule / half-space pairs at one configuration.

        The first :attr:`n_pairs` columns of :meth:`distances` (no beam, no incidence): what a move
        between poses must keep clear (:mod:`pin_kpi_oed.program.transitions`).

        Args:
            q: configuration (n,) rad (m for prismatic joints).

        Returns:
            (n_pairs,) m; negative = penetration. The cell's required clearance is not subtracted.
        """
        self._activate_mesh_pairs(True)
        pin.framesForwardKinematics(self.model, self.data, np.asarray(q, float))
        pin.updateGeometryPlacements(self.model, self.data, self.gm, self.gd)
        pin.computeDistances(self.gm, self.gd)
        return self._pairs_computed()

    def _activate_mesh_pairs(self, active: bool) -> None:
        """The mesh pairs computed by ``computeDistances`` (True) or left to :meth:`min_pair_distance` (False)."""
        if self._mesh_active != active:
            for p in self.mesh_pairs:
                if active:
                    self.gd.activateCollisionPair(p)
                else:
                    self.gd.deactivateCollisionPair(p)
            self._mesh_active = active

    def _pairs_computed(self) -> np.ndarray:
        """The pairs' signed distances (n_pairs,) m of the last ``computeDistances``, non-convex meshes re-tested."""
        d = np.array(list(map(_MIN_DISTANCE, self._results)))[:self.n_pairs]
        return mesh_penetration(self, d) if self.mesh_pairs else d

    def min_pair_distance(self, q: np.ndarray) -> float:
        """The smallest of :meth:`pair_distances` at one configuration (m; ``inf`` with no pairs).

        Coal computes every pair as in :meth:`pair_distances`; Pinocchio's ``computeDistances`` returns the index
        of the smallest, so only that result is read (reading all of them costs several times Coal's work). When
        that smallest is within the contact tolerance of a non-convex mesh, every pair's result of that call is read
        and re-tested as in :meth:`pair_distances` (:func:`mesh_penetration` changes only pairs that close): the
        same value, but for the last digits of Coal's warm-started GJK pairs (a second call would start them
        from this one's results; ~1e-16 m). A pair of a robot capsule and a non-convex mesh is computed only when
        the capsule's distance to the box around the mesh (:func:`mesh_boxes`) does not keep it
        :data:`BOX_SLACK_M` above the smallest distance found (the other pairs first, then the mesh pairs from the
        nearest box): the same smallest value, at about half the cost in the UR10 cell.

        Args:
            q: configuration (n,) rad (m for prismatic joints).

        Returns:
            Smallest signed distance (m); the cell's required clearance is not subtracted.
        """
        if not self.n_pairs:
            return float("inf")
        # forward kinematics, the geometry's placements and every pair's distance in one call (no frame placements:
        # nothing here reads them; :meth:`pair_distances` places the frames)
        if self.mesh_boxes is not None:
            return self._min_beside_boxes(np.asarray(q, float))
        k = pin.computeDistances(self.model, self.data, self.gm, self.gd, np.asarray(q, float))
        d_min = float(self._results[k].min_distance)
        if not self.mesh_pairs or d_min > _MESH_CONTACT_M:
            return d_min
        return float(self._pairs_computed().min())  # placed and computed above

    def _min_beside_boxes(self, q: np.ndarray) -> float:
        """:meth:`min_pair_distance` with the mesh pairs computed only where their robot capsule's distance to the box
        around the mesh (:attr:`mesh_boxes`, Coal) is not :data:`BOX_SLACK_M` above the smallest distance found: the
        same smallest value (a pair left out is farther than it); every pair computed when the smallest is within
        the contact tolerance of a mesh (the penetration re-test reads them all)."""
        self._activate_mesh_pairs(False)
        k = pin.computeDistances(self.model, self.data, self.gm, self.gd, q)
        res, gm, gd = self._results, self.gm, self.gd
        d_min = float(res[k].min_distance) if k < self.n_pairs else math.inf
        bgm, bgd, bres = self.mesh_boxes
        pin.updateGeometryPlacements(self.model, self.data, bgm, bgd)
        kb = pin.computeDistances(bgm, bgd)
        if d_min > _MESH_CONTACT_M and bres[kb].min_distance > d_min + BOX_SLACK_M:
            return d_min  # every mesh pair farther than the smallest found
        low = np.array(list(map(_MIN_DISTANCE, bres)))
        done = np.zeros(len(low), bool)
        for j in np.argsort(low, kind="stable"):
            if low[j] > d_min + BOX_SLACK_M:
                break
            pin.computeDistance(gm, gd, self.mesh_pairs[j])
            done[j] = True
            d_min = min(d_min, float(res[self.mesh_pairs[j]].min_distance))
        if d_min > _MESH_CONTACT_M:
            return d_min
        for j in np.flatnonzero(~done):
            pin.computeDistance(gm, gd, self.mesh_pairs[j])
        return float(self._pairs_computed().min())  # every pair computed at q

    def distances(self, Q: np.ndarray) -> np.ndarray:
        """Signed distances of every checked pair and beam target (columns named by :attr:`names`).

        Args:
            Q: configurations (m, n) rad.

        Returns:
            (m, len(names)) m; negative = penetration. The cell's required clearance is not subtracted.
        """
        Q = np.atleast_2d(np.asarray(Q, float))
        return np.array([self._pose(q)[0] for q in Q]).reshape(Q.shape[0], len(self.names))

    def check(self, Q: np.ndarray, tol: float = 1e-7) -> FeasibilityReport:
        """Check every pose of a design.

        Args:
            Q: configurations (m, n) rad.
            tol: tolerance on clearances (m) and joint bounds (rad) for rounding.

        Returns:
            The :class:`FeasibilityReport`.
        """
        cell = self.cell
        Q = np.atleast_2d(np.asarray(Q, float))
        m, P = Q.shape[0], self.n_pairs
        cos_max = np.cos(np.radians(cell.incidence_max_deg))
        cf, vis, clr, inc, worst = np.ones(m, bool), np.ones(m, bool), np.zeros(m), np.zeros(m), []
        bounds = np.all((Q >= cell.q_lower - tol) & (Q <= cell.q_upper + tol), axis=1)
        for i, q in enumerate(Q):
            d, c = self._pose(q)
            d = d - cell.clearance_m
            k = int(np.argmin(d[:P])) if P else -1
            best = d[k] if P else np.inf
            cf[i] = best >= -tol
            kb = P + int(np.argmin(d[P:])) if d.size > P else -1
            bbest = d[kb] if kb >= 0 else np.inf
            inc[i] = float(np.degrees(np.arccos(np.clip(c, -1.0, 1.0))))
            vis[i] = bbest >= -tol and c >= cos_max - 1e-9
            if bbest < best:
                best, k = bbest, kb
            clr[i] = best
            worst.append(self.names[k] if k >= 0 else "")
        return FeasibilityReport(cf, vis, bounds, clr, inc, worst, len(self.names))


# ---------------------------------------------------------------------- environment meshes
#: a BVH pair that Coal's distance puts within this (m) is tested with coal.collide for penetration
_MESH_CONTACT_M = 1e-6


#: how far (m) the box around a mesh must keep a robot capsule above the smallest pair distance found before
#: :meth:`FeasibilityChecker.min_pair_distance` leaves that mesh pair out: far above Coal's GJK tolerance
BOX_SLACK_M = 1e-4


def mesh_boxes(chk: FeasibilityChecker) -> tuple | None:
    """The robot capsules of the mesh pairs against boxes around the meshes, in a geometry model of their own.

    Coal's distance between a capsule and a BVH triangle mesh is the dearest of the check's pairs (the UR10 cell's
    workpiece: eight such pairs cost several times its 88 capsule pairs); the box (the mesh's vertices' bounding
    box in its own frame, placed as the mesh, 1e-6 m wider) holds every triangle, so a capsule's distance to it is a
    lower bound of its distance to the mesh.

    Args:
        chk: the checker (its ``mesh_pairs`` of a robot capsule and a fixed mesh).

    Returns:
        (``pin.GeometryModel``, its ``GeometryData``, the data's distance results), one pair per entry of
        ``chk.mesh_pairs`` in that order; None when a mesh pair is not of that kind.
    """
    import coal

    go, robot = chk.gm.geometryObjects, set(chk.robot_ids)
    bgm = pin.GeometryModel()
    for j, p in enumerate(chk.mesh_pairs):
        i, k = chk.pairs[p]
        if i not in robot:
            i, k = k, i
        mesh = go[k].geometry
        if i not in robot or go[k].parentJoint != 0 or not hasattr(mesh, "vertices"):
            return None
        V = np.asarray(mesh.vertices(), float).reshape(-1, 3)
        lo, hi = V.min(axis=0) - 1e-6, V.max(axis=0) + 1e-6
        a = bgm.addGeometryObject(pin.GeometryObject(f"capsule_{j}", go[i].parentJoint, go[i].parentFrame,
                                                     go[i].placement, go[i].geometry))
        centre = go[k].placement * pin.SE3(np.eye(3), 0.5 * (lo + hi))
        b = bgm.addGeometryObject(pin.GeometryObject(f"box_{j}", 0, 0, centre, coal.Box(*(hi - lo))))
        bgm.addCollisionPair(pin.CollisionPair(a, b))
    bgd = pin.GeometryData(bgm)
    return bgm, bgd, list(bgd.distanceResults)


def add_environment_solids(chk: FeasibilityChecker) -> tuple[list[int], set[int]]:
    """Add the cell's environment geometry (:mod:`pin_kpi_oed.cell.environment`) to the checker's model.

    Each solid is fixed in the base frame, labelled (solid name, environment object name) so that the
    skip lists may name the object.

    Returns:
        (the geometry ids added, those of them that are non-convex meshes (Coal BVH models), for
        :func:`mesh_penetration`).
    """
    base_T_W = chk.cell.W_T_base.inverse()
    ids: list[int] = []
    mesh_ids: set[int] = set()
    for e in chk.cell.environment:
        for s in e.solids:
            go = pin.GeometryObject(s.name, 0, 0, base_T_W * s.W_T_g, s.geometry)
            i = chk.gm.addGeometryObject(go)
            chk.labels.append((s.name, e.name))
            ids.append(i)
            if not s.convex:
                mesh_ids.add(i)
    return ids, mesh_ids


def _penetration(g1, M1: pin.SE3, g2, M2: pin.SE3) -> float | None:
    """Coal's penetration depth (m, <= -1e-6) of two intersecting shapes, None if they do not intersect."""
    import coal

    req = coal.CollisionRequest()
    req.enable_contact = True
    req.num_max_contacts = 16
    res = coal.CollisionResult()
    if not coal.collide(g1, coal.Transform3s(M1.rotation, M1.translation), g2,
                        coal.Transform3s(M2.rotation, M2.translation), req, res):
        return None
    depth = min((res.getContact(k).penetration_depth for k in range(res.numContacts())), default=0.0)
    return min(float(depth), -_MESH_CONTACT_M)


def mesh_penetration(chk: FeasibilityChecker, d: np.ndarray) -> np.ndarray:
    """Pair distances with the penetration of non-convex meshes made negative.

    Coal's distance between a capsule and a BVH triangle mesh is negative when the capsule crosses
    triangles (a depth per triangle, not of the solid), but about 0 in degenerate contacts (a capsule
    crossing a plate with its end on the far face: ``tests/test_environment.py``); pairs within 1e-6 m
    are tested with ``coal.collide`` at the current placements (``chk.gd.oMg``) and, when they
    intersect, get Coal's contact depth (at least 1e-6 m deep), so that the check flags them.

    Args:
        chk: the checker (its ``pairs`` and ``mesh_pairs``), after :meth:`FeasibilityChecker.pair_distances`
            placed the geometry.
        d: (n_pairs,) distances (m), changed in place.

    Returns:
        ``d``.
    """
    go, oMg = chk.gm.geometryObjects, chk.gd.oMg
    for p in chk.mesh_pairs:
        if d[p] <= _MESH_CONTACT_M:
            i, k = chk.pairs[p]
            pen = _penetration(go[i].geometry, oMg[i], go[k].geometry, oMg[k])
            if pen is not None:
                d[p] = min(d[p], pen)
    return d


def beam_mesh_penetration(chk: FeasibilityChecker, beam, Tb, d: np.ndarray) -> None:
    """The beam's distances to non-convex meshes made negative where it passes through them (in place;
    ``d`` holds the pairs first, then the beam targets)."""
    for k, gid in enumerate(chk.beam_targets):
        j = chk.n_pairs + k
        if gid in chk.mesh_ids and d[j] <= _MESH_CONTACT_M:
            Mb = pin.SE3(Tb.getRotation(), Tb.getTranslation())
            pen = _penetration(beam, Mb, chk.gm.geometryObjects[gid].geometry, chk.gd.oMg[gid])
            if pen is not None:
                d[j] = min(d[j], pen)
