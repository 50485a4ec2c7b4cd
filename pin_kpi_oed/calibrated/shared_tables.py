"""Tables of what a calibrated model computed lately, so that a monitor's checks do not compute it again.

The robot's kinematics, shared between a calibrated model's station models: every station measures the same
robot — its joint placements (the ``joint_p`` part of the raw parameter vector) are the model's, only the set-up
(tracker pose, reflector, probe) differs. A check asks many station models of one model (the model's own station,
the set-up registered on the rows, the same with another σ factor) for the same forward kinematics at the rows, at
their registration configurations and at the working configurations, and a registration's least squares asks again
at every step although only the tracker pose moves. :class:`StationTracker` is a
:class:`~pin_kpi_oed.model.tracker.TrackerModel` whose kinematics are looked up in one small table shared by every
station model, keyed by what they depend on: the robot, the joint placements' parameters, the configurations and the
tool point. A hit returns the very arrays the first call computed (read-only): every prediction and Jacobian is
bit for bit the one computed without the table. Its chain (joint axes and types, nominal placements: read-only) is
built once per robot, not once per station model (:meth:`~pin_kpi_oed.model.kinematics.Chain.shared`, as for every
measurement model).

What the model says about one configuration, kept per configuration: the discrepancy's posterior mean and variance
at a configuration, and whether it lies outside the training's joint-space coverage, depend on that configuration
alone. A monitor asks for them at every row when it predicts the row, then again at every check of the growing
window the row is in (its registration, its σ factor, the rows' joint covariance, the model's own set-up, each on
the same rows), and at the same working configurations at every check. :func:`discrepancy_at` and
:func:`outside_coverage` answer from a table of the configurations asked for lately (one per discrepancy or
coverage object) and compute only the rows not in it, in one batch — inside :func:`row_tables` (the monitor's
replay), where the model's discrepancy and coverage stay as they are; outside it they ask the objects every time.
A row's mean and variance come from the batch they were first computed in: the Gaussian process evaluates each row
on its own (its kernel row, its triangular solve), so another batch changes them by rounding only (relative 1e-16).
The posterior covariance between a window's rows (:func:`posterior_covariance_at`) is k(Q, Q) − VᵀV with V the
kernel's columns at the rows whitened by the training rows' Cholesky factor: each row's column, computed once, serves
every window it is in (the factor formed once per discrepancy, as the process forms its own, and checked against
the process's covariance on its first rows). Inside :func:`row_tables` too, :func:`remembered` keeps a few results
(a station's Jacobian at the registration rows, asked by the registration's σ factor, the rows' covariance and the
TCP σ alike) under a key naming all they depend on.
"""

from __future__ import annotations

import threading
from collections import OrderedDict
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any

import numpy as np
import scipy.linalg as sla

from pin_kpi_oed.discrepancy.gp import JITTER
from pin_kpi_oed.model.kinematics import Kinematics
from pin_kpi_oed.model.tracker import TrackerModel

__all__ = ["StationTracker", "KINEMATICS_TABLE_SIZE", "KINEMATICS_TABLE_ROWS", "clear_shared_kinematics",
           "discrepancy_at", "outside_coverage", "posterior_covariance_at", "remembered", "row_tables",
           "ROW_TABLE_SIZE", "COLUMN_TABLE_SIZE", "RESULT_TABLE_SIZE", "RESULT_TABLE_NUMBERS"]

#: Entries the shared table keeps (the least recently used leaves first): a check asks for a handful of
#: (configurations, tool point) pairs.
KINEMATICS_TABLE_SIZE = 32
#: The most configurations the table holds over all its entries (about 1 kB each); a larger batch is not kept.
KINEMATICS_TABLE_ROWS = 20000

_TABLE: OrderedDict[tuple, tuple[Any, Kinematics]] = OrderedDict()
_LOCK = threading.Lock()        # the tables' bookkeeping (the kinematics themselves are computed outside it)


def clear_shared_kinematics() -> None:
    """Empty the shared table (frees its arrays; results are unchanged either way)."""
    _TABLE.clear()


