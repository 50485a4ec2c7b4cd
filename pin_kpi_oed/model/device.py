"""What a calibration measurement device is: the :class:`MeasurementModel` interface.

A measurement model h(p, q) (paper eq. 3) maps the raw parameters p and a robot configuration q
to the ``nh`` numbers the device reports for one measurement. The raw parameters are the robot's
joint-placement errors (:mod:`pin_kpi_oed.model.parameters`, 6 per joint, shared by every device)
followed by the device's own *set-up groups*, declared by :meth:`MeasurementModel.setup_spec`
(the laser tracker: ``tracker`` pose + ``reflector`` offset, + ``probe`` orientation for a 6-DoF
probe). Every consumer (identifiability, covariance, criteria, design) takes group names from the
model (:attr:`MeasurementModel.setup_groups`, :attr:`frame_group`, :attr:`target_groups`), never
hard-coded.

A device implements, for m configurations Q (m, n):

=========================  ==========================================================================
``predict(p, Q)``           h, (m, nh)
``jacobian(p, Q)``          ∂h/∂p, (m, nh, np) (exact at any p: right Jacobians of exp6/exp3 included)
``jacobian_dq(p, Q)``       (Y, J, ∂J/∂q (m, nh, np, n), Ydq): Y = the leading k rows of h that σ
                            depends on (tracker: positions, k = 3), Ydq = ∂Y/∂q (m, k, n)
``sigma(p, Q, Y=None)``     standard deviation of every row, (m, nh)
``kpi(p, Q_work)``          KPI s (eq. 12): the TCP in the device frame, (t, 3) m
``kpi_jacobian(p, Q_work)`` E = ∂s/∂p (eq. 24e), (3t, np)
``sensor_pose(p)``          pose of the robot base in the device frame (``pin.SE3``)
``setup_spec()``            set-up groups ``((name, kind), ...)``, kinds of :data:`GROUP_KINDS`
``frame_group``             the group of ``sensor_pose``'s error (a ``pose`` group)
``target_groups``           the groups describing the measured target on the tool (their null
                            directions only re-label the tool point, see ``check_kpi`` in
                            :mod:`pin_kpi_oed.oed.identifiability`)
``nh``                      rows per measurement
=========================  ==========================================================================

and gets from this base class: the batched robot kinematics at p (:meth:`kinematics`,
:meth:`joint_placements`), the Jacobian of a tool point seen from the device frame
(:meth:`sensor_point`, the building block of every point-measuring device), the block-diagonal
right Jacobian (:meth:`right_jacobian`), the weighted Jacobian F = Σ⁻¹ ∂h/∂p (eq. 24d) and its
q-derivative (:meth:`weighted_jacobian`, :meth:`weighted_jacobian_dq`), ∂Y/∂q without the costly
second derivative (:meth:`prediction_dq`, used by the effects) and plain-words identifiability
notes (:meth:`identifiability_notes`, default none). A new device is one module: a subclass that
sets ``robot`` and ``layout = self.make_layout()`` and calls ``self.init_kinematics()``
(see ``tests/test_device.py`` for a camera measuring a marker).
"""

from __future__ import annotations

import functools
from abc import ABC, abstractmethod
from dataclasses import dataclass, field

import numpy as np
import pinocchio as pin

from pin_kpi_oed.errors import InputError
from pin_kpi_oed.model.kinematics import Chain, Kinematics, placement_jacobian, point_velocity, skew
from pin_kpi_oed.model.parameters import ParameterLayout
from pin_kpi_oed.model.robot import Robot

__all__ = ["MeasurementModel", "SensorPoint"]

#: The identity, broadcast into the device-frame columns of every Jacobian (read-only).
_EYE3 = np.eye(3)
_EYE3.flags.writeable = False


@functools.lru_cache(maxsize=16)
def _joint_pairs(n: int) -> tuple[tuple[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]]:
    """The joint pairs of ∂J/∂q for a chain of n joints: ((j, k) with k before j), ((j, k) with k ≥ j), read-only."""
    before, after = np.tril_indices(n, -1), np.triu_indices(n)
    for a in (*before, *after):
        a.flags.writeable = False
    return before, after


