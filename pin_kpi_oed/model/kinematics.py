"""The one batched kinematics core: joint types and axes from Pinocchio, chain FK, point Jacobians.

Forward kinematics of a serial chain (paper eq. 1)::

    oMi_j(q) = oMi_parent(j) · M_j · exp(S_j q_j),      oMtool = oMi_n · M_tool

with ``M_j`` the (possibly perturbed) joint placement, ``S_j`` the joint's motion axis (a unit
rotation axis for a revolute joint, a unit translation axis for a prismatic one) and ``M_tool``
the tool frame's placement on the last joint. :class:`Chain` composes it with NumPy for all m
configurations at once: reading Pinocchio's per-configuration results back into Python costs
~10 µs per configuration, which the design optimiser cannot afford. The tests check it against
``pin.forwardKinematics`` / ``pin.computeJointJacobians`` to 1e-12.

World twists. Column k of Pinocchio's WORLD joint Jacobian is the twist (v_k, ω_k) of joint k:
revolute ω_k = R_A,k a_k, v_k = t_A,k × ω_k (the linear velocity of the point at the world
origin); prismatic ω_k = 0, v_k = R_A,k u_k. A point x carried by joint k ≥ j moves with
∂x/∂q_j = v_j + ω_j × x.

Joint-placement Jacobian of a tool point x (right perturbation M_j ← M_j · exp6(δ_j),
:mod:`pin_kpi_oed.model.parameters`)::

    ∂x/∂δ_j = [ R_A,j ,  −[x − t_A,j]× R_A,j ]

with (R_A,j, t_A,j) the frame of joint j before its own motion.

Also here: :func:`skew`, :func:`se3_from_matrix` (a checked 4×4 → ``pin.SE3``) and
:func:`revolute_mask` (the one "is this joint revolute or prismatic" test).
"""

from __future__ import annotations

import threading
from collections import OrderedDict
from dataclasses import dataclass
from typing import Any
from collections.abc import Iterator, Sequence

import numpy as np
import pinocchio as pin

from pin_kpi_oed.errors import InputError, RobotLoadError

__all__ = ["skew", "cross3", "se3_from_matrix", "joint_motion_axes", "revolute_mask", "joint_unit", "ChainFrames",
           "Kinematics", "Chain", "placement_jacobian", "point_velocity"]

#: The chains :meth:`Chain.shared` keeps (the least recently asked leave first), and the lock of their table.
_SHARED_SIZE = 16
_SHARED: OrderedDict[tuple, Chain] = OrderedDict()
_SHARED_LOCK = threading.Lock()

#: Tolerance on the motion axes of a pure revolute (unit angular, zero linear part) or prismatic joint.
_AXIS_TOL = 1e-9


def skew(v: np.ndarray) -> np.ndarray:
    """Batched cross-product matrices [v]×.

    Args:
        v: vectors, (..., 3).

    Returns:
        (..., 3, 3) with ``skew(v) @ x == np.cross(v, x)``.
    """
    v = np.asarray(v)
    S = np.zeros(v.shape[:-1] + (3, 3))
    S[..., 0, 1], S[..., 0, 2] = -v[..., 2], v[..., 1]
    S[..., 1, 0], S[..., 1, 2] = v[..., 2], -v[..., 0]
    S[..., 2, 0], S[..., 2, 1] = -v[..., 1], v[..., 0]
    return S


def cross3(a: np.ndarray, b: np.ndarray, axis: int = -1) -> np.ndarray:
    """Batched cross products a × b of float 3-vectors: ``np.cross(a, b, axis=axis)`` bit for bit (the same products
    and differences) without its axis handling, which took two thirds of its time on a few rows; the components are
    read by basic indexing and written into one preallocated result (no ``moveaxis``, no ``stack``).

    Args:
        a, b: vectors, 3 along ``axis``, broadcast against each other (float64).
        axis: the axis holding the vectors' components.

    Returns:
        The products, 3 along ``axis``.
    """
    pa, pb = (slice(None),) * (axis % a.ndim), (slice(None),) * (axis % b.ndim)
    a0, a1, a2 = a[pa + (0,)], a[pa + (1,)], a[pa + (2,)]
    b0, b1, b2 = b[pb + (0,)], b[pb + (1,)], b[pb + (2,)]
    c0 = a1 * b2 - a2 * b1
    shape = np.shape(c0)
    ax = axis % (len(shape) + 1)
    out = np.empty(shape[:ax] + (3,) + shape[ax:], dtype=np.result_type(a, b))
    po = (slice(None),) * ax
    out[po + (0,)] = c0
    out[po + (1,)] = a2 * b0 - a0 * b2
    out[po + (2,)] = a0 * b1 - a1 * b0
    return out


