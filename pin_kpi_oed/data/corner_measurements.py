"""Camera measurement files: the board's detected corners, one CSV row per corner (px, rad).

A camera measures a calibration board's corners in an image taken at one robot pose. The file has one row per
detected corner::

    pose,corner,u_px,v_px,shoulder_pan_joint,shoulder_lift_joint,...
    img_000,0,612.41,488.07,0.0,-1.57,...
    img_000,1,641.93,487.55,0.0,-1.57,...

==============================  ========  ==========================================================
column                          unit      meaning
==============================  ========  ==========================================================
``pose``                        (text)    the image (pose) label; rows of one pose share its joints
``corner``                      (int)     the corner's id on the board (row · (columns − 1) + column)
``u_px``, ``v_px``              px        the corner's image coordinates (OpenCV's convention: pixel
                                          centres at whole numbers)
one per actuated joint, named   rad       the joint values of the pose (prismatic joints: m)
exactly as in the URDF
==============================  ========  ==========================================================

A corner not detected has no row (it is never guessed). :func:`corner_arrays` turns the rows into the camera
model's layout: the poses' joint values (m, n) and their pixels (m, 2N) with NaN for a corner not seen.
"""

from __future__ import annotations

import csv
import io
import math
import os
from dataclasses import dataclass

import numpy as np

from pin_kpi_oed.data.atomic import atomic_write_text
from pin_kpi_oed.data.table import read_text_table
from pin_kpi_oed.errors import InputError

__all__ = ["CornerSet", "read_corners", "write_corners", "is_corner_file", "CORNER_COLUMNS"]

#: the columns every camera measurement file has besides the joints
CORNER_COLUMNS = ("pose", "corner", "u_px", "v_px")


@dataclass
class CornerSet:
    """Detected board corners, one entry per corner (SI units, px).

    Attributes:
        pose: the pose (image) label of every row, (k,) str.
        corner: the corner id of every row, (k,) int.
        uv_px: the corner's (u, v), (k, 2) px.
        joint_names: the joint columns; q: the joint values of every row, (k, n) rad (m for prismatic joints).
    """

    pose: np.ndarray
    corner: np.ndarray
    uv_px: np.ndarray
    joint_names: list[str]
    q: np.ndarray

    def __len__(self) -> int:
        return len(self.pose)

    @property
    def poses(self) -> list[str]:
        """The pose labels in their first-appearance order."""
        return list(dict.fromkeys(self.pose.tolist()))

    def arrays(self, n_corners: int, source: str = "camera measurements") -> tuple[list[str], np.ndarray, np.ndarray]:
        """(pose labels, joint values (m, n), pixels (m, 2 n_corners) with NaN for a corner not detected).

        Raises:
            InputError: a corner id outside the board, a corner twice in one pose, or a pose whose rows disagree
                on its joint values.
        """
        labels = self.poses
        index = {lab: i for i, lab in enumerate(labels)}
        Q = np.full((len(labels), len(self.joint_names)), np.nan)
        uv = np.full((len(labels), 2 * n_corners), np.nan)
        for k in range(len(self)):
            i, c = index[self.pose[k]], int(self.corner[k])
            if not 0 <= c < n_corners:
                raise InputError(f"{source}: row {k + 2}: corner {c} is not on the board (ids 0..{n_corners - 1})")
            if np.isfinite(uv[i, 2 * c]):
                raise InputError(f"{source}: pose '{self.pose[k]}' has corner {c} twice")
            if np.isnan(Q[i, 0]):
                Q[i] = self.q[k]
            elif not np.allclose(Q[i], self.q[k], rtol=0.0, atol=1e-12):
                raise InputError(f"{source}: pose '{self.pose[k]}': row {k + 2}'s joint values differ from the "
                                 "pose's first row")
            uv[i, 2 * c:2 * c + 2] = self.uv_px[k]
        return labels, Q, uv

    @classmethod
    def from_arrays(cls, labels: list[str], Q: np.ndarray, uv: np.ndarray, joint_names: list[str]) -> CornerSet:
        """Rows from (pose labels, joint values (m, n), pixels (m, 2N), NaN for a corner not seen)."""
        Q, uv = np.atleast_2d(np.asarray(Q, float)), np.atleast_2d(np.asarray(uv, float))
        N = uv.shape[1] // 2
        pix = uv.reshape(len(Q), N, 2)
        seen = np.all(np.isfinite(pix), axis=2)
        i, c = np.nonzero(seen)
        return cls(np.asarray(labels, dtype=object)[i].astype(str), c.astype(int), pix[i, c], list(joint_names),
                   Q[i])


