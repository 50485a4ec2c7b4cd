"""Importer for the IPA UR10 laser-tracker data set (Landgraf et al., CASE 2021).

The data (``ipa-robot-accuracy``, MIT licence) are four series of a Universal
Robots UR10 (CB3) measured with a Leica laser tracker and a T-Mac 6-DoF probe
on the flange: ``Series_A/measurements_grid.csv``,
``Series_B/measurements_joint_configurations.csv``,
``Series_C/measurements_random_poses.csv`` and
``Series_D/measurements_iso_cubes.csv``.

Source format
-------------
* ``;``-separated, **decimal commas** (``0,365141``; ``2,78E-05``), header row,
  one measurement per row; CRLF or LF line ends; the last line may lack its
  line end.
* ``Timestamp``: ``YYYYMMDDhhmmss`` in Series A. In Series B/C/D a spreadsheet
  mangled it to ``2,02011E+13`` (minute resolution lost, all rows equal), so
  no time is available there.
* ``Goal x, Goal y, Goal z`` (m) and ``Goal roll, Goal pitch, Goal yaw`` (rad):
  the commanded T-Mac pose in the robot base frame.
* ``shoulder_pan_joint … wrist_3_joint`` (rad): joint configuration.
* ``measurement_temperature`` (°C).
* ``measurement_x, _y, _z`` (mm, tracker frame) and ``measurement_rx, _ry, _rz``
  (deg, Euler angles, see below); in Series B/C/D each of these is followed by
  ``measurement_std_<axis>`` (same unit). Series A has no std columns.

Orientation convention
----------------------
The data set's notes call the angles "extrinsic XYZ". The data say otherwise:
the rotation angle between two measured orientations, ``angle(R_i R_jᵀ)``, is
independent of the unknown tracker and probe frames and must match the one
from the nominal UR10 forward kinematics of the recorded joint values. With
``R = Rx(rx)·Ry(ry)·Rz(rz)`` (intrinsic X-Y'-Z'', scipy ``'XYZ'``) the median
mismatch is 0.04–0.07° on all four series and a fit of the two constant frames
leaves 0.07–0.10° (the nominal model's error); with extrinsic ``'xyz'``
(``Rz·Ry·Rx``) it is 0.3–1.6° and the fit leaves degrees, up to 167°. The
importer therefore uses :data:`IPA_EULER_SEQ` = ``'XYZ'``
(``Rotation.from_euler('XYZ', [rx, ry, rz], degrees=True)``); the test suite
re-checks this on the data.

Conversion to :class:`~pin_kpi_oed.data.measurements.MeasurementSet` (SI)
------------------------------------------------------------
* ``q`` ← the six joint columns (rad), names :data:`UR10_JOINT_NAMES`.
* ``position_m`` ← ``measurement_x/y/z`` / 1000.
* ``rotvec_rad`` ← rotation vector of ``measurement_rx/ry/rz`` (see above).
* ``sigma_m`` ← ``measurement_std_x/y/z`` / 1000 (Series B/C/D; ``None`` for A).
  These are the scatter of the tracker's averaged reading (typically ~10 µm,
  some below 1 µm), **not** the tracker's accuracy: use them as weights only
  with care.
* ``temperature_c`` ← ``measurement_temperature``.
* ``time_s`` ← Series A: seconds since the first row (file order is *not*
  chronological: Series A spans about 100.8 h over 4 days and has 9 backward
  steps); Series B/C/D: ``None``.
* ``payload_kg`` ← ``None``.
* ``extra``: ``goal_x, goal_y, goal_z`` (m), ``goal_roll, goal_pitch, goal_yaw``
  (rad, as in the file), ``sigma_euler_rx, sigma_euler_ry, sigma_euler_rz``
  (rad, std of the Euler angles; B/C/D only), and any unknown numeric column
  under its own name.

``Trafo_TM_F_init.txt`` (and ``…_calib.txt``): four lines of four
space-separated numbers, ``.`` decimals, a homogeneous 4×4 transform between
the T-Mac and the flange ("T_TM_F"; the source only says "initial
transformation from T-Mac to flange"), translation in mm; the last line has no
line end. :func:`read_ipa_flange_transform` returns it with the translation in m.
"""

from __future__ import annotations

import copy
import csv
import hashlib
import io as _stdio
import math
import os
import re
from datetime import datetime
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from pin_kpi_oed.errors import InputError
from pin_kpi_oed.data.measurements import MeasurementSet, check_positive_sigma, parse_numeric_table

