"""The optimiser's capsule segments as a Pinocchio ``GeometryModel``: Coal distances and witness points.

The ``backend="geometry"`` path of :meth:`pin_kpi_oed.cell.collision.CollisionModel.evaluate`: one
``pin.computeDistances`` per configuration in C++, witness points projected back onto the segments.
"""

from __future__ import annotations

from collections.abc import Iterable
from itertools import compress
from operator import attrgetter

import numpy as np
import pinocchio as pin

from pin_kpi_oed.cell.feasibility import coal_capsule
from pin_kpi_oed.cell.segment_model import SegmentModel


__all__ = ["GeometryDistances", "beam_frames"]

_MIN_DISTANCE = attrgetter("min_distance")


def beam_frames(a: np.ndarray, B: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Frames of capsules from a fixed point a to points B (m, 3): rotations taking z to B − a (m, 3, 3),
    centres (m, 3) and half lengths (m,), m (Rodrigues' formula, batched; the same frames as
    :func:`~pin_kpi_oed.cell.feasibility.coal_capsule` up to a rotation about the axis)."""
    d = B - a
    L = np.linalg.norm(d, axis=1)
    u = d / np.where(L > 0, L, 1.0)[:, None]
    c = u[:, 2]  # cos of the angle between z and u
    k = np.stack([-u[:, 1], u[:, 0], np.zeros_like(c)], axis=1)  # z × u (sin θ · axis)
    K = np.zeros((d.shape[0], 3, 3))
    K[:, 0, 1], K[:, 0, 2], K[:, 1, 0] = -k[:, 2], k[:, 1], k[:, 2]
    K[:, 1, 2], K[:, 2, 0], K[:, 2, 1] = -k[:, 0], -k[:, 1], k[:, 0]
    f = np.where(c > -1 + 1e-12, 1.0 / (1.0 + np.where(c > -1 + 1e-12, c, 0.0)), 0.0)
    R = np.eye(3) + K + (K @ K) * f[:, None, None]
    R[c <= -1 + 1e-12] = np.diag([1.0, -1.0, -1.0])  # z to −z
    return R, 0.5 * (a + B), 0.5 * L


class GeometryDistances:
    """The segments of a :class:`~pin_kpi_oed.cell.collision.CollisionModel` as a Pinocchio ``GeometryModel``
    (Coal capsules).

    Robot capsules hang on their joints, obstacles on the universe, and the beam — a capsule from the
    tracker to the reflector whose length changes with q — is re-shaped and re-placed per
    configuration. One ``pin.computeDistances`` per configuration evaluates every pair of
    ``coll.pairs`` in C++; the witness points (on the capsules' surfaces) are projected back onto the
    segments, which gives the segment parameters (s, t) that the witness-point gradient of
    :meth:`~pin_kpi_oed.cell.collision.CollisionModel.evaluate` needs (∂d/∂q from the witness points and the
    joints' twists).

    Args:
        coll: the constraint model whose segments and pairs are built.
    """

    def __init__(self, coll: SegmentModel):
        rm = coll.robot.model
        self.model, self.data = rm, rm.createData()
        self.gm = pin.GeometryModel()
        jids = list(coll.robot.joint_ids)
        for k in range(len(coll.seg_names)):
            j = int(coll.seg_joint[k])
            parent = jids[j - 1] if j > 0 else 0
            shape, T = coal_capsule(coll.A_loc[k], coll.B_loc[k], coll.radius[k])
            self.gm.addGeometryObject(pin.GeometryObject(coll.seg_names[k], parent, 0,
                                                         pin.SE3(T.getRotation(), T.getTranslation()), shape))
        self.beam, self.tracker = coll.beam, coll.tracker
        self.pairs = coll.pairs
        for a, b in self.pairs:
            self.gm.addCollisionPair(pin.CollisionPair(int(a), int(b)))
        self.gd = pin.GeometryData(self.gm)
        # references into GeometryData's result vector (iterating the vector wraps anew each time: 30x slower)
        self.results = list(self.gd.distanceResults)
        self.uses_beam = bool(np.any(self.pairs == self.beam)) if len(self.pairs) else False
        self.radius = coll.radius

    def witness(self, Q: np.ndarray, EA: np.ndarray, EB: np.ndarray, band: float | None = None
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Segment distances, parameters and witness points of every pair at every configuration.

        Args:
            Q: configurations (m, n) rad.
            EA, EB: the segments' end points at Q (m, S, 3), m (from
                :meth:`~pin_kpi_oed.cell.collision.CollisionModel.endpoints`).
            band: if given (m), witness points only for the pairs within ``band`` of their
                configuration's closest pair (reading a witness point from Python costs ~10× a
                distance); the others are marked ``far`` (their s, t, w are zeros, never to be read).

        Returns:
            dseg (m, P) segment distances (capsule distance + radii) m, (s, t) (m, P) in [0, 1], the
            witness points on the segments w1, w2 (m, P, 3) m, and far (m, P) bool.
        """
        m, P = Q.shape[0], len(self.pairs)
        far = np.ones(m * P, bool)
        beam_obj = self.gm.geometryObjects[self.beam]
        beam_shape = beam_obj.geometry
        res = self.results
        if self.uses_beam:
            Rb, cb, hb = beam_frames(self.tracker, EB[:, self.beam])
        model, data, gm, gd = self.model, self.data, self.gm, self.gd
        se3, distances, pairs = pin.SE3, pin.computeDistances, range(P)
        rows: list[int] = []
        pts: list[np.ndarray] = []
        dists: list[list[float]] = []
        for i in range(m):
            if self.uses_beam:
                beam_shape.halfLength = hb[i]
                beam_obj.placement = se3(Rb[i], cb[i])
            distances(model, data, gm, gd, Q[i])  # forward kinematics, placements, then every pair's distance
            di = list(map(_MIN_DISTANCE, res))
            dists.append(di)
            # the pairs with d <= min + band (lim >= d: the same test, in C)
            sel: Iterable[int] = pairs if band is None else compress(pairs, map((min(di) + band).__ge__, di))
            at = i * P
            for k in sel:
                r = res[k]
                rows.append(at + k)
                pts.append(r.getNearestPoint1())
                pts.append(r.getNearestPoint2())
        dist = np.array(dists, float).reshape(m, P)
        i1, i2 = self.pairs[:, 0], self.pairs[:, 1]
        # the witness points projected on their segments for the rows read only (the far rows' are never read)
        s, t = np.zeros(m * P), np.zeros(m * P)
        w1, w2 = np.zeros((m * P, 3)), np.zeros((m * P, 3))
        if rows:
            far[rows] = False
            near = np.reshape(pts, (-1, 2, 3))
            ci, pi = np.divmod(np.asarray(rows), P)

            def project(p: np.ndarray, A: np.ndarray, B: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
                d = B - A
                L2 = np.einsum("pa,pa->p", d, d)
                u = np.clip(np.einsum("pa,pa->p", p - A, d) / np.where(L2 > 0, L2, 1.0), 0.0, 1.0)
                return u, A + u[..., None] * d

            s[rows], w1[rows] = project(near[:, 0], EA[ci, i1[pi]], EB[ci, i1[pi]])
            t[rows], w2[rows] = project(near[:, 1], EA[ci, i2[pi]], EB[ci, i2[pi]])
        return (dist + self.radius[i1] + self.radius[i2], s.reshape(m, P), t.reshape(m, P), w1.reshape(m, P, 3),
                w2.reshape(m, P, 3), far.reshape(m, P))
