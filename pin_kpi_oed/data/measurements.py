"""Measurement files: read, validate and write laser-tracker measurements (CSV).

A measurement is one robot configuration ``q`` together with what the tracker
saw there: the reflector position in the tracker frame and, for a 6-DoF probe,
the probe orientation. All quantities are SI: metres, radians, seconds, kg, °C.

CSV format
----------
* Plain comma-separated text, UTF-8 (a byte-order mark is accepted), ``.``
  as decimal point. The first row is a header; every following row is one
  measurement. Blank lines (or rows whose cells are all empty) are ignored.
  Header names are matched exactly (case-sensitive) after stripping spaces.
* Columns, in any order:

  ==============================  ========  ========================================
  column                          unit      meaning
  ==============================  ========  ========================================
  one per actuated joint, named   rad       joint position (for prismatic joints: m)
  exactly as in the URDF
  ``x``, ``y``, ``z``             m         reflector position in the tracker frame
                                            (required)
  ``rx``, ``ry``, ``rz``          rad       optional: orientation of a 6-DoF probe in
                                            the tracker frame as a rotation vector
                                            (axis × angle); all three or none
  ``sigma``                       m         optional: isotropic standard deviation of
                                            the position (same on x, y and z)
  ``sigma_x``, ``sigma_y``,       m         optional: per-axis standard deviation, all
  ``sigma_z``                               three or none; not together with ``sigma``
  ``temperature``                 °C        optional: ambient/robot temperature
  ``payload``                     kg        optional: payload mass
  ``time``                        s         optional: time stamp (any origin)
  ``station``                     (text)    optional: label of the measurement set-up
                                            (tracker placement) the row was taken
                                            from, text or integer (``B``, ``1``);
                                            compared as text after stripping spaces.
                                            Rows of one station share one tracker
                                            pose (and reflector); see below
  anything else                   (any)     kept as a numeric "extra" column
  ==============================  ========  ========================================

* Every cell must be a finite number (``nan``, ``inf`` or an empty cell are
  errors), except the ``station`` cells, which are labels (never empty);
  standard deviations must be > 0 and payloads >= 0.
* Stations: a file without a ``station`` column is one station. Several files
  of one calibration (``identify --data B.csv --data C.csv``) are each their
  own station (labelled by the file name without extension) unless they carry
  a ``station`` column; :func:`concat_measurements` joins them. Identification
  fits one tracker pose per station and the robot's parameters shared by all.
* ``x, y, z`` may be left out only where positions are not needed
  (``read_measurements(..., require_position=False)``, e.g. ``pin-kpi-oed
  predict`` on joint values alone); they are then NaN in the set.
* Joint columns: if ``joint_names`` is passed to :func:`read_measurements`,
  exactly those columns are the joints (in that order) and every other
  unrecognised column goes to :attr:`MeasurementSet.extra`; without it, every
  unrecognised column is a joint, in file order, and ``extra`` is empty.
* Unit guard: the file is rejected as "looks like mm/degrees" if the median
  distance ``|(x, y, z)|`` exceeds ``max(50 m, 20 × reach_m)`` (trackers stand
  a few metres from the robot; a file in mm has distances in the thousands),
  if ``reach_m`` is given and the median distance of the points from their
  median point exceeds ``20 × reach_m`` (the reflector cannot wander farther
  than about the reach), if any joint value or rotation-vector component
  exceeds ``2π + 0.1`` in magnitude (degrees), or if the median standard
  deviation exceeds 0.1 m (mm or µm).
* Units and column names as they come: ``read_measurements(..., units="mm,deg",
  columns="joint_a1=A1,x=X")`` (CLI: ``--units`` / ``--columns`` on every command that reads
  measurements) renames the file's columns first and converts the numbers to SI after parsing
  (lengths: x, y, z, sigma, prismatic joints; angles: rx, ry, rz, revolute joints). Without them
  a file in mm / degrees or with other names is refused with one line that says which option
  to use. The table is read with pandas (:mod:`pin_kpi_oed.data.table`).
* Two rows with identical joint values and identical measurement (x, y, z and,
  if present, rx, ry, rz) are duplicates and rejected.

Example::

    shoulder_pan_joint,shoulder_lift_joint,elbow_joint,wrist_1_joint,wrist_2_joint,wrist_3_joint,x,y,z,sigma_x,sigma_y,sigma_z,temperature
    0.1,-1.2,1.3,-0.4,1.5,0.0,0.3839712,-3.2407562,0.2017262,4.2e-05,2.2e-05,5.6e-06,21.68

:func:`write_measurements` writes the joint columns, then ``x,y,z``, then
``rx,ry,rz``, ``sigma_x,sigma_y,sigma_z``, ``temperature``, ``payload``,
``time``, ``station`` (each only if present) and finally the extra columns, with
shortest-round-trip float formatting (``repr``), so that reading the file back
gives bit-identical arrays. Per-axis sigma is always written as
``sigma_x,sigma_y,sigma_z`` (never the isotropic ``sigma``).

Files are written atomically (:func:`atomic_write_text`,
:func:`atomic_write_json`): the text goes to a temporary file in the target
directory, is flushed to disk and then renamed over the target with
:func:`os.replace`, so a reader sees either the old or the new file, never a
half-written one.
"""

