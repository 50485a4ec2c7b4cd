r"""Thermal expansion: every link length scales with 1 + α (T − T_ref), a first-order tool offset."""

from __future__ import annotations

from typing import Any

import numpy as np

from pin_kpi_oed.effects.base import Effect, check_aux_len
from pin_kpi_oed.errors import InputError
from pin_kpi_oed.model.robot import Robot

__all__ = ["ThermalExpansion"]


class ThermalExpansion(Effect):
    """Link lengths scale with 1 + α (T − T_ref); a first-order tool offset (needs ``temperature``)."""

    name = "thermal_expansion"
    unit = "1/K"
    plausible_max = 1e-3
    description = "link lengths (joint placements, tool-frame offset) scale with 1 + alpha (T - T_ref)"
    requires = ("temperature_c",)

    def __init__(self, robot: Robot, t_ref_c: float = 20.0):
        super().__init__(robot)
        if not np.isfinite(t_ref_c):
            raise InputError(f"{self.name}: T_ref must be finite, got {t_ref_c}")
        self.t_ref_c = float(t_ref_c)

    def options(self) -> dict:
        """Constructor keyword arguments that rebuild this effect (JSON-able; stored in the model file)."""
        return {"t_ref_c": float(self.t_ref_c)}

    def param_names(self, robot=None):
        return [f"{self.name}.alpha"]

    def check(self, aux):
        note = super().check(aux)
        if note is None and np.ptp(np.asarray(aux.temperature_c, float)) < 1e-6:
            return f"{self.name}: skipped, the temperature is constant ({aux.temperature_c[0]:g} °C): " \
                   "a constant scale is absorbed by the link lengths"
        return note

    def direction(self, Q: np.ndarray, model: Any, p: np.ndarray | None = None) -> np.ndarray:
        """ΔY per unit strain ε = α ΔT: Σ_j ∂y/∂δ_j,trans R_jᵀ t_j + ∂y/∂r R_toolᵀ t_tool, (m, 3) m."""
        if model is None:
            raise InputError(f"{self.name}: needs the measurement model (TrackerModel) to compute its offset")
        p = np.zeros(model.n_params) if p is None else np.asarray(p, float)
        J = model.jacobian(p, Q)[:, :3, :]  # (m, 3, np)
        L = model.layout
        u = np.zeros(model.n_params)
        rb = model.robot
        for k, jid in enumerate(rb.joint_ids):
            M = rb.model.jointPlacements[jid]
            s = L.joint_slice(k)
            u[s.start:s.start + 3] = M.rotation.T @ M.translation
        Mt = rb.model.frames[rb.tool_frame_id].placement
        u[L.reflector] = Mt.rotation.T @ Mt.translation
        return J @ u

    def tool_offset(self, theta, Q, aux=None, model=None, p=None):
        th = self._theta(theta)
        Q = np.atleast_2d(np.asarray(Q, float))
        note = self.check(aux)
        if aux is None or getattr(aux, "temperature_c", None) is None:
            raise InputError(note or f"{self.name}: the measurements have no 'temperature' column")
        check_aux_len(aux, Q.shape[0], self.name)
        dT = np.asarray(aux.temperature_c, float) - self.t_ref_c
        V = self.direction(Q, model, p) * dT[:, None]  # (m, 3)
        D = V[:, :, None]
        return D @ th, D

    def to_dict(self):
        d = super().to_dict()
        d["t_ref_c"] = self.t_ref_c
        return d
