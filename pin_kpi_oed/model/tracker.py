"""Measurement model h(p, q) of a laser tracker (3-D reflector or 6-DoF probe), paper eqs. 3–6.

A laser tracker measures the reflector position in its own frame (eq. 3)::

    y = h(p, q) = tracker_T_base(p) · oMtool(p, q) · r(p)              (3-D, m)

and, for a 6-DoF probe, also the probe orientation
``R = R_tb · R_tool(q) · R_probe`` (compared as a rotation vector, rad).
Set-up groups (:mod:`pin_kpi_oed.model.parameters`): ``tracker`` (pose), ``reflector`` (point)
and, for the probe, ``probe`` (rotation). Implements :class:`~pin_kpi_oed.model.device.MeasurementModel`.

Parameter Jacobian (right perturbation of joint j's placement, A_j = frame of
joint j before its own motion, p = reflector in the base frame)::

    ∂p/∂δ_j = [ R_A ,  −[p − t_A]× R_A ]        ∂ω/∂δ_j = [ 0 , R_A ]

tracker (T = T0·exp6(δ_t)): ∂y/∂δ_t = [R_T, −R_T [p]×]; reflector: ∂y/∂r = R_T R_tool.
All blocks are multiplied by R_T (tracker frame) and by the right Jacobian of
exp6 at the current δ (identity at the nominal model).

Derivative w.r.t. the joint values, used by the design optimiser: with
(v_k, ω_k) the world twist of joint k (a column of Pinocchio's WORLD joint
Jacobian) and ṗ_k = v_k + ω_k × p::

    k before j:   ∂(∂p/∂δ_j)/∂q_k = [ω_k]× ∂p/∂δ_j
    k ≥ j:        ∂(∂p/∂δ_j)/∂q_k = [ 0 , −[ṗ_k]× R_A ]

(a prismatic joint has ω_k = 0 and ṗ_k = v_k, its unit axis in the base frame).

Laser incidence angle (eq. 4): cos β = zᵀ g with z the reflector's axis (tool z)
and g the unit beam from the reflector to the tracker; feasible if β ≤ 30°.

Noise (:class:`~pin_kpi_oed.model.noise.NoiseModel`): per-axis σ (m) in the tracker frame, or
distance dependent σ = a + b·range; weighted residuals f₁ = Σ⁻¹(η − h) (eq. 6).
"""

from __future__ import annotations

from typing import Literal, overload

from dataclasses import dataclass, field, replace
from collections.abc import Sequence

import numpy as np
import pinocchio as pin

from pin_kpi_oed.data.tool_header import ToolSpec
from pin_kpi_oed.model.device import MeasurementModel
from pin_kpi_oed.model.kinematics import point_velocity, skew
from pin_kpi_oed.model.nests import check_nests, check_row_nest
from pin_kpi_oed.model.noise import NoiseModel
from pin_kpi_oed.model.parameters import PROBE_SETUP, TRACKER_SETUP, ParameterLayout
from pin_kpi_oed.model.robot import Robot

__all__ = ["TrackerModel"]