from __future__ import annotations

import csv
import dataclasses
import io as _stdio
import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np
import pandas as pd

from pin_kpi_oed.data.atomic import atomic_write_text
from pin_kpi_oed.data.table import Units, parse_columns, parse_units, read_text_table, rename_header
from pin_kpi_oed.errors import InputError

__all__ = [
    "POSITION_COLUMNS",
    "ROTVEC_COLUMNS",
    "SIGMA_COLUMN",
    "SIGMA_AXIS_COLUMNS",
    "TEMPERATURE_COLUMN",
    "PAYLOAD_COLUMN",
    "TIME_COLUMN",
    "RESERVED_COLUMNS",
    "STATION_COLUMN",
    "MeasurementSet",
    "read_measurements",
    "write_measurements",
    "concat_measurements",
]

POSITION_COLUMNS: tuple[str, str, str] = ("x", "y", "z")
ROTVEC_COLUMNS: tuple[str, str, str] = ("rx", "ry", "rz")
SIGMA_COLUMN = "sigma"
SIGMA_AXIS_COLUMNS: tuple[str, str, str] = ("sigma_x", "sigma_y", "sigma_z")
TEMPERATURE_COLUMN = "temperature"
PAYLOAD_COLUMN = "payload"
TIME_COLUMN = "time"
STATION_COLUMN = "station"
RESERVED_COLUMNS: frozenset[str] = frozenset(
    POSITION_COLUMNS
    + ROTVEC_COLUMNS
    + SIGMA_AXIS_COLUMNS
    + (SIGMA_COLUMN, TEMPERATURE_COLUMN, PAYLOAD_COLUMN, TIME_COLUMN, STATION_COLUMN)
)

#: Joint values (rad) or rotation-vector components beyond this look like degrees.
ANGLE_LIMIT_RAD = 2.0 * math.pi + 0.1
#: Median tracker-to-reflector distance (m) beyond which a file looks like mm.
MAX_MEDIAN_DISTANCE_M = 50.0
#: Factor on the robot reach for the reach-based mm guard.
REACH_FACTOR = 20.0
#: Median standard deviation (m) beyond which sigma looks like mm/µm.
MAX_MEDIAN_SIGMA_M = 0.1


# --------------------------------------------------------------------------- #
# Data container
# --------------------------------------------------------------------------- #
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

    def with_station(self, label: str) -> "MeasurementSet":
        """A copy whose rows all belong to station ``label``."""
        return dataclasses.replace(self, station=np.full(len(self), str(label), dtype=object))

    def subset(self, idx: Sequence[int] | np.ndarray | slice) -> "MeasurementSet":
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
        )

    def split(self, fraction: float, seed: int | None = 0) -> tuple["MeasurementSet", "MeasurementSet"]:
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

    def kfold(self, k: int, seed: int | None = 0) -> list[tuple["MeasurementSet", "MeasurementSet"]]:
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


# --------------------------------------------------------------------------- #
# Reading
# --------------------------------------------------------------------------- #
def _fmt_rows(rows: list[int], lines: list[int], idx: Sequence[int], first: int = 3) -> str:
    """``row r (line l)`` of the first few rows, and how many there are in all (a message stays one short line)."""
    out = ", ".join(f"row {rows[i]} (line {lines[i]})" for i in idx[:first])
    return out + (f" and {len(idx) - first} more ({len(idx)} rows)" if len(idx) > first else "")


