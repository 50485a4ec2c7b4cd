"""The paper's 90 notional arms: KR 15/2-like arms whose upper arm a2 (``lambda``, 0.650 ... 1.100 m) and forearm d4
(``mu``, 0.600 ... 1.000 m) vary on a 10 x 9 grid, every other value that of :data:`~pin_kpi_oed.model.kuka.KR15`.
Lengths in m."""

from __future__ import annotations

import math

import numpy as np

from pin_kpi_oed.errors import InputError
from pin_kpi_oed.model.kuka import KR15, KukaGeometry

__all__ = ["notional_arm", "notional_arms"]


def notional_arm(lambda_m: float, mu_m: float) -> KukaGeometry:
    """KR 15/2-like notional arm with upper arm ``a2 = lambda_m`` and forearm ``d4 = mu_m``.

    All other values (d1, a1, a3, d6, joint limits, capsule radii, mass) are
    those of :data:`KR15`.

    Args:
        lambda_m: Upper-arm length a2 ("segment two"), metres, > 0.
        mu_m: Forearm length d4 ("segment four"), metres, > 0.

    Returns:
        The arm geometry, named ``notional_a2_<mm>_d4_<mm>`` (4-digit millimetres,
        e.g. ``notional_a2_0650_d4_0600``).

    Raises:
        InputError: If a length is not finite and positive.
    """
    for label, value in (("lambda_m", lambda_m), ("mu_m", mu_m)):
        if not (isinstance(value, (int, float, np.floating)) and math.isfinite(value) and value > 0.0):
            raise InputError(f"notional_arm: {label} = {value!r} must be a finite length > 0 (m)")
    name = f"notional_a2_{round(lambda_m * 1000.0):04d}_d4_{round(mu_m * 1000.0):04d}"
    return KukaGeometry(
        name=name,
        d1=KR15.d1,
        a1=KR15.a1,
        a2=float(lambda_m),
        a3=KR15.a3,
        d4=float(mu_m),
        d6=KR15.d6,
        q_lower=KR15.q_lower,
        q_upper=KR15.q_upper,
        capsule_radii=dict(KR15.capsule_radii),
        total_mass_kg=KR15.total_mass_kg,
        velocity_limits=KR15.velocity_limits,
        effort_limits=KR15.effort_limits,
    )


def notional_arms() -> list[KukaGeometry]:
    """The paper's 90 notional arms.

    Returns:
        ``notional_arm(lambda, mu)`` for lambda in {0.650, 0.700, ..., 1.100} m
        (10 values, outer loop) and mu in {0.600, 0.650, ..., 1.000} m
        (9 values, inner loop); the first arm has the KR 15/2 geometry.
    """
    lambdas = [(650 + 50 * i) / 1000.0 for i in range(10)]
    mus = [(600 + 50 * j) / 1000.0 for j in range(9)]
    return [notional_arm(lam, mu) for lam in lambdas for mu in mus]