@dataclass
class TrackerModel(MeasurementModel):
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
        tool: what the model was declared with beyond its geometry (a
            :class:`~pin_kpi_oed.data.tool_header.ToolSpec`: a cell's TCP and working configurations), or None;
            :func:`~pin_kpi_oed.identification.identify.identify` keeps it in the calibrated model.
        nests_m: the reflector nests on the tool, (k, 3) m in the tool frame; nest 0 is ``reflector_m``
            (default: that one nest). The nests are known relative to each other (bored in one holder): the
            ``reflector`` group is one offset shared by every nest (:mod:`pin_kpi_oed.model.nests`).
        row_nest: the nest of every row of the configurations this model is called with, (m,) int, or None
            (every row at nest 0); set by :meth:`at_nests`.
    """

    robot: Robot
    tracker_T_base: pin.SE3 = field(default_factory=pin.SE3.Identity)
    reflector_m: np.ndarray = field(default_factory=lambda: np.zeros(3))
    tcp_m: np.ndarray = field(default_factory=lambda: np.zeros(3))
    noise: NoiseModel = field(default_factory=NoiseModel)
    pose6d: bool = False
    probe_R: np.ndarray = field(default_factory=lambda: np.eye(3))
    layout: ParameterLayout | None = None
    tool: ToolSpec | None = field(default=None, repr=False, compare=False)
    nests_m: np.ndarray | None = None
    row_nest: np.ndarray | None = field(default=None, repr=False, compare=False)

    def __post_init__(self) -> None:
        self.reflector_m = np.asarray(self.reflector_m, float).reshape(3)
        self.nests_m = check_nests(self.reflector_m, self.nests_m)
        if self.row_nest is not None:
            self.row_nest = check_row_nest(self.row_nest, len(self.nests_m))
        self.tcp_m = np.asarray(self.tcp_m, float).reshape(3)
        if self.layout is None:
            self.layout = self.make_layout()
        self.init_kinematics()

    # ------------------------------------------------------------------ the device's declaration
    def setup_spec(self) -> tuple[tuple[str, str], ...]:
        """``tracker`` (pose), ``reflector`` (point), + ``probe`` (rotation) for a 6-DoF probe."""
        return PROBE_SETUP if self.pose6d else TRACKER_SETUP

    @property
    def frame_group(self) -> str:
        """``"tracker"``: the tracker pose error."""
        return "tracker"

    @property
    def target_groups(self) -> tuple[str, ...]:
        """``("reflector",)``, + ``"probe"`` for a 6-DoF probe."""
        return ("reflector", "probe") if self.pose6d else ("reflector",)

    @property
    def nh(self) -> int:
        """Rows per measurement: 3 (position) or 6 (position + orientation)."""
        return 6 if self.pose6d else 3

    # ------------------------------------------------------------------ parameters
    def tracker_pose(self, p: np.ndarray) -> pin.SE3:
        """tracker_T_base at parameters ``p``."""
        return self.tracker_T_base * pin.exp6(np.asarray(p)[self.layout.tracker])

    def sensor_pose(self, p: np.ndarray) -> pin.SE3:
        """The device frame: :meth:`tracker_pose`."""
        return self.tracker_pose(p)

    def reflector(self, p: np.ndarray) -> np.ndarray:
        """Reflector offset in the tool frame at parameters ``p`` (m)."""
        return self.reflector_m + np.asarray(p)[self.layout.reflector]

    @property
    def n_nests(self) -> int:
        """Number of reflector nests on the tool."""
        return len(self.nests_m)

    def at_nests(self, nest: np.ndarray | None) -> TrackerModel:
        """This model measuring row i at nest ``nest[i]`` (the same layout, so the same parameters).

        Args:
            nest: the nest of every row, (m,) int in 0 … k−1; None: every row at nest 0.

        Returns:
            A :class:`TrackerModel` whose predictions and Jacobians take (m, n) configurations, row i at its nest.

        Raises:
            InputError: a nest index that is not one of the model's nests.
        """
        return replace(self, row_nest=None if nest is None else np.asarray(nest))

    def points(self, p: np.ndarray) -> np.ndarray:
        """The measured reflector offsets in the tool frame at parameters ``p``: (3,) m, or (m, 3) per row when
        the model measures several nests (:meth:`at_nests`); the shared offset ``p[reflector]`` moves all."""
        if self.row_nest is None:
            return self.reflector(p)
        return self.nests_m[self.row_nest] + np.asarray(p)[self.layout.reflector]

    def _probe_rotation(self, p: np.ndarray) -> np.ndarray:
        return self.probe_R @ pin.exp3(np.asarray(p)[self.layout.probe])

    # ------------------------------------------------------------------ prediction
    def predict(self, p: np.ndarray, Q: np.ndarray) -> np.ndarray:
        """Model response h(p, q) (eq. 3): reflector positions in the tracker frame, (m, 3) m.

        For 6-D models, (m, 6): position and the rotation vector of the probe orientation (rad).
        """
        kin = self.kinematics(p, Q, self.points(p))
        T = self.tracker_pose(p)
        Y = kin.p @ T.rotation.T + T.translation
        if not self.pose6d:
            return Y
        R_probe = self._probe_rotation(p)
        W = np.array([pin.log3(R) for R in T.rotation @ kin.R_tool @ R_probe])  # the rows' products in one call
        return np.hstack([Y, W])

    def kpi(self, p: np.ndarray, Q_work: np.ndarray) -> np.ndarray:
        """KPI s (eq. 12): TCP point in the tracker frame at each working configuration, (t, 3) m."""
        kin = self.kinematics(p, Q_work, self.tcp_m)
        T = self.tracker_pose(p)
        return kin.p @ T.rotation.T + T.translation

    # ------------------------------------------------------------------ Jacobians
    def _rotation_jacobian(self, p: np.ndarray, Q: np.ndarray, with_dq: bool) -> tuple[np.ndarray, np.ndarray | None]:
        """Angular Jacobian (tracker frame) of the probe orientation, (m, 3, np) and its q-derivative."""
        L = self.layout
        kin = self.kinematics(p, Q, self.points(p))
        RT = self.tracker_pose(p).rotation
        m, n = kin.p.shape[0], L.n_joints
        R_probe = self._probe_rotation(p)
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
        J = self.sensor_point(p, Q, self.points(p), offset_group="reflector").J
        if self.pose6d:
            Jw, _ = self._rotation_jacobian(p, Q, with_dq=False)
            J = np.concatenate([J, Jw], axis=1)
        return self.at_parameters(J, p)

    def base_jacobian(self, p: np.ndarray, Q: np.ndarray, cols: Sequence[int] | None = None) -> np.ndarray:
        """Jacobian of the reflector positions w.r.t. the raw parameters, rotated into the robot base frame.

        Args:
            p: raw parameters; Q: configurations (m, n) rad; cols: the parameter columns to keep (default all).

        Returns:
            (m, 3, k): R_tbᵀ · dh/dp (m per parameter unit), R_tb the tracker pose's rotation at ``p``.
        """
        J = self.jacobian(p, Q)[:, :3, :]
        if cols is not None:
            J = J[:, :, list(cols)]
        return np.einsum("ba,mbp->map", self.tracker_pose(p).rotation, J)

    def jacobian_dq(self, p: np.ndarray, Q: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Parameter Jacobian and its derivative w.r.t. the joint values.

        Returns:
            Y: predicted positions (m, 3) m (tracker frame).
            J: dh/dp, (m, nh, np).
            dJ: d²h/dp dq, (m, nh, np, n); ``dJ[i, :, :, k]`` = ∂J_i/∂q_ik.
            Ydq: dy/dq of the positions, (m, 3, n).
        """
        p = np.asarray(p, float)
        sp = self.sensor_point(p, Q, self.points(p), offset_group="reflector", with_dq=True)
        Y, J, dJ, Ydq = sp.Y, sp.J, sp.dJ, sp.Ydq
        if self.pose6d:
            Jw, dJw = self._rotation_jacobian(p, Q, with_dq=True)
            J = np.concatenate([J, Jw], axis=1)
            dJ = np.concatenate([dJ, dJw], axis=1)
        if not np.any(p):  # right Jacobians are the identity at the nominal model
            return Y, J, dJ, Ydq
        Jr = self.right_jacobian(p)
        return Y, J @ Jr, np.moveaxis(np.moveaxis(dJ, 3, 2) @ Jr, 2, 3), Ydq

    def prediction_dq(self, p: np.ndarray, Q: np.ndarray) -> np.ndarray:
        """dy/dq of the reflector positions (tracker frame), (m, 3, n), without the costly d²h/dp dq."""
        p = np.asarray(p, float)
        kin = self.kinematics(p, Q, self.points(p))
        return np.einsum("ab,mbn->man", self.tracker_pose(p).rotation, point_velocity(kin))

    def kpi_jacobian(self, p: np.ndarray, Q_work: np.ndarray) -> np.ndarray:
        """KPI sensitivity E = ds/dp (eq. 24e), stacked over working configurations, (3t, np)."""
        p = np.asarray(p, float)
        J = self.sensor_point(p, Q_work, self.tcp_m).J
        return self.at_parameters(J, p).reshape(-1, self.n_params)

    def kpi_rotation_jacobian(self, p: np.ndarray, Q_work: np.ndarray) -> np.ndarray:
        """Sensitivity of the tool frame's orientation (tracker frame, rotation vector) to the parameters at the
        working configurations, (3t, np) rad per parameter unit: the rotational rows of the 6-D KPI.

        Joint j's placement turns the tool by R_T R_A,j δω_j; the tracker pose by R_T δω_t; translations, the
        reflector and the TCP point do not turn it.
        """
        p = np.asarray(p, float)
        L = self.layout
        kin = self.kinematics(p, Q_work, self.tcp_m)
        m = kin.p.shape[0]
        J = np.zeros((m, 3, self.n_params))
        for k in range(L.n_joints):
            J[:, :, L.joint_slice(k).start + 3:L.joint_slice(k).stop] = kin.R_A[:, k]
        fs = L.group_slice(self.frame_group)
        J[:, :, fs.start + 3:fs.stop] = np.eye(3)
        J = np.einsum("ab,mbp->map", self.sensor_pose(p).rotation, J)
        return self.at_parameters(J, p).reshape(-1, self.n_params)

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

    # ------------------------------------------------------------------ incidence angle
    @overload
    def incidence_cos(self, p: np.ndarray, Q: np.ndarray, with_grad: Literal[False] = ...) -> np.ndarray: ...
    @overload
    def incidence_cos(self, p: np.ndarray, Q: np.ndarray, with_grad: Literal[True]
                      ) -> tuple[np.ndarray, np.ndarray]: ...

    def incidence_cos(self, p: np.ndarray, Q: np.ndarray, with_grad: bool = False
                      ) -> np.ndarray | tuple[np.ndarray, np.ndarray]:
        """cos β of the laser incidence angle (eq. 4) and optionally d cos β / dq, (m,) and (m, n).

        z = reflector axis (tool z) and g = unit beam from the reflector to the tracker.
        """
        p = np.asarray(p, float)
        T = self.tracker_pose(p)
        if not with_grad:  # the reflector and the tool axis only
            y, z = self._beam_ends(T, *self._tool_pose(p, Q, self.points(p)))
            return -np.einsum("ma,ma->m", z, y) / np.linalg.norm(y, axis=1)
        kin = self.kinematics(p, Q, self.points(p))
        RT = T.rotation
        y, z = self._beam_ends(T, kin.p, kin.R_tool)
        r = np.linalg.norm(y, axis=1)
        zy = np.einsum("ma,ma->m", z, y)
        c = -zy / r
        w = kin.twist[:, 3:, :]
        dy = np.einsum("ab,mbn->man", RT, point_velocity(kin))
        wT = np.einsum("ab,mbn->man", RT, w)
        dz = np.cross(wT, z[:, :, None], axis=1)
        dc = (-(np.einsum("man,ma->mn", dz, y) + np.einsum("ma,man->mn", z, dy)) / r[:, None]
              + (zy / r ** 3)[:, None] * np.einsum("ma,man->mn", y, dy))
        return c, dc

    @staticmethod
    def _beam_ends(T: pin.SE3, P: np.ndarray, R_tool: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The reflectors at P (m, 3) m (base frame) in the tracker frame T, and their axes (tool z of the rotations
        R_tool (m, 3, 3)) there: (y (m, 3) m, z (m, 3))."""
        return P @ T.rotation.T + T.translation, np.einsum("ab,mb->ma", T.rotation, R_tool[:, :, 2])

    # ------------------------------------------------------------------ notes
    def identifiability_notes(self) -> list[str]:
        """A reflector on the last joint axis (3-D): two directions lost, a TCP off that axis not estimable."""
        rb = self.robot
        _, ang = self.joint_axes
        if np.linalg.norm(ang[-1]) < 0.5:
            return []
        Mt = rb.model.frames[rb.tool_frame_id].placement
        # last joint axis expressed in the tool frame, through the tool-frame point Mt^-1 * 0
        axis = Mt.rotation.T @ ang[-1]
        origin = Mt.actInv(np.zeros(3))
        r = self.reflector_m - origin
        dist = np.linalg.norm(r - (r @ axis) * axis)
        if dist < 1e-3 and not self.pose6d:
            return [f"the reflector is {dist * 1e3:.2f} mm from the axis of {rb.joint_names[-1]}: the tool's "
                    f"rotation about that axis does not move it, so two more directions are lost (rank drops by 2) "
                    f"and a TCP off that axis is not estimable; mount the reflector off the axis (a few cm) or use "
                    f"a 6-DoF probe"]
        return []