def parse_numeric_table(rows: Sequence[Sequence[str]], lines: Sequence[int], header: Sequence[str], src: str,
                        parse: Callable[[str], float] = float, found: str = "",
                        skip: Sequence[str] = ()) -> np.ndarray:
    """Parse the cells of a table into floats, naming the file, column, row and value of any bad cell.

    The cells go into a :class:`pandas.DataFrame` and are converted column-block-wise by NumPy
    (``astype(float)``: Python's correctly rounded parser, so ``repr`` floats read back bit-identical);
    a custom ``parse`` (e.g. decimal commas) is mapped over the cells. Only when a conversion fails
    are the cells scanned, in row-major order, for the first bad one.

    Args:
        rows: the cells of each data row (strings).
        lines: the file line number of each row (for messages).
        header: column names.
        src: file name for messages.
        parse: cell parser (``float``, or one for decimal commas); raises ValueError on bad cells.
        found: description of the columns found, added to a wrong-cell-count message.
        skip: columns not parsed (left NaN), e.g. timestamps.

    Returns:
        (len(rows), len(header)) array.

    Raises:
        InputError: a row with the wrong number of cells, a cell that is not a number, NaN or inf.
    """
    ncol = len(header)
    for r, (cells, line) in enumerate(zip(rows, lines)):
        if len(cells) != ncol:
            raise InputError(f"{src}: row {r + 1} (line {line}) has {len(cells)} cells, the header has {ncol}"
                             + (f" ({found})" if found else ""))
    cols = [c for c, name in enumerate(header) if name not in set(skip)]
    data = np.full((len(rows), ncol), np.nan)
    if not rows or not cols:
        return data
    text = pd.DataFrame(list(rows), dtype=object).iloc[:, cols]
    try:
        if parse is float or parse is _parse_float:
            values = text.apply(lambda col: col.str.strip()).to_numpy().astype(float)
        else:
            values = text.apply(lambda col: col.map(parse)).to_numpy(dtype=float)
    except (ValueError, TypeError):
        values = None
    if values is None:  # find the first cell that is not a number (row-major), to name it
        for r, line in enumerate(lines):
            for c in cols:
                cell = rows[r][c]
                try:
                    parse(cell)
                except ValueError:
                    shown = repr(cell) if cell.strip() else "an empty cell"
                    raise InputError(f"{src}: column '{header[c]}', row {r + 1} (line {line}): {shown} is not a "
                                     "number") from None
        raise InputError(f"{src}: cannot convert the table to numbers")  # pragma: no cover - parse is consistent
    bad = ~np.isfinite(values)
    if bad.any():
        r, k = np.argwhere(bad)[0]
        c = cols[k]
        raise InputError(f"{src}: column '{header[c]}', row {r + 1} (line {lines[r]}): value {rows[r][c].strip()!r} "
                         "is not finite (NaN/inf)")
    data[:, cols] = values
    return data


def check_positive_sigma(sigma: np.ndarray, names: Sequence[str], lines: Sequence[int], src: str,
                         unit: str = "m") -> None:
    """Raise if a standard deviation is not > 0, naming the file, column, row and value.

    Raises:
        InputError: the first offending cell.
    """
    bad = np.argwhere(sigma <= 0)
    if bad.size:
        r, a = bad[0]
        raise InputError(f"{src}: column '{names[a]}', row {r + 1} (line {lines[r]}): "
                         f"standard deviation {float(sigma[r, a])!r} {unit} must be > 0")


def _parse_float(cell: str) -> float:
    return float(cell.strip())


def _read_table(p: Path, src: str) -> tuple[list[str], int, list[list[str]], list[int]]:
    """Step 1: the header and the data rows (cells as text) with their file line numbers (pandas)."""
    header, header_line, rows, row_lines = read_text_table(p, src, "measurement file")
    if not header:
        raise InputError(f"{src}: empty file, expected a header row (joint names, x, y, z, ...)")
    if len(header) == 1 and ";" in header[0]:
        raise InputError(
            f"{src}: header '{header[0][:60]}' looks ';'-separated; this reader expects ',' "
            "(use pin_kpi_oed.data.ipa.import_ipa for IPA files, or convert the file)"
        )
    if not rows:
        raise InputError(f"{src}: no measurement rows after the header")
    return header, header_line, rows, row_lines


