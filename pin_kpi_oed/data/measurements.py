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
  anything else                   (any)     kept as a numeric "extra" column
  ==============================  ========  ========================================

* Every cell must be a finite number (``nan``, ``inf`` or an empty cell are
  errors); standard deviations must be > 0 and payloads >= 0.
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
* Two rows with identical joint values and identical measurement (x, y, z and,
  if present, rx, ry, rz) are duplicates and rejected.

Example::

    shoulder_pan_joint,shoulder_lift_joint,elbow_joint,wrist_1_joint,wrist_2_joint,wrist_3_joint,x,y,z,sigma_x,sigma_y,sigma_z,temperature
    0.1,-1.2,1.3,-0.4,1.5,0.0,0.3839712,-3.2407562,0.2017262,4.2e-05,2.2e-05,5.6e-06,21.68

:func:`write_measurements` writes the joint columns, then ``x,y,z``, then
``rx,ry,rz``, ``sigma_x,sigma_y,sigma_z``, ``temperature``, ``payload``,
``time`` (each only if present) and finally the extra columns, with
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
import io as _stdio
import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np

from pin_kpi_oed.data.atomic import atomic_write_text
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
    "MeasurementSet",
    "read_measurements",
    "write_measurements",
]

POSITION_COLUMNS: tuple[str, str, str] = ("x", "y", "z")
ROTVEC_COLUMNS: tuple[str, str, str] = ("rx", "ry", "rz")
SIGMA_COLUMN = "sigma"
SIGMA_AXIS_COLUMNS: tuple[str, str, str] = ("sigma_x", "sigma_y", "sigma_z")
TEMPERATURE_COLUMN = "temperature"
PAYLOAD_COLUMN = "payload"
TIME_COLUMN = "time"
RESERVED_COLUMNS: frozenset[str] = frozenset(
    POSITION_COLUMNS
    + ROTVEC_COLUMNS
    + SIGMA_AXIS_COLUMNS
    + (SIGMA_COLUMN, TEMPERATURE_COLUMN, PAYLOAD_COLUMN, TIME_COLUMN)
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

    Raises:
        InputError: At construction, if an array has the wrong shape or the
            joint names are not unique / do not match the columns of ``q``.
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

    def __len__(self) -> int:
        """Number of measurements ``m``."""
        return int(self.q.shape[0])

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
def _fmt_rows(rows: list[int], lines: list[int], idx: Sequence[int]) -> str:
    return ", ".join(f"row {rows[i]} (line {lines[i]})" for i in idx)


def parse_numeric_table(rows: Sequence[Sequence[str]], lines: Sequence[int], header: Sequence[str], src: str,
                        parse: Callable[[str], float] = float, found: str = "",
                        skip: Sequence[str] = ()) -> np.ndarray:
    """Parse the cells of a table into floats, naming the file, column, row and value of any bad cell.

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
    cols = [c for c, name in enumerate(header) if name not in set(skip)]
    data = np.full((len(rows), ncol), np.nan)
    for r, (cells, line) in enumerate(zip(rows, lines)):
        if len(cells) != ncol:
            raise InputError(f"{src}: row {r + 1} (line {line}) has {len(cells)} cells, the header has {ncol}"
                             + (f" ({found})" if found else ""))
        for c in cols:
            cell = cells[c]
            try:
                v = parse(cell)
            except ValueError:
                shown = repr(cell) if cell.strip() else "an empty cell"
                raise InputError(f"{src}: column '{header[c]}', row {r + 1} (line {line}): {shown} is not a number"
                                 ) from None
            if not math.isfinite(v):
                raise InputError(f"{src}: column '{header[c]}', row {r + 1} (line {line}): value {cell.strip()!r} "
                                 "is not finite (NaN/inf)")
            data[r, c] = v
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


def read_measurements(
    path: str | os.PathLike[str],
    joint_names: list[str] | None = None,
    reach_m: float | None = None,
) -> MeasurementSet:
    """Read and validate a measurement CSV file (format: see the module docstring).

    Row numbers in error messages count data rows from 1 (the header is not
    counted); the file line number is given too.

    Args:
        path: CSV file.
        joint_names: Expected joint columns (e.g. the actuated joints of the
            URDF), in model order. ``None``: every unrecognised column is a joint.
        reach_m: Robot reach (m); if given, enables the reach-based mm guard.

    Returns:
        The measurements, in file order, in SI units.

    Raises:
        InputError: If the file is missing or unreadable, the header lacks joint
            or x/y/z columns, a column is duplicated, a row has the wrong number
            of cells, a cell is not a finite number, a standard deviation is
            <= 0 or a payload < 0, the values look like mm or degrees, or two
            rows are duplicates. The message names the file, column, row and value.
    """
    p = Path(path)
    src = str(p)
    if not p.exists():
        raise InputError(f"measurement file '{src}' does not exist")
    if p.is_dir():
        raise InputError(f"measurement file '{src}' is a directory, expected a CSV file")
    if reach_m is not None and not (math.isfinite(float(reach_m)) and float(reach_m) > 0):
        raise InputError(f"reach_m must be a positive number of metres, got {reach_m!r}")
    try:
        text = p.read_text(encoding="utf-8-sig")
    except UnicodeDecodeError as exc:
        raise InputError(f"{src}: not a UTF-8 text file ({exc})") from None
    except OSError as exc:
        raise InputError(f"{src}: cannot read file ({exc.strerror})") from None

    reader = csv.reader(_stdio.StringIO(text, newline=""))
    header: list[str] | None = None
    header_line = 0
    rows: list[list[str]] = []
    row_lines: list[int] = []
    for cells in reader:
        if not cells or all(not c.strip() for c in cells):
            continue
        if header is None:
            header = [c.strip() for c in cells]
            header_line = reader.line_num
            continue
        rows.append(cells)
        row_lines.append(reader.line_num)
    if header is None:
        raise InputError(f"{src}: empty file, expected a header row (joint names, x, y, z, ...)")
    if len(header) == 1 and ";" in header[0]:
        raise InputError(
            f"{src}: header '{header[0][:60]}' looks ';'-separated; this reader expects ',' "
            "(use pin_kpi_oed.data.ipa.import_ipa for IPA files, or convert the file)"
        )
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
    if missing_xyz:
        raise InputError(
            f"{src}: missing position column(s) {', '.join(missing_xyz)} (m, tracker frame); "
            f"columns found: {found}"
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
                f"{src}: missing joint column(s) {', '.join(missing)} (rad); columns found: {found}"
            )
        extra_names = [c for c in header if c not in RESERVED_COLUMNS and c not in set(joints)]

    # ---- parse every cell ------------------------------------------------- #
    m = len(rows)
    if m == 0:
        raise InputError(f"{src}: no measurement rows after the header")
    data = parse_numeric_table(rows, row_lines, header, src, _parse_float, found)
    row_nums = list(range(1, m + 1))

    def col(name: str) -> np.ndarray:
        return data[:, seen[name]].copy()

    def cols(names: Sequence[str]) -> np.ndarray:
        return data[:, [seen[n] for n in names]].copy()

    q = cols(joints)
    pos = cols(POSITION_COLUMNS)
    rotvec = cols(ROTVEC_COLUMNS) if rot_present else None
    if sig_axes:
        sigma = cols(SIGMA_AXIS_COLUMNS)
        sigma_names: Sequence[str] = SIGMA_AXIS_COLUMNS
    elif SIGMA_COLUMN in seen:
        sigma = np.repeat(col(SIGMA_COLUMN)[:, None], 3, axis=1)
        sigma_names = (SIGMA_COLUMN,) * 3
    else:
        sigma = None
        sigma_names = ()
    temperature = col(TEMPERATURE_COLUMN) if TEMPERATURE_COLUMN in seen else None
    payload = col(PAYLOAD_COLUMN) if PAYLOAD_COLUMN in seen else None
    time = col(TIME_COLUMN) if TIME_COLUMN in seen else None

    # ---- value checks ----------------------------------------------------- #
    if sigma is not None:
        check_positive_sigma(sigma, sigma_names, row_lines, src)
    if payload is not None and np.any(payload < 0):
        r = int(np.flatnonzero(payload < 0)[0])
        raise InputError(
            f"{src}: column 'payload', row {r + 1} (line {row_lines[r]}): payload {float(payload[r])!r} kg must be >= 0"
        )

    # ---- unit guard ------------------------------------------------------- #
    dist = np.linalg.norm(pos, axis=1)
    med = float(np.median(dist))
    limit = MAX_MEDIAN_DISTANCE_M if reach_m is None else max(MAX_MEDIAN_DISTANCE_M, REACH_FACTOR * float(reach_m))
    if med > limit:
        r = int(np.argmax(dist))
        raise InputError(
            f"{src}: columns x, y, z: median distance from the tracker {med:.6g} m exceeds {limit:g} m "
            f"(e.g. row {r + 1} (line {row_lines[r]}): {dist[r]:.6g}); looks like mm/degrees; convert to m/rad"
        )
    if reach_m is not None:
        spread = np.linalg.norm(pos - np.median(pos, axis=0), axis=1)
        med_spread = float(np.median(spread))
        if med_spread > REACH_FACTOR * float(reach_m):
            r = int(np.argmax(spread))
            raise InputError(
                f"{src}: columns x, y, z: median distance of the points from their median point "
                f"{med_spread:.6g} m exceeds {REACH_FACTOR:g} x reach ({float(reach_m):g} m) "
                f"(e.g. row {r + 1} (line {row_lines[r]})); looks like mm/degrees; convert to m/rad"
            )
    for arr, names in ((q, joints), (rotvec, ROTVEC_COLUMNS)):
        if arr is None:
            continue
        big = np.abs(arr) > ANGLE_LIMIT_RAD
        if np.any(big):
            r, c = np.argwhere(big)[0]
            raise InputError(
                f"{src}: column '{names[c]}', row {r + 1} (line {row_lines[r]}): value {float(arr[r, c])!r} "
                f"exceeds 2π+0.1 rad in magnitude; looks like mm/degrees; convert to m/rad"
            )
    if sigma is not None:
        med_sigma = float(np.median(sigma))
        if med_sigma > MAX_MEDIAN_SIGMA_M:
            r = int(np.argmax(sigma.max(axis=1)))
            raise InputError(
                f"{src}: column(s) {', '.join(dict.fromkeys(sigma_names))}: median standard deviation "
                f"{med_sigma:.6g} m exceeds {MAX_MEDIAN_SIGMA_M:g} m (e.g. row {r + 1} (line {row_lines[r]}): "
                f"{sigma[r].max():.6g}); looks like mm/degrees; convert to m/rad"
            )

    # ---- duplicates ------------------------------------------------------- #
    key_parts = [q, pos] + ([rotvec] if rotvec is not None else [])
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
        raise InputError(
            f"{src}: duplicate measurements (same joint values and same x, y, z"
            f"{', rx, ry, rz' if rotvec is not None else ''}): " + "; ".join(parts) + more
        )

    return MeasurementSet(
        joint_names=joints,
        q=q,
        position_m=pos,
        rotvec_rad=rotvec,
        sigma_m=sigma,
        temperature_c=temperature,
        payload_kg=payload,
        time_s=time,
        source=src,
        extra={n: col(n) for n in extra_names},
    )


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
    ``sigma_x,sigma_y,sigma_z``, ``temperature``, ``payload``, ``time``, then
    the extra columns. Floats use ``repr`` so a read-back is bit-identical.

    Args:
        ms: The measurements (SI units).
        path: Target CSV file; replaced atomically if it exists.

    Raises:
        InputError: If a joint/extra name is empty, padded with spaces, reserved
            or used twice, or the target directory does not exist.
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
    for name, arr in ms.extra.items():
        header.append(name)
        blocks.append(np.asarray(arr, dtype=float)[:, None])
    table = np.hstack(blocks) if len(ms) else np.empty((0, len(header)))

    buf = _stdio.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(header)
    for row in table:
        writer.writerow([_format_float(v) for v in row])
    atomic_write_text(path, buf.getvalue())
