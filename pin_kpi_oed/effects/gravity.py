"""Gravity-driven effects: gravity torque of the arm (+ payload), joint compliance and backlash."""

from __future__ import annotations

import abc
import hashlib
from typing import Any
from collections.abc import Sequence

import numpy as np
import pinocchio as pin

from pin_kpi_oed.effects.base import Effect, check_aux_len
from pin_kpi_oed.errors import InputError
from pin_kpi_oed.model.robot import Robot

__all__ = ["LOADED_REL_TOL", "gravity_torque", "loaded_joints", "GravityEffect", "JointCompliance", "Backlash"]

#: Relative threshold (of the largest joint torque) above which a joint counts as gravity-loaded.
LOADED_REL_TOL = 1e-2


def gravity_torque(robot: Robot, Q: np.ndarray, payload_kg: np.ndarray | float | None = None) -> np.ndarray:
    """Gravity torque τ_g(q) of every configuration, (m, n) N·m (revolute) / N (prismatic).

    Pinocchio's generalized gravity from the URDF inertias, plus a point mass of
    ``payload_kg`` at the tool-frame origin: τ = −J_toolᵀ m g.

    Args:
        robot: the arm (``robot.model.gravity`` is used, default (0, 0, −9.81) m/s²).
        Q: configurations, (m, n) rad.
        payload_kg: payload per configuration (m,) or a scalar (kg); None = no payload.
    """
    Q = np.atleast_2d(np.asarray(Q, float))
    model, data = robot.model, robot.model.createData()
    m = Q.shape[0]
    tau = np.empty((m, robot.nq))
    for i in range(m):
        tau[i] = pin.computeGeneralizedGravity(model, data, Q[i])
    if payload_kg is not None:
        pl = np.broadcast_to(np.asarray(payload_kg, float), (m,))
        g = np.asarray(model.gravity.linear, float)
        fid = robot.tool_frame_id
        for k in np.flatnonzero(pl != 0):
            i = int(k)
            J = pin.computeFrameJacobian(model, data, Q[i], fid, pin.ReferenceFrame.LOCAL_WORLD_ALIGNED)
            tau[i] -= J[:3].T @ (pl[i] * g)
    return tau


def loaded_joints(robot: Robot, rel_tol: float = LOADED_REL_TOL, n: int = 200, seed: int = 12345) -> np.ndarray:
    """Mask of joints whose gravity torque (URDF masses + 1 kg at the tool) reaches rel_tol of the largest."""
    Q = robot.random_q(np.random.default_rng(seed), n)
    t = np.abs(gravity_torque(robot, Q)).max(axis=0) + np.abs(gravity_torque(robot, Q, 1.0)).max(axis=0)
    if not np.any(t > 0):
        return np.zeros(robot.nq, bool)
    return t > rel_tol * t.max()


class GravityEffect(Effect):
    """Shared machinery of the gravity-driven effects (compliance, backlash): τ_g with a small cache."""

    def __init__(self, robot: Robot, joints: Sequence[str] | str | None = None):
        super().__init__(robot)
        if joints is None:
            mask = loaded_joints(robot)
        elif isinstance(joints, str) and joints == "all":
            mask = np.ones(robot.nq, bool)
        else:
            unknown = [j for j in joints if j not in robot.joint_names]
            if unknown:
                raise InputError(f"{self.name}: unknown joint(s) {unknown} (joints: {', '.join(robot.joint_names)})")
            mask = np.array([j in set(joints) for j in robot.joint_names])
        self.joints = np.flatnonzero(mask)
        self._cache: dict[bytes, np.ndarray] = {}

    def options(self) -> dict:
        """Constructor keyword arguments that rebuild this effect (JSON-able; stored in the model file)."""
        return {"joints": [self.robot.joint_names[int(j)] for j in self.joints]}

    def param_names(self, robot: Robot | None = None) -> list[str]:
        return [f"{self.name}.{self.robot.joint_names[j]}" for j in self.joints]

    def torque(self, Q: np.ndarray, aux: Any = None) -> np.ndarray:
        """Gravity torque (m, n) at Q, with the payload column of ``aux`` if present (cached)."""
        Q = np.atleast_2d(np.asarray(Q, float))
        check_aux_len(aux, Q.shape[0], self.name)
        pl = None if aux is None else getattr(aux, "payload_kg", None)
        h = hashlib.blake2b(Q.tobytes(), digest_size=16)
        h.update(str(Q.shape).encode())
        if pl is not None:
            h.update(np.asarray(pl, float).tobytes())
        key = h.digest()
        if key not in self._cache:
            if len(self._cache) > 8:
                self._cache.clear()
            self._cache[key] = gravity_torque(self.robot, Q, pl)
        return self._cache[key]

    @abc.abstractmethod
    def _basis(self, tau: np.ndarray) -> np.ndarray:
        """Per-joint basis B(τ_g) (m, n) of Δq_j = θ_j · B_j (compliance: τ; backlash: sign τ)."""

    def joint_offset(self, theta, Q, aux=None):
        Q = np.atleast_2d(np.asarray(Q, float))
        return self._per_joint_offset(theta, self._basis(self.torque(Q, aux)))


class JointCompliance(GravityEffect):
    """Joint elasticity: Δq_j = c_j · τ_g,j(q) (c in rad/(N·m)), gravity from the URDF inertias + payload."""

    name = "joint_compliance"
    unit = "rad/(N*m)"
    plausible_max = 1e-4
    description = "joint deflection = compliance x gravity torque (URDF inertias + payload column)"

    def _basis(self, tau):
        return tau


class Backlash(GravityEffect):
    """Backlash / lost motion: Δq_j = β_j · sign(τ_g,j(q)) (β in rad), flips with the gravity torque's sign."""

    name = "backlash"
    unit = "rad"
    plausible_max = 1e-2
    description = "joint offset flipping with the sign of the joint's gravity torque"

    def _basis(self, tau):
        return np.sign(tau)