@dataclass
class _Columns:
    """Step 2: which header column holds what (names checked, groups complete)."""

    seen: dict[str, int]
    joints: list[str]
    extra: list[str]
    position: bool
    rotvec: bool
    sigma_names: tuple[str, ...]
    found: str


def _check_header(header: list[str], header_line: int, src: str, joint_names: list[str] | None,
                  require_position: bool) -> _Columns:
    """Step 2: unique non-empty names; x, y, z (unless optional); complete rx/ry/rz and sigma groups; joints."""
    seen: dict[str, int] = {}
    for i, name in enumerate(header):
        if not name:
            raise InputError(f"{src}: header (line {header_line}) column {i + 1} has an empty name")
        if name in seen:
            raise InputError(
                f"{src}: column '{name}' appears twice in the header (columns {seen[name] + 1} and {i + 1})"
            )
        seen[name] = i
    found = ", ".join(header)
    missing_xyz = [c for c in POSITION_COLUMNS if c not in seen]
    if missing_xyz and (require_position or len(missing_xyz) != 3):
        raise InputError(
            f"{src}: missing position column(s) {', '.join(missing_xyz)} (m, tracker frame); "
            f"columns found: {found}; map other names with --columns x=X,..."
        )
    rot_present = [c for c in ROTVEC_COLUMNS if c in seen]
    if rot_present and len(rot_present) != 3:
        raise InputError(
            f"{src}: orientation needs all of rx, ry, rz (rotation vector, rad); "
            f"found only {', '.join(rot_present)}"
        )
    sig_axes = [c for c in SIGMA_AXIS_COLUMNS if c in seen]
    if sig_axes and len(sig_axes) != 3:
        raise InputError(
            f"{src}: per-axis sigma needs all of sigma_x, sigma_y, sigma_z (m); found only {', '.join(sig_axes)}"
        )
    if sig_axes and SIGMA_COLUMN in seen:
        raise InputError(f"{src}: give either 'sigma' or 'sigma_x, sigma_y, sigma_z', not both")
    sigma_names: tuple[str, ...] = SIGMA_AXIS_COLUMNS if sig_axes else (
        (SIGMA_COLUMN,) * 3 if SIGMA_COLUMN in seen else ())

    if joint_names is None:
        joints = [c for c in header if c not in RESERVED_COLUMNS]
        if not joints:
            raise InputError(f"{src}: no joint columns found; columns found: {found}")
        extra_names: list[str] = []
    else:
        joints = [str(j) for j in joint_names]
        if len(set(joints)) != len(joints):
            raise InputError(f"{src}: joint_names contains duplicates: {joints}")
        clash = [j for j in joints if j in RESERVED_COLUMNS]
        if clash:
            raise InputError(f"{src}: joint name(s) {clash} clash with reserved column names")
        missing = [j for j in joints if j not in seen]
        if missing:
            raise InputError(
                f"{src}: missing joint column(s) {', '.join(missing)} (rad); columns found: {found}; map other "
                f"names with --columns {missing[0]}=NAME,..."
            )
        extra_names = [c for c in header if c not in RESERVED_COLUMNS and c not in set(joints)]
    return _Columns(seen, joints, extra_names, not missing_xyz, bool(rot_present), sigma_names, found)


def _build_set(data: np.ndarray, rows: list[list[str]], cols: _Columns, src: str) -> MeasurementSet:
    """Step 3: the parsed table as a :class:`MeasurementSet` (station labels taken as text)."""
    seen = cols.seen

    def col(name: str) -> np.ndarray | None:
        return data[:, seen[name]].copy() if name in seen else None

    def block(names: Sequence[str]) -> np.ndarray:
        return data[:, [seen[n] for n in names]].copy()

    m = data.shape[0]
    station = None
    if STATION_COLUMN in seen:
        station = np.array([r[seen[STATION_COLUMN]].strip() for r in rows], dtype=object)
        empty = np.flatnonzero(station == "")
        if empty.size:
            raise InputError(f"{src}: column 'station', row {int(empty[0]) + 1}: empty station label "
                             "(give every row a label, e.g. B or 1)")
    return MeasurementSet(
        joint_names=cols.joints,
        q=block(cols.joints),
        position_m=block(POSITION_COLUMNS) if cols.position else np.full((m, 3), np.nan),
        rotvec_rad=block(ROTVEC_COLUMNS) if cols.rotvec else None,
        sigma_m=block(cols.sigma_names) if cols.sigma_names else None,
        temperature_c=col(TEMPERATURE_COLUMN),
        payload_kg=col(PAYLOAD_COLUMN),
        time_s=col(TIME_COLUMN),
        source=src,
        extra={n: col(n) for n in cols.extra},
        station=station,
    )


