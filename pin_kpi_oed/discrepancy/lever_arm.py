r"""The lever arm a reflector-learnt discrepancy leaves out at a TCP away from the reflector.

The discrepancy δ(q) is learnt from reflector positions: it is the error of a point that moves with the reflector.
An unmodelled rotation δθ(q) of the flange moves a TCP at d = TCP − reflector (tool frame) by δθ × d, which no
reflector position shows (one reflector cannot observe the flange's rotation). For an isotropic rotation error of
σ_θ per axis,

.. math::  \mathbb{E}\,|\delta\theta \times d|^2 = 2\,\sigma_\theta^2\,|d|^2,

so the 3-D RMS at the TCP grows by sqrt(2)·σ_θ·|d| in quadrature. Neither ``design``'s honest σ nor
``compensate``'s σ includes it; both say so when |d| ≥ :data:`LEVER_ARM_NOTE_M`. A reflector at (or near) the TCP
avoids it.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["LEVER_ARM_NOTE_M", "LEVER_ARM_EXAMPLE_RAD", "lever_arm_m", "lever_arm_sigma_m", "lever_arm_line"]

#: TCP-reflector distance (m) from which the outputs state the lever arm.
LEVER_ARM_NOTE_M = 1e-3
#: Flange rotation (rad per axis) the lever-arm line quotes as an example.
LEVER_ARM_EXAMPLE_RAD = 1e-4


def lever_arm_m(tcp_m: np.ndarray, reflector_m: np.ndarray) -> float:
    """|d| (m): the TCP's distance from the reflector, both in the tool frame (m)."""
    return float(np.linalg.norm(np.asarray(tcp_m, float) - np.asarray(reflector_m, float)))


def lever_arm_sigma_m(distance_m: float, sigma_rad: float = LEVER_ARM_EXAMPLE_RAD) -> float:
    """sqrt(2)·σ_θ·|d| (m): the 3-D RMS an isotropic flange rotation of ``sigma_rad`` per axis adds at distance
    ``distance_m`` (m) from the reflector."""
    return math.sqrt(2.0) * float(sigma_rad) * float(distance_m)


def lever_arm_line(distance_m: float, what: str = "the sigma with the discrepancy") -> str:
    """One line: ``what`` is learnt at the reflector and leaves out the flange rotation at a TCP ``distance_m`` away."""
    add = lever_arm_sigma_m(distance_m)
    return (f"lever arm: the discrepancy is learnt at the reflector and the TCP is {distance_m * 1e3:.1f} mm from it; "
            f"{what} leaves out the flange's unmodelled rotation, which one reflector cannot see "
            f"({LEVER_ARM_EXAMPLE_RAD * 1e3:g} mrad per axis adds {add * 1e6:.1f} um in quadrature at the TCP); "
            f"a reflector at the TCP avoids it")