def se3_from_matrix(T: Any, where: str = "transform") -> pin.SE3:
    """A 4×4 homogeneous matrix (translation in m) -> ``pin.SE3``, checked to be a rigid transform.

    The rotation block is projected onto SO(3) (SVD) after the check, so rounding in a file does
    not leave a slightly non-orthonormal rotation.

    Args:
        T: the matrix (nested lists or array).
        where: name of the file / field, used in error messages.

    Returns:
        The transform.

    Raises:
        InputError: not 4×4, not finite, or the rotation block is not a proper rotation (1e-6).
    """
    M = np.asarray(T, dtype=float)
    if M.shape != (4, 4) or not np.all(np.isfinite(M)):
        raise InputError(f"{where}: expected a finite 4x4 matrix, got shape {M.shape}")
    R = M[:3, :3]
    if np.abs(R.T @ R - np.eye(3)).max() > 1e-6 or np.linalg.det(R) < 0:
        raise InputError(f"{where}: the rotation block is not a proper rotation matrix")
    U, _, Vt = np.linalg.svd(R)
    return pin.SE3(U @ Vt, M[:3, 3].copy())


def joint_motion_axes(model: pin.Model, joint_ids: Sequence[int]) -> tuple[np.ndarray, np.ndarray]:
    """Motion axes of 1-DoF joints in their own frames, from Pinocchio's joint Jacobians.

    Args:
        model: Pinocchio model.
        joint_ids: joint indices (each with one velocity DoF).

    Returns:
        (linear (n, 3), angular (n, 3)): S_j = (linear, angular); a revolute joint has a unit
        angular part and zero linear part, a prismatic one the reverse.
    """
    data = model.createData()
    pin.computeJointJacobians(model, data, pin.neutral(model))
    J = np.asarray(data.J).reshape(6, model.nv)  # eigenpy returns a 1-D array when nv == 1
    lin, ang = [], []
    for j in joint_ids:
        S = data.oMi[j].actInv(pin.Motion(J[:, model.joints[j].idx_v]))
        lin.append(S.linear.copy())
        ang.append(S.angular.copy())
    return np.array(lin).reshape(-1, 3), np.array(ang).reshape(-1, 3)


def revolute_mask(model: pin.Model, joint_ids: Sequence[int]) -> np.ndarray:
    """Whether each 1-DoF joint is revolute (True) or prismatic (False).

    Args:
        model: Pinocchio model.
        joint_ids: joint indices.

    Returns:
        Boolean array (n,).

    Raises:
        RobotLoadError: a joint that is neither a pure rotation nor a pure translation (e.g. helical).
    """
    return _revolute_from_axes(model, joint_ids, *joint_motion_axes(model, joint_ids))


def _revolute_from_axes(model: pin.Model, joint_ids: Sequence[int], lin: np.ndarray, ang: np.ndarray) -> np.ndarray:
    """:func:`revolute_mask` from the joints' motion axes (:func:`joint_motion_axes`)."""
    nl, na = np.linalg.norm(lin, axis=1), np.linalg.norm(ang, axis=1)
    rev = (np.abs(na - 1.0) < _AXIS_TOL) & (nl < _AXIS_TOL)
    pri = (np.abs(nl - 1.0) < _AXIS_TOL) & (na < _AXIS_TOL)
    bad = np.flatnonzero(~(rev | pri))
    if bad.size:
        j = list(joint_ids)[int(bad[0])]
        raise RobotLoadError(f"joint '{model.names[j]}' ({model.joints[j].shortname()}) is neither revolute nor "
                             "prismatic")
    return rev


def joint_unit(revolute: bool) -> str:
    """SI unit of a joint value: ``"rad"`` (revolute) or ``"m"`` (prismatic)."""
    return "rad" if revolute else "m"


