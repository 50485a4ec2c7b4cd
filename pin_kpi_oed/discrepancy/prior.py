"""The discrepancy a design assumes before (or without) a fit of its own: the kernel over joint angles, the per-axis
scale S (m, robot base frame) and the white level w; the documented default before any measurement."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from pin_kpi_oed.discrepancy.kernel import JointKernel
from pin_kpi_oed.errors import InputError

__all__ = ["DiscrepancyPrior", "DEFAULT_DISCREPANCY", "default_discrepancy"]


#: The default discrepancy before any measurement (a stated assumption, not a fit): per-axis scale S, white level,
#: kernel amplitudes (share of S² in the whole-configuration and one-joint parts) and length scales (rad).
DEFAULT_DISCREPANCY = {"scale_m": 1e-4, "white_m": 1e-5, "product_share": 0.5, "length_scale_rad": 1.0,
                       "joint_length_scale_rad": 0.5}


@dataclass
class DiscrepancyPrior:
    """The discrepancy a design assumes: kernel, per-axis scale and white level.

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
        kernel = d.kernel if getattr(d, "kind", "white") != "white" else None
        return cls(kernel, np.asarray(d.scale_m, float), float(max(d.noise, 1e-12)), source)

    def cov(self, Qa: np.ndarray, Qb: np.ndarray | None = None) -> np.ndarray:
        """k(Qa, Qb) (normalised; zeros for a white discrepancy)."""
        Qa = np.atleast_2d(Qa)
        if self.kernel is None:
            return np.zeros((len(Qa), len(Qa) if Qb is None else len(np.atleast_2d(Qb))))
        return self.kernel(Qa, None if Qb is None else np.atleast_2d(Qb))

    def grad_x(self, X: np.ndarray, Y: np.ndarray) -> np.ndarray:
        """∂k(x_i, y_k)/∂x_i, (n, m, d) per rad (zeros for a white discrepancy)."""
        X, Y = np.atleast_2d(X), np.atleast_2d(Y)
        if self.kernel is None:
            return np.zeros((len(X), len(Y), X.shape[1]))
        return self.kernel.grad_x(X, Y)

    def prior_sigma_m(self) -> np.ndarray:
        """Prior σ of δ per axis (m): s_a sqrt(k(q, q))."""
        if self.kernel is None:
            return np.zeros(3)
        d = max(np.size(self.kernel.length_scale), np.size(self.kernel.joint_amplitude))
        kqq = float(self.kernel.diag(np.zeros((1, d)))[0])
        return self.scale_m * np.sqrt(kqq)

    def describe(self) -> str:
        """One line: source, σ of δ and of the white term per axis (µm), kernel hyper-parameters."""
        white = self.scale_m * np.sqrt(self.noise)
        words = (f"discrepancy ({self.source or 'given'}): delta sigma per axis "
                 f"{', '.join(f'{v * 1e6:.1f}' for v in self.prior_sigma_m())} um, white "
                 f"{', '.join(f'{v * 1e6:.1f}' for v in white)} um (base frame x, y, z)")
        if self.kernel is not None:
            kd = self.kernel.to_dict()
            words += (f"; kernel amplitude {kd['amplitude']:.3g}, length scales "
                      f"{', '.join(f'{v:.2g}' for v in kd['length_scale_rad'])} rad, joint amplitudes "
                      f"{', '.join(f'{v:.2g}' for v in kd['joint_amplitude'])}, joint length scales "
                      f"{', '.join(f'{v:.2g}' for v in kd['joint_length_scale_rad'])} rad")
        else:
            words += "; white only (no correlation between poses)"
        return words


def default_discrepancy(n_joints: int) -> DiscrepancyPrior:
    """The documented default before any measurement (:data:`DEFAULT_DISCREPANCY`).

    S = 0.1 mm per axis, white 10 µm per axis (w = (10 µm / 0.1 mm)² = 0.01), k(q, q) = 1 split half into the
    whole-configuration part (c² = 0.5, L_j = 1 rad) and half into one-joint parts (a_j² = 0.5/d, ℓ_j = 0.5 rad).
    A stated assumption of the order of the residuals after geometric calibration of industrial arms (the
    real UR10 data of this package leave 0.1-0.5 mm); pass ``--model`` with a fitted discrepancy for a real one.
    """
    D = DEFAULT_DISCREPANCY
    share = D["product_share"]
    k = JointKernel(np.sqrt(share), np.full(n_joints, D["length_scale_rad"]),
                    np.full(n_joints, np.sqrt((1 - share) / n_joints)), np.full(n_joints, D["joint_length_scale_rad"]))
    return DiscrepancyPrior(k, np.full(3, D["scale_m"]), (D["white_m"] / D["scale_m"]) ** 2,
                            "default: S = 0.1 mm, white 10 um per axis, length scales 1 rad (whole configuration) "
                            "and 0.5 rad (one joint); an assumption, not a fit")