class StationTracker(TrackerModel):
    """A :class:`~pin_kpi_oed.model.tracker.TrackerModel` whose robot kinematics come from the table shared by all
    station models of its robot (module docstring); its chain is the one every measurement model of the robot shares
    (:meth:`~pin_kpi_oed.model.kinematics.Chain.shared`); everything else is the tracker model's."""

    def at_nests(self, nest: np.ndarray | None) -> StationTracker:
        """:meth:`TrackerModel.at_nests`: the same model measuring each row at its nest, a station tracker too.

        Args:
            nest: the nest of every row, (m,) int; None: every row at nest 0.

        Returns:
            The :class:`StationTracker` (its kinematics from the same table).

        Raises:
            InputError: a nest index that is not one of the model's nests.
        """
        out = super().at_nests(nest)
        assert isinstance(out, StationTracker)
        return out

    def kinematics(self, p: np.ndarray, Q: np.ndarray, point_m: np.ndarray) -> Kinematics:
        """:meth:`TrackerModel.kinematics`, looked up first in the shared table.

        Args:
            p: raw parameters (only the joint placements' part enters the kinematics).
            Q: configurations (m, n) rad; point_m: the tool point in the tool frame (m).

        Returns:
            The read-only :class:`~pin_kpi_oed.model.kinematics.Kinematics`.

        Raises:
            InputError: wrong parameter or joint count (as :class:`TrackerModel`).
        """
        p = np.asarray(p, float)
        Qa = np.asarray(Q, float)
        L = self.layout
        if p.shape != (L.n,) or Qa.ndim != 2:
            return super().kinematics(p, Q, point_m)
        joints = np.concatenate([p[L.joint_slice(j)] for j in range(L.n_joints)])
        key = (id(self.robot), joints.tobytes(), Qa.shape, Qa.tobytes(), np.asarray(point_m, float).tobytes())
        with _LOCK:
            hit = _TABLE.get(key)
            if hit is not None and hit[0] is self.robot:
                _TABLE.move_to_end(key)
                return hit[1]
        kin = super().kinematics(p, Qa, point_m)
        if len(Qa) <= KINEMATICS_TABLE_ROWS:
            with _LOCK:
                _TABLE[key] = (self.robot, kin)
                while len(_TABLE) > KINEMATICS_TABLE_SIZE or sum(k[2][0] for k in _TABLE) > KINEMATICS_TABLE_ROWS:
                    _TABLE.popitem(last=False)
        return kin


#: Configurations each table keeps (the least recently asked leave first).
ROW_TABLE_SIZE = 4096
#: Whitened kernel columns :func:`posterior_covariance_at` keeps (a column holds the training rows' count of
#: numbers; a monitor's window holds at most a few hundred rows).
COLUMN_TABLE_SIZE = 600
#: Results :func:`remembered` keeps (the least recently asked leave first), and the most numbers they hold together
#: (8 MB); a larger result is not kept.
RESULT_TABLE_SIZE = 64
RESULT_TABLE_NUMBERS = 1_000_000

_TABLES: OrderedDict[int, tuple[Any, OrderedDict]] = OrderedDict()
_RESULTS: OrderedDict[tuple, np.ndarray] = OrderedDict()
_FACTORS: dict[int, tuple[Any, np.ndarray | None]] = {}
_ACTIVE = [0]


@contextmanager
def row_tables() -> Iterator[None]:
    """Keep the tables while inside (nested uses share them); emptied when the outermost use ends. Inside, the
    discrepancy and coverage objects asked must not change."""
    _ACTIVE[0] += 1
    try:
        yield
    finally:
        _ACTIVE[0] -= 1
        if not _ACTIVE[0]:
            _TABLES.clear()
            _RESULTS.clear()
            _FACTORS.clear()


def remembered(key: tuple, compute: Callable[[], np.ndarray]) -> np.ndarray:
    """``compute()``; inside :func:`row_tables`, a copy of the result kept under ``key`` (hashable, naming everything
    the result depends on), computed on the first ask.

    Args:
        key: the result's key; compute: computes the array.

    Returns:
        The array (a copy the caller may change).
    """
    if not _ACTIVE[0]:
        return compute()
    hit = _RESULTS.get(key)
    if hit is None:
        hit = np.asarray(compute())
        if hit.size > RESULT_TABLE_NUMBERS // 4:
            return hit
        _RESULTS[key] = hit
        while len(_RESULTS) > RESULT_TABLE_SIZE or sum(a.size for a in _RESULTS.values()) > RESULT_TABLE_NUMBERS:
            _RESULTS.popitem(last=False)
    _RESULTS.move_to_end(key)
    return hit.copy()


def _table(owner: Any) -> OrderedDict:
    """The table of ``owner`` (a discrepancy or a coverage), made on first use; the tables of the four objects asked
    last are kept."""
    entry = _TABLES.get(id(owner))
    if entry is None or entry[0] is not owner:
        entry = (owner, OrderedDict())
        _TABLES[id(owner)] = entry
        while len(_TABLES) > 4:
            _TABLES.popitem(last=False)
    _TABLES.move_to_end(id(owner))
    return entry[1]