def _check_values(ms: MeasurementSet, cols: _Columns, row_lines: list[int], src: str) -> None:
    """Step 4: standard deviations > 0, payloads >= 0."""
    if ms.sigma_m is not None:
        check_positive_sigma(ms.sigma_m, cols.sigma_names, row_lines, src)
    if ms.payload_kg is not None and np.any(ms.payload_kg < 0):
        r = int(np.flatnonzero(ms.payload_kg < 0)[0])
        raise InputError(
            f"{src}: column 'payload', row {r + 1} (line {row_lines[r]}): payload {float(ms.payload_kg[r])!r} kg "
            "must be >= 0"
        )


def _check_units(ms: MeasurementSet, cols: _Columns, row_lines: list[int], src: str, reach_m: float | None,
                 joint_units: Sequence[str] | None = None) -> None:
    """Step 5: the unit guard (mm instead of m, degrees instead of rad, sigma in mm/µm)."""
    pos = ms.position_m
    if cols.position:
        dist = np.linalg.norm(pos, axis=1)
        med = float(np.median(dist))
        limit = MAX_MEDIAN_DISTANCE_M if reach_m is None else max(MAX_MEDIAN_DISTANCE_M, REACH_FACTOR * float(reach_m))
        if med > limit:
            r = int(np.argmax(dist))
            raise InputError(
                f"{src}: columns x, y, z: median distance from the tracker {med:.6g} m exceeds {limit:g} m "
                f"(e.g. row {r + 1} (line {row_lines[r]}): {dist[r]:.6g}); looks like mm/degrees; convert to m/rad or declare the units (--units mm,deg)"
            )
    if reach_m is not None and cols.position:
        for rows in ms.station_rows().values():  # each station has its own tracker frame
            spread = np.linalg.norm(pos[rows] - np.median(pos[rows], axis=0), axis=1)
            med_spread = float(np.median(spread))
            if med_spread > REACH_FACTOR * float(reach_m):
                r = int(rows[np.argmax(spread)])
                raise InputError(
                    f"{src}: columns x, y, z: median distance of the points from their median point "
                    f"{med_spread:.6g} m exceeds {REACH_FACTOR:g} x reach ({float(reach_m):g} m) "
                    f"(e.g. row {r + 1} (line {row_lines[r]})); looks like mm/degrees; convert to m/rad or declare the units (--units mm,deg)"
                )
    rev = np.array([u != "m" for u in joint_units]) if joint_units is not None else np.ones(len(cols.joints), bool)
    for arr, names, mask in ((ms.q, cols.joints, rev), (ms.rotvec_rad, ROTVEC_COLUMNS, np.ones(3, bool))):
        if arr is None:
            continue
        big = (np.abs(arr) > ANGLE_LIMIT_RAD) & mask[None, :]  # prismatic joints (m) are not angles
        if np.any(big):
            r, c = np.argwhere(big)[0]
            raise InputError(
                f"{src}: column '{names[c]}', row {r + 1} (line {row_lines[r]}): value {float(arr[r, c])!r} "
                f"exceeds 2π+0.1 rad in magnitude; looks like mm/degrees; convert to m/rad or declare the units (--units mm,deg)"
            )
    if ms.sigma_m is not None:
        sigma = ms.sigma_m
        med_sigma = float(np.median(sigma))
        if med_sigma > MAX_MEDIAN_SIGMA_M:
            r = int(np.argmax(sigma.max(axis=1)))
            raise InputError(
                f"{src}: column(s) {', '.join(dict.fromkeys(cols.sigma_names))}: median standard deviation "
                f"{med_sigma:.6g} m exceeds {MAX_MEDIAN_SIGMA_M:g} m (e.g. row {r + 1} (line {row_lines[r]}): "
                f"{sigma[r].max():.6g}); looks like mm/degrees; convert to m/rad or declare the units (--units mm,deg)"
            )


