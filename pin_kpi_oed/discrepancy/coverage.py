r"""Joint-space coverage: where a calibration's predictions rest on measured configurations and where they extrapolate.

One measure for every command that predicts (``predict``, ``compensate``, ``register``'s advice, the fit-quality gate,
the diagnosis' extrapolation cause): a configuration q is *covered* when its nearest training configuration, in the
wrapped joint-space distance

.. math::  d(q, q') = \Bigl(\sum_j \operatorname{wrap}(q_j - q'_j)^2\Bigr)^{1/2},
           \qquad \operatorname{wrap}(x) = ((x + π) \bmod 2π) - π,

lies within the coverage radius ρ, **and** each of its angles lies within ρ_j of a training angle of the same
joint. The *combination* of the angles counts, not each joint alone: a row whose every angle was measured, but
never together (shoulder of one pose, elbow of another), is far from every training configuration and is flagged;
the per-joint test flags a row beyond the measured range of one joint even where the training poses are sparse
in joint space as a whole.

The radius is set by the training configurations themselves: with d_i the distance of training configuration i to
its nearest other one (duplicates removed),

.. math::  ρ = \max\bigl(ρ_{\min},\; κ\,\mathrm{quantile}_{0.95}(d_i)\bigr),

κ = :data:`RADIUS_FACTOR`, ρ_min = :data:`MIN_RADIUS_RAD`, and ρ_j alike from the training angles of joint j
alone (the distance of each to its nearest other one, wrapped). A new configuration drawn from the same distribution as
the training is as far from its nearest training configuration as those are from each other, so about 95 % of such
rows are covered whatever the number of poses or the joint count; a configuration beyond the spacing of the
measured set is not. Angles are wrapped (revolute joints); a prismatic joint's metres enter the distance as they are.

The training configurations kept for the measure are a seeded subset of at most :data:`MAX_STORED` distinct rows.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.spatial import cKDTree

from pin_kpi_oed.discrepancy.arrays import decode_array, encode_array

__all__ = ["JointCoverage", "RADIUS_FACTOR", "MIN_RADIUS_RAD", "MAX_STORED"]

#: κ: the coverage radius is this times the 95 % quantile of the training's nearest-neighbour distances.
RADIUS_FACTOR = 1.25
#: ρ_min: smallest coverage radius (rad), for dense training sets.
MIN_RADIUS_RAD = 0.05
#: Most training configurations the measure keeps (a seeded subset above it).
MAX_STORED = 2000
_TWO_PI = 2.0 * np.pi


def _wrapped(Q: np.ndarray) -> np.ndarray:
    """Angles in [0, 2π) (the periodic box of the k-d tree)."""
    W = np.mod(np.asarray(Q, float), _TWO_PI)
    W[W >= _TWO_PI] = 0.0
    return W


@dataclass
class JointCoverage:
    """The training configurations of a calibration and its coverage radius (see the module docstring).

    Attributes:
        Z: training configurations kept (k, d) rad.
        radius_rad: ρ, the joint-space coverage radius (rad).
        joint_radius_rad: ρ_j, the per-joint coverage radius (d,) rad.
        n_rows: training rows the measure was built from.
    """

    Z: np.ndarray
    radius_rad: float
    joint_radius_rad: np.ndarray
    n_rows: int = 0

    @classmethod
    def from_training(cls, Q: np.ndarray, seed: int = 0) -> JointCoverage:
        """The coverage of training configurations Q (n, d) rad (seeded subset above :data:`MAX_STORED` rows)."""
        Q = np.atleast_2d(np.asarray(Q, float))
        W = _wrapped(Q)
        _, first = np.unique(np.round(W, 9), axis=0, return_index=True)
        U = Q[np.sort(first)]
        if len(U) > MAX_STORED:
            U = U[np.sort(np.random.default_rng(seed).permutation(len(U))[:MAX_STORED])]
        radius, per_joint = MIN_RADIUS_RAD, np.full(U.shape[1], MIN_RADIUS_RAD)
        if len(U) >= 2:
            d, _ = cKDTree(_wrapped(U), boxsize=_TWO_PI).query(_wrapped(U), k=2)
            radius = max(MIN_RADIUS_RAD, RADIUS_FACTOR * float(np.quantile(d[:, 1], 0.95)))
            for j in range(U.shape[1]):
                a = np.unique(np.round(_wrapped(U[:, j]), 9))
                if a.size >= 2:
                    gap = np.diff(np.r_[a, a[0] + _TWO_PI])          # to the next angle, wrapped
                    nn = np.minimum(gap, np.roll(gap, 1))             # to the nearest other angle
                    per_joint[j] = max(MIN_RADIUS_RAD, RADIUS_FACTOR * float(np.quantile(nn, 0.95)))
        return cls(U, float(radius), per_joint, int(len(Q)))

    def distance(self, Q: np.ndarray) -> np.ndarray:
        """(m,) wrapped joint-space distance (rad) of each configuration to its nearest training configuration."""
        Q = np.atleast_2d(np.asarray(Q, float))
        if len(self.Z) == 0:
            return np.full(len(Q), np.inf)
        d, _ = cKDTree(_wrapped(self.Z), boxsize=_TWO_PI).query(_wrapped(Q), k=1)
        return np.asarray(d, float)

    def joint_distance(self, Q: np.ndarray) -> np.ndarray:
        """(m, d) wrapped distance (rad) of each angle to the nearest training angle of the same joint."""
        Q = np.atleast_2d(np.asarray(Q, float))
        out = np.empty(Q.shape)
        for j in range(Q.shape[1]):
            a = np.sort(_wrapped(self.Z[:, j]))
            ext = np.r_[a - _TWO_PI, a, a + _TWO_PI]
            t = _wrapped(Q[:, j])
            i = np.clip(np.searchsorted(ext, t), 1, ext.size - 1)
            out[:, j] = np.minimum(np.abs(t - ext[i - 1]), np.abs(t - ext[i]))
        return out

    def covered(self, Q: np.ndarray) -> np.ndarray:
        """(m,) bool: configurations within ρ of a training configuration and each angle within ρ_j of a
        training angle of its joint."""
        if len(self.Z) == 0:
            return np.zeros(len(np.atleast_2d(Q)), bool)
        return (self.distance(Q) <= self.radius_rad) & np.all(self.joint_distance(Q) <= self.joint_radius_rad, axis=1)

    def extrapolation(self, Q: np.ndarray) -> np.ndarray:
        """(m,) bool: configurations outside the coverage (the negation of :meth:`covered`)."""
        return ~self.covered(Q)

    def share_covered(self, Q: np.ndarray) -> float:
        """Share of the configurations Q that are covered."""
        return float(np.mean(self.covered(Q))) if len(np.atleast_2d(Q)) else float("nan")

    def to_dict(self) -> dict:
        """Plain data for a model file (configurations as base64 float64)."""
        return {"measure": "joint_space_nearest/1", "radius_rad": float(self.radius_rad),
                "joint_radius_rad": [float(v) for v in self.joint_radius_rad], "n_rows": int(self.n_rows),
                "Z_rad": encode_array(self.Z)}

    @classmethod
    def from_dict(cls, d: Any, n_joints: int, where: str) -> JointCoverage:
        """Inverse of :meth:`to_dict`.

        Raises:
            ValueError: a damaged block (the field named with ``where``).
        """
        if not isinstance(d, dict) or d.get("measure") != "joint_space_nearest/1":
            raise ValueError(f"{where}: must be an object with measure 'joint_space_nearest/1'")
        r = d.get("radius_rad")
        if isinstance(r, bool) or not isinstance(r, (int, float)) or not np.isfinite(r) or r <= 0:
            raise ValueError(f"{where}.radius_rad: must be a positive number (rad), got {r!r}")
        Z = decode_array(d.get("Z_rad"), f"{where}.Z_rad", (None, n_joints))
        try:
            rj = np.asarray(d.get("joint_radius_rad"), float)
        except (TypeError, ValueError):
            rj = np.zeros(0)
        if rj.shape != (n_joints,) or not np.all(np.isfinite(rj)) or np.any(rj <= 0):
            raise ValueError(f"{where}.joint_radius_rad: must be {n_joints} positive numbers (rad)")
        n = d.get("n_rows", len(Z))
        if isinstance(n, bool) or not isinstance(n, int) or n < 0:
            raise ValueError(f"{where}.n_rows: must be a non-negative integer, got {n!r}")
        return cls(Z, float(r), rj, int(n))
