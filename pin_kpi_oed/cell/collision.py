"""Collision, line-of-sight and incidence constraints with exact gradients (paper eqs. 4, 20–24b).

The paper counts n(n−1)/2 − (n−1) pairs for n one-capsule links (eq. 22) and differentiates the
segment distance (eq. 23); here the pairs are listed explicitly (skip lists, pruning) and the
gradient is the witness-point form below.

Every constraint is written ``g(q) ≥ 0`` for one measurement configuration q:

* **capsule pairs** (eq. 20): ``d = d_P(b₁, b₂) − r₁ − r₂ − c ≥ 0`` where d_P is the distance of
  the two segments (eq. 21) and c the cell's clearance. Pairs: non-adjacent robot capsules
  (self-collision), robot capsules and obstacle capsules, and the **laser beam** — a thin capsule
  from the tracker to the reflector — against the robot's capsules and the obstacles;
* **half-spaces** ``{x : nᵀx ≥ o}`` (wall, floor; section 3.2): per capsule end point e,
  ``nᵀe − o − r − c ≥ 0`` (a capsule lies in a half-space iff both end points do, so this is
  exact and smooth, two rows per capsule);
* **incidence** (eq. 4): ``cos β − cos β_max ≥ 0`` with cos β = zᵀg, z the reflector axis and g
  the unit beam towards the tracker (:meth:`TrackerModel.incidence_cos`).

Distances and gradients. The segment distance is computed in closed form for all pairs and
all m configurations at once (the clamped closest-point algorithm of Lumelsky / Ericson); it
gives the witness points w₁ = A₁ + s(B₁ − A₁), w₂ = A₂ + t(B₂ − A₂) and the unit normal
n = (w₂ − w₁)/‖w₂ − w₁‖. By Danskin's theorem (the minimiser (s, t) is optimal, its feasible
set [0,1]² does not depend on q), the gradient is that of the distance of the two
*material* witness points::

    ∂d/∂q = nᵀ ( ∂w₂/∂q − ∂w₁/∂q ),   ∂w/∂q = (1 − s) ∂A/∂q + s ∂B/∂q,

and for a point x carried by joint k, ∂x/∂q_j = v_j + ω_j × x for j ≤ k ((v_j, ω_j) the
world twist of joint j, Pinocchio's WORLD Jacobian column). This holds in penetration too
(d < 0 while the segments are apart); only intersecting segments (d_P = 0) have no gradient.
The same distances from Coal are available with ``backend="geometry"``: the segments as
capsules of a ``pin.GeometryModel`` (:class:`~pin_kpi_oed.cell.coal_distances.GeometryDistances`), one
``pin.computeDistances`` per configuration in C++, witness points projected back onto the segments and the same
witness-point gradient; the tests check it equals the closed form to 1e-9 (the closed form stays
the optimiser's default and the test oracle: on 60 poses the Coal path costs 1.7× its CPU time with
the KS band, 2.6× with every witness point read, dominated by reading results from Python).
``backend="coal"`` (``coal.distance`` per pair from Python) is the slow reference.

Sparsity. A row depends on the joints that move one of its two elements but not both rigidly
together: a pair of robot capsules on joints k₁ < k₂ depends on q_{k₁+1} … q_{k₂} only.

Pruning (exact, before optimisation): a robot capsule on joint k ≥ 2 stays within
R_k = Σ_{j=3..k} ‖M_j.t‖ + ‖x‖ + r of the origin of joint 2, which moves on a circle about
joint 1's axis; robot–obstacle and robot–half-space rows whose lower bound over the
(sampled, chord error added) circle is positive can never be active and are dropped.

Independent check: :class:`pin_kpi_oed.cell.feasibility.FeasibilityChecker` re-evaluates a
design densely with Pinocchio and Coal — none of this module's code path.
"""

from __future__ import annotations

from typing import Literal, overload

import numpy as np
import pinocchio as pin

