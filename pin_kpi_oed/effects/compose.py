r"""Combining effects with a measurement model: ``Y = h(p, Q + ΣΔq) + ΣΔy`` and its derivatives."""

from __future__ import annotations

from typing import Any
from collections.abc import Sequence

import numpy as np

from pin_kpi_oed.effects.base import Effect
from pin_kpi_oed.errors import InputError

__all__ = ["sum_joint_offsets", "sum_tool_offsets", "predict_with_effects", "position_dq", "visible_rms",
           "size_effect", "effect_jacobian"]


def sum_joint_offsets(effects: Sequence[tuple[Effect, np.ndarray]], Q: np.ndarray, aux: Any = None
                      ) -> tuple[np.ndarray, list[np.ndarray]]:
    """Σ dQ of several (effect, θ) and the list of their dQ/dθ."""
    Q = np.atleast_2d(np.asarray(Q, float))
    dQ = np.zeros_like(Q)
    ders = []
    for eff, th in effects:
        d, D = eff.joint_offset(th, Q, aux)
        dQ += d
        ders.append(D)
    return dQ, ders


def sum_tool_offsets(effects: Sequence[tuple[Effect, np.ndarray]], Q: np.ndarray, aux: Any, model: Any,
                     p: np.ndarray) -> tuple[np.ndarray, list[np.ndarray]]:
    """Σ dY of several (effect, θ) and the list of their dY/dθ."""
    Q = np.atleast_2d(np.asarray(Q, float))
    dY = np.zeros((Q.shape[0], 3))
    ders = []
    for eff, th in effects:
        d, D = eff.tool_offset(th, Q, aux, model, p)
        dY += d
        ders.append(D)
    return dY, ders


def predict_with_effects(model: Any, p: np.ndarray, Q: np.ndarray, aux: Any,
                         effects: Sequence[tuple[Effect, np.ndarray]]) -> np.ndarray:
    """Y = model.predict(p, Q + Σ dQ) + Σ dY (positions; orientation rows untouched), (m, nh)."""
    Q = np.atleast_2d(np.asarray(Q, float))
    dQ, _ = sum_joint_offsets(effects, Q, aux)
    Y = model.predict(p, Q + dQ).copy()
    dY, _ = sum_tool_offsets(effects, Q, aux, model, p)
    Y[:, :3] += dY
    return Y


def position_dq(model: Any, p: np.ndarray, Q: np.ndarray) -> np.ndarray:
    """dy/dq of the reflector positions (tracker frame), (m, 3, n), without the costly d²h/dp dq.

    :meth:`~pin_kpi_oed.model.device.MeasurementModel.prediction_dq` of the model.
    """
    return model.prediction_dq(np.asarray(p, float), Q)


def visible_rms(model: Any, p: np.ndarray, Q: np.ndarray, aux: Any,
                effects: Sequence[tuple[Effect, np.ndarray]], base: np.ndarray | None = None) -> float:
    """Per-axis RMS (m) of the part of the effects' displacement the geometric parameters cannot absorb.

    The displacement ΔY = predict_with_effects − predict (positions) is projected out of the span
    of the position Jacobian columns ``base`` (default: all raw parameters) at ``p``; what is left
    is what a geometric calibration leaves in the residuals. Use it to size simulated effects
    relative to the measurement noise ("k × σ").
    """
    Q = np.atleast_2d(np.asarray(Q, float))
    p = np.asarray(p, float)
    D = (predict_with_effects(model, p, Q, aux, effects)[:, :3] - model.predict(p, Q)[:, :3]).ravel()
    J = model.jacobian(p, Q)[:, :3, :]
    if base is not None:
        J = J[:, :, np.asarray(base, int)]
    A = J.reshape(-1, J.shape[-1])
    n = np.linalg.norm(A, axis=0)
    A = A[:, n > 0] / n[n > 0]
    U, s, _ = np.linalg.svd(A, full_matrices=False)
    U = U[:, s > 1e-10 * s[0]]
    r = D - U @ (U.T @ D)
    return float(np.sqrt(np.mean(r ** 2)))


def size_effect(model: Any, p: np.ndarray, Q: np.ndarray, aux: Any, effect: Effect, theta: np.ndarray,
                target_rms_m: float, base: np.ndarray | None = None, iters: int = 3) -> np.ndarray:
    """Rescale ``theta`` so that the effect's visible part (:func:`visible_rms`) is ``target_rms_m`` per axis.

    θ is first shrunk into the linear regime (joint offsets ≤ 10 µrad, tool offsets ≤ 10 µm),
    then scaled by the ratio target / visible a few times (the displacement is linear in θ up
    to second-order kinematics).

    Raises:
        InputError: the effect moves nothing visible with these configurations.
    """
    Q = np.atleast_2d(np.asarray(Q, float))
    th = np.asarray(theta, float).copy()
    dQ, _ = effect.joint_offset(th, Q, aux)
    dY, _ = effect.tool_offset(th, Q, aux, model, p)
    big = max(float(np.abs(dQ).max(initial=0.0)), float(np.abs(dY).max(initial=0.0)))
    if big > 1e-5:
        th *= 1e-5 / big
    for _ in range(iters):
        vis = visible_rms(model, p, Q, aux, [(effect, th)], base)
        if not vis > 0:
            raise InputError(f"{effect.name}: moves nothing a geometric calibration cannot absorb at these "
                             "configurations; it cannot be sized")
        th = th * (float(target_rms_m) / vis)
    return th


def effect_jacobian(model: Any, p: np.ndarray, Q: np.ndarray, aux: Any,
                    effects: Sequence[tuple[Effect, np.ndarray]]) -> np.ndarray:
    """∂Y/∂θ of the positions for the stacked θ of ``effects``: Ydq(Q+ΣdQ)·∂dQ/∂θ + ∂dY/∂θ, (m, 3, Σk)."""
    Q = np.atleast_2d(np.asarray(Q, float))
    dQ, dq_ders = sum_joint_offsets(effects, Q, aux)
    Ydq = position_dq(model, p, Q + dQ) if any(np.any(D) for D in dq_ders) else None
    _, dy_ders = sum_tool_offsets(effects, Q, aux, model, p)
    blocks = []
    for Dq, Dy in zip(dq_ders, dy_ders):
        B = Dy.copy()
        if Ydq is not None and np.any(Dq):
            B += Ydq @ Dq
        blocks.append(B)
    if not blocks:
        return np.zeros((Q.shape[0], 3, 0))
    return np.concatenate(blocks, axis=2)
