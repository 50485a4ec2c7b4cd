"""Measurement model h(p, q) of a laser tracker, its Jacobians and noise (paper eqs. 3–6).

A laser tracker measures the reflector position in its own frame (eq. 3)::

    y = h(p, q) = tracker_T_base(p) · oMtool(p, q) · r(p)              (3-D, m)

and, for a 6-DoF probe, also the probe orientation
``R = R_tb · R_tool(q) · R_probe`` (compared as a rotation vector, rad).

Parameter Jacobian (right perturbation of joint j's placement, A_j = frame of
joint j before its own motion, p = reflector in the base frame)::

    ∂p/∂δ_j = [ R_A ,  −[p − t_A]× R_A ]        ∂ω/∂δ_j = [ 0 , R_A ]

tracker (T = T0·exp6(δ_t)): ∂y/∂δ_t = [R_T, −R_T [p]×]; reflector: ∂y/∂r = R_T R_tool.
All blocks are multiplied by R_T (tracker frame) and by the right Jacobian of
exp6 at the current δ (identity at the nominal model).

Derivative w.r.t. the joint angles, used by the design optimiser: with
(v_k, ω_k) the world twist of joint k (a column of Pinocchio's WORLD joint
Jacobian) and ṗ_k = v_k + ω_k × p::

    k before j:   ∂(∂p/∂δ_j)/∂q_k = [ω_k]× ∂p/∂δ_j
    k ≥ j:        ∂(∂p/∂δ_j)/∂q_k = [ 0 , −[ṗ_k]× R_A ]

Laser incidence angle (eq. 4): cos β = zᵀ g with z the reflector's axis (tool z)
and g the unit beam from the reflector to the tracker; feasible if β ≤ 30°.

Noise: per-axis σ (m) in the tracker frame, or distance dependent
σ = a + b·range (how trackers specify their MPE); weighted residuals
f₁ = Σ⁻¹(η − h) (eq. 6).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pinocchio as pin

from pin_kpi_oed.errors import InputError
from pin_kpi_oed.model.parameters import ParameterLayout
from pin_kpi_oed.model.robot import Robot


def skew(v: np.ndarray) -> np.ndarray:
    """Batched cross-product matrices: (..., 3) -> (..., 3, 3)."""
    v = np.asarray(v)
    S = np.zeros(v.shape[:-1] + (3, 3))
    S[..., 0, 1], S[..., 0, 2] = -v[..., 2], v[..., 1]
    S[..., 1, 0], S[..., 1, 2] = v[..., 2], -v[..., 0]
    S[..., 2, 0], S[..., 2, 1] = -v[..., 1], v[..., 0]
    return S


@dataclass
class NoiseModel:
    """Laser-tracker measurement noise.

    Attributes:
        sigma_xyz_m: per-axis standard deviation in the tracker frame (m).
        range_a_m: constant part a of a distance-dependent σ = a + b·range (m); None = per-axis σ.
        range_b: proportional part b (m per m of range).
        sigma_rot_rad: orientation noise of a 6-DoF probe (rad).
    """

    sigma_xyz_m: tuple[float, float, float] = (1e-6, 1e-6, 1e-6)
    range_a_m: float | None = None
    range_b: float = 0.0
    sigma_rot_rad: float = 1e-4

    def __post_init__(self) -> None:
        s = np.asarray(self.sigma_xyz_m, float).ravel()
        if s.size == 1:
            s = np.repeat(s, 3)
        if s.size != 3 or not np.all(np.isfinite(s)) or np.any(s <= 0):
            raise InputError(f"noise sigma must be 1 or 3 positive finite values (m), got {self.sigma_xyz_m}")
        self.sigma_xyz_m = tuple(float(x) for x in s)
        if self.range_a_m is not None and not (self.range_a_m > 0 and self.range_b >= 0):
            raise InputError(f"distance-dependent noise needs a > 0 m and b >= 0, got a={self.range_a_m}, "
                             f"b={self.range_b}")

    def sigma(self, y: np.ndarray) -> np.ndarray:
        """Per-axis σ (m) of position measurements ``y`` (m × 3, tracker frame)."""
        y = np.atleast_2d(y)
        if self.range_a_m is None:
            return np.broadcast_to(np.asarray(self.sigma_xyz_m), y.shape).copy()
        rng = np.linalg.norm(y, axis=1, keepdims=True)
        return np.repeat(self.range_a_m + self.range_b * rng, 3, axis=1)

    def to_dict(self) -> dict:
        """Plain numbers for JSON (SI units)."""
        return {"sigma_xyz_m": list(self.sigma_xyz_m), "range_a_m": self.range_a_m,
                "range_b": self.range_b, "sigma_rot_rad": self.sigma_rot_rad}

    @classmethod
    def from_dict(cls, d: dict) -> "NoiseModel":
        """Inverse of :meth:`to_dict`."""
        return cls(sigma_xyz_m=tuple(d.get("sigma_xyz_m", (1e-6,) * 3)), range_a_m=d.get("range_a_m"),
                   range_b=float(d.get("range_b", 0.0)), sigma_rot_rad=float(d.get("sigma_rot_rad", 1e-4)))


@dataclass
class Kinematics:
    """Per-configuration kinematic quantities in the base frame (batched over m configurations).

    Attributes:
        p: reflector (or any tool point) position, (m, 3).
        R_tool: tool-frame rotation, (m, 3, 3).
        R_A: rotation of each joint's frame before its motion, (m, n, 3, 3).
        t_A: its origin, (m, n, 3).
        twist: world twists (v, ω) of the joints, (m, 6, n).
    """

    p: np.ndarray
    R_tool: np.ndarray
    R_A: np.ndarray
    t_A: np.ndarray
    twist: np.ndarray


@dataclass
class TrackerModel:
    """Calibration measurement model of a robot measured by a laser tracker.

    Attributes:
        robot: the serial arm.
        tracker_T_base: nominal pose of the robot base in the tracker frame (SE3).
        reflector_m: nominal reflector offset in the tool frame (m).
        tcp_m: the KPI point in the tool frame (m); default the tool-frame origin.
        noise: measurement noise model.
        pose6d: measurements include the probe orientation (6-DoF probe).
        probe_R: nominal probe orientation in the tool frame (6-D only).
        layout: the parameter layout (names, fixed, prior).
    """

    robot: Robot
    tracker_T_base: pin.SE3 = field(default_factory=pin.SE3.Identity)
    reflector_m: np.ndarray = field(default_factory=lambda: np.zeros(3))
    tcp_m: np.ndarray = field(default_factory=lambda: np.zeros(3))
    noise: NoiseModel = field(default_factory=NoiseModel)
    pose6d: bool = False
    probe_R: np.ndarray = field(default_factory=lambda: np.eye(3))
    layout: ParameterLayout | None = None

    def __post_init__(self) -> None:
        self.reflector_m = np.asarray(self.reflector_m, float).reshape(3)
        self.tcp_m = np.asarray(self.tcp_m, float).reshape(3)
        if self.layout is None:
            self.layout = ParameterLayout(self.robot.joint_names, pose6d=self.pose6d)
        self._nominal = [self.robot.model.jointPlacements[j].copy() for j in self.robot.joint_ids]
        self._model = self.robot.model.copy()
        self._data = self._model.createData()
        self._p_applied: np.ndarray | None = None
        self._apply(np.zeros(self.n_params))

    # ------------------------------------------------------------------ parameters
    @property
    def n_params(self) -> int:
        """Number of raw parameters."""
        return self.layout.n

    @property
    def nh(self) -> int:
        """Rows per measurement: 3 (position) or 6 (position + orientation)."""
        return 6 if self.pose6d else 3

    def _apply(self, p: np.ndarray) -> None:
        p = np.asarray(p, float)
        if p.shape != (self.n_params,):
            raise InputError(f"parameter vector must have {self.n_params} entries, got shape {p.shape}")
        if self._p_applied is not None and np.array_equal(p, self._p_applied):
            return
        for k, j in enumerate(self.robot.joint_ids):
            self._model.jointPlacements[j] = self._nominal[k] * pin.exp6(p[self.layout.joint_slice(k)])
        self._p_applied = p.copy()

    def tracker_pose(self, p: np.ndarray) -> pin.SE3:
        """tracker_T_base at parameters ``p``."""
        return self.tracker_T_base * pin.exp6(np.asarray(p)[self.layout.tracker])

    def reflector(self, p: np.ndarray) -> np.ndarray:
        """Reflector offset in the tool frame at parameters ``p`` (m)."""
        return self.reflector_m + np.asarray(p)[self.layout.reflector]

    def joint_placements(self, p: np.ndarray) -> list[pin.SE3]:
        """Joint placements M_j·exp6(δ_j) at parameters ``p`` (for URDF export)."""
        self._apply(p)
        return [self._model.jointPlacements[j].copy() for j in self.robot.joint_ids]

    # ------------------------------------------------------------------ kinematics
    @property
    def joint_axes(self) -> tuple[np.ndarray, np.ndarray]:
        """Local motion axes of the joints from Pinocchio: (linear (n, 3), angular (n, 3)); computed once."""
        if not hasattr(self, "_axes"):
            self._axes = self._compute_joint_axes()
        return self._axes

    def _compute_joint_axes(self) -> tuple[np.ndarray, np.ndarray]:
        model, data = self.robot.model, self.robot.model.createData()
        q0 = pin.neutral(model)
        pin.computeJointJacobians(model, data, q0)
        lin, ang = [], []
        for k, j in enumerate(self.robot.joint_ids):
            S = data.oMi[j].actInv(pin.Motion(data.J[:, k]))
            lin.append(S.linear.copy())
            ang.append(S.angular.copy())
        return np.array(lin), np.array(ang)

    def kinematics(self, p: np.ndarray, Q: np.ndarray, point_m: np.ndarray, need_twist: bool = True) -> Kinematics:
        """Forward kinematics of a tool point for every configuration (base frame), batched.

        The chain oMi_j = oMi_parent · M_j · exp(S_j q_j) is composed with NumPy over all m
        configurations at once, from Pinocchio's (perturbed) joint placements and motion axes;
        reading Pinocchio's per-configuration results back into Python costs ~10 µs per
        configuration, which the design optimiser cannot afford. ``tests/test_measurement.py``
        checks it against ``pin.forwardKinematics`` and ``pin.computeJointJacobians`` to 1e-12.

        Args:
            p: raw parameters.
            Q: configurations, (m, n) rad.
            point_m: point in the tool frame (m).
            need_twist: also compute the joints' world twists (as Pinocchio's WORLD Jacobian).
        """
        self._apply(p)
        model = self._model
        Q = np.atleast_2d(np.asarray(Q, float))
        m, n = Q.shape
        if n != self.robot.nq:
            raise InputError(f"configurations must have {self.robot.nq} joint values, got {n}")
        lin, ang = self.joint_axes
        revolute = np.linalg.norm(ang, axis=1) > 0.5
        R_A = np.empty((m, n, 3, 3))
        t_A = np.empty((m, n, 3))
        twist = np.empty((m, 6, n))
        R = np.broadcast_to(np.eye(3), (m, 3, 3))
        t = np.zeros((m, 3))
        for k, j in enumerate(self.robot.joint_ids):
            Mj = model.jointPlacements[j]
            t = t + R @ Mj.translation
            R = R @ Mj.rotation
            R_A[:, k], t_A[:, k] = R, t
            if revolute[k]:
                a = ang[k]
                K = skew(a)
                s, c = np.sin(Q[:, k])[:, None, None], np.cos(Q[:, k])[:, None, None]
                Rq = np.eye(3) + s * K + (1 - c) * (K @ K)
                w = R @ a
                twist[:, 3:, k] = w
                twist[:, :3, k] = -np.cross(w, t)
                R = R @ Rq
            else:
                twist[:, :3, k] = R @ lin[k]
                twist[:, 3:, k] = 0.0
                t = t + (R @ lin[k]) * Q[:, k:k + 1]
        Mt = model.frames[self.robot.tool_frame_id].placement
        # tool frame: attached to the last joint (fixed joints folded into its placement)
        t = t + R @ Mt.translation
        R = R @ Mt.rotation
        P = t + R @ np.asarray(point_m, float)
        return Kinematics(P, R, R_A, t_A, twist)

    def predict(self, p: np.ndarray, Q: np.ndarray) -> np.ndarray:
        """Model response h(p, q) (eq. 3): reflector positions in the tracker frame, (m, 3) m.

        For 6-D models, (m, 6): position and the rotation vector of the probe orientation (rad).
        """
        kin = self.kinematics(p, Q, self.reflector(p), need_twist=False)
        T = self.tracker_pose(p)
        Y = kin.p @ T.rotation.T + T.translation
        if not self.pose6d:
            return Y
        R_probe = self.probe_R @ pin.exp3(np.asarray(p)[self.layout.probe])
        W = np.array([pin.log3(T.rotation @ Rt @ R_probe) for Rt in kin.R_tool])
        return np.hstack([Y, W])

    def kpi(self, p: np.ndarray, Q_work: np.ndarray) -> np.ndarray:
        """KPI s (eq. 12): TCP point in the tracker frame at each working configuration, (t, 3) m."""
        kin = self.kinematics(p, Q_work, self.tcp_m, need_twist=False)
        T = self.tracker_pose(p)
        return kin.p @ T.rotation.T + T.translation

    # ------------------------------------------------------------------ Jacobians
    def _right_jac(self, p: np.ndarray) -> np.ndarray:
        """Block-diagonal right Jacobians of exp6/exp3 at ``p`` (identity at nominal), (np, np)."""
        L = self.layout
        Jr = np.eye(self.n_params)
        if not np.any(p):
            return Jr
        for k in range(L.n_joints):
            s = L.joint_slice(k)
            Jr[s, s] = pin.Jexp6(pin.Motion(p[s]))
        Jr[L.tracker, L.tracker] = pin.Jexp6(pin.Motion(p[L.tracker]))
        if L.pose6d:
            Jr[L.probe, L.probe] = pin.Jexp3(p[L.probe])
        return Jr

    def _point_jacobian(self, p: np.ndarray, Q: np.ndarray, point_m: np.ndarray, with_dq: bool,
                        with_reflector: bool) -> tuple[np.ndarray, np.ndarray | None, np.ndarray, np.ndarray]:
        """Jacobian of a tool point in the tracker frame w.r.t. all raw parameters.

        Returns:
            (Y (m, 3), J (m, 3, np), dJ (m, 3, np, n) or None, Ydq (m, 3, n)).
        """
        L = self.layout
        kin = self.kinematics(p, Q, point_m, need_twist=True)
        T = self.tracker_pose(p)
        RT = T.rotation
        m, n = kin.p.shape[0], L.n_joints
        J = np.zeros((m, 3, self.n_params))
        d = kin.p[:, None, :] - kin.t_A  # (m, n, 3)
        blk = np.concatenate([kin.R_A, -skew(d) @ kin.R_A], axis=-1)  # (m, n, 3, 6)
        for k in range(n):
            J[:, :, L.joint_slice(k)] = blk[:, k]
        J[:, :, L.tracker] = np.concatenate([np.broadcast_to(np.eye(3), (m, 3, 3)), -skew(kin.p)], axis=-1)
        if with_reflector:
            J[:, :, L.reflector] = kin.R_tool
        J = RT @ J
        v, w = kin.twist[:, :3, :], kin.twist[:, 3:, :]  # (m, 3, n)
        pdot = v + np.cross(w, kin.p[:, :, None], axis=1)  # (m, 3, n)
        Ydq = np.einsum("ab,mbn->man", RT, pdot)
        Y = kin.p @ RT.T + T.translation
        dJ = None
        if with_dq:
            dJ = np.zeros((m, 3, self.n_params, n))
            Wsk = skew(np.moveaxis(w, 1, 2))  # (m, n, 3, 3) [ω_k]×
            Pdsk = skew(np.moveaxis(pdot, 1, 2))  # (m, n, 3, 3) [ṗ_k]×
            before = np.tril(np.ones((n, n), bool), -1)  # before[j, k]: joint k precedes joint j
            # k before j: the whole block rotates with joint k
            D = (Wsk[:, None] @ blk[:, :, None]) * before[None, :, :, None, None]
            # k >= j: only the rotational columns change, by -[ṗ_k]× R_A(j)
            D[..., 3:] -= (Pdsk[:, None] @ kin.R_A[:, :, None]) * ~before[None, :, :, None, None]
            nj = 6 * n
            dJ[:, :, :nj, :] = np.moveaxis(D, (1, 2, 3, 4), (2, 4, 1, 3)).reshape(m, 3, nj, n)
            dJ[:, :, L.tracker.start + 3:L.tracker.stop, :] = -np.moveaxis(Pdsk, 1, 3)
            if with_reflector:
                dJ[:, :, L.reflector, :] = np.moveaxis(Wsk @ kin.R_tool[:, None], 1, 3)
            dJ = (RT @ dJ.reshape(m, 3, -1)).reshape(dJ.shape)
        return Y, J, dJ, Ydq

    def _rotation_jacobian(self, p: np.ndarray, Q: np.ndarray, with_dq: bool) -> tuple[np.ndarray, np.ndarray | None]:
        """Angular Jacobian (tracker frame) of the probe orientation, (m, 3, np) and its q-derivative."""
        L = self.layout
        kin = self.kinematics(p, Q, self.reflector(p), need_twist=True)
        RT = self.tracker_pose(p).rotation
        m, n = kin.p.shape[0], L.n_joints
        R_probe = self.probe_R @ pin.exp3(np.asarray(p)[L.probe])
        J = np.zeros((m, 3, self.n_params))
        for k in range(n):
            J[:, :, L.joint_slice(k).start + 3:L.joint_slice(k).stop] = kin.R_A[:, k]
        J[:, :, L.tracker.start + 3:L.tracker.stop] = np.eye(3)
        J[:, :, L.probe] = kin.R_tool @ R_probe
        J = np.einsum("ab,mbp->map", RT, J)
        dJ = None
        if with_dq:
            w = kin.twist[:, 3:, :]
            Wsk = skew(np.moveaxis(w, 1, 2))
            dJ = np.zeros((m, 3, self.n_params, n))
            for j in range(n):
                s = L.joint_slice(j)
                for k in range(j):
                    dJ[:, :, s.start + 3:s.stop, k] = Wsk[:, k] @ kin.R_A[:, j]
                dJ[:, :, L.probe, j] = Wsk[:, j] @ kin.R_tool @ R_probe
            dJ = (RT @ dJ.reshape(m, 3, -1)).reshape(dJ.shape)
        return J, dJ

    def jacobian(self, p: np.ndarray, Q: np.ndarray) -> np.ndarray:
        """Jacobian dh/dp of every measurement w.r.t. all raw parameters, (m, nh, np).

        Exact at any ``p`` (includes the right Jacobian of exp6 at the current δ).
        """
        p = np.asarray(p, float)
        _, J, _, _ = self._point_jacobian(p, Q, self.reflector(p), with_dq=False, with_reflector=True)
        if self.pose6d:
            Jw, _ = self._rotation_jacobian(p, Q, with_dq=False)
            J = np.concatenate([J, Jw], axis=1)
        return J @ self._right_jac(p)

    def jacobian_dq(self, p: np.ndarray, Q: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Parameter Jacobian and its derivative w.r.t. the joint angles.

        Returns:
            Y: predicted positions (m, 3) m (tracker frame).
            J: dh/dp, (m, nh, np).
            dJ: d²h/dp dq, (m, nh, np, n); ``dJ[i, :, :, k]`` = ∂J_i/∂q_ik.
            Ydq: dy/dq of the positions, (m, 3, n).
        """
        p = np.asarray(p, float)
        Y, J, dJ, Ydq = self._point_jacobian(p, Q, self.reflector(p), with_dq=True, with_reflector=True)
        if self.pose6d:
            Jw, dJw = self._rotation_jacobian(p, Q, with_dq=True)
            J = np.concatenate([J, Jw], axis=1)
            dJ = np.concatenate([dJ, dJw], axis=1)
        if not np.any(p):  # right Jacobians are the identity at the nominal model
            return Y, J, dJ, Ydq
        Jr = self._right_jac(p)
        return Y, J @ Jr, np.moveaxis(np.moveaxis(dJ, 3, 2) @ Jr, 2, 3), Ydq

    def kpi_jacobian(self, p: np.ndarray, Q_work: np.ndarray) -> np.ndarray:
        """KPI sensitivity E = ds/dp (eq. 24e), stacked over working configurations, (3t, np)."""
        p = np.asarray(p, float)
        _, J, _, _ = self._point_jacobian(p, Q_work, self.tcp_m, with_dq=False, with_reflector=False)
        return (J @ self._right_jac(p)).reshape(-1, self.n_params)

    # ------------------------------------------------------------------ weighting
    def sigma(self, p: np.ndarray, Q: np.ndarray, Y: np.ndarray | None = None) -> np.ndarray:
        """Standard deviation of every measurement row, (m, nh) (m; rad for orientation rows)."""
        if Y is None:
            Y = self.predict(p, Q)[:, :3]
        s = self.noise.sigma(Y)
        if self.pose6d:
            s = np.hstack([s, np.full_like(s, self.noise.sigma_rot_rad)])
        return s

    def weighted_jacobian_dq(self, p: np.ndarray, Q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """F = Σ⁻¹ dh/dp (eq. 24d) and dF/dq, including the q-dependence of a range-dependent σ.

        Returns:
            F: (m, nh, np); dF: (m, nh, np, n).
        """
        Y, J, dJ, Ydq = self.jacobian_dq(p, Q)
        S = self.sigma(p, Q, Y)
        F = J / S[:, :, None]
        dF = dJ / S[:, :, None, None]
        if self.noise.range_a_m is not None and self.noise.range_b > 0:
            r = np.linalg.norm(Y, axis=1)
            dsig = self.noise.range_b * np.einsum("ma,man->mn", Y / r[:, None], Ydq)  # (m, n)
            dS = np.zeros(S.shape + (Q.shape[1],))
            dS[:, :3, :] = dsig[:, None, :]
            dF -= J[:, :, :, None] * dS[:, :, None, :] / (S ** 2)[:, :, None, None]
        return F, dF

    def weighted_jacobian(self, p: np.ndarray, Q: np.ndarray) -> np.ndarray:
        """F = Σ⁻¹ dh/dp (eq. 24d), (m, nh, np)."""
        J = self.jacobian(p, Q)
        return J / self.sigma(p, Q)[:, :, None]

    # ------------------------------------------------------------------ incidence angle
    def incidence_cos(self, p: np.ndarray, Q: np.ndarray, with_grad: bool = False
                      ) -> np.ndarray | tuple[np.ndarray, np.ndarray]:
        """cos β of the laser incidence angle (eq. 4) and optionally d cos β / dq, (m,) and (m, n).

        z = reflector axis (tool z) and g = unit beam from the reflector to the tracker.
        """
        p = np.asarray(p, float)
        kin = self.kinematics(p, Q, self.reflector(p), need_twist=with_grad)
        T = self.tracker_pose(p)
        RT = T.rotation
        y = kin.p @ RT.T + T.translation  # reflector in the tracker frame
        z = np.einsum("ab,mb->ma", RT, kin.R_tool[:, :, 2])
        r = np.linalg.norm(y, axis=1)
        c = -np.einsum("ma,ma->m", z, y) / r
        if not with_grad:
            return c
        v, w = kin.twist[:, :3, :], kin.twist[:, 3:, :]
        pdot = v + np.cross(w, kin.p[:, :, None], axis=1)
        dy = np.einsum("ab,mbn->man", RT, pdot)
        wT = np.einsum("ab,mbn->man", RT, w)
        dz = np.cross(wT, z[:, :, None], axis=1)
        zy = np.einsum("ma,ma->m", z, y)
        dc = (-(np.einsum("man,ma->mn", dz, y) + np.einsum("ma,man->mn", z, dy)) / r[:, None]
              + (zy / r ** 3)[:, None] * np.einsum("ma,man->mn", y, dy))
        return c, dc