from pin_kpi_oed.cell.cell_model import Cell
from pin_kpi_oed.cell.cell_checks import check_static, check_working
from pin_kpi_oed.cell.coal_distances import GeometryDistances
from pin_kpi_oed.cell.constraint_rows import HALF, INCID, PAIR, ConstraintRows
from pin_kpi_oed.cell.feasibility import coal_capsule
from pin_kpi_oed.cell.segments import cross, point_segment_distance, segment_closest
from pin_kpi_oed.model.kinematics import Chain
from pin_kpi_oed.model.tracker import TrackerModel

__all__ = ["CollisionModel", "ConstraintRows", "PAIR", "HALF", "INCID", "segment_closest"]


# ---------------------------------------------------------------------------- the optimiser's model
class CollisionModel:
    """All constraints g(q) ≥ 0 of a cell, evaluated for m configurations in one batched call.

    Args:
        cell: the measurement cell.
        collision: include capsule, half-space and beam rows (False: incidence only).
        incidence: include the incidence row.
        prune: drop robot–obstacle and robot–half-space rows that can never be active.
        model: the cell's measurement model (built if None).

    Raises:
        InputError: a fixed robot capsule collides with an obstacle (not in skip_pairs), the
            tracker is inside an obstacle, or the working configurations collide / are out of sight.
    """

    def __init__(self, cell: Cell, collision: bool = True, incidence: bool = True, prune: bool = True,
                 model: TrackerModel | None = None):
        self.cell = cell
        self.robot = cell.robot
        self.model = model if model is not None else cell.tracker_model()
        self.p0 = np.zeros(self.model.n_params)
        rm = self.robot.model
        self.n = self.robot.nq
        # the measurement model's chain when it is this robot's: its remembered frames serve the incidence row too
        self.fk = self.model.chain if self.model.robot is self.robot else Chain(rm, self.robot.joint_ids)
        jpos = {j: k + 1 for k, j in enumerate(self.robot.joint_ids)}  # pinocchio joint id -> chain index
        self.cos_max = float(np.cos(np.radians(cell.incidence_max_deg)))
        base_T_W = cell.W_T_base.inverse()

        # ---- segment table: robot capsules, obstacles, beam
        names, joint, A, B, rad, link = [], [], [], [], [], []
        for c in cell.robot_capsules:
            fid = rm.getFrameId(c.link, pin.FrameType.BODY)
            fr = rm.frames[fid]
            jid = int(fr.parentJoint)
            names.append(c.name)
            link.append(c.link)
            joint.append(jpos.get(jid, 0))
            A.append(fr.placement.act(c.a))
            B.append(fr.placement.act(c.b))
            rad.append(c.radius)
        self.n_robot = len(names)
        for o in cell.obstacles:
            names.append(o.name)
            link.append(None)
            joint.append(-1)  # static, base frame
            A.append(base_T_W.act(o.a))
            B.append(base_T_W.act(o.b))
            rad.append(o.radius)
        self.n_obst = len(cell.obstacles)
        tool = rm.frames[self.robot.tool_frame_id]
        self.refl_joint = jpos[int(tool.parentJoint)]
        self.refl_local = tool.placement.act(self.model.reflector_m)
        self.tracker = cell.tracker_in_base.copy()
        names.append("beam")
        link.append(None)
        joint.append(-2)
        A.append(self.tracker)
        B.append(np.zeros(3))
        rad.append(cell.beam_radius_m)
        self.seg_names, self.seg_link = names, link
        self.seg_joint = np.array(joint)
        self.A_loc, self.B_loc = np.array(A), np.array(B)
        self.radius = np.array(rad)
        self.beam = len(names) - 1
        self.halfspaces = []
        for h in cell.half_spaces:
            nb = base_T_W.rotation @ h.normal
            ob = h.offset - h.normal @ cell.W_T_base.translation
            self.halfspaces.append((nb, float(ob)))

        check_static(self)
        self.rows_all = self._build_rows(collision, incidence, prune=False)
        self.rows = self._build_rows(collision, incidence, prune) if prune else self.rows_all
        self.set_rows(self.rows)
        if collision:
            check_working(self)

    # ------------------------------------------------------------------ set-up
    def skipped(self, a: int, b: int) -> bool:
        """Whether segments a and b are in the user's skip list (by capsule, link or obstacle name)."""
        ka = {self.seg_names[a], self.seg_link[a]} - {None}
        kb = {self.seg_names[b], self.seg_link[b]} - {None}
        for x, y in self.cell.skip_pairs:
            if (x in ka and y in kb) or (x in kb and y in ka):
                return True
        return False

    def beam_skipped(self, a: int) -> bool:
        keys = {self.seg_names[a], self.seg_link[a]} - {None}
        return any(x in keys for x in self.cell.beam_skip)

    def _adjacent(self, ja: int, jb: int) -> bool:
        return ja == jb or abs(ja - jb) == 1

    def _build_rows(self, collision: bool, incidence: bool, prune: bool) -> dict:
        nr, n = self.n_robot, self.n
        pairs, hs, names, deps = [], [], [], []
        rob = range(nr)
        obst = range(nr, nr + self.n_obst)
        bound = self._prune_bounds() if prune and collision else None  # only the collision rows are pruned
        clr = self.cell.clearance_m
        if collision:
            for a in rob:
                for b in rob:
                    if b <= a:
                        continue
                    ja, jb = self.seg_joint[a], self.seg_joint[b]
                    if self._adjacent(ja, jb) or self.skipped(a, b):
                        continue
                    lo, hi = sorted((ja, jb))
                    pairs.append((a, b))
                    names.append(f"robot:{self.seg_names[a]}|{self.seg_names[b]}")
                    deps.append(np.arange(lo, hi))
            for a in rob:
                ja = self.seg_joint[a]
                if ja == 0:
                    continue  # fixed capsules: checked once in _check_static
                for o in obst:
                    if self.skipped(a, o):
                        continue
                    if bound is not None and bound["obst"][a, o - nr] > clr + 1e-9:
                        continue
                    pairs.append((a, o))
                    names.append(f"{self.seg_names[a]}|{self.seg_names[o]}")
                    deps.append(np.arange(ja))
            bj = self.refl_joint
            for a in list(rob) + list(obst):
                if self.beam_skipped(a):
                    continue
                pairs.append((self.beam, a))
                names.append(f"beam|{self.seg_names[a]}")
                deps.append(np.arange(max(bj, self.seg_joint[a])))
            for a in rob:
                ja = self.seg_joint[a]
                if ja == 0:
                    continue
                for h, hsp in enumerate(self.cell.half_spaces):
                    if self.skipped_half(a, hsp.name):
                        continue
                    if bound is not None and bound["half"][a, h] > clr + 1e-9:
                        continue
                    for e in (0, 1):
                        hs.append((a, h, e))
                        names.append(f"{self.seg_names[a]}@{hsp.name}:{'ab'[e]}")
                        deps.append(np.arange(ja))
            for h, hsp in enumerate(self.cell.half_spaces):
                if hsp.name in self.cell.beam_skip:
                    continue
                hs.append((self.beam, h, 1))
                names.append(f"beam@{hsp.name}")
                deps.append(np.arange(bj))
        kinds = [PAIR] * len(pairs) + [HALF] * len(hs)
        units = ["m"] * len(kinds)
        if incidence:
            names.append("incidence")
            deps.append(np.arange(n))
            kinds.append(INCID)
            units.append("cos")
        # rows were appended pairs first (robot, obstacle, beam), then half-spaces, then incidence
        return {"pairs": np.array(pairs, int).reshape(-1, 2), "half": np.array(hs, int).reshape(-1, 3),
                "incidence": incidence, "rows": ConstraintRows(names, np.array(kinds, int), deps, units)}

    def skipped_half(self, a: int, hname: str) -> bool:
        keys = {self.seg_names[a], self.seg_link[a]} - {None}
        return any((x in keys and y == hname) or (y in keys and x == hname) for x, y in self.cell.skip_pairs)

    def set_rows(self, rows: dict) -> None:
        self.pairs, self.half = rows["pairs"], rows["half"]
        self.with_incidence = rows["incidence"]
        self.info: ConstraintRows = rows["rows"]
        self.units, self.names = list(self.info.units), list(self.info.names)
        # Jacobian structure of one configuration: (row, joint) for each structural non-zero
        r, c = [], []
        for i, d in enumerate(self.info.deps):
            r += [i] * len(d)
            c += list(d)
        self.jac_rows, self.jac_cols = np.array(r, int), np.array(c, int)

    def _prune_bounds(self) -> dict:
        """Lower bounds over all configurations of robot–obstacle and robot–half-space clearances.

        Joint 2's origin moves on a circle about joint 1's axis (q1 within its bounds, sampled every
        0.25°, chord error added); every capsule of joint k ≥ 2 stays within R_k of it. Capsules
        of joint 1 are swept exactly at the samples. Returns arrays (n_robot, n_obst), (n_robot, n_half).
        """
        nr = self.n_robot
        out_o = np.full((nr, self.n_obst), -np.inf)
        out_h = np.full((nr, len(self.halfspaces)), -np.inf)
        if self.n < 2 or not self.fk.revolute[0]:
            return {"obst": out_o, "half": out_h}
        q1 = np.arange(self.robot.q_lower[0], self.robot.q_upper[0], np.radians(0.25))
        q1 = np.append(q1, self.robot.q_upper[0])
        Q = np.zeros((q1.size, self.n))
        Q[:, 0] = q1
        fr = self.fk.frames(Q)
        R, t = fr.R, fr.t
        step = np.radians(0.25)
        o2 = t[:, 1] + R[:, 1] @ self.fk.placements[1].translation  # joint-2 origin on its circle
        axis_pt = t[:, 1][0]
        rho2 = np.linalg.norm(np.cross(o2[0] - axis_pt, R[0, 1] @ self.fk.ang[0]))
        obsA = self.A_loc[nr:nr + self.n_obst]
        obsB = self.B_loc[nr:nr + self.n_obst]
        obsr = self.radius[nr:nr + self.n_obst]
        # the joint-2 origin's distances to each obstacle and its heights over each half-space: the same for every
        # capsule beyond joint 1 (only its reach R_k differs), computed once
        far_o = (np.stack([point_segment_distance(o2, obsA[o], obsB[o]) for o in range(self.n_obst)], axis=1)
                 - obsr if self.n_obst else np.zeros((o2.shape[0], 0)))
        far_h = [(o2 @ nv).min() - off for nv, off in self.halfspaces]
        for a in range(nr):
            k = self.seg_joint[a]
            if k < 1:
                continue
            if k == 1:
                Aw = t[:, 1] + np.einsum("mij,j->mi", R[:, 1], self.A_loc[a])
                Bw = t[:, 1] + np.einsum("mij,j->mi", R[:, 1], self.B_loc[a])
                rho = max(np.linalg.norm(Aw[0] - axis_pt), np.linalg.norm(Bw[0] - axis_pt))
                err = rho * step / 2
                for o in range(self.n_obst):
                    _, _, w1, w2 = segment_closest(Aw, Bw, np.broadcast_to(obsA[o], Aw.shape),
                                                   np.broadcast_to(obsB[o], Bw.shape))
                    d = np.linalg.norm(w2 - w1, axis=-1) - self.radius[a] - obsr[o] - err
                    out_o[a, o] = d.min()
                for h, (nv, off) in enumerate(self.halfspaces):
                    d = np.minimum(Aw @ nv, Bw @ nv) - off - self.radius[a] - err
                    out_h[a, h] = d.min()
                continue
            Rk = sum(np.linalg.norm(self.fk.placements[j].translation) for j in range(2, k))
            Rk += max(np.linalg.norm(self.A_loc[a]), np.linalg.norm(self.B_loc[a])) + self.radius[a]
            err = rho2 * step / 2
            out_o[a] = (far_o - Rk - err).min(axis=0)
            for h, base in enumerate(far_h):
                out_h[a, h] = base - Rk - err
        return {"obst": out_o, "half": out_h}

    # ------------------------------------------------------------------ evaluation
    @property
    def n_rows(self) -> int:
        """Constraint rows per configuration."""
        return self.info.n

    def _masks(self) -> tuple[np.ndarray, np.ndarray]:
        """(S, n) masks: joint j moves end point A / B of segment s."""
        if not hasattr(self, "_mask_cache"):
            jj = self.seg_joint.copy()
            jj[self.beam] = self.refl_joint
            mB = (np.arange(self.n)[None, :] < jj[:, None]).astype(float)
            mA = mB.copy()
            mA[self.beam] = 0.0  # the beam starts at the (static) tracker
            self._mask_cache = (mA, mB)
        return self._mask_cache

    def endpoints(self, Q: np.ndarray, with_grad: bool = False
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray | None, np.ndarray | None]:
        """End points of every segment (base frame) and optionally their Jacobians w.r.t. q.

        Returns:
            EA, EB (m, S, 3) m; JA, JB (m, S, 3, n) or None.
        """
        EA, EB, V, W = self._endpoints(np.atleast_2d(np.asarray(Q, float)), with_grad)
        if not with_grad:
            return EA, EB, None, None
        mA, mB = self._masks()
        JA = (V[:, None] + cross(W[:, None], EA[:, :, None])) * mA[None, :, :, None]  # (m, S, n, 3)
        JB = (V[:, None] + cross(W[:, None], EB[:, :, None])) * mB[None, :, :, None]
        return EA, EB, np.swapaxes(JA, 2, 3), np.swapaxes(JB, 2, 3)

    def _endpoints(self, Q: np.ndarray, twists: bool = True) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        fr = self.fk.frames(Q, twists=twists)
        R, t, V, W = fr.R, fr.t, fr.V, fr.W
        j = np.where(self.seg_joint >= 0, self.seg_joint, 0)
        j[self.beam] = self.refl_joint
        Rj, tj = R[:, j], t[:, j]  # (m, S, 3, 3)
        EA = tj + np.einsum("msij,sj->msi", Rj, self.A_loc)
        EB = tj + np.einsum("msij,sj->msi", Rj, self.B_loc)
        static = self.seg_joint < 0
        EA[:, static] = self.A_loc[static]
        EB[:, static] = self.B_loc[static]
        EB[:, self.beam] = tj[:, self.beam] + Rj[:, self.beam] @ self.refl_local
        return EA, EB, V, W

    @overload
    def evaluate(self, Q: np.ndarray, with_grad: Literal[False], backend: str = ..., band: float | None = ...
                 ) -> np.ndarray: ...
    @overload
    def evaluate(self, Q: np.ndarray, with_grad: Literal[True] = ..., backend: str = ..., band: float | None = ...
                 ) -> tuple[np.ndarray, np.ndarray]: ...
    @overload
    def evaluate(self, Q: np.ndarray, with_grad: bool, backend: str = ..., band: float | None = ...
                 ) -> np.ndarray | tuple[np.ndarray, np.ndarray]: ...

    def evaluate(self, Q: np.ndarray, with_grad: bool = True, backend: str = "numpy", band: float | None = None
                 ) -> np.ndarray | tuple[np.ndarray, np.ndarray]:
        """Constraint values g(Q) ≥ 0 and gradients for all configurations at once.

        The gradient of a pair row uses ∂d/∂q_j = nᵀ ∂w₂/∂q_j − nᵀ ∂w₁/∂q_j with, for a witness point
        w = (1 − s) A + s B of a segment whose end points are carried by joints (k_A, k_B),
        nᵀ ∂w/∂q_j = (1 − s) [nᵀv_j + ω_jᵀ(A × n)]·[j ≤ k_A] + s [nᵀv_j + ω_jᵀ(B × n)]·[j ≤ k_B]
        (triple product; no per-point Jacobian is formed).

        Args:
            Q: configurations (m, n) rad.
            with_grad: also return the gradients.
            backend: ``"numpy"`` (closed-form batched segment distances, the optimiser's default),
                ``"geometry"`` (witness points from one ``pin.computeDistances`` call per configuration on
                a ``pin.GeometryModel`` of the segments:
                :class:`~pin_kpi_oed.cell.coal_distances.GeometryDistances`) or ``"coal"``
                (``coal.distance`` per pair and configuration from Python, for verification).
            band: ``geometry`` backend only: gradients of the pair rows only within ``band`` (m) of the
                configuration's closest pair, zero for the others (their values are exact). With the
                Kreisselmeier–Steinhauser aggregate of length ℓ a band of 40ℓ changes the aggregate's
                gradient by < e⁻⁴⁰ relative.

        Returns:
            g (m, rows) — metres for distances, cosine for the incidence row — and, with
            ``with_grad``, G (m, rows, n) = ∂g/∂q (dense; zero outside ``info.deps``).
        """
        Q = np.atleast_2d(np.asarray(Q, float))
        m, n = Q.shape
        EA, EB, V, W = self._endpoints(Q, with_grad)
        clr = self.cell.clearance_m
        gs, Gs = [], []
        mA, mB = self._masks()
        rows = []
        if len(self.pairs):
            rows.append(self._pair_rows(Q, EA, EB, V, W, clr, mA, mB, with_grad, backend, band))
        if len(self.half):
            rows.append(self._halfspace_rows(EA, EB, V, W, clr, mA, mB, with_grad))
        if self.with_incidence:
            rows.append(self._incidence_row(Q, with_grad))
        for gk, Gk in rows:
            gs.append(gk)
            if with_grad:
                Gs.append(Gk)
        g = np.concatenate(gs, axis=1) if gs else np.zeros((m, 0))
        if not with_grad:
            return g
        G = np.concatenate(Gs, axis=1) if Gs else np.zeros((m, 0, n))
        return g, G

    def _pair_rows(self, Q: np.ndarray, EA: np.ndarray, EB: np.ndarray, V: np.ndarray, W: np.ndarray, clr: float,
                   mA: np.ndarray, mB: np.ndarray, with_grad: bool, backend: str, band: float | None
                   ) -> tuple[np.ndarray, np.ndarray | None]:
        """Capsule-pair rows of :meth:`evaluate`: distance minus radii and clearance (m), gradient or None."""
        i1, i2 = self.pairs[:, 0], self.pairs[:, 1]
        far = None
        if backend == "geometry":
            if not hasattr(self, "_geometry"):
                self._geometry = GeometryDistances(self)
            dseg, s, t, w1, w2, far = self._geometry.witness(Q, EA, EB, band if with_grad else -np.inf)
            diff = w2 - w1
        else:
            if backend == "coal":
                s, t, w1, w2 = self._coal_witness(EA, EB, i1, i2)
            else:
                s, t, w1, w2 = segment_closest(EA[:, i1], EB[:, i1], EA[:, i2], EB[:, i2])
            diff = w2 - w1
            dseg = np.sqrt(np.einsum("mpa,mpa->mp", diff, diff))
        g = dseg - self.radius[i1] - self.radius[i2] - clr
        if not with_grad:
            return g, None
        VT, WT = np.swapaxes(V, 1, 2), np.swapaxes(W, 1, 2)  # (m, 3, n)
        if far is None:
            return g, self._pair_gradient(slice(None), EA, EB, diff, dseg, s, t, VT, WT, mA, mB)
        # outside the band: not evaluated (see ``band``); pairs outside it at every configuration are not computed
        c = np.flatnonzero(~far.all(axis=0))
        Gp = np.zeros((Q.shape[0], len(i1), Q.shape[1]))
        Gp[:, c] = self._pair_gradient(c, EA, EB, diff[:, c], dseg[:, c], s[:, c], t[:, c], VT, WT, mA, mB)
        Gp[far] = 0.0
        return g, Gp

    def _pair_gradient(self, c: slice | np.ndarray, EA: np.ndarray, EB: np.ndarray, diff: np.ndarray, dseg: np.ndarray,
                       s: np.ndarray, t: np.ndarray, VT: np.ndarray, WT: np.ndarray, mA: np.ndarray, mB: np.ndarray
                       ) -> np.ndarray:
        """∂/∂q of the pair rows ``c`` (:meth:`evaluate`'s witness-point form), (m, len(c), n)."""
        i1, i2 = self.pairs[c, 0], self.pairs[c, 1]
        nrm = diff / np.where(dseg > 0, dseg, 1.0)[..., None]
        nv = nrm @ VT  # (m, P, n)

        def side(P: np.ndarray, u: np.ndarray, mask: np.ndarray) -> np.ndarray:
            # u (nv + (P × n) W) · mask, in place (the same operations on the same operands: the same bits)
            r = cross(P, nrm) @ WT
            r += nv
            r *= u[..., None]
            r *= mask
            return r

        out = side(EA[:, i2], 1.0 - t, mA[i2])
        out += side(EB[:, i2], t, mB[i2])
        out -= side(EA[:, i1], 1.0 - s, mA[i1])
        out -= side(EB[:, i1], s, mB[i1])
        return out

    def _halfspace_rows(self, EA: np.ndarray, EB: np.ndarray, V: np.ndarray, W: np.ndarray, clr: float,
                        mA: np.ndarray, mB: np.ndarray, with_grad: bool) -> tuple[np.ndarray, np.ndarray | None]:
        """Capsule end point / half-space rows of :meth:`evaluate` (m), gradient or None."""
        a, h, e = self.half[:, 0], self.half[:, 1], self.half[:, 2]
        Nh = np.array([self.halfspaces[k][0] for k in h]).reshape(-1, 3)
        Oh = np.array([self.halfspaces[k][1] for k in h])
        P = np.where(e[None, :, None] == 0, EA[:, a], EB[:, a])
        g = np.einsum("mpa,pa->mp", P, Nh) - Oh - self.radius[a] - clr
        if not with_grad:
            return g, None
        mask = np.where(e[:, None] == 0, mA[a], mB[a])
        return g, (Nh @ np.swapaxes(V, 1, 2) + cross(P, Nh[None]) @ np.swapaxes(W, 1, 2)) * mask[None]

    def _incidence_row(self, Q: np.ndarray, with_grad: bool) -> tuple[np.ndarray, np.ndarray | None]:
        """Incidence row of :meth:`evaluate`: cos(angle) − cos(max angle), gradient or None."""
        if with_grad:
            c, dc = self.model.incidence_cos(self.p0, Q, with_grad=True)
            return (c - self.cos_max)[:, None], dc[:, None, :]
        c = self.model.incidence_cos(self.p0, Q)
        return (c - self.cos_max)[:, None], None

    def _coal_witness(self, EA: np.ndarray, EB: np.ndarray, i1: np.ndarray, i2: np.ndarray
                      ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Witness points on the segments from ``coal.distance`` of the capsule pairs."""
        import coal

        m, P = EA.shape[0], i1.size
        s, t = np.zeros((m, P)), np.zeros((m, P))
        w1, w2 = np.zeros((m, P, 3)), np.zeros((m, P, 3))
        req = coal.DistanceRequest()
        for i in range(m):
            for p in range(P):
                out = []
                for k in (i1[p], i2[p]):
                    a, b = EA[i, k], EB[i, k]
                    shape, T = coal_capsule(a, b, self.radius[k])
                    out.append((shape, T, a, b))
                res = coal.DistanceResult()
                coal.distance(out[0][0], out[0][1], out[1][0], out[1][1], req, res)
                for (_shape, _T, a, b), wp, sp, wo in ((out[0], res.getNearestPoint1(), s, w1),
                                                     (out[1], res.getNearestPoint2(), t, w2)):
                    d = b - a
                    L2 = d @ d
                    u = float(np.clip((wp - a) @ d / L2, 0, 1)) if L2 > 0 else 0.0
                    sp[i, p] = u
                    wo[i, p] = a + u * d
        return s, t, w1, w2

    def feasible(self, Q: np.ndarray, tol: float = 0.0) -> np.ndarray:
        """Per configuration: every row ≥ −tol and within the joint bounds (fast path), (m,) bool.

        The same decision as ``np.all(evaluate(Q, with_grad=False) >= -tol, axis=1)``, through
        :meth:`row_minima` (capsule pairs certainly clear by a bounding-sphere test are not computed).
        """
        Q = np.atleast_2d(np.asarray(Q, float))
        dmin, inc = self.row_minima(Q, exact_below=-tol + 1e-9)
        return (dmin >= -tol) & (inc >= -tol) & np.all((Q >= self.robot.q_lower) & (Q <= self.robot.q_upper), axis=1)

    def row_minima(self, Q: np.ndarray, exact_below: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
        """Smallest distance row and the incidence row of every configuration, cheaply.

        Values are those of :meth:`evaluate` (same kernels: :func:`segment_closest`, the half-space and
        incidence rows). A capsule pair is computed only when its bounding-sphere bound
        ‖c₁ − c₂‖ − h₁ − h₂ − r₁ − r₂ − clearance (segment centres c, half lengths h; ≤ the pair row by
        the triangle inequality, 1e-9 m subtracted for rounding) is below ``exact_below``; so the
        returned minimum is the exact smallest distance row wherever that is below ``exact_below``,
        and some value ≥ ``exact_below`` elsewhere.

        Args:
            Q: configurations (m, n) rad.
            exact_below: distance (m) below which the minimum must be exact.

        Returns:
            (smallest distance row (m,) m, ``+inf`` without distance rows; incidence row cos β − cos β_max
            (m,), ``+inf`` without it).
        """
        Q = np.atleast_2d(np.asarray(Q, float))
        m = Q.shape[0]
        EA, EB, V, W = self._endpoints(Q, False)
        clr = self.cell.clearance_m
        dmin = np.full(m, np.inf)
        if len(self.half):
            gh, _ = self._halfspace_rows(EA, EB, V, W, clr, None, None, False)
            dmin = np.minimum(dmin, gh.min(axis=1))
        if len(self.pairs):
            i1, i2 = self.pairs[:, 0], self.pairs[:, 1]
            C, H = 0.5 * (EA + EB), 0.5 * np.linalg.norm(EB - EA, axis=-1)  # (m, S, 3), (m, S)
            dc = C[:, i1] - C[:, i2]
            lb = (np.sqrt(np.einsum("mpa,mpa->mp", dc, dc)) - H[:, i1] - H[:, i2]
                  - self.radius[i1] - self.radius[i2] - clr - 1e-9)
            ci, pi = np.nonzero(lb < exact_below)
            g = lb
            if ci.size:
                a, b = i1[pi], i2[pi]
                _, _, w1, w2 = segment_closest(EA[ci, a], EB[ci, a], EA[ci, b], EB[ci, b])
                diff = w2 - w1
                g[ci, pi] = np.sqrt(np.einsum("pa,pa->p", diff, diff)) - self.radius[a] - self.radius[b] - clr
            dmin = np.minimum(dmin, g.min(axis=1))
        inc = self._incidence_row(Q, False)[0][:, 0] if self.with_incidence else np.full(m, np.inf)
        return dmin, inc
