"""A cheap, verified lower bound of the collision checker's pair distances for many configurations at once.

:class:`MoveBound` lets :class:`~pin_kpi_oed.program.transitions.TransitionChecker` skip the exact (Coal)
evaluation of the samples of a move that the bound proves clear; the samples it cannot decide, the end
poses and every sample that decides a result are checked exactly, so decisions and smallest clearances are
those of the exact check.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from pin_kpi_oed.cell.feasibility import FeasibilityChecker

__all__ = ["MoveBound"]


class MoveBound:
    """A cheap lower bound of every pair distance of the checker, for many configurations at once.

    Per pair of the :class:`FeasibilityChecker` (the same pairs, the same skip lists): capsule–capsule
    and capsule–half-space distances in closed form (numpy; Coal computes the same closed forms), a
    capsule against an environment solid bounded by its distance to the enclosing capsules the cell
    fitted to that environment object (every vertex inside them): when it is clear of them by b > 0 it
    is clear of the solid by at least b; when it touches them there is no bound (−inf: the sample is
    checked exactly). Pairs of two fixed objects are constant (+inf: the exact end-pose checks see them).
    The bound is verified against the exact distances on seeded random configurations when built;
    a geometry it cannot bound, or any excess, disables it (every sample is then checked exactly).
    """

    def __init__(self, checker: FeasibilityChecker):
        from pin_kpi_oed.cell.collision import segment_closest
        from pin_kpi_oed.model.kinematics import Chain

        self._closest = segment_closest
        self.ok = False
        self.n_pairs = checker.n_pairs
        ids = [int(j) for j in checker.cell.robot.joint_ids]
        if any(j > 0 and j not in ids for j in checker.robot_joint):
            return  # a capsule on a joint outside the chain: no bound
        self.chain = Chain(checker.model, ids)
        try:
            found = self._collect(checker, {j: k + 1 for k, j in enumerate(ids)})
        except AttributeError:  # a geometry that is not a capsule where one was expected
            return
        if found is None:
            return
        self._tables(*found)
        self.ok = self._verify(checker)

    def _collect(self, chk: FeasibilityChecker, jslot: dict) -> tuple[dict, dict, list] | None:
        """Segments (key -> chain frame index (0: fixed), A, B, radius), segment-pair rows and half-space rows
        of every pair; None when a pair cannot be bounded."""
        cell, go = chk.cell, chk.gm.geometryObjects
        base_T_W = cell.W_T_base.inverse()
        robot = dict(zip(chk.robot_ids, chk.robot_joint))
        half = dict(zip(chk.half_ids, cell.half_spaces))
        env_caps = {e.name: [(base_T_W.act(c.a), base_T_W.act(c.b), float(c.radius)) for c in e.capsules]
                    for e in cell.environment}
        segs: dict = {}

        def seg_of(i: int) -> int:
            if i not in segs:
                M, g = go[i].placement, go[i].geometry
                h = float(g.halfLength)
                segs[i] = (jslot.get(robot.get(i, 0), 0), M.act(np.array([0.0, 0.0, -h])),
                           M.act(np.array([0.0, 0.0, h])), float(g.radius))
            return i

        rows: dict = {}  # (seg key, seg key) -> row index of the segment-pair table
        self.pair_rows: list[list[int]] = [[] for _ in range(chk.n_pairs)]
        self.soft = np.zeros(chk.n_pairs, bool)  # bounds through enclosing capsules (no bound when touching)
        H: list[tuple[int, object, np.ndarray, float]] = []
        for p, (i, k) in enumerate(chk.pairs):
            if robot.get(i, 0) == 0 and robot.get(k, 0) == 0:
                continue  # both fixed: constant
            if robot.get(i, 0) == 0:
                i, k = k, i
            si = seg_of(i)
            if k in half:
                M = go[k].placement
                n = M.rotation @ np.asarray(half[k].normal, float)
                H.append((p, si, n, float(half[k].offset) + float(n @ M.translation)))
                continue
            if k in robot or type(go[k].geometry).__name__ == "Capsule":
                others: list[Any] = [seg_of(k)]
            else:
                owner = chk.labels[k][1]
                if not env_caps.get(owner):
                    return None  # a solid without enclosing capsules: no bound
                others = [("env", owner, c) for c in range(len(env_caps[owner]))]
                for c, cap in enumerate(env_caps[owner]):
                    segs.setdefault(("env", owner, c), (0, *cap))
                self.soft[p] = True
            for sk in others:
                self.pair_rows[p].append(rows.setdefault((si, sk), len(rows)))
        return segs, rows, H

    def _tables(self, segs: dict, rows: dict, H: list) -> None:
        """The arrays :meth:`pairs` works on."""
        keys, order = list(rows), list(segs)
        index = {k: u for u, k in enumerate(order)}
        self.U_joint = np.array([segs[k][0] for k in order], int)
        self.U_A = np.array([segs[k][1] for k in order], float).reshape(-1, 3)
        self.U_B = np.array([segs[k][2] for k in order], float).reshape(-1, 3)
        self.U1 = np.array([index[a] for a, _ in keys], int)
        self.U2 = np.array([index[b] for _, b in keys], int)
        self.R = np.array([segs[a][3] + segs[b][3] for a, b in keys], float)
        # each row's two segments inside balls (centre, half length + radius): |c1 - c2| - the two radii bounds the row
        self.U_C = 0.5 * (self.U_A + self.U_B)
        half = 0.5 * np.linalg.norm(self.U_B - self.U_A, axis=1)
        self.R_ball = half[self.U1] + half[self.U2] + self.R
        self.H_pair = np.array([h[0] for h in H], int)
        self.H_seg = np.array([index[h[1]] for h in H], int)
        self.H_n = np.array([h[2] for h in H], float).reshape(-1, 3)
        self.H_off = np.array([h[3] + segs[h[1]][3] for h in H], float)
        self.bounded = np.array([bool(r) for r in self.pair_rows], bool)
        self.bounded[self.H_pair] = True
        flat = [(p, r) for p, rs in enumerate(self.pair_rows) for r in rs]
        self.flat_pair = np.array([p for p, _ in flat], int)
        self.flat_row = np.array([r for _, r in flat], int)
        self.starts = np.flatnonzero(np.r_[True, np.diff(self.flat_pair) != 0]) if flat else np.zeros(0, int)
        self.first_pair = self.flat_pair[self.starts] if flat else np.zeros(0, int)
        #: the rows of the pairs bounded by their closest points, and those of the soft pairs (no bound when one
        #: is not positive): what :meth:`__call__` takes its minimum over
        self.hard_rows = np.unique(self.flat_row[~self.soft[self.flat_pair]]) if flat else np.zeros(0, int)
        self.soft_rows = np.unique(self.flat_row[self.soft[self.flat_pair]]) if flat else np.zeros(0, int)

    def _verify(self, chk: FeasibilityChecker) -> bool:
        """The bound never exceeds the exact distances on seeded random configurations; constant pairs are."""
        cell = chk.cell
        rng = np.random.default_rng(11)
        Q = cell.q_lower + rng.random((48, cell.q_lower.size)) * (cell.q_upper - cell.q_lower)
        exact = np.array([chk.pair_distances(q) for q in Q])
        ok = True
        for cap in (None, 0.1):
            lb = self.pairs(Q, cap)
            fin = np.isfinite(lb)
            ok &= bool(np.all(lb[fin] <= exact[fin] + 1e-9))
        return ok and bool(np.all(np.ptp(exact[:, ~self.bounded], axis=0) < 1e-12))

    def _frames(self, Q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        fr = self.chain.frames(Q, twists=False)  # batched numpy forward kinematics; frame 0 is the base
        return fr.R, fr.t

    def pairs(self, Q: np.ndarray, cap: float | None = None) -> np.ndarray:
        """(m, n_pairs) lower bounds of the pair distances (m); +inf for constant pairs.

        With ``cap`` > 0, a segment pair whose enclosing balls keep at least ``cap`` apart at a configuration of Q
        is bounded there by the balls' distance (a weaker bound, ≥ cap) instead of its closest points: below
        ``cap`` the smallest bound of a configuration is the same as without, and the closest points are computed
        only where the balls come closer than ``cap``. With ``cap`` ≤ 0 (a soft pair's ball distance may then be
        ≤ 0 and above ``cap``) the balls stand in only for segment pairs that keep ``cap`` apart at every
        configuration.
        """
        d, da, db = self._rows(Q, cap)
        out = np.full((len(d), self.n_pairs), np.inf)
        if self.flat_row.size:
            out[:, self.first_pair] = np.minimum.reduceat(d[:, self.flat_row], self.starts, axis=1)
            soft = out[:, self.soft]
            out[:, self.soft] = np.where(soft > 0, soft, -np.inf)  # touching the enclosing capsules: no bound
        if self.H_pair.size:
            out[:, self.H_pair] = np.minimum(out[:, self.H_pair], np.minimum(da, db) - self.H_off)
        return out

    def __call__(self, Q: np.ndarray, cap: float | None = None) -> np.ndarray:
        """(m,) lower bound of the smallest pair distance at each configuration (m); see :meth:`pairs` for ``cap``.

        The smallest entry of each row of :meth:`pairs`, bit for bit, taken over the segment-pair rows directly
        (without the (m, n_pairs) table): a pair's bound is the least of its rows' or its half-space value, a soft
        pair's −inf when one of its rows is not positive.

        Args:
            Q: configurations (m, n) (rad for revolute joints, m for prismatic ones).
            cap: see :meth:`pairs` (m).

        Returns:
            (m,) the bound minus 1e-9 m.
        """
        d, da, db = self._rows(Q, cap)
        low = np.full(len(d), np.inf)
        if self.hard_rows.size:
            low = d[:, self.hard_rows].min(axis=1)
        if self.soft_rows.size:  # a soft pair's row not positive (or NaN): no bound
            soft = d[:, self.soft_rows]
            low = np.minimum(low, np.where(np.any(~(soft > 0), axis=1), -np.inf, soft.min(axis=1)))
        if self.H_pair.size:
            low = np.minimum(low, (np.minimum(da, db) - self.H_off).min(axis=1))
        return low - 1e-9

    def _rows(self, Q: np.ndarray, cap: float | None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The bound of every segment-pair row at every configuration (m, rows) (see :meth:`pairs` for ``cap``)
        and the signed distances of the half-space rows' two segment ends (m, H) each (m)."""
        Q = np.atleast_2d(np.asarray(Q, float))
        Rs, ts = self._frames(Q)
        Rj, tj = Rs[:, self.U_joint], ts[:, self.U_joint]
        EA = np.einsum("msij,sj->msi", Rj, self.U_A) + tj  # every segment's end points, (m, S, 3): a few dozen
        EB = np.einsum("msij,sj->msi", Rj, self.U_B) + tj
        d = np.zeros((len(Q), 0))
        if self.flat_row.size:
            if cap is None:
                u1, u2 = self.U1, self.U2
                d = self._closest_rows(EA[:, u1], EB[:, u1], EA[:, u2], EB[:, u2], self.R)
            else:
                C = np.einsum("msij,sj->msi", Rj, self.U_C) + tj
                dC = C[:, self.U1] - C[:, self.U2]
                d = np.sqrt(np.einsum("mri,mri->mr", dC, dC)) - self.R_ball
                near = d < cap
                if cap <= 0:  # no ball distance at or below 0 may stand in for a soft pair's closest points
                    near[:] = np.any(near, axis=0)
                mi, ri = np.nonzero(near)
                if mi.size:  # the (configuration, row) entries the balls cannot settle, as one row of entries
                    S = EA.shape[1]
                    k1, k2 = mi * S + self.U1[ri], mi * S + self.U2[ri]
                    A, B = EA.reshape(-1, 3), EB.reshape(-1, 3)
                    d[mi, ri] = self._closest_rows(A[k1][None], B[k1][None], A[k2][None], B[k2][None],
                                                   self.R[ri])[0]
        da = db = np.zeros((len(Q), 0))
        if self.H_pair.size:
            da = np.einsum("mhi,hi->mh", EA[:, self.H_seg], self.H_n)
            db = np.einsum("mhi,hi->mh", EB[:, self.H_seg], self.H_n)
        return d, da, db

    def _closest_rows(self, A1: np.ndarray, B1: np.ndarray, A2: np.ndarray, B2: np.ndarray, R: np.ndarray
                      ) -> np.ndarray:
        """Closest-point bounds of segment pairs [A1, B1], [A2, B2] (m, r, 3) whose radii sum to R (r,):
        their distance minus R, (m, r) m."""
        _, _, w1, w2 = self._closest(A1, B1, A2, B2)
        w = w2 - w1
        return np.sqrt(np.einsum("mri,mri->mr", w, w)) - R
