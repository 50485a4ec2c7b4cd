"""The measurement container: ``MeasurementSet`` (configurations, tracker readings, optional columns; SI units).

Column names and file format: :mod:`pin_kpi_oed.data.measurements`.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any
from collections.abc import Sequence

import numpy as np

from pin_kpi_oed.data.tool_header import ToolSpec, resolve_tool
from pin_kpi_oed.errors import InputError

__all__ = ["POSITION_COLUMNS", "ROTVEC_COLUMNS", "SIGMA_COLUMN", "SIGMA_AXIS_COLUMNS", "TEMPERATURE_COLUMN",
           "PAYLOAD_COLUMN", "TIME_COLUMN", "RESERVED_COLUMNS", "STATION_COLUMN", "NEST_COLUMN", "MeasurementSet",
           "concat_measurements"]

POSITION_COLUMNS: tuple[str, str, str] = ("x", "y", "z")
ROTVEC_COLUMNS: tuple[str, str, str] = ("rx", "ry", "rz")
SIGMA_COLUMN = "sigma"
SIGMA_AXIS_COLUMNS: tuple[str, str, str] = ("sigma_x", "sigma_y", "sigma_z")
TEMPERATURE_COLUMN = "temperature"
PAYLOAD_COLUMN = "payload"
TIME_COLUMN = "time"
STATION_COLUMN = "station"
#: the column of the reflector nest a row was measured at (an integer; kept among the extra columns,
#: :mod:`pin_kpi_oed.model.nests`)
NEST_COLUMN = "nest"
RESERVED_COLUMNS: frozenset[str] = frozenset(
    POSITION_COLUMNS
    + ROTVEC_COLUMNS
    + SIGMA_AXIS_COLUMNS
    + (SIGMA_COLUMN, TEMPERATURE_COLUMN, PAYLOAD_COLUMN, TIME_COLUMN, STATION_COLUMN)
)


def _opt_array(value: Any, shape: tuple[int, ...], name: str) -> np.ndarray | None:
    if value is None:
        return None
    arr = np.asarray(value, dtype=float)
    if arr.shape != shape:
        raise InputError(f"MeasurementSet field '{name}' has shape {arr.shape}, expected {shape}")
    return arr


@dataclass
class MeasurementSet:
    """A set of ``m`` tracker measurements of an ``n``-joint robot (SI units).

    Attributes:
        joint_names: Names of the actuated joints, one per column of ``q``.
        q: Joint positions, shape (m, n), rad (m for prismatic joints).
        position_m: Measured reflector positions in the tracker frame, (m, 3), m.
        rotvec_rad: Measured probe orientations in the tracker frame as rotation
            vectors, (m, 3), rad; ``None`` for a 3-DoF reflector.
        sigma_m: Per-axis standard deviation of the positions, (m, 3), m; or ``None``.
        temperature_c: Temperature per measurement, (m,), °C; or ``None``.
        payload_kg: Payload per measurement, (m,), kg; or ``None``.
        time_s: Time stamp per measurement, (m,), s; or ``None``.
        source: Path of the file the set was read from ("" if built in memory).
        extra: Further numeric columns, name -> (m,) array (units as in the file).
        station: Label of the measurement set-up (tracker placement) of every row,
            (m,) text; ``None`` = one station for all rows.
        tool: The tool the rows were measured with (robot, tool frame, reflector, TCP, working
            configurations; :mod:`pin_kpi_oed.data.tool_header`), from the file's header; ``None``: unknown.

    Raises:
        InputError: At construction, if an array has the wrong shape, the
            joint names are not unique / do not match the columns of ``q``, or a
            station label is empty.
    """

    joint_names: list[str]
    q: np.ndarray
    position_m: np.ndarray
    rotvec_rad: np.ndarray | None = None
    sigma_m: np.ndarray | None = None
    temperature_c: np.ndarray | None = None
    payload_kg: np.ndarray | None = None
    time_s: np.ndarray | None = None
    source: str = ""
    extra: dict[str, np.ndarray] = field(default_factory=dict)
    station: np.ndarray | None = None
    tool: ToolSpec | None = None

    def __post_init__(self) -> None:
        self.joint_names = [str(n) for n in self.joint_names]
        if len(set(self.joint_names)) != len(self.joint_names):
            dup = sorted({n for n in self.joint_names if self.joint_names.count(n) > 1})
            raise InputError(f"MeasurementSet: duplicate joint names {dup}")
        self.q = np.asarray(self.q, dtype=float)
        if self.q.ndim != 2 or self.q.shape[1] != len(self.joint_names):
            raise InputError(
                f"MeasurementSet field 'q' has shape {self.q.shape}, expected (m, {len(self.joint_names)}) "
                f"for joints {self.joint_names}"
            )
        m = self.q.shape[0]
        self.position_m = np.asarray(self.position_m, dtype=float)
        if self.position_m.shape != (m, 3):
            raise InputError(
                f"MeasurementSet field 'position_m' has shape {self.position_m.shape}, expected {(m, 3)}"
            )
        self.rotvec_rad = _opt_array(self.rotvec_rad, (m, 3), "rotvec_rad")
        self.sigma_m = _opt_array(self.sigma_m, (m, 3), "sigma_m")
        self.temperature_c = _opt_array(self.temperature_c, (m,), "temperature_c")
        self.payload_kg = _opt_array(self.payload_kg, (m,), "payload_kg")
        self.time_s = _opt_array(self.time_s, (m,), "time_s")
        self.source = str(self.source)
        extra: dict[str, np.ndarray] = {}
        for k, v in dict(self.extra).items():
            if v is None:
                raise InputError(f"MeasurementSet field extra[{k!r}] is None, expected an array of shape {(m,)}")
            extra[str(k)] = _opt_array(v, (m,), f"extra[{k!r}]")
        self.extra = extra
        if self.station is not None:
            labels = np.array([str(v).strip() for v in np.asarray(self.station, dtype=object).reshape(-1)],
                              dtype=object)
            if labels.shape != (m,):
                raise InputError(f"MeasurementSet field 'station' has shape {labels.shape}, expected {(m,)}")
            empty = np.flatnonzero(labels == "")
            if empty.size:
                raise InputError(f"{self.source or 'MeasurementSet'}: column 'station', row {int(empty[0]) + 1}: "
                                 "empty station label")
            self.station = labels

    def __len__(self) -> int:
        """Number of measurements ``m``."""
        return int(self.q.shape[0])

    @property
    def has_position(self) -> bool:
        """Whether every row has a measured position (False for files read without ``x, y, z``)."""
        return bool(np.all(np.isfinite(self.position_m)))

    def station_labels(self, default: str = "") -> list[str]:
        """Station labels in order of first appearance (``[default]`` without a station column)."""
        if self.station is None:
            return [default]
        return list(dict.fromkeys(self.station.tolist()))

    def station_rows(self, default: str = "") -> dict[str, np.ndarray]:
        """Row indices of every station, label -> (k,) int, in order of first appearance."""
        if self.station is None:
            return {default: np.arange(len(self))}
        return {lab: np.flatnonzero(self.station == lab) for lab in self.station_labels()}

    def with_station(self, label: str) -> MeasurementSet:
        """A copy whose rows all belong to station ``label``."""
        return dataclasses.replace(self, station=np.full(len(self), str(label), dtype=object))

    def subset(self, idx: Sequence[int] | np.ndarray | slice) -> MeasurementSet:
        """Measurements selected by ``idx``, as a new set (arrays are copies).

        Args:
            idx: Integer indices (any order, repeats allowed), a boolean mask of
                length ``len(self)``, or a slice.

        Returns:
            A :class:`MeasurementSet` with the selected rows, same joints/source.

        Raises:
            InputError: If an index is out of range or a mask has the wrong length.
        """
        m = len(self)
        if not isinstance(idx, slice):
            arr = np.asarray(idx)
            if arr.dtype == bool:
                if arr.shape != (m,):
                    raise InputError(f"subset: boolean mask has shape {arr.shape}, expected ({m},)")
                idx = np.flatnonzero(arr)
            else:
                if arr.size and not np.issubdtype(arr.dtype, np.integer):
                    raise InputError(f"subset: indices must be integers, got dtype {arr.dtype}")
                idx = arr.astype(int).reshape(-1)
                bad = idx[(idx < -m) | (idx >= m)]
                if bad.size:
                    raise InputError(f"subset: index {int(bad[0])} out of range for {m} measurements")

        def take(a: np.ndarray | None) -> np.ndarray | None:
            return None if a is None else np.array(a[idx], dtype=float)

        return MeasurementSet(
            joint_names=list(self.joint_names),
            q=take(self.q),
            position_m=take(self.position_m),
            rotvec_rad=take(self.rotvec_rad),
            sigma_m=take(self.sigma_m),
            temperature_c=take(self.temperature_c),
            payload_kg=take(self.payload_kg),
            time_s=take(self.time_s),
            source=self.source,
            extra={k: take(v) for k, v in self.extra.items()},
            station=None if self.station is None else self.station[idx].copy(),
            tool=self.tool,
        )

    def split(self, fraction: float, seed: int | None = 0) -> tuple[MeasurementSet, MeasurementSet]:
        """Random train/test split (reproducible for a given seed).

        Rows are drawn with ``numpy.random.default_rng(seed).permutation``; each
        part keeps the file order of its rows.

        Args:
            fraction: Share of the measurements that go to the training set,
                0 < fraction < 1; the training set gets ``round(fraction * m)`` rows.
            seed: Seed of :func:`numpy.random.default_rng`.

        Returns:
            ``(train, test)``: disjoint sets that together hold every row once.

        Raises:
            InputError: If ``fraction`` is outside (0, 1) or a part would be empty.
        """
        m = len(self)
        if not (isinstance(fraction, (int, float)) and 0.0 < float(fraction) < 1.0):
            raise InputError(f"split: fraction must be in (0, 1), got {fraction!r}")
        n_train = int(round(float(fraction) * m))
        if n_train < 1 or n_train > m - 1:
            raise InputError(
                f"split: fraction {fraction} of {m} measurements leaves an empty part "
                f"({n_train} train, {m - n_train} test)"
            )
        perm = np.random.default_rng(seed).permutation(m)
        return self.subset(np.sort(perm[:n_train])), self.subset(np.sort(perm[n_train:]))

    def kfold(self, k: int, seed: int | None = 0) -> list[tuple[MeasurementSet, MeasurementSet]]:
        """K-fold cross-validation splits (reproducible for a given seed).

        The rows are shuffled once with ``numpy.random.default_rng(seed)`` and
        cut into ``k`` folds whose sizes differ by at most one; fold ``i`` is the
        test set of the ``i``-th pair. Each part keeps the file order of its rows.

        Args:
            k: Number of folds, 2 <= k <= len(self).
            seed: Seed of :func:`numpy.random.default_rng`.

        Returns:
            A list of ``k`` pairs ``(train, test)``; the test sets are disjoint
            and together hold every row exactly once.

        Raises:
            InputError: If ``k`` is not an integer in [2, len(self)].
        """
        m = len(self)
        if isinstance(k, bool) or not isinstance(k, (int, np.integer)) or not 2 <= int(k) <= m:
            raise InputError(f"kfold: k must be an integer in [2, {m}] (number of measurements), got {k!r}")
        perm = np.random.default_rng(seed).permutation(m)
        folds = np.array_split(perm, int(k))
        out = []
        for i, test_idx in enumerate(folds):
            train_idx = np.concatenate([f for j, f in enumerate(folds) if j != i])
            out.append((self.subset(np.sort(train_idx)), self.subset(np.sort(test_idx))))
        return out


def concat_measurements(sets: Sequence[MeasurementSet], labels: Sequence[str] | None = None,
                        source: str | None = None) -> MeasurementSet:
    """Join measurement sets row-wise (e.g. several files of one calibration), keeping their stations.

    A set without a station column becomes one station, labelled ``labels[i]`` (default: the
    file name of its ``source`` without extension). Columns are kept only when every set has
    them (rx/ry/rz, sigma, temperature, payload, time, extra columns); the others are dropped.

    Args:
        sets: the sets, with the same joint names (any order is not allowed: same order).
        labels: station label of each set that has no station column.
        source: ``source`` of the result (default: the sources joined by ``+``).

    Returns:
        One :class:`MeasurementSet` with a ``station`` column.

    Raises:
        InputError: no sets, different joint names, two sets without a station column
            that would get the same label, or headers naming different robots, tool frames or TCPs.
    """
    sets = list(sets)
    if not sets:
        raise InputError("concat_measurements: no measurement sets given")
    joints = list(sets[0].joint_names)
    for s in sets[1:]:
        if list(s.joint_names) != joints:
            raise InputError(f"{s.source or 'measurement set'}: joint columns {', '.join(s.joint_names)} differ from "
                             f"{sets[0].source or 'the first set'}'s {', '.join(joints)}")
    auto: dict[str, str] = {}
    stations = []
    for i, s in enumerate(sets):
        if s.station is not None:
            stations.append(s.station)
            continue
        lab = str(labels[i]) if labels is not None else (Path(s.source).stem if s.source else f"station{i + 1}")
        if lab in auto:
            raise InputError(f"{s.source or 'measurement set'}: would be station '{lab}' like {auto[lab]}; give the "
                             "files distinct names or a 'station' column")
        auto[lab] = s.source or f"set {i + 1}"
        stations.append(np.full(len(s), lab, dtype=object))

    def cat(attr: str) -> np.ndarray | None:
        vals = [getattr(s, attr) for s in sets]
        return None if any(v is None for v in vals) else np.concatenate(vals, axis=0)

    common = [k for k in sets[0].extra if all(k in s.extra for s in sets)]
    tools = [s.tool for s in sets if s.tool is not None]
    # one robot, tool frame and TCP for every set; the reflector and working configurations may differ per station
    tool = resolve_tool(tools, skip=("reflector_m", "q_work")) if tools else None
    if tool is not None:
        tool.source = tools[0].source
    return MeasurementSet(joint_names=joints, q=cat("q"), position_m=cat("position_m"), rotvec_rad=cat("rotvec_rad"),
                          sigma_m=cat("sigma_m"), temperature_c=cat("temperature_c"), payload_kg=cat("payload_kg"),
                          time_s=cat("time_s"),
                          source=source if source is not None else "+".join(s.source for s in sets if s.source),
                          extra={k: np.concatenate([s.extra[k] for s in sets]) for k in common},
                          station=np.concatenate(stations), tool=tool)
