r"""Several reflector nests on one tool: which nest a measurement row was taken at, and what the nests share.

A tool may carry several nests (seats of the reflector), their positions ``nests_m`` (k, 3) known in the tool
frame relative to each other (bored in one holder, from its drawing or a coordinate measuring machine). Row i of a
measurement is taken at nest ``nest[i]``::

    y_i = tracker_T_base · oMtool(p, q_i) · (nests_m[nest_i] + δr)

**Parameters.** One offset δr (the ``reflector`` group) is shared by every nest: the holder's placement on the
tool, the one unknown a set of nests known relative to each other leaves. As with one reflector it moves no TCP
(the TCP is given in the tool frame, the holder is not). What a second nest makes identifiable is what moves the
nests apart: the last joint's rotation about its own axis (with one nest off that axis the shared offset absorbs
it exactly) and, with a nest on the last axis, the placement's rotations across it. The last joint's translation
along its axis stays absorbed by δr under any set of nests (it moves every nest alike), so a TCP away from the
nests keeps that part of its σ (:mod:`pin_kpi_oed.oed.held`); one offset per nest would add three unknowns per nest
and absorb the rotations as well, and buys nothing at the TCP.

The measurement file carries the nest of each row in a column ``nest`` (an integer 0 … k−1; no column: every row
at nest 0); :func:`nest_column` reads and checks it.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from pin_kpi_oed.data.measurement_set import NEST_COLUMN
from pin_kpi_oed.errors import InputError

__all__ = ["NEST_COLUMN", "check_nests", "check_row_nest", "nest_column"]


def check_nests(reflector_m: np.ndarray, nests_m: Any, where: str = "nests_m") -> np.ndarray:
    """The nests of a tool, (k, 3) m, nest 0 equal to the reflector offset.

    Args:
        reflector_m: the reflector offset in the tool frame (3,) m; nests_m: the nests (k, 3) m or None (one nest).
        where: the field named in an error.

    Returns:
        (k, 3) float array.

    Raises:
        InputError: not k × 3 finite numbers, two nests closer than 1 mm, or nest 0 not the reflector offset.
    """
    if nests_m is None:
        return np.asarray(reflector_m, float).reshape(1, 3).copy()
    try:
        N = np.asarray(nests_m, float)
    except (TypeError, ValueError):
        raise InputError(f"{where}: expected a list of [x, y, z] positions in m") from None
    if N.ndim != 2 or N.shape[1] != 3 or len(N) == 0 or not np.all(np.isfinite(N)):
        raise InputError(f"{where}: expected a list of [x, y, z] positions in m, got shape {N.shape}")
    d = np.linalg.norm(N[:, None, :] - N[None, :, :], axis=2) + np.eye(len(N))
    if np.any(d < 1e-3):
        i, j = np.argwhere(d < 1e-3)[0]
        raise InputError(f"{where}: nests {i} and {j} are {d[i, j] * 1e3:.3g} mm apart (one nest listed twice?)")
    if np.linalg.norm(N[0] - np.asarray(reflector_m, float)) > 1e-9:
        raise InputError(f"{where}: nest 0 {N[0].tolist()} is not reflector_m {np.asarray(reflector_m).tolist()} "
                         "(list the reflector offset first)")
    return N.copy()


def check_row_nest(nest: Any, k: int, where: str = "column 'nest'") -> np.ndarray:
    """Nest indices of rows, (m,) int, each in 0 … k−1.

    Raises:
        InputError: a value that is not an integer of a nest (the row and value named).
    """
    v = np.asarray(nest, float).reshape(-1)
    bad = np.flatnonzero(~np.isfinite(v) | (v != np.round(v)) | (v < 0) | (v > k - 1))
    if bad.size:
        i = int(bad[0])
        raise InputError(f"{where}, row {i + 1}: nest {v[i]:g} is not one of the tool's nests 0 … {k - 1}")
    return v.astype(int)


def nest_column(data: Any, k: int) -> np.ndarray | None:
    """The nest of every row of a measurement set (its ``nest`` column, kept among the extra columns), checked
    against the tool's ``k`` nests; None when the file has no such column (every row at nest 0).

    Raises:
        InputError: a row at a nest the tool does not have (the file, row and value named).
    """
    col = getattr(data, "extra", {}).get(NEST_COLUMN)
    if col is None:
        return None
    src = getattr(data, "source", "") or "measurements"
    return check_row_nest(col, k, f"{src}: column '{NEST_COLUMN}'")
