"""The segment table of a collision model, as its checks and its Coal distances read it.

A :class:`~pin_kpi_oed.cell.collision.CollisionModel` is built from the cell's capsules: robot capsules hang on
their joints, obstacles on the base, and the beam runs from the tracker to the reflector. The static and working
checks of a cell (:mod:`pin_kpi_oed.cell.cell_checks`) and the Coal geometry of the same segments
(:mod:`pin_kpi_oed.cell.coal_distances`) need only this table and the constraint evaluation; :class:`SegmentModel`
states it, so that both sit below the collision model instead of importing it back.
"""

from __future__ import annotations

from typing import Any, Literal, Protocol

import numpy as np

from pin_kpi_oed.cell.cell_model import Cell
from pin_kpi_oed.cell.constraint_rows import ConstraintRows

__all__ = ["SegmentModel"]


class SegmentModel(Protocol):
    """Segments (m, base frame; robot segments in their joint's frame) and the rows built on them.

    Attributes:
        cell: the cell the table was built from.
        robot: the cell's robot.
        n_robot, n_obst: the number of robot capsules and obstacle capsules (the beam is last).
        tracker: the tracker's position in the base frame (3,) m.
        seg_names: segment names; ``seg_joint`` their chain index (0 fixed, −1 obstacle, −2 beam).
        A_loc, B_loc, radius: end points (k, 3) m and radii (k,) m.
        beam: the beam's segment index.
        halfspaces: (normal, offset) of each half-space in the base frame (m).
        pairs, half, with_incidence, info, jac_rows, jac_cols: the active constraint rows
            (see :meth:`set_rows`); ``rows_all`` every row before pruning.
    """

    cell: Cell
    robot: Any
    n_robot: int
    n_obst: int
    tracker: np.ndarray
    seg_names: list[str]
    seg_joint: np.ndarray
    A_loc: np.ndarray
    B_loc: np.ndarray
    radius: np.ndarray
    beam: int
    halfspaces: list[tuple[np.ndarray, float]]
    pairs: Any
    half: Any
    with_incidence: bool
    info: ConstraintRows
    jac_rows: np.ndarray
    jac_cols: np.ndarray
    rows_all: dict

    def skipped(self, a: int, b: int) -> bool:
        """Whether segments a and b are in the user's skip list."""

    def beam_skipped(self, a: int) -> bool:
        """Whether segment a may cross the beam."""

    def skipped_half(self, a: int, hname: str) -> bool:
        """Whether segment a may cross half-space ``hname``."""

    def set_rows(self, rows: dict) -> None:
        """Make ``rows`` the active constraint rows."""

    def evaluate(self, Q: np.ndarray, with_grad: Literal[False], backend: str = ..., band: float | None = ...
                 ) -> np.ndarray:
        """Constraint values g(Q) ≥ 0 of the active rows, (m, rows)."""