def _check_duplicates(ms: MeasurementSet, row_lines: list[int], src: str) -> None:
    """Step 6: no two rows with identical joint values and identical measurement."""
    m = len(ms)
    row_nums = list(range(1, m + 1))
    key_parts = [ms.q] + ([ms.position_m] if ms.has_position else []) + \
        ([ms.rotvec_rad] if ms.rotvec_rad is not None else [])
    keys = np.hstack(key_parts) + 0.0  # +0.0 folds -0.0 into 0.0
    first: dict[bytes, int] = {}
    dups: dict[int, list[int]] = {}
    for r in range(m):
        kb = keys[r].tobytes()
        if kb in first:
            dups.setdefault(first[kb], []).append(r)
        else:
            first[kb] = r
    if dups:
        parts = []
        for orig, copies in list(dups.items())[:5]:
            verb = "is a duplicate of" if len(copies) == 1 else "are duplicates of"
            parts.append(f"{_fmt_rows(row_nums, row_lines, copies)} {verb} {_fmt_rows(row_nums, row_lines, [orig])}")
        more = f" (and {len(dups) - 5} more groups)" if len(dups) > 5 else ""
        what = "same joint values and same x, y, z" if ms.has_position else "same joint values"
        raise InputError(
            f"{src}: duplicate measurements ({what}"
            f"{', rx, ry, rz' if ms.rotvec_rad is not None else ''}): " + "; ".join(parts) + more
        )


def _apply_units(ms: MeasurementSet, u: Units, joint_units: Sequence[str] | None) -> MeasurementSet:
    """Step 3b: declared units to SI (lengths: x, y, z, sigma, prismatic joints; angles: rx, ry, rz, revolute
    joints). Temperature (°C), payload (kg), time (s) and extra columns are not converted."""
    if u.is_si:
        return ms
    n = len(ms.joint_names)
    ju = list(joint_units) if joint_units is not None else ["rad"] * n
    if len(ju) != n or any(x not in ("rad", "m") for x in ju):
        raise InputError(f"joint_units must give 'rad' or 'm' for each of the {n} joints, got {ju}")
    scale = np.array([u.angle_rad if x == "rad" else u.length_m for x in ju])
    return dataclasses.replace(
        ms, q=ms.q * scale, position_m=ms.position_m * u.length_m,
        rotvec_rad=None if ms.rotvec_rad is None else ms.rotvec_rad * u.angle_rad,
        sigma_m=None if ms.sigma_m is None else ms.sigma_m * u.length_m)


def read_measurements(
    path: str | os.PathLike[str],
    joint_names: list[str] | None = None,
    reach_m: float | None = None,
    require_position: bool = True,
    units: str | Units | None = None,
    columns: str | dict[str, str] | None = None,
    joint_units: Sequence[str] | None = None,
) -> MeasurementSet:
    """Read and validate a measurement CSV file (format: see the module docstring).

    Steps: read the table, check the header, parse every cell (file, column, row
    and value named on error), build the set, check values, units and duplicates.
    Row numbers in error messages count data rows from 1 (the header is not
    counted); the file line number is given too.

    Args:
        path: CSV file.
        joint_names: Expected joint columns (e.g. the actuated joints of the
            URDF), in model order. ``None``: every unrecognised column is a joint.
        reach_m: Robot reach (m); if given, enables the reach-based mm guard.
        require_position: False accepts a file without ``x, y, z`` (positions
            NaN, :attr:`MeasurementSet.has_position` False), e.g. for predictions.
        units: declared units of the file's numbers, e.g. ``"mm,deg"``
            (:func:`pin_kpi_oed.data.table.parse_units`); converted to SI on reading. None:
            the file is SI and the unit guard refuses mm / degrees.
        columns: column mapping ``"joint_a1=A1,x=X"`` (package name = file name), applied to the
            header before anything else.
        joint_units: ``"rad"`` or ``"m"`` per joint of ``joint_names`` (prismatic joints are
            lengths under ``units``); default all ``"rad"``.

    Returns:
        The measurements, in file order, in SI units.

    Raises:
        InputError: If the file is missing or unreadable, the header lacks joint
            or x/y/z columns, a column is duplicated, a row has the wrong number
            of cells, a cell is not a finite number (or a station label is empty),
            a standard deviation is <= 0 or a payload < 0, the values look like mm
            or degrees, or two rows are duplicates. The message names the file,
            column, row and value.
    """
    p = Path(path)
    src = str(p)
    if reach_m is not None and not (math.isfinite(float(reach_m)) and float(reach_m) > 0):
        raise InputError(f"reach_m must be a positive number of metres, got {reach_m!r}")
    u = parse_units(units)
    mapping = parse_columns(columns)
    header, header_line, rows, row_lines = _read_table(p, src)
    header = rename_header(header, mapping, src)
    cols = _check_header(header, header_line, src, joint_names, require_position)
    data = parse_numeric_table(rows, row_lines, header, src, _parse_float, cols.found, skip=(STATION_COLUMN,))
    ms = _apply_units(_build_set(data, rows, cols, src), u, joint_units)
    _check_values(ms, cols, row_lines, src)
    _check_units(ms, cols, row_lines, src, reach_m, joint_units)
    _check_duplicates(ms, row_lines, src)
    return ms


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
        InputError: no sets, different joint names, or two sets without a station column
            that would get the same label.
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
    return MeasurementSet(joint_names=joints, q=cat("q"), position_m=cat("position_m"), rotvec_rad=cat("rotvec_rad"),
                          sigma_m=cat("sigma_m"), temperature_c=cat("temperature_c"), payload_kg=cat("payload_kg"),
                          time_s=cat("time_s"),
                          source=source if source is not None else "+".join(s.source for s in sets if s.source),
                          extra={k: np.concatenate([s.extra[k] for s in sets]) for k in common},
                          station=np.concatenate(stations))