__all__ = [
    "UR10_JOINT_NAMES",
    "IPA_EULER_SEQ",
    "import_ipa",
    "read_ipa_flange_transform",
]

#: Joint names of the UR10 (example-robot-data ``ur10_robot.urdf``), in model order.
UR10_JOINT_NAMES: tuple[str, ...] = (
    "shoulder_pan_joint",
    "shoulder_lift_joint",
    "elbow_joint",
    "wrist_1_joint",
    "wrist_2_joint",
    "wrist_3_joint",
)

#: scipy Euler sequence of ``measurement_rx, _ry, _rz``: intrinsic X-Y'-Z'' (see module docstring).
IPA_EULER_SEQ = "XYZ"

_MM = 1e-3
_TIMESTAMP_RE = re.compile(r"^\d{14}$")
_POS = ("measurement_x", "measurement_y", "measurement_z")
_ROT = ("measurement_rx", "measurement_ry", "measurement_rz")
_POS_STD = ("measurement_std_x", "measurement_std_y", "measurement_std_z")
_ROT_STD = ("measurement_std_rx", "measurement_std_ry", "measurement_std_rz")
_TEMP = "measurement_temperature"
_TIMESTAMP = "Timestamp"
_GOAL = {
    "Goal x": "goal_x",
    "Goal y": "goal_y",
    "Goal z": "goal_z",
    "Goal roll": "goal_roll",
    "Goal pitch": "goal_pitch",
    "Goal yaw": "goal_yaw",
}
_KNOWN = (set(UR10_JOINT_NAMES) | set(_POS) | set(_ROT) | set(_POS_STD) | set(_ROT_STD) | {_TEMP, _TIMESTAMP}
          | set(_GOAL))


def _clean(cell: str) -> str:
    return cell.strip().strip("\x00").strip()


def _parse_decimal_comma(cell: str) -> float:
    """``'0,365141'`` -> 0.365141, ``'2,78E-05'`` -> 2.78e-05 (raises ValueError)."""
    return float(_clean(cell).replace(",", "."))


def _read_text(p: Path) -> str:
    return _decoded(p.read_bytes())


def _decoded(raw: bytes) -> str:
    try:
        return raw.decode("utf-8-sig")
    except UnicodeDecodeError:
        return raw.decode("latin-1")


def _resolve_measurement_file(p: Path) -> Path:
    if p.is_dir():
        cands = sorted(p.glob("measurements_*.csv"))
        if len(cands) != 1:
            raise InputError(
                f"IPA folder '{p}': expected exactly one measurements_*.csv, found "
                f"{[c.name for c in cands] or 'none'}"
            )
        return cands[0]
    return p


#: (the file as named, SHA-256 of its bytes) -> the set imported from it: the last few series read in this process
_IMPORTED: dict[tuple[str, bytes], MeasurementSet] = {}
#: series kept in :data:`_IMPORTED` (the data set has four)
_MAX_IMPORTED = 4


def import_ipa(path: str | os.PathLike[str]) -> MeasurementSet:
    """Import one IPA UR10 measurement series and convert it to SI units.

    A file read again with the same bytes (a series several commands or tests of one process read) is converted
    once: the set is kept by the file's name and the SHA-256 of its bytes (the last four files) and each call gets
    its own deep copy (a caller writing into its arrays changes no other's).

    Args:
        path: A ``measurements_*.csv`` file of the IPA data set, or a series
            folder (``Series_C``) holding exactly one such file.

    Returns:
        A :class:`~pin_kpi_oed.data.measurements.MeasurementSet` in file order: ``q`` (rad),
        ``position_m`` (m, tracker frame), ``rotvec_rad`` (rad, tracker frame),
        ``sigma_m`` (m; ``None`` for Series A), ``temperature_c`` (°C, if the
        column exists), ``time_s`` (s since the first row; only if every
        timestamp is a proper ``YYYYMMDDhhmmss``, i.e. Series A), goal pose and
        Euler-angle std in ``extra`` (see the module docstring).

    Raises:
        InputError: If the file is missing, a joint or position column is
            missing, a row has the wrong number of cells, or a cell is not a
            finite number / a standard deviation is not > 0 (the message names
            file, column, row and value).
    """
    p = _resolve_measurement_file(Path(path))
    src = str(p)
    if not p.is_file():
        raise InputError(f"IPA measurement file '{src}' does not exist")
    raw = p.read_bytes()
    key = (src, hashlib.sha256(raw).digest())
    ms = _IMPORTED.pop(key, None)
    if ms is None:
        ms = _converted(_decoded(raw), src)
        while len(_IMPORTED) >= _MAX_IMPORTED:
            _IMPORTED.pop(next(iter(_IMPORTED)))
    _IMPORTED[key] = ms  # the most recent last
    return copy.deepcopy(ms)


