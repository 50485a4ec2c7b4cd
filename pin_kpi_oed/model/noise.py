"""Measurement noise of a laser tracker (paper eq. 6 weights).

Per-axis σ (m) in the tracker frame, or distance dependent σ = a + b·range (how trackers specify
their maximum permissible error); a 6-DoF probe adds an orientation σ (rad). The weighted
residuals are f₁ = Σ⁻¹(η − h) (eq. 6).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pin_kpi_oed.errors import InputError


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
        self.sigma_xyz_m = (float(s[0]), float(s[1]), float(s[2]))
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
    def from_dict(cls, d: dict) -> NoiseModel:
        """Inverse of :meth:`to_dict`."""
        return cls(sigma_xyz_m=tuple(d.get("sigma_xyz_m", (1e-6,) * 3)), range_a_m=d.get("range_a_m"),
                   range_b=float(d.get("range_b", 0.0)), sigma_rot_rad=float(d.get("sigma_rot_rad", 1e-4)))