def write_corners(cs: CornerSet, path: str | os.PathLike[str]) -> None:
    """Write the corners as CSV (module docstring), atomically; floats read back bit-identical.

    Raises:
        InputError: a joint name that clashes with the corner columns.
    """
    clash = [n for n in cs.joint_names if n in CORNER_COLUMNS]
    if clash:
        raise InputError(f"cannot write '{path}': joint column(s) {clash} clash with the corner columns")
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(list(CORNER_COLUMNS) + list(cs.joint_names))
    for k in range(len(cs)):
        w.writerow([cs.pose[k], int(cs.corner[k]), repr(float(cs.uv_px[k, 0])), repr(float(cs.uv_px[k, 1]))]
                   + [repr(float(v)) for v in cs.q[k]])
    atomic_write_text(path, buf.getvalue())


def is_corner_file(header: list[str]) -> bool:
    """Whether a measurement file's header is a camera's (:data:`CORNER_COLUMNS`)."""
    return all(c in header for c in CORNER_COLUMNS)


def read_corners(path: str | os.PathLike[str]) -> CornerSet:
    """Read a camera measurement file (module docstring).

    Returns:
        The :class:`CornerSet`.

    Raises:
        InputError: a missing file or column, a cell that is not a number, a corner id that is not a whole number,
            a joint value beyond ±4π rad (degrees?), or no rows; the file, row and column named.
    """
    src = str(path)
    header, _, rows, lines = read_text_table(path, src, "camera measurement file")
    missing = [c for c in CORNER_COLUMNS if c not in header]
    if missing:
        raise InputError(f"{src}: missing column(s) {', '.join(missing)} (a camera measurement file has "
                         f"{', '.join(CORNER_COLUMNS)} and one column per joint)")
    joints = [h for h in header if h not in CORNER_COLUMNS]
    if not joints:
        raise InputError(f"{src}: no joint columns (one per joint, named as in the URDF, rad)")
    if not rows:
        raise InputError(f"{src}: no corner rows")
    col = {h: i for i, h in enumerate(header)}
    pose, corner, uv, q = [], [], [], []
    for r, row in zip(lines, rows):
        if len(row) != len(header):
            raise InputError(f"{src}: line {r}: {len(row)} cells, the header has {len(header)}")
        pose.append(str(row[col["pose"]]).strip())
        corner.append(_number(row[col["corner"]], src, r, "corner", whole=True))
        uv.append([_number(row[col[c]], src, r, c) for c in ("u_px", "v_px")])
        q.append([_number(row[col[j]], src, r, j) for j in joints])
    Q = np.asarray(q, float)
    if np.abs(Q).max() > 4 * math.pi:
        i, j = (int(x) for x in np.unravel_index(int(np.argmax(np.abs(Q))), Q.shape))
        raise InputError(f"{src}: line {lines[i]}, column '{joints[j]}': {Q[i, j]:g} is beyond ±4π rad: the joint "
                         "values look like degrees; give them in rad")
    return CornerSet(np.asarray(pose, dtype=str), np.asarray(corner, int), np.asarray(uv, float), joints, Q)


def _number(text: object, src: str, row: int, column: str, whole: bool = False) -> float:
    try:
        v = float(str(text).strip())
    except ValueError:
        raise InputError(f"{src}: line {row}, column '{column}': {text!r} is not a number") from None
    if not math.isfinite(v) or (whole and (v != int(v) or v < 0)):
        raise InputError(f"{src}: line {row}, column '{column}': {text!r} is not a "
                         f"{'whole number >= 0' if whole else 'finite number'}")
    return int(v) if whole else v