def _converted(text: str, src: str) -> MeasurementSet:
    """The measurement set of the IPA file text ``text`` (named ``src`` in messages): see :func:`import_ipa`."""
    header, rows, lines = _read_ipa_table(text, src)
    idx = {name: i for i, name in enumerate(header)}
    data = _numbers(header, rows, lines, src)

    def cols(names: tuple[str, ...]) -> np.ndarray:
        return data[:, [idx[n] for n in names]].copy()

    rotvec = None
    if all(n in idx for n in _ROT):
        rotvec = Rotation.from_euler(IPA_EULER_SEQ, cols(_ROT), degrees=True).as_rotvec()
    sigma_m = None
    if all(n in idx for n in _POS_STD):
        sigma_m = cols(_POS_STD)
        check_positive_sigma(sigma_m, _POS_STD, lines, src, unit="mm")
        sigma_m = sigma_m * _MM
    return MeasurementSet(
        joint_names=list(UR10_JOINT_NAMES),
        q=cols(UR10_JOINT_NAMES),
        position_m=cols(_POS) * _MM,
        rotvec_rad=rotvec,
        sigma_m=sigma_m,
        temperature_c=data[:, idx[_TEMP]].copy() if _TEMP in idx else None,
        payload_kg=None,
        time_s=_time_column(rows, lines, idx, src),
        source=src,
        extra=_extra_columns(data, header, idx, lines, src),
    )


def _read_ipa_table(text: str, src: str) -> tuple[list[str], list[list[str]], list[int]]:
    """The header and the data rows (cells as text) with their line numbers; the required columns checked."""
    reader = csv.reader(_stdio.StringIO(text, newline=""), delimiter=";")
    header: list[str] | None = None
    rows: list[list[str]] = []
    lines: list[int] = []
    for cells in reader:
        if not cells or all(not _clean(c) for c in cells):
            continue
        if header is None:
            header = [_clean(c) for c in cells]
            continue
        rows.append(cells)
        lines.append(reader.line_num)
    if header is None:
        raise InputError(f"{src}: empty file, expected the IPA header (Timestamp;Goal x;...)")
    if len(header) == 1 and "," in header[0]:
        raise InputError(f"{src}: header is not ';'-separated ({header[0][:60]!r}); not an IPA file?")
    missing = [c for c in UR10_JOINT_NAMES + _POS if c not in header]
    if missing:
        raise InputError(f"{src}: missing column(s) {', '.join(missing)}; columns found: {'; '.join(header)}")
    if not rows:
        raise InputError(f"{src}: no measurement rows after the header")
    return header, rows, lines


def _numbers(header: list[str], rows: list[list[str]], lines: list[int], src: str) -> np.ndarray:
    """The table's numbers (the timestamps left NaN): what ``parse_numeric_table`` gives with the decimal-comma
    parser, the same array bit for bit, from the cells made plain number text in one list comprehension and converted
    by NumPy (Python's ``float`` on each: the parser mapped cell by cell took 0.21 s of Series A's 0.4 s, this 0.14 s);
    a table with a row of another length or a cell that is not a finite number goes to ``parse_numeric_table``, whose
    refusal names it."""
    ncol = len(header)
    cols = [c for c, name in enumerate(header) if name != _TIMESTAMP]
    if cols and all(len(r) == ncol for r in rows):
        try:
            values = np.array([[r[c].strip().strip("\x00").strip().replace(",", ".") for c in cols] for r in rows],
                              dtype=object).astype(float)
        except (ValueError, TypeError):
            values = None
        if values is not None and np.isfinite(values).all():
            data = np.full((len(rows), ncol), np.nan)
            data[:, cols] = values
            return data
    return parse_numeric_table(rows, lines, header, src, _parse_decimal_comma, skip=(_TIMESTAMP,))