@dataclass
class ChainFrames:
    """Joint frames and world twists of a chain, batched over m configurations (base frame).

    Attributes:
        R: rotations of the frames after each joint's motion, (m, n+1, 3, 3); index 0 is the
            chain root (identity), index k the k-th joint (1-based).
        t: their origins, (m, n+1, 3) m.
        R_A: rotation of each joint's frame before its motion (A_j = oMi_parent · M_j), (m, n, 3, 3).
        t_A: its origin, (m, n, 3) m.
        V: linear parts of the joints' world twists (velocity of the point at the world origin), (m, n, 3).
        W: angular parts, (m, n, 3) (zero for prismatic joints).
    """

    R: np.ndarray
    t: np.ndarray
    R_A: np.ndarray
    t_A: np.ndarray
    V: np.ndarray
    W: np.ndarray

    @property
    def twist(self) -> np.ndarray:
        """World twists (v, ω) as columns, (m, 6, n): Pinocchio's WORLD joint Jacobian (C-contiguous)."""
        m, n = self.V.shape[:2]
        out = np.empty((m, 6, n))
        out[:, :3] = np.swapaxes(self.V, 1, 2)
        out[:, 3:] = np.swapaxes(self.W, 1, 2)
        return out


@dataclass
class Kinematics:
    """Kinematics of one tool point for every configuration (base frame, batched over m).

    Attributes:
        p: the tool point (e.g. the reflector), (m, 3) m.
        R_tool: tool-frame rotation, (m, 3, 3).
        R_A: rotation of each joint's frame before its motion, (m, n, 3, 3).
        t_A: its origin, (m, n, 3) m.
        twist: world twists (v, ω) of the joints, (m, 6, n) = Pinocchio's WORLD joint Jacobian.
    """

    p: np.ndarray
    R_tool: np.ndarray
    R_A: np.ndarray
    t_A: np.ndarray
    twist: np.ndarray


