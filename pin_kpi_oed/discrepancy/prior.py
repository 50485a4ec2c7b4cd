"""The discrepancy a design assumes before (or without) a fit of its own: the kernel over joint angles, the per-axis
scale S (m, robot base frame) and the white level w (a :class:`~pin_kpi_oed.discrepancy.base.DiscrepancyModel`; the
documented defaults per robot class: :mod:`pin_kpi_oed.oed.discrepancy_defaults`)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from pin_kpi_oed.discrepancy.base import DiscrepancyModel
from pin_kpi_oed.errors import InputError

__all__ = ["DiscrepancyPrior"]


@dataclass
class DiscrepancyPrior(DiscrepancyModel):
    """The discrepancy a design assumes: kernel, per-axis scale and white level (the
    :class:`~pin_kpi_oed.discrepancy.base.DiscrepancyModel` vocabulary: ``covariance``, ``delta_sigma_m``, ...).

    Attributes:
        kernel: the :class:`JointKernel` (normalised), or None for a white discrepancy (k ≡ 0).
        scale_m: per-axis scale S (3,) m, robot base frame.
        noise: white level w (normalised; the white σ per axis is s_a·sqrt(w), m).
        source: where it comes from (printed in the design output).
    """

    kernel: Any
    scale_m: np.ndarray
    noise: float
    source: str = ""

    def __post_init__(self) -> None:
        self.scale_m = np.broadcast_to(np.asarray(self.scale_m, float), (3,)).copy()
        if not (np.all(np.isfinite(self.scale_m)) and np.all(self.scale_m > 0)):
            raise InputError(f"discrepancy scale must be 3 positive numbers (m), got {self.scale_m}")
        if not (np.isfinite(self.noise) and self.noise > 0):
            raise InputError(f"discrepancy white level must be > 0, got {self.noise}")

    @classmethod
    def from_discrepancy(cls, d: Any, source: str = "") -> DiscrepancyPrior:
        """The prior (kernel, S, w) of a fitted :class:`~pin_kpi_oed.discrepancy.gp.Discrepancy` (its data not used:
        a new calibration re-fits the robot)."""
        return cls(d.kernel, np.asarray(d.scale_m, float), float(max(d.noise, 1e-12)), source)

    def describe(self) -> str:
        """One line: source, σ of δ and of the white term per axis (µm), kernel hyper-parameters."""
        words = (f"discrepancy ({self.source or 'given'}): delta sigma per axis "
                 f"{', '.join(f'{v * 1e6:.1f}' for v in self.delta_sigma_m)} um, white "
                 f"{', '.join(f'{v * 1e6:.1f}' for v in self.white_sigma_m)} um (base frame x, y, z)")
        if self.kernel is not None:
            kd = self.kernel.to_dict()
            units = kd.get("joint_units")

            def lengths(key: str) -> str:
                if units is None:
                    return f"{', '.join(f'{v:.2g}' for v in kd[key + '_rad'])} rad"
                return ", ".join(f"{v:.2g} {u}" for v, u in zip(kd[key], units))
            words += (f"; kernel amplitude {kd['amplitude']:.3g}, length scales {lengths('length_scale')}, joint "
                      f"amplitudes {', '.join(f'{v:.2g}' for v in kd['joint_amplitude'])}, joint length scales "
                      f"{lengths('joint_length_scale')}")
        else:
            words += "; white only (no correlation between poses)"
        return words
