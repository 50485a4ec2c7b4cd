"""Small helpers shared by the CLI modules (parsing option values)."""

from __future__ import annotations

import argparse
from typing import Any

import numpy as np

from pin_kpi_oed.errors import InputError
from pin_kpi_oed.validation.options import floats


def parse_floats(text: str, n: int | tuple[int, ...], what: str) -> np.ndarray:
    """Parse ``"x,y,z"`` into floats (SI units); ``n`` is the allowed count(s).

    Raises:
        InputError: not numbers, not finite, or the wrong count (naming the option ``what``).
    """
    ns = (n,) if isinstance(n, int) else n
    v = np.array(floats(text, what))  # the one comma-number parser (validation.options)
    if v.size not in ns:
        raise InputError(f"{what}: expected {' or '.join(map(str, ns))} finite comma-separated numbers, got '{text}'")
    return v


def add_table_options(p: argparse.ArgumentParser) -> None:
    """``--units`` and ``--columns``: read measurement / target files as they come (one call per command)."""
    p.add_argument("--units", default=None,
                   help="units of the numbers in the input files, e.g. mm,deg (default: SI, m and rad; a file in "
                        "mm/degrees is refused without this)")
    p.add_argument("--columns", default=None,
                   help="column names of the input files, ours=theirs, e.g. joint_a1=A1,...,x=X,y=Y,z=Z")


def table_options(args: argparse.Namespace, robot: Any = None) -> dict:
    """Keyword arguments of the readers from ``--units`` / ``--columns`` (and the robot's joint units and the
    largest magnitude of each joint's limits: a wrist of ±400° is not read as degrees).

    Raises:
        InputError: an unknown unit or a malformed mapping (named with the option).
    """
    from pin_kpi_oed.data.table import parse_columns, parse_units

    columns = getattr(args, "columns", None)
    parse_columns(columns)  # a malformed mapping is refused before any file is read
    out = {"units": parse_units(getattr(args, "units", None)), "columns": columns}
    if robot is not None:
        out["joint_units"] = list(robot.joint_units)
        out["joint_guard"] = robot.unit_guard.tolist()  # a joint of a few turns (its own limit) keeps its range
    return out