def _rows(owner: Any, Q: np.ndarray, need: Any, compute: Any, size: int = ROW_TABLE_SIZE) -> list:
    """Each row's entry of ``owner``'s table; the rows without one, or whose entry fails ``need``, computed by
    ``compute(rows, old_entries)`` in one batch."""
    table = _table(owner)
    keys = [row.tobytes() for row in Q]
    got = [table.get(k) for k in keys]
    miss = [i for i, e in enumerate(got) if e is None or not need(e)]
    if miss:
        new = compute(np.asarray(miss), [got[i] for i in miss])
        for i, e in zip(miss, new):
            got[i] = table[keys[i]] = e
    for k in keys:
        table.move_to_end(k)
    while len(table) > size:
        table.popitem(last=False)
    return got


def discrepancy_at(d: Any, Q: np.ndarray, return_var: bool = True) -> tuple[np.ndarray, np.ndarray | None]:
    """:meth:`~pin_kpi_oed.discrepancy.gp.Discrepancy.predict` of the discrepancy ``d`` at configurations Q (m, n)
    rad, the rows asked for lately taken from ``d``'s table (module docstring).

    Returns:
        (mean (m, 3) m base frame, its variance per axis (m, 3) m² or None without ``return_var``).
    """
    Q = np.ascontiguousarray(np.atleast_2d(np.asarray(Q, float)))
    if len(Q) == 0 or not _ACTIVE[0]:
        return d.predict(Q, return_var)

    def compute(rows: np.ndarray, old: list) -> list:
        mean, var = d.predict(Q[rows], return_var)
        return [(mean[k] if e is None else e[0], None if var is None else var[k]) for k, e in enumerate(old)]

    got = _rows(d, Q, lambda e: e[1] is not None or not return_var, compute)
    mean = np.array([e[0] for e in got])
    return mean, (np.array([e[1] for e in got]) if return_var else None)


def outside_coverage(cov: Any, Q: np.ndarray) -> np.ndarray:
    """:meth:`~pin_kpi_oed.discrepancy.coverage.JointCoverage.extrapolation` of the coverage ``cov`` at
    configurations Q (m, n) rad: (m,) bool, the rows asked for lately taken from ``cov``'s table."""
    Q = np.ascontiguousarray(np.atleast_2d(np.asarray(Q, float)))
    if len(Q) == 0 or not _ACTIVE[0]:
        return np.asarray(cov.extrapolation(Q), bool)
    got = _rows(cov, Q, lambda e: True, lambda rows, old: list(np.asarray(cov.extrapolation(Q[rows]), bool)))
    return np.array(got, bool)


def posterior_covariance_at(d: Any, Q: np.ndarray) -> np.ndarray:
    """:meth:`~pin_kpi_oed.discrepancy.gp.Discrepancy.posterior_covariance` of the discrepancy ``d`` between the
    configurations Q (m, n) rad, (m, m) in normalised units; inside :func:`row_tables`, for an exact Gaussian
    process, from each row's whitened kernel column computed once (module docstring)."""
    Q = np.ascontiguousarray(np.atleast_2d(np.asarray(Q, float)))
    if not _ACTIVE[0] or getattr(d, "kind", None) != "exact" or len(Q) == 0:
        return d.posterior_covariance(Q)
    entry = _FACTORS.get(id(d))
    if entry is None or entry[0] is not d:
        entry = _FACTORS[id(d)] = (d, _checked_factor(d, Q))
    L = entry[1]
    if L is None:
        return d.posterior_covariance(Q)

    def compute(rows: np.ndarray, old: list) -> list:
        V = sla.solve_triangular(L, d.kernel(Q[rows], d.Z).T, lower=True, check_finite=False)
        return list(V.T)

    V = np.array(_rows(L, Q, lambda e: True, compute, COLUMN_TABLE_SIZE)).T
    return d.kernel(Q) - V.T @ V


def _checked_factor(d: Any, Q: np.ndarray) -> np.ndarray | None:
    """The lower Cholesky factor of K(Z, Z) + (w + jitter) I of an exact process, formed as the process forms its
    own; None (the process asked every time) when the covariance it gives at Q differs from the process's."""
    K = d.kernel(d.Z) + (d.noise + JITTER) * np.eye(len(d.Z))
    L = sla.cholesky(K, lower=True, check_finite=False)
    V = sla.solve_triangular(L, d.kernel(Q, d.Z).T, lower=True, check_finite=False)
    ours, theirs = d.kernel(Q) - V.T @ V, d.posterior_covariance(Q)
    same = np.allclose(ours, theirs, rtol=1e-8, atol=1e-10 * float(np.max(np.abs(theirs))))
    return L if same else None