# --------------------------------------------------------------------------- #
# Writing
# --------------------------------------------------------------------------- #
def _format_float(v: float) -> str:
    """Shortest string that reads back as the same float (``repr``)."""
    return repr(float(v))


def _check_column_names(ms: MeasurementSet, path: str) -> None:
    names = list(ms.joint_names) + list(ms.extra)
    for n in names:
        if not n or n != n.strip():
            raise InputError(f"cannot write '{path}': column name {n!r} is empty or has leading/trailing spaces")
    clash = [n for n in names if n in RESERVED_COLUMNS]
    if clash:
        raise InputError(f"cannot write '{path}': joint/extra column name(s) {clash} clash with reserved columns")
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise InputError(f"cannot write '{path}': column name(s) {dup} used both as joint and extra column")


def write_measurements(ms: MeasurementSet, path: str | os.PathLike[str]) -> None:
    """Write a measurement set as CSV (format: see the module docstring), atomically.

    Columns: joints, ``x,y,z``, then if present ``rx,ry,rz``,
    ``sigma_x,sigma_y,sigma_z``, ``temperature``, ``payload``, ``time``,
    ``station`` (text), then the extra columns. Floats use ``repr`` so a read-back is bit-identical.

    Args:
        ms: The measurements (SI units).
        path: Target CSV file; replaced atomically if it exists.

    Raises:
        InputError: If a joint/extra name is empty, padded with spaces, reserved
            or used twice, the set has no positions, or the target directory does not exist.
    """
    target = str(path)
    _check_column_names(ms, target)
    header: list[str] = list(ms.joint_names) + list(POSITION_COLUMNS)
    blocks: list[np.ndarray] = [ms.q, ms.position_m]
    if ms.rotvec_rad is not None:
        header += list(ROTVEC_COLUMNS)
        blocks.append(ms.rotvec_rad)
    if ms.sigma_m is not None:
        header += list(SIGMA_AXIS_COLUMNS)
        blocks.append(ms.sigma_m)
    for name, arr in ((TEMPERATURE_COLUMN, ms.temperature_c), (PAYLOAD_COLUMN, ms.payload_kg), (TIME_COLUMN, ms.time_s)):
        if arr is not None:
            header.append(name)
            blocks.append(arr[:, None])
    n_before_station = len(header)
    if ms.station is not None:
        header.append(STATION_COLUMN)
    extra_blocks = [np.asarray(arr, dtype=float)[:, None] for arr in ms.extra.values()]
    header += list(ms.extra)
    table = np.hstack(blocks + extra_blocks) if len(ms) else np.empty((0, len(header)))
    if not ms.has_position:
        raise InputError(f"cannot write '{target}': the set has no measured positions (x, y, z)")

    buf = _stdio.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(header)
    for i, row in enumerate(table):
        cells = [_format_float(v) for v in row]
        if ms.station is not None:
            cells.insert(n_before_station, str(ms.station[i]))
        writer.writerow(cells)
    atomic_write_text(path, buf.getvalue())
