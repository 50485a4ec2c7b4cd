r"""Joint-space coverage: where a calibration's predictions rest on measured configurations and where they extrapolate.

One measure for every command that predicts (``predict``, ``compensate``, ``register``'s advice, the fit-quality gate,
the diagnosis' extrapolation cause): a configuration q is *covered* when its nearest training configuration, in the
wrapped joint-space distance

.. math::  d(q, q') = \Bigl(\sum_j \operatorname{wrap}(q_j - q'_j)^2\Bigr)^{1/2},
           \qquad \operatorname{wrap}(x) = ((x + π) \bmod 2π) - π,

lies within the coverage radius ρ, **and** each of its angles lies within ρ_j of a training angle of the same
joint. Only *periodic* joints are wrapped — revolute joints whose limits span 2π or more, where q and q + 2π are
the same link pose (:attr:`~pin_kpi_oed.model.robot.Robot.periodic_joints`); a prismatic joint (a linear track)
enters in metres as it is, and a revolute joint with a narrower range linearly (the ends of its range are far apart,
not neighbours). The *combination* of the angles counts, not each joint alone: a row whose every angle was measured, but
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
measured set is not.

The training configurations kept for the measure are a seeded subset of at most :data:`MAX_STORED` distinct rows.
"""

from __future__ import annotations

import threading
from collections import OrderedDict
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from scipy.spatial import cKDTree

from pin_kpi_oed.discrepancy.arrays import decode_array, encode_array

__all__ = ["JointCoverage", "RADIUS_FACTOR", "MIN_RADIUS_RAD", "MAX_STORED", "joint_space_box", "joint_distance"]

#: κ: the coverage radius is this times the 95 % quantile of the training's nearest-neighbour distances.
RADIUS_FACTOR = 1.25
#: ρ_min: smallest coverage radius (rad), for dense training sets.
MIN_RADIUS_RAD = 0.05
#: Most training configurations the measure keeps (a seeded subset above it).
MAX_STORED = 2000
_TWO_PI = 2.0 * np.pi
#: Trainings whose coverage is remembered (:class:`_CoverageCache`).
REMEMBERED = 4


class _CoverageCache:
    """The coverage of the last few trainings, keyed by their configurations' bytes, the seed and the periodic joints:
    a diagnosis fits its training rows once per candidate effect, each fit states the same coverage (and the
    discrepancy's fit states it again), which costs a k-d tree and a sort per joint each time. Each call returns a
    fresh :class:`JointCoverage` with its own arrays, equal to the one computed (every number the same)."""

    def __init__(self, size: int = REMEMBERED) -> None:
        self.size = int(size)
        self.entries: OrderedDict[bytes, JointCoverage] = OrderedDict()
        self.lock = threading.Lock()

    @staticmethod
    def key(Q: np.ndarray, seed: int, periodic: np.ndarray | None) -> bytes:
        """What the coverage depends on: Q's shape and values, the seed, the periodic joints."""
        per = b"N" if periodic is None else b"P" + np.asarray(periodic, bool).tobytes()
        return np.asarray(Q.shape, np.int64).tobytes() + int(seed).to_bytes(8, "little", signed=True) + per + \
            np.ascontiguousarray(Q).tobytes()

    def get(self, key: bytes) -> JointCoverage | None:
        """A copy of the remembered coverage for ``key``, or None."""
        with self.lock:
            got = self.entries.get(key)
            if got is not None:
                self.entries.move_to_end(key)
        return None if got is None else got.copy()

    def put(self, key: bytes, cov: JointCoverage) -> None:
        """Remember a copy of ``cov`` under ``key`` (the oldest forgotten beyond :attr:`size`)."""
        with self.lock:
            self.entries[key] = cov.copy()
            self.entries.move_to_end(key)
            while len(self.entries) > self.size:
                self.entries.popitem(last=False)


