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

from dataclasses import dataclass
from typing import Any
from collections.abc import Sequence

import numpy as np
import pinocchio as pin

from pin_kpi_oed.errors import InputError, RobotLoadError

__all__ = ["skew", "cross3", "se3_from_matrix", "joint_motion_axes", "revolute_mask", "joint_unit", "ChainFrames",
           "Kinematics", "Chain", "placement_jacobian", "point_velocity"]

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


def cross3(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Batched cross products a × b of float 3-vectors: ``np.cross(a, b)`` bit for bit (the same products and
    differences, in its order) without its axis handling, which took two thirds of its time on a few rows.

    Args:
        a, b: vectors, (..., 3), broadcast against each other (float64).

    Returns:
        (..., 3).
    """
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    out = np.empty(a.shape if a.shape == b.shape else np.broadcast_shapes(a.shape, b.shape))
    np.multiply(a1, b2, out=out[..., 0])
    out[..., 0] -= a2 * b1
    np.multiply(a2, b0, out=out[..., 1])
    out[..., 1] -= a0 * b2
    np.multiply(a0, b1, out=out[..., 2])
    out[..., 2] -= a1 * b0
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
    lin, ang = joint_motion_axes(model, joint_ids)
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
        self.revolute = revolute_mask(model, self.joint_ids)
        self.placements = [model.jointPlacements[j].copy() for j in self.joint_ids]
        self.tool_placement = (model.frames[tool_frame_id].placement.copy() if tool_frame_id is not None
                               else pin.SE3.Identity())
        K = skew(self.ang)
        self._K, self._KK = K, K @ K

    @classmethod
    def from_robot(cls, robot: Any) -> Chain:
        """The chain of a :class:`~pin_kpi_oed.model.robot.Robot` (joints base to tip, its tool frame)."""
        return cls(robot.model, robot.joint_ids, robot.tool_frame_id)

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

        Args:
            Q: configurations, (m, n) (rad for revolute, m for prismatic joints).
            placements: joint placements M_j to use (default the nominal ones), e.g. perturbed.
            twists: compute the world twists (False: ``V`` and ``W`` are zeros, for callers that need the
                frames only).

        Returns:
            The :class:`ChainFrames`.

        Raises:
            InputError: Q does not have n columns.
        """
        Q = self._check(Q)
        M = self.placements if placements is None else placements
        m, n = Q.shape
        R = np.empty((m, n + 1, 3, 3))
        t = np.empty((m, n + 1, 3))
        R_A = np.empty((m, n, 3, 3))
        t_A = np.empty((m, n, 3))
        V = np.zeros((m, n, 3))
        W = np.zeros((m, n, 3))
        eye = np.eye(3)
        R[:, 0], t[:, 0] = eye, 0.0
        Rc = np.broadcast_to(eye, (m, 3, 3))
        tc = np.zeros((m, 3))
        for k in range(n):
            Mk = M[k]
            tc = tc + Rc @ Mk.translation
            Rc = Rc @ Mk.rotation
            R_A[:, k], t_A[:, k] = Rc, tc
            if self.revolute[k]:
                if twists:
                    w = Rc @ self.ang[k]
                    W[:, k] = w
                    V[:, k] = -cross3(w, tc)
                s, c = np.sin(Q[:, k])[:, None, None], np.cos(Q[:, k])[:, None, None]
                Rc = Rc @ (eye + s * self._K[k] + (1.0 - c) * self._KK[k])
            else:
                u = Rc @ self.lin[k]
                V[:, k] = u if twists else 0.0
                tc = tc + u * Q[:, k:k + 1]
            R[:, k + 1], t[:, k + 1] = Rc, tc
        return ChainFrames(R, t, R_A, t_A, V, W)

    def tool_point(self, Q: np.ndarray, point_m: np.ndarray, placements: Sequence[pin.SE3] | None = None
                   ) -> Kinematics:
        """Forward kinematics of a point of the tool frame for every configuration (base frame).

        Args:
            Q: configurations, (m, n) (rad / m).
            point_m: the point in the tool frame, (3,) m, or one per configuration, (m, 3) m.
            placements: joint placements to use (default the nominal ones).

        Returns:
            The :class:`Kinematics` (point, tool rotation, joint frames before motion, world twists).
        """
        fr = self.frames(Q, placements)
        Mt = self.tool_placement
        R_last, t_last = fr.R[:, -1], fr.t[:, -1]
        t = t_last + R_last @ Mt.translation
        R = R_last @ Mt.rotation
        point = np.asarray(point_m, float)
        if point.ndim == 2:
            if point.shape != t.shape:
                raise InputError(f"{point.shape[0]} tool points for {t.shape[0]} configurations")
            P = t + np.einsum("mab,mb->ma", R, point)
        else:
            P = t + R @ point
        return Kinematics(P, R, fr.R_A, fr.t_A, fr.twist)


def placement_jacobian(kin: Kinematics) -> np.ndarray:
    """∂x/∂δ_j of the tool point w.r.t. every joint-placement error (base frame), (m, n, 3, 6).

    ``[R_A,j, −[x − t_A,j]× R_A,j]`` (module docstring); δ_j = (translation, rotation).
    """
    d = kin.p[:, None, :] - kin.t_A
    return np.concatenate([kin.R_A, -skew(d) @ kin.R_A], axis=-1)


def point_velocity(kin: Kinematics) -> np.ndarray:
    """∂x/∂q of the tool point (base frame): ṗ_k = v_k + ω_k × x, (m, 3, n)."""
    v, w = kin.twist[:, :3, :], kin.twist[:, 3:, :]
    return v + np.cross(w, kin.p[:, :, None], axis=1)
