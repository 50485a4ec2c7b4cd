r"""The working *region* of the discrepancy-aware KPI: the working configurations W plus seeded configurations near
them.

Why: the discrepancy δ(q) is a Gaussian process over the joint angles whose fitted length scales are short (on the
real UR10 about 0.05 rad on the shoulder-lift joint). Its covariance between two configurations 0.1 rad apart is
already small, so tr C_s at the five configurations of W says almost nothing about the TCP error a few tenths of a
radian away, where the robot also works: a design that minimises it places its poses at W and is no better than
random near the work. Taking the KPI over W plus configurations spread within a radius R of W (Euclidean in joint
space, the metric the learning curves score with) makes the design cover the region. On the real UR10
(``studies.learning_curves``, method ``kpi_gp_region``: W plus up to 100 rows within 0.5 rad) this form was 14–40 %
better than random at every size from 12 to 120 poses, where the W form was not.

:func:`working_region` is the one place the region is drawn: ``pin-kpi-oed design --work-radius/--work-samples``
samples it in the cell (feasible configurations only), the learning-curves study takes measured pool rows within R.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from collections.abc import Callable
from typing import Any

import numpy as np

from pin_kpi_oed.errors import InputError

__all__ = ["DEFAULT_WORK_RADIUS_RAD", "DEFAULT_WORK_SAMPLES", "WorkingRegion", "near_rows", "working_region",
           "region_in_cell", "default_region"]

#: Default radius (rad) of the working region of ``kpi_gp`` (the learning curves' scoring radius).
DEFAULT_WORK_RADIUS_RAD = 0.5
#: Default number of region configurations besides W.
DEFAULT_WORK_SAMPLES = 100


@dataclass
class WorkingRegion:
    """W plus the configurations of the region near it.

    Attributes:
        q_work: the working configurations W (t, n) rad.
        q_near: the region's other configurations (k, n) rad (k = 0 when R = 0 or none was kept).
        radius_rad: R; joints: the distance is Euclidean over the first ``joints`` joints (the others are held at
            the nearest W's values when sampled).
        samples: K requested; drawn: configurations drawn (sampled) or pool rows within R (pool).
        seed: the seed of every random choice; source: ``"sampled"``, ``"pool"`` or ``"none"`` (R = 0 or K = 0).
        indices: with a pool, the pool rows of ``q_near``; else None.
    """

    q_work: np.ndarray
    q_near: np.ndarray
    radius_rad: float
    joints: int
    samples: int
    drawn: int
    seed: int
    source: str
    indices: np.ndarray | None = field(default=None, repr=False)

    @property
    def kept(self) -> int:
        """Region configurations besides W."""
        return int(len(self.q_near))

    def configurations(self) -> np.ndarray:
        """The KPI's configurations: W, then the region's others ((t + k, n) rad)."""
        return np.vstack([self.q_work, self.q_near]) if self.kept else np.array(self.q_work, float)

    def describe(self) -> str:
        """One line: the region the KPI is taken over."""
        if self.source == "none":
            return f"working region: the {len(self.q_work)} working configurations alone (R = 0)"
        what = ("drawn uniformly within R, within the joint bounds and collision-free" if self.source == "sampled"
                else "pool rows within R")
        return (f"working region: the {len(self.q_work)} working configurations + {self.kept} of {self.drawn} "
                f"configurations {what} (R = {self.radius_rad:g} rad, Euclidean over joints 1-{self.joints}; "
                f"{self.samples} requested, seed {self.seed})")

    def to_dict(self) -> dict:
        """Plain JSON-able dict (rad)."""
        return {"radius_rad": self.radius_rad, "joints": self.joints, "samples_requested": self.samples,
                "drawn": self.drawn, "kept": self.kept, "seed": self.seed, "source": self.source,
                "metric": f"Euclidean over joints 1-{self.joints} (rad), to the nearest working configuration",
                "q_near_rad": np.asarray(self.q_near, float).tolist()}


def near_rows(Q: np.ndarray, q_work: np.ndarray, radius_rad: float, joints: int) -> np.ndarray:
    """Rows of Q within ``radius_rad`` (Euclidean, rad, first ``joints`` joints) of any working configuration."""
    d = np.linalg.norm(Q[:, None, :joints] - q_work[None, :, :joints], axis=2)
    return np.flatnonzero(d.min(axis=1) <= radius_rad)


def _sample_ball(q_work: np.ndarray, radius: float, k: int, joints: int, rng: np.random.Generator) -> np.ndarray:
    """k configurations uniform in the R-ball (first ``joints`` joints) around a uniformly chosen W; the other joints
    are the centre's."""
    centre = q_work[rng.integers(len(q_work), size=k)]
    u = rng.standard_normal((k, joints))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    r = radius * rng.random(k) ** (1.0 / joints)
    Q = np.array(centre, float)
    Q[:, :joints] += u * r[:, None]
    return Q


def working_region(q_work: np.ndarray, radius_rad: float = DEFAULT_WORK_RADIUS_RAD,
                   samples: int = DEFAULT_WORK_SAMPLES, seed: int = 0, *, pool: np.ndarray | None = None,
                   joints: int = 5, feasible: Callable[[np.ndarray], np.ndarray] | None = None) -> WorkingRegion:
    """The working region of the discrepancy-aware KPI (see the module docstring for why W alone is not enough).

    Without ``pool``: ``samples`` configurations drawn uniformly in the R-ball (Euclidean over the first ``joints``
    joints, the other joints at the centre's values) around a working configuration chosen uniformly, all seeded by
    ``seed``; those ``feasible`` rejects (joint bounds, collision, incidence in the cell) are dropped, so fewer than
    ``samples`` may be kept. With ``pool``: the pool rows within R (those ``feasible`` accepts), at most ``samples``
    of them chosen by ``numpy.random.default_rng([seed, 1])`` (the learning curves' choice).

    Args:
        q_work: W (t, n) rad.
        radius_rad: R (rad); 0 gives W alone.
        samples: K, the most configurations besides W.
        seed: seed of the draws.
        pool: candidate rows (N, n) rad, or None to sample.
        joints: joints of the distance (at most n).
        feasible: Q (k, n) -> bool mask (k,) of the configurations to keep, or None to keep all
            (:func:`region_in_cell`: joint bounds and collision).

    Raises:
        InputError: R < 0 or K < 0.
    """
    q_work = np.atleast_2d(np.asarray(q_work, float))
    radius_rad, samples, joints = float(radius_rad), int(samples), min(int(joints), q_work.shape[1])
    if not radius_rad >= 0.0 or samples < 0:
        raise InputError(f"working region: the radius must be >= 0 rad and the samples >= 0, got {radius_rad:g} rad "
                         f"and {samples}")
    empty = np.zeros((0, q_work.shape[1]))
    if radius_rad == 0.0 or samples == 0:
        return WorkingRegion(q_work, empty, radius_rad, joints, samples, 0, seed, "none")
    if pool is not None:
        pool = np.atleast_2d(np.asarray(pool, float))
        near = near_rows(pool, q_work, radius_rad, joints)
        drawn = int(near.size)
        if feasible is not None and near.size:
            near = near[np.asarray(feasible(pool[near]), bool)]
        if near.size > samples:
            near = np.sort(np.random.default_rng([seed, 1]).choice(near, samples, replace=False))
        return WorkingRegion(q_work, pool[near], radius_rad, joints, samples, drawn, seed, "pool", indices=near)
    Q = _sample_ball(q_work, radius_rad, samples, joints, np.random.default_rng([seed, 4]))
    if feasible is not None:
        Q = Q[np.asarray(feasible(Q), bool)]
    return WorkingRegion(q_work, Q, radius_rad, joints, samples, samples, seed, "sampled")


def region_in_cell(cell: Any, radius_rad: float = DEFAULT_WORK_RADIUS_RAD, samples: int = DEFAULT_WORK_SAMPLES,
                   seed: int = 0, joints: int = 5) -> WorkingRegion:
    """The working region of ``kpi_gp`` in a cell (``design --work-radius/--work-samples``): ``samples`` seeded
    configurations within ``radius_rad`` of the cell's working configurations, those outside the joint bounds or in
    collision (the cell's independent check) dropped; R = 0 or K = 0 leaves W alone. The tracker's line of sight and
    incidence are not required: the region is where the robot works, not where it is measured (the working
    configurations themselves usually face away from the tracker). Pass it to the design problem
    (:class:`~pin_kpi_oed.design.problem_options.ProblemOptions` ``region``).

    Args:
        cell: the :class:`~pin_kpi_oed.cell.cell_model.Cell` (untightened: where the robot works).
        radius_rad: R (rad); samples: K; seed: the draws' seed; joints: joints of the distance.

    Raises:
        InputError: R < 0 or K < 0 (named ``work_radius_rad`` / ``work_samples``).
    """
    from pin_kpi_oed.cell.feasibility import FeasibilityChecker

    if not float(radius_rad) >= 0.0 or int(samples) < 0:
        raise InputError(f"work_radius_rad ({float(radius_rad):g}) and work_samples ({int(samples)}) must be >= 0")
    checker = FeasibilityChecker(cell)

    def reachable(Q: np.ndarray) -> np.ndarray:
        rep = checker.check(Q)
        return rep.within_bounds & rep.collision_free

    return working_region(cell.q_work, radius_rad, samples, seed, joints=joints, feasible=reachable)


def default_region(cell: Any, criteria: Any, radius_rad: float | None = None, samples: int | None = None,
                   seed: int = 0) -> WorkingRegion | None:
    """The working region a design draws (:func:`region_in_cell`, the design's seed): R = ``radius_rad``, default
    :data:`DEFAULT_WORK_RADIUS_RAD` when ``kpi_gp`` is among ``criteria`` and 0 otherwise; K = ``samples``, default
    :data:`DEFAULT_WORK_SAMPLES`. None when R = 0 or K = 0 (the working configurations alone).

    Raises:
        InputError: R < 0 or K < 0 (named ``work_radius_rad`` / ``work_samples``).
    """
    radius = float(radius_rad) if radius_rad is not None else (
        DEFAULT_WORK_RADIUS_RAD if "kpi_gp" in criteria else 0.0)
    k = DEFAULT_WORK_SAMPLES if samples is None else int(samples)
    if not radius >= 0 or k < 0:
        raise InputError(f"work_radius_rad ({radius:g}) and work_samples ({k}) must be >= 0")
    if radius == 0 or k == 0:
        return None
    return region_in_cell(cell, radius, k, seed)