def _time_column(rows: list[list[str]], lines: list[int], idx: dict[str, int], src: str) -> np.ndarray | None:
    """Seconds since the first row when every timestamp is a proper YYYYMMDDhhmmss (Series A), else None."""
    if _TIMESTAMP not in idx:
        return None
    stamps = [_clean(r[idx[_TIMESTAMP]]) for r in rows]
    if not all(_TIMESTAMP_RE.match(s) for s in stamps):
        return None
    try:  # the fields by position (14 digits: strptime reads them so when it reads them), else strptime's message
        dt = [datetime(int(s[:4]), int(s[4:6]), int(s[6:8]), int(s[8:10]), int(s[10:12]), int(s[12:]))
              for s in stamps]
    except ValueError:
        dt = []
    try:
        dt = dt or [datetime.strptime(s, "%Y%m%d%H%M%S") for s in stamps]
    except ValueError as exc:
        bad = next(i for i, s in enumerate(stamps) if not _valid_stamp(s))
        raise InputError(
            f"{src}: column 'Timestamp', row {bad + 1} (line {lines[bad]}): {stamps[bad]!r} "
            f"is not a valid YYYYMMDDhhmmss time ({exc})"
        ) from None
    return np.array([(t - dt[0]).total_seconds() for t in dt], dtype=float)


def _extra_columns(data: np.ndarray, header: list[str], idx: dict[str, int], lines: list[int], src: str
                   ) -> dict[str, np.ndarray]:
    """Goal pose, Euler-angle std (rad) and unknown numeric columns (see the module docstring)."""
    extra: dict[str, np.ndarray] = {}
    for name, key in _GOAL.items():
        if name in idx:
            extra[key] = data[:, idx[name]].copy()
    if all(n in idx for n in _ROT_STD):
        rot_std = data[:, [idx[n] for n in _ROT_STD]]
        check_positive_sigma(rot_std, _ROT_STD, lines, src, unit="deg")
        rot_std = np.deg2rad(rot_std)
        for a, key in enumerate(("sigma_euler_rx", "sigma_euler_ry", "sigma_euler_rz")):
            extra[key] = rot_std[:, a].copy()
    for name in header:
        if name not in _KNOWN:
            extra[name] = data[:, idx[name]].copy()
    return extra


def _valid_stamp(s: str) -> bool:
    try:
        datetime.strptime(s, "%Y%m%d%H%M%S")
    except ValueError:
        return False
    return True


def read_ipa_flange_transform(
    folder: str | os.PathLike[str], filename: str = "Trafo_TM_F_init.txt"
) -> np.ndarray:
    """Read the T-Mac/flange transform of an IPA series, translation in metres.

    Args:
        folder: Series folder (``Series_C``) or the transform file itself.
        filename: File inside ``folder``: ``Trafo_TM_F_init.txt`` (default) or
            ``Trafo_TM_F_init_calib.txt``.

    Returns:
        The 4×4 homogeneous matrix as stored ("T_TM_F"), with the translation
        column converted from mm to m; the rotation is not re-orthonormalised.

    Raises:
        InputError: If the file is missing, does not hold 4 lines of 4 numbers,
            the last row is not ``0 0 0 1``, or the rotation block is not a
            rotation (|RᵀR − I| > 1e-4 or det < 0).
    """
    p = Path(folder)
    if p.is_dir():
        p = p / filename
    src = str(p)
    if not p.is_file():
        raise InputError(f"IPA flange transform '{src}' does not exist")
    lines = [ln for ln in _read_text(p).splitlines() if ln.strip().strip("\x00")]
    if len(lines) != 4:
        raise InputError(f"{src}: expected 4 lines of 4 numbers, found {len(lines)} non-empty lines")
    T = np.empty((4, 4))
    for r, ln in enumerate(lines):
        cells = ln.replace(";", " ").replace("\t", " ").strip().strip("\x00").split()
        if len(cells) != 4:
            raise InputError(f"{src}: line {r + 1} has {len(cells)} numbers, expected 4: {ln.strip()!r}")
        for c, cell in enumerate(cells):
            try:
                v = float(cell)
            except ValueError:
                raise InputError(f"{src}: line {r + 1}, column {c + 1}: {cell!r} is not a number") from None
            if not math.isfinite(v):
                raise InputError(f"{src}: line {r + 1}, column {c + 1}: value {cell!r} is not finite")
            T[r, c] = v
    if not np.allclose(T[3], [0.0, 0.0, 0.0, 1.0], atol=1e-9):
        raise InputError(f"{src}: line 4 is {T[3].tolist()}, expected 0 0 0 1")
    R = T[:3, :3]
    err = float(np.abs(R.T @ R - np.eye(3)).max())
    if err > 1e-4 or np.linalg.det(R) < 0:
        raise InputError(
            f"{src}: the 3×3 block is not a rotation (max |RᵀR − I| = {err:.3g}, det = {np.linalg.det(R):.6g})"
        )
    T[:3, 3] *= _MM
    T[3] = [0.0, 0.0, 0.0, 1.0]
    return T