class Chain:
    """Batched forward kinematics of a serial chain of 1-DoF revolute/prismatic joints.

    Args:
        model: Pinocchio model; its ``jointPlacements`` are the nominal placements.
        joint_ids: the chain's joints, base to tip (each joint's parent is the previous one).
        tool_frame_id: frame whose placement on the last joint is the tool placement (optional).

    Attributes:
        lin, ang: local motion axes (n, 3) (:func:`joint_motion_axes`).
        revolute: boolean mask (n,) (:func:`revolute_mask`).
        placements: nominal joint placements M_j.
        tool_placement: M_tool (identity without a tool frame).

    Raises:
        RobotLoadError: a joint that is neither revolute nor prismatic.
    """

    def __init__(self, model: pin.Model, joint_ids: Sequence[int], tool_frame_id: int | None = None):
        self.model = model
        self.joint_ids = [int(j) for j in joint_ids]
        self.lin, self.ang = joint_motion_axes(model, self.joint_ids)
        self.revolute = _revolute_from_axes(model, self.joint_ids, self.lin, self.ang)
        self.placements = [model.jointPlacements[j].copy() for j in self.joint_ids]
        self.tool_placement = (model.frames[tool_frame_id].placement.copy() if tool_frame_id is not None
                               else pin.SE3.Identity())
        K = skew(self.ang)
        self._K, self._KK = K, K @ K
        self._eye, self._eye9 = np.eye(3), np.eye(3).ravel()
        self._K9, self._KK9 = self._K.reshape(-1, 9), self._KK.reshape(-1, 9)
        self._rev = [bool(r) for r in self.revolute]
        self._rev_idx = np.flatnonzero(self.revolute)
        self._frames_last: tuple[tuple, ChainFrames, bool] | None = None

    @classmethod
    def from_robot(cls, robot: Any) -> Chain:
        """The chain of a :class:`~pin_kpi_oed.model.robot.Robot` (joints base to tip, its tool frame)."""
        return cls(robot.model, robot.joint_ids, robot.tool_frame_id)

    @classmethod
    def shared(cls, robot: Any) -> Chain:
        """The chain of a robot (:meth:`from_robot`) built once and shared by every caller of the same Pinocchio model
        with the same joints, joint placements and tool frame (the last 16 kept): a measurement model made per
        station, per nest or per fit does not read the joint axes from Pinocchio again. The shared chain is only
        read by its users; a model whose placements were changed since gets a chain of its own.

        Args:
            robot: the :class:`~pin_kpi_oed.model.robot.Robot`.

        Returns:
            The chain.
        """
        model, tool = robot.model, robot.tool_frame_id
        ids = tuple(int(j) for j in robot.joint_ids)
        H = np.array([model.jointPlacements[j].homogeneous for j in ids])
        Ht = b"" if tool is None else model.frames[tool].placement.homogeneous.tobytes()
        key = (id(model), ids, tool, H.tobytes(), Ht)
        with _SHARED_LOCK:
            hit = _SHARED.get(key)
            if hit is not None and hit.model is model:
                _SHARED.move_to_end(key)
                return hit
        chain = cls(model, ids, tool)
        with _SHARED_LOCK:
            _SHARED[key] = chain  # the entry holds the model: its id is not reused while it is kept
            while len(_SHARED) > _SHARED_SIZE:
                _SHARED.popitem(last=False)
        return chain

    @property
    def n(self) -> int:
        """Number of joints."""
        return len(self.joint_ids)

    def _check(self, Q: np.ndarray) -> np.ndarray:
        Q = np.atleast_2d(np.asarray(Q, float))
        if Q.ndim != 2 or Q.shape[1] != self.n:
            raise InputError(f"configurations must have {self.n} joint values, got shape {Q.shape}")
        return Q

    def frames(self, Q: np.ndarray, placements: Sequence[pin.SE3] | None = None, twists: bool = True
               ) -> ChainFrames:
        """Joint frames and world twists for configurations Q (eq. 1).

        The last result is remembered and returned again for the same configurations and placement values (a
        design step asks for the frames of the same Q for its objective, its collision rows and its incidence
        row). A product by a constant matrix is one matrix product over all configurations ((3m, 3) by (3, 3)):
        the same numbers as the per-configuration products, at a fraction of their cost.

        Args:
            Q: configurations, (m, n) (rad for revolute, m for prismatic joints).
            placements: joint placements M_j to use (default the nominal ones), e.g. perturbed.
            twists: compute the world twists (False: ``V`` and ``W`` are not computed — zeros, or the twists
                remembered from an earlier call —, for callers that need the frames only).

        Returns:
            The :class:`ChainFrames` (read-only arrays, shared by the callers of the same arguments).

        Raises:
            InputError: Q does not have n columns.
        """
        Q = self._check(Q)
        M = self.placements if placements is None else placements
        H = np.array([Mk.homogeneous for Mk in M])
        key = (Q.shape, Q.tobytes(), H.tobytes())
        last = self._frames_last  # one read: safe when two threads ask at once
        if last is not None and last[0] == key and (last[2] or not twists):
            return last[1]
        fr = self._frames(Q, H, twists)
        for a in (fr.R, fr.t, fr.R_A, fr.t_A, fr.V, fr.W):
            a.flags.writeable = False
        self._frames_last = (key, fr, twists)
        return fr

    def _frames(self, Q: np.ndarray, H: np.ndarray, twists: bool) -> ChainFrames:
        """:meth:`frames` computed: ``H`` the placements as 4×4 matrices (n, 4, 4).

        The products of :meth:`_walk`, written out in one loop (no generator step per joint); the twists of the
        revolute joints (v_j = t_A,j × ω_j) in one product over the chain."""
        m, n = Q.shape
        R = np.empty((m, n + 1, 3, 3))
        t = np.empty((m, n + 1, 3))
        R_A = np.empty((m, n, 3, 3))
        t_A = np.empty((m, n, 3))
        V = np.zeros((m, n, 3))
        W = np.zeros((m, n, 3))
        R[:, 0], t[:, 0] = self._eye, 0.0
        rot, trans = H[:, :3, :3].copy(), H[:, :3, 3].copy()
        X = self._rodrigues(Q)
        Rc = np.tile(self._eye, (m, 1, 1))
        tc = np.zeros((m, 3))
        m3, ang, lin = 3 * m, self.ang, self.lin
        for k, rev in enumerate(self._rev):
            Rf = Rc.reshape(m3, 3)
            tc = tc + (Rf @ trans[k]).reshape(m, 3)
            RA = (Rf @ rot[k]).reshape(m, 3, 3)
            R_A[:, k], t_A[:, k] = RA, tc
            if rev:
                if twists:
                    W[:, k] = (RA.reshape(m3, 3) @ ang[k]).reshape(m, 3)  # ω_j = R_A,j a_j
                Rc = RA @ X[:, k]
            else:
                Rc = RA
                u = (RA.reshape(m3, 3) @ lin[k]).reshape(m, 3)
                if twists:
                    V[:, k] = u
                tc = tc + u * Q[:, k:k + 1]
            R[:, k + 1], t[:, k + 1] = Rc, tc
        if twists and self._rev_idx.size:
            if self._rev_idx.size == n:
                V = -cross3(W, t_A)  # v_j = t_A,j × ω_j (the point at the world origin)
            else:
                r = self._rev_idx
                V[:, r] = -cross3(W[:, r], t_A[:, r])
        return ChainFrames(R, t, R_A, t_A, V, W)

    def _rodrigues(self, Q: np.ndarray) -> np.ndarray:
        """exp(S_j q_j) of the revolute joints (I + sin q K + (1 − cos q) K²), (m, n, 3, 3)."""
        m, n = Q.shape
        X = np.sin(Q)[:, :, None] * self._K9
        X += self._eye9  # I + sin q K (the sum of the same two numbers, in place: no third array of this size)
        X += (1.0 - np.cos(Q))[:, :, None] * self._KK9
        return X.reshape(m, n, 3, 3)

    def _walk(self, Q: np.ndarray, H: np.ndarray
              ) -> Iterator[tuple[int, np.ndarray, np.ndarray, np.ndarray | None, np.ndarray, np.ndarray]]:
        """The chain walked base to tip: per joint k, (k, R_A (m, 3, 3), t_A (m, 3), u (the prismatic axis in the
        world (m, 3), None for a revolute joint), R and t after its motion). A product by a constant is one matrix
        product over all configurations ((3m, 3) by (3, 3)): the same numbers as the per-configuration products."""
        m = Q.shape[0]
        rot, trans = H[:, :3, :3].copy(), H[:, :3, 3].copy()
        X = self._rodrigues(Q)
        Rc = np.tile(self._eye, (m, 1, 1))
        tc = np.zeros((m, 3))
        for k, rev in enumerate(self._rev):
            Rf = Rc.reshape(3 * m, 3)
            tc = tc + (Rf @ trans[k]).reshape(m, 3)
            RA = (Rf @ rot[k]).reshape(m, 3, 3)
            tA, u = tc, None
            if rev:
                Rc = RA @ X[:, k]
            else:
                Rc = RA
                u = (RA.reshape(3 * m, 3) @ self.lin[k]).reshape(m, 3)
                tc = tc + u * Q[:, k:k + 1]
            yield k, RA, tA, u, Rc, tc

    def _tip(self, Q: np.ndarray, H: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The last joint's frame (R (m, 3, 3), t (m, 3) m) by the products of :meth:`_frames` (the same numbers),
        without keeping the frames before it."""
        last = (np.tile(self._eye, (Q.shape[0], 1, 1)), np.zeros((Q.shape[0], 3)))
        for step in self._walk(Q, H):
            last = step[4:]
        return last

    def tool_pose(self, Q: np.ndarray, point_m: np.ndarray, placements: Sequence[pin.SE3] | None = None
                  ) -> tuple[np.ndarray, np.ndarray]:
        """A point of the tool frame and the tool frame's rotation only (base frame): :meth:`tool_point`'s ``p`` and
        ``R_tool``, the same numbers, without the joint frames and twists (a feasibility filter over many samples).

        Args:
            Q: configurations, (m, n) (rad / m).
            point_m: the point in the tool frame, (3,) m, or one per configuration, (m, 3) m.
            placements: joint placements to use (default the nominal ones).

        Returns:
            (point (m, 3) m, tool rotation (m, 3, 3)).
        """
        Q = self._check(Q)
        M = self.placements if placements is None else placements
        H = np.array([Mk.homogeneous for Mk in M])
        last = self._frames_last
        if last is not None and last[0] == (Q.shape, Q.tobytes(), H.tobytes()):
            R_last, t_last = last[1].R[:, -1], last[1].t[:, -1]
        else:
            R_last, t_last = self._tip(Q, H)
        return self._tool(R_last, t_last, point_m)

    def _tool(self, R_last: np.ndarray, t_last: np.ndarray, point_m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The tool point and rotation from the last joint's frame."""
        Mt = self.tool_placement
        m = R_last.shape[0]
        R_last = np.ascontiguousarray(R_last).reshape(3 * m, 3)
        t = t_last + (R_last @ Mt.translation).reshape(m, 3)
        R = (R_last @ Mt.rotation).reshape(m, 3, 3)
        point = np.asarray(point_m, float)
        if point.ndim == 2:
            if point.shape != t.shape:
                raise InputError(f"{point.shape[0]} tool points for {t.shape[0]} configurations")
            return t + np.einsum("mab,mb->ma", R, point), R
        return t + (R.reshape(3 * m, 3) @ point).reshape(m, 3), R

    def tool_point(self, Q: np.ndarray, point_m: np.ndarray, placements: Sequence[pin.SE3] | None = None,
                   twists: bool = True) -> Kinematics:
        """Forward kinematics of a point of the tool frame for every configuration (base frame).

        Args:
            Q: configurations, (m, n) (rad / m).
            point_m: the point in the tool frame, (3,) m, or one per configuration, (m, 3) m.
            placements: joint placements to use (default the nominal ones).
            twists: compute the world twists (False: ``twist`` is not computed, as in :meth:`frames`).

        Returns:
            The :class:`Kinematics` (point, tool rotation, joint frames before motion, world twists).
        """
        fr = self.frames(Q, placements, twists)
        P, R = self._tool(fr.R[:, -1], fr.t[:, -1], point_m)
        return Kinematics(P, R, fr.R_A, fr.t_A, fr.twist)

    def tool_points(self, Q: np.ndarray, point_m: np.ndarray, rotations: np.ndarray, translations: np.ndarray
                    ) -> np.ndarray:
        """A point of the tool frame at every configuration under each of d sets of joint placements (base frame):
        the robots of a Monte-Carlo's draws in one batched pass.

        Args:
            Q: configurations, (m, n) (rad / m).
            point_m: the point in the tool frame, (3,) m, or one per set, (d, 3) m.
            rotations: each set's joint placements' rotations M_j, (d, n, 3, 3).
            translations: their translations, (d, n, 3) m.

        Returns:
            (d, m, 3) m: set i's points, those of :meth:`tool_point` with set i's placements to rounding (~1e-16 m).

        Raises:
            InputError: Q does not have n columns, placements not (d, n, 3, 3) and (d, n, 3), or points not (d, 3).
        """
        Q = self._check(Q)
        Rm, tm = np.asarray(rotations, float), np.asarray(translations, float)
        m, n = Q.shape
        if Rm.ndim != 4 or Rm.shape[1:] != (n, 3, 3) or tm.shape != (Rm.shape[0], n, 3):
            raise InputError(f"joint placements of shapes {Rm.shape} and {tm.shape}: expected (d, {n}, 3, 3) and "
                             f"(d, {n}, 3)")
        X = self._rodrigues(Q)
        Rc = np.broadcast_to(self._eye, (Rm.shape[0], m, 3, 3))
        tc = np.zeros((Rm.shape[0], m, 3))
        for k in range(n):
            tc = tc + (Rc @ tm[:, None, k, :, None])[..., 0]
            Rc = Rc @ Rm[:, None, k]
            if self._rev[k]:
                Rc = Rc @ X[None, :, k]
            else:
                tc = tc + (Rc @ self.lin[k]) * Q[None, :, k, None]
        Mt = self.tool_placement
        point = np.asarray(point_m, float)
        R = Rc @ Mt.rotation
        if point.ndim == 2:
            if point.shape != (Rm.shape[0], 3):
                raise InputError(f"{point.shape[0]} tool points for {Rm.shape[0]} sets of joint placements")
            return tc + Rc @ Mt.translation + (R @ point[:, None, :, None])[..., 0]
        return tc + Rc @ Mt.translation + R @ point


def placement_jacobian(kin: Kinematics) -> np.ndarray:
    """∂x/∂δ_j of the tool point w.r.t. every joint-placement error (base frame), (m, n, 3, 6).

    ``[R_A,j, −[x − t_A,j]× R_A,j]`` (module docstring); δ_j = (translation, rotation).
    """
    d = kin.p[:, None, :] - kin.t_A
    return np.concatenate([kin.R_A, -skew(d) @ kin.R_A], axis=-1)


def point_velocity(kin: Kinematics) -> np.ndarray:
    """∂x/∂q of the tool point (base frame): ṗ_k = v_k + ω_k × x, (m, 3, n)."""
    v, w = kin.twist[:, :3, :], kin.twist[:, 3:, :]
    return v + cross3(w, kin.p[:, :, None], axis=1)