@dataclass
class SensorPoint:
    """A tool point seen from the device frame, with its parameter Jacobian (batched over m).

    Attributes:
        Y: the point in the device frame, (m, 3) m.
        J: ∂Y/∂p w.r.t. every raw parameter at the *tangent* coordinates (right Jacobians not
            applied; see :meth:`MeasurementModel.right_jacobian`), (m, 3, np).
        dJ: ∂J/∂q, (m, 3, np, n), or None.
        kin: the base-frame kinematics of the point.
        RT: the device frame's rotation (the rotation of ``sensor_pose``), (3, 3).
        Ydq: ∂Y/∂q, (m, 3, n) (property: computed on the first read when ∂J/∂q was not asked for).
    """

    Y: np.ndarray
    J: np.ndarray
    dJ: np.ndarray | None
    kin: Kinematics
    RT: np.ndarray
    ydq: np.ndarray | None = field(default=None, repr=False)

    @property
    def Ydq(self) -> np.ndarray:
        """∂Y/∂q = R_T ṗ, (m, 3, n) m per joint unit."""
        if self.ydq is None:
            self.ydq = np.einsum("ab,mbn->man", self.RT, point_velocity(self.kin))
        return self.ydq


class MeasurementModel(ABC):
    """Interface of a calibration measurement device (see the module docstring).

    Attributes:
        robot: the serial arm.
        layout: the raw parameter layout (joints, then :meth:`setup_spec`'s groups).
    """

    robot: Robot
    layout: ParameterLayout

    # ------------------------------------------------------------------ what a device declares
    @abstractmethod
    def setup_spec(self) -> tuple[tuple[str, str], ...]:
        """The device's set-up parameter groups ``((name, kind), ...)``, kinds ``pose``/``point``/``rotation``."""

    @property
    @abstractmethod
    def frame_group(self) -> str:
        """The ``pose`` group of the device frame's error (``sensor_pose(p) = T0 · exp6(p[group])``)."""

    @property
    @abstractmethod
    def target_groups(self) -> tuple[str, ...]:
        """The groups describing the measured target on the tool (reflector, probe orientation, marker)."""

    @property
    @abstractmethod
    def nh(self) -> int:
        """Rows per measurement."""

    @abstractmethod
    def sensor_pose(self, p: np.ndarray) -> pin.SE3:
        """Pose of the robot base in the device frame at parameters ``p``."""

    @abstractmethod
    def predict(self, p: np.ndarray, Q: np.ndarray) -> np.ndarray:
        """Model response h(p, q) (eq. 3), (m, nh)."""

    @abstractmethod
    def jacobian(self, p: np.ndarray, Q: np.ndarray) -> np.ndarray:
        """∂h/∂p at any ``p``, (m, nh, np)."""

    @abstractmethod
    def jacobian_dq(self, p: np.ndarray, Q: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(Y (m, k), J (m, nh, np), dJ (m, nh, np, n), Ydq (m, k, n)); Y = leading k rows of h."""

    @abstractmethod
    def sigma(self, p: np.ndarray, Q: np.ndarray, Y: np.ndarray | None = None) -> np.ndarray:
        """Standard deviation of every row, (m, nh); ``Y`` as returned by :meth:`jacobian_dq` (optional)."""

    @abstractmethod
    def kpi(self, p: np.ndarray, Q_work: np.ndarray) -> np.ndarray:
        """KPI s (eq. 12): the TCP in the device frame at each working configuration, (t, 3) m."""

    @abstractmethod
    def kpi_jacobian(self, p: np.ndarray, Q_work: np.ndarray) -> np.ndarray:
        """KPI sensitivity E = ∂s/∂p (eq. 24e), stacked over working configurations, (3t, np)."""

    # ------------------------------------------------------------------ parameters
    def make_layout(self) -> ParameterLayout:
        """A fresh layout: the robot's joints, then :meth:`setup_spec`'s groups (nothing fixed, no prior)."""
        return ParameterLayout(list(self.robot.joint_names), setup=self.setup_spec())

    @property
    def setup_groups(self) -> tuple[str, ...]:
        """Names of the set-up groups of this model's layout, in vector order."""
        return self.layout.setup_groups

    @property
    def n_params(self) -> int:
        """Number of raw parameters."""
        return self.layout.n

    def right_jacobian(self, p: np.ndarray) -> np.ndarray:
        """Block-diagonal right Jacobians of exp6 (joints, ``pose`` groups) / exp3 (``rotation`` groups), (np, np).

        Identity at the nominal model (p = 0) and for ``point`` groups.
        """
        L = self.layout
        p = np.ascontiguousarray(p, float)
        Jr = np.eye(self.n_params)
        if not np.any(p):
            return Jr
        for a in range(0, 6 * L.n_joints, 6):  # joint k's block at 6k (pin.Jexp6 of the vector: its Motion's numbers)
            Jr[a:a + 6, a:a + 6] = pin.Jexp6(p[a:a + 6])
        for g, kind in L.setup:
            s = L.group_slice(g)
            if kind == "pose":
                Jr[s, s] = pin.Jexp6(p[s])
            elif kind == "rotation":
                Jr[s, s] = pin.Jexp3(p[s])
        return Jr

    def at_parameters(self, J: np.ndarray, p: np.ndarray) -> np.ndarray:
        """A Jacobian at the tangent coordinates times the right Jacobian at ``p``: ``J @ right_jacobian(p)``.

        At the nominal model (p = 0) the right Jacobian is the identity: the product is J's own numbers (a zero of
        either sign as +0.0, as the product gives it: ``J + 0.0``), made without the product (a pool of
        configurations at the nominal model costs a third less).

        Args:
            J: the Jacobian, (..., np) per parameter unit, finite.
            p: raw parameters.

        Returns:
            (..., np), a new array.
        """
        if not np.any(p):
            return J + 0.0
        return J @ self.right_jacobian(p)

    # ------------------------------------------------------------------ robot kinematics at p
    def init_kinematics(self, chain: Chain | None = None) -> None:
        """Set up the batched kinematics of ``robot`` (call once ``robot`` and ``layout`` are set).

        Args:
            chain: the robot's chain when it is already built (shared between models of one robot; only read);
                None: the one :meth:`~pin_kpi_oed.model.kinematics.Chain.shared` gives for the robot.
        """
        self._chain = Chain.shared(self.robot) if chain is None else chain
        self._nominal = [M.copy() for M in self._chain.placements]
        self._placements = list(self._nominal)
        self._p_applied: np.ndarray | None = None
        self._apply(np.zeros(self.n_params))

    def _apply(self, p: np.ndarray) -> None:
        """Perturb the joint placements M_j ← M_j · exp6(δ_j) (cached for the last ``p``)."""
        p = np.asarray(p, float)
        if p.shape != (self.n_params,):
            raise InputError(f"parameter vector must have {self.n_params} entries, got shape {p.shape}")
        if self._p_applied is not None and np.array_equal(p, self._p_applied):
            return
        self._placements = self._placements_at(p)
        self._p_applied = p.copy()

    def _placements_at(self, p: np.ndarray) -> list[pin.SE3]:
        """The joint placements M_j · exp6(δ_j) at raw parameters p (nothing cached)."""
        return [M * pin.exp6(p[self.layout.joint_slice(k)]) for k, M in enumerate(self._nominal)]

    @property
    def chain(self) -> Chain:
        """The robot's :class:`~pin_kpi_oed.model.kinematics.Chain` (nominal placements, joint axes and types)."""
        return self._chain

    @property
    def joint_axes(self) -> tuple[np.ndarray, np.ndarray]:
        """Local motion axes of the joints from Pinocchio: (linear (n, 3), angular (n, 3))."""
        return self._chain.lin, self._chain.ang

    def joint_placements(self, p: np.ndarray) -> list[pin.SE3]:
        """Joint placements M_j·exp6(δ_j) at parameters ``p`` (for URDF export)."""
        self._apply(p)
        return [M.copy() for M in self._placements]

    def pinocchio_model(self, p: np.ndarray) -> pin.Model:
        """A copy of the robot's Pinocchio model with the joint placements at parameters ``p``."""
        model = self.robot.model.copy()
        for j, M in zip(self.robot.joint_ids, self.joint_placements(p)):
            model.jointPlacements[j] = M
        return model

    def kinematics(self, p: np.ndarray, Q: np.ndarray, point_m: np.ndarray) -> Kinematics:
        """Forward kinematics of a tool point at parameters ``p`` for every configuration (base frame).

        Args:
            p: raw parameters.
            Q: configurations, (m, n) (rad for revolute, m for prismatic joints).
            point_m: the point in the tool frame (m).

        Returns:
            :class:`~pin_kpi_oed.model.kinematics.Kinematics` (``.p``, ``.R_tool``, ``.R_A``, ``.t_A``,
            ``.twist`` = Pinocchio's WORLD joint Jacobian), read-only: the last result is remembered and
            returned again for the same ``p``, ``Q`` and point (a least-squares step asks for the residuals,
            the Jacobian and the effects' columns at the same point).

        Raises:
            InputError: wrong parameter count or joint count.
        """
        key, Q, point_m = self._kin_key(p, Q, point_m)
        last = getattr(self, "_kin_last", None)  # one read: safe when two threads ask at once
        if last is not None and last[0] == key:
            return last[1]
        kin = self._chain.tool_point(Q, point_m, self._placements)
        for a in (kin.p, kin.R_tool, kin.R_A, kin.t_A, kin.twist):
            a.flags.writeable = False  # shared by the callers of the same p, Q and point
        self._kin_last = (key, kin)
        return kin

    def sensor_points(self, P: np.ndarray, Q: np.ndarray, point_m: np.ndarray) -> np.ndarray:
        """A tool point in the device frame at each of d parameter vectors (a Monte-Carlo's draws), without the
        Jacobians of :meth:`sensor_point`: the robots' kinematics in one batched pass
        (:meth:`~pin_kpi_oed.model.kinematics.Chain.tool_points`).

        Args:
            P: raw parameter vectors, (d, np).
            Q: configurations, (m, n) (rad / m).
            point_m: the point in the tool frame, (3,) m, or one per parameter vector, (d, 3) m.

        Returns:
            (d, m, 3) m: row i is ``sensor_point(P[i], Q, point_m[i]).Y`` to rounding (~1e-16 m).

        Raises:
            InputError: wrong parameter count or joint count.
        """
        P = np.atleast_2d(np.asarray(P, float))
        if P.ndim != 2 or P.shape[1] != self.n_params:
            raise InputError(f"parameter vectors must have {self.n_params} entries, got shape {P.shape}")
        d, n = P.shape[0], len(self._nominal)
        Rm, tm = np.empty((d, n, 3, 3)), np.empty((d, n, 3))
        RT, tT = np.empty((d, 3, 3)), np.empty((d, 3))
        for i, p in enumerate(P):
            for k, Mk in enumerate(self._placements_at(p)):
                Rm[i, k], tm[i, k] = Mk.rotation, Mk.translation
            T = self.sensor_pose(p)
            RT[i], tT[i] = T.rotation, T.translation
        X = self._chain.tool_points(np.atleast_2d(np.asarray(Q, float)), point_m, Rm, tm)
        return np.einsum("dab,dmb->dma", RT, X) + tT[:, None]

    def _kin_key(self, p: np.ndarray, Q: np.ndarray, point_m: np.ndarray) -> tuple[tuple, np.ndarray, np.ndarray]:
        """p applied, Q checked: (the key of :meth:`kinematics`'s remembered result, Q (m, n), the point (3,) or
        (m, 3) as floats)."""
        self._apply(p)
        Q = np.atleast_2d(np.asarray(Q, float))
        if Q.shape[1] != self.robot.nq:
            raise InputError(f"configurations must have {self.robot.nq} joint values, got {Q.shape[1]}")
        point_m = np.asarray(point_m, float)
        return (self._p_applied.tobytes(), Q.shape, Q.tobytes(), point_m.tobytes()), Q, point_m

    def _tool_pose(self, p: np.ndarray, Q: np.ndarray, point_m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The tool point and the tool rotation of :meth:`kinematics` (the same numbers), without the joint frames
        and twists unless they are remembered: (m, 3) m, (m, 3, 3)."""
        key, Q, point_m = self._kin_key(p, Q, point_m)
        last = getattr(self, "_kin_last", None)
        if last is not None and last[0] == key:
            return last[1].p, last[1].R_tool
        return self._chain.tool_pose(Q, point_m, self._placements)

    def sensor_point(self, p: np.ndarray, Q: np.ndarray, point_m: np.ndarray, offset_group: str | None = None,
                     with_dq: bool = False) -> SensorPoint:
        """A tool point in the device frame, Y = T(p)·x(p, q), and its Jacobian w.r.t. all raw parameters.

        Columns: joint placements ``R_T ∂x/∂δ_j`` (:func:`~pin_kpi_oed.model.kinematics.placement_jacobian`),
        the device frame ``R_T [I, −[x]×]`` (T = T0·exp6(δ)), and, if ``offset_group`` names a ``point``
        group that offsets this point in the tool frame, ``R_T R_tool``. With ``with_dq`` also ∂J/∂q
        (module docstring of :mod:`pin_kpi_oed.model.tracker`).

        Args:
            p: raw parameters.
            Q: configurations (m, n).
            point_m: the point in the tool frame (m), at ``p``.
            offset_group: the ``point`` group moving this point, or None.
            with_dq: also compute ∂J/∂q.

        Returns:
            The :class:`SensorPoint`.
        """
        L = self.layout
        kin = self.kinematics(p, Q, point_m)
        T = self.sensor_pose(p)
        RT = T.rotation.copy(order="K")  # pin's view of T (which the lazy ``Ydq`` outlives) copied, its layout kept
        frame = L.group_slice(self.frame_group)
        m, n = kin.p.shape[0], L.n_joints
        nj = 6 * n
        J = np.zeros((m, 3, self.n_params))
        blk = placement_jacobian(kin)  # (m, n, 3, 6)
        np.reshape(J[:, :, :nj], (m, 3, n, 6), copy=False)[...] = np.swapaxes(blk, 1, 2)  # J[.., 6k:6k+6] = blk[:, k]
        J[:, :, frame.start:frame.start + 3] = _EYE3
        J[:, :, frame.start + 3:frame.stop] = -skew(kin.p)
        offset = L.group_slice(offset_group) if offset_group is not None else None
        if offset is not None:
            J[:, :, offset] = kin.R_tool
        J = RT @ J
        Y = kin.p @ RT.T + T.translation
        if not with_dq:
            return SensorPoint(Y, J, None, kin, RT)
        w = kin.twist[:, 3:, :]  # (m, 3, n)
        pdot = point_velocity(kin)  # (m, 3, n)
        Ydq = np.einsum("ab,mbn->man", RT, pdot)
        dJ = np.zeros((m, 3, self.n_params, n))
        Wsk = skew(np.moveaxis(w, 1, 2))  # (m, n, 3, 3) [ω_k]×
        Pdsk = skew(np.moveaxis(pdot, 1, 2))  # (m, n, 3, 3) [ṗ_k]×
        # a view (no copy): D[:, a, j, c, k] = ∂J[:, a, 6j + c]/∂q_k
        D = np.reshape(dJ[:, :, :nj, :], (m, 3, n, 6, n), copy=False)
        (jb, kb), (ja, ka) = _joint_pairs(n)
        D[:, :, jb, :, kb] = np.swapaxes(Wsk[:, kb] @ blk[:, jb], 0, 1)  # k before j: the whole block rotates
        D[:, :, ja, 3:, ka] = -np.swapaxes(Pdsk[:, ka] @ kin.R_A[:, ja], 0, 1)  # k >= j: -[ṗ_k]× R_A(j)
        dJ[:, :, frame.start + 3:frame.stop, :] = -np.moveaxis(Pdsk, 1, 3)
        if offset is not None:
            dJ[:, :, offset, :] = np.moveaxis(Wsk @ kin.R_tool[:, None], 1, 3)
        dJ = (RT @ dJ.reshape(m, 3, -1)).reshape(dJ.shape)
        return SensorPoint(Y, J, dJ, kin, RT, Ydq)

    # ------------------------------------------------------------------ derived quantities
    def prediction_dq(self, p: np.ndarray, Q: np.ndarray) -> np.ndarray:
        """Ydq = ∂Y/∂q of the leading rows of h (as :meth:`jacobian_dq`), (m, k, n).

        Devices override it to skip the costly ∂²h/∂p∂q; the effects use it (``dQ`` of a joint-angle
        error moves the measurement by ``Ydq · dQ``).
        """
        return self.jacobian_dq(p, Q)[3]

    def weighted_jacobian(self, p: np.ndarray, Q: np.ndarray) -> np.ndarray:
        """F = Σ⁻¹ ∂h/∂p (eq. 24d), (m, nh, np)."""
        J = self.jacobian(p, Q)
        return J / self.sigma(p, Q)[:, :, None]

    def weighted_jacobian_dq(self, p: np.ndarray, Q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """F = Σ⁻¹ ∂h/∂p (eq. 24d) and ∂F/∂q, for a σ that does not depend on q (override otherwise).

        Returns:
            F: (m, nh, np); dF: (m, nh, np, n).
        """
        Y, J, dJ, _ = self.jacobian_dq(p, Q)
        S = self.sigma(p, Q, Y)
        return J / S[:, :, None], dJ / S[:, :, None, None]

    def identifiability_notes(self) -> list[str]:
        """Plain-words notes on the set-up for :func:`~pin_kpi_oed.oed.identifiability.analyse` (default none)."""
        return []