def joint_space_box(Q: np.ndarray, periodic: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Configurations Q (n, d) in the box of a periodic k-d tree, and the box's size per joint.

    Args:
        Q: joint values (n, d), rad / m.
        periodic: (d,) bool, joints compared modulo 2π; None: every joint (configurations of unknown joints).

    Returns:
        (W, box): W = Q with the periodic columns wrapped into [0, 2π); box (d,) = 2π for a periodic joint, 0 (no
        wrap) for the others — ``cKDTree(W, boxsize=box)`` measures the distance of the module docstring.
    """
    Q = np.atleast_2d(np.asarray(Q, float))
    per = np.ones(Q.shape[1], bool) if periodic is None else np.asarray(periodic, bool).reshape(-1)
    if per.shape != (Q.shape[1],):
        raise ValueError(f"periodic mask of {per.size} joints for configurations of {Q.shape[1]}")
    W = Q.copy()
    W[:, per] = np.mod(W[:, per], _TWO_PI)
    W[:, per] = np.where(W[:, per] >= _TWO_PI, 0.0, W[:, per])
    return W, np.where(per, _TWO_PI, 0.0)


def joint_distance(Z: np.ndarray, Q: np.ndarray, periodic: np.ndarray | None = None) -> np.ndarray:
    """(m, d) distance (rad / m; wrapped for a ``periodic`` joint, None: every joint) of each value of Q (m, d) to
    the nearest value of the same joint in Z (k, d); inf when Z is empty."""
    Q = np.atleast_2d(np.asarray(Q, float))
    Z = np.asarray(Z, float).reshape(-1, Q.shape[1])
    if not len(Z):
        return np.full(Q.shape, np.inf)
    WZ, box = joint_space_box(Z, periodic)
    WQ, _ = joint_space_box(Q, periodic)
    out = np.empty(Q.shape)
    for j in range(Q.shape[1]):
        a = np.sort(WZ[:, j])
        ext = np.r_[a - _TWO_PI, a, a + _TWO_PI] if box[j] > 0 else np.r_[a[0], a]
        i = np.clip(np.searchsorted(ext, WQ[:, j]), 1, ext.size - 1)
        out[:, j] = np.minimum(np.abs(WQ[:, j] - ext[i - 1]), np.abs(WQ[:, j] - ext[i]))
    return out


def _nearest_gap(a: np.ndarray, periodic: bool) -> np.ndarray:
    """Distance of each of the sorted distinct values ``a`` to its nearest other one (wrapped when periodic)."""
    if periodic:
        gap = np.diff(np.r_[a, a[0] + _TWO_PI])  # to the next angle, wrapped
        return np.minimum(gap, np.roll(gap, 1))
    gap = np.diff(a)
    return np.minimum(np.r_[np.inf, gap], np.r_[gap, np.inf])


@dataclass
class JointCoverage:
    """The training configurations of a calibration and its coverage radius (see the module docstring).

    Attributes:
        Z: training configurations kept (k, d) rad.
        radius_rad: ρ, the joint-space coverage radius (rad).
        joint_radius_rad: ρ_j, the per-joint coverage radius (d,) rad.
        n_rows: training rows the measure was built from.
        periodic: (d,) bool, the joints compared modulo 2π (:func:`joint_space_box`); None: every joint.
    """

    Z: np.ndarray
    radius_rad: float
    joint_radius_rad: np.ndarray
    n_rows: int = 0
    periodic: np.ndarray | None = None

    @classmethod
    def from_training(cls, Q: np.ndarray, seed: int = 0, periodic: np.ndarray | None = None) -> JointCoverage:
        """The coverage of training configurations Q (n, d) rad / m (seeded subset above :data:`MAX_STORED` rows).

        Args:
            Q: training configurations (n, d).
            seed: seed of the subset.
            periodic: (d,) bool, the joints compared modulo 2π (the robot's
                :attr:`~pin_kpi_oed.model.robot.Robot.periodic_joints`); None: every joint.
        """
        Q = np.atleast_2d(np.asarray(Q, float))
        key = _COVERAGES.key(Q, seed, periodic)
        known = _COVERAGES.get(key)
        if known is not None:
            return known
        out = cls._measured(Q, seed, periodic)
        _COVERAGES.put(key, out)
        return out

    @classmethod
    def _measured(cls, Q: np.ndarray, seed: int, periodic: np.ndarray | None) -> JointCoverage:
        """:meth:`from_training` computed (Q already (n, d) float)."""
        W, box = joint_space_box(Q, periodic)
        per = box > 0
        _, first = np.unique(np.round(W, 9), axis=0, return_index=True)
        U = Q[np.sort(first)]
        if len(U) > MAX_STORED:
            U = U[np.sort(np.random.default_rng(seed).permutation(len(U))[:MAX_STORED])]
        radius, per_joint = MIN_RADIUS_RAD, np.full(U.shape[1], MIN_RADIUS_RAD)
        if len(U) >= 2:
            WU, _ = joint_space_box(U, per)
            d, _ = cKDTree(WU, boxsize=box).query(WU, k=2)
            radius = max(MIN_RADIUS_RAD, RADIUS_FACTOR * float(np.quantile(d[:, 1], 0.95)))
            for j in range(U.shape[1]):
                a = np.unique(np.round(WU[:, j], 9))
                if a.size >= 2:
                    nn = _nearest_gap(a, bool(per[j]))
                    per_joint[j] = max(MIN_RADIUS_RAD, RADIUS_FACTOR * float(np.quantile(nn, 0.95)))
        return cls(U, float(radius), per_joint, int(len(Q)), per.copy())

    def copy(self) -> JointCoverage:
        """The same coverage with its own arrays."""
        return replace(self, Z=self.Z.copy(), joint_radius_rad=self.joint_radius_rad.copy(),
                       periodic=None if self.periodic is None else self.periodic.copy())

    def distance(self, Q: np.ndarray) -> np.ndarray:
        """(m,) joint-space distance (rad / m) of each configuration to its nearest training configuration."""
        Q = np.atleast_2d(np.asarray(Q, float))
        if len(self.Z) == 0:
            return np.full(len(Q), np.inf)
        WZ, box = joint_space_box(self.Z, self.periodic)
        d, _ = cKDTree(WZ, boxsize=box).query(joint_space_box(Q, self.periodic)[0], k=1)
        return np.asarray(d, float)

    def joint_distance(self, Q: np.ndarray) -> np.ndarray:
        """(m, d) distance (rad / m) of each value to the nearest training value of the same joint
        (:func:`joint_distance`)."""
        return joint_distance(self.Z, Q, self.periodic)

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
        out = {"measure": "joint_space_nearest/1", "radius_rad": float(self.radius_rad),
               "joint_radius_rad": [float(v) for v in self.joint_radius_rad], "n_rows": int(self.n_rows),
               "Z_rad": encode_array(self.Z)}
        if self.periodic is not None:
            out["periodic"] = [bool(v) for v in self.periodic]
        return out

    @classmethod
    def from_dict(cls, d: Any, n_joints: int, where: str, periodic: np.ndarray | None = None) -> JointCoverage:
        """Inverse of :meth:`to_dict`; ``periodic`` (the robot's) for a block written without its ``periodic``
        field (None: every joint, as such blocks were built).

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
        per = d.get("periodic", None if periodic is None else [bool(v) for v in np.asarray(periodic, bool)])
        if per is not None and (not isinstance(per, list) or len(per) != n_joints
                                or not all(isinstance(v, bool) for v in per)):
            raise ValueError(f"{where}.periodic: must be {n_joints} true/false values, got {per!r}")
        return cls(Z, float(r), rj, int(n), None if per is None else np.array(per, bool))


#: One shared cache: the trainings of the last few fits (:meth:`JointCoverage.from_training`).
_COVERAGES = _CoverageCache()
