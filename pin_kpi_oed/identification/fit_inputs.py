"""Step 1 of :func:`~pin_kpi_oed.identification.identify.identify`: the checked inputs.

Joint columns, units, duplicate rows, weights, and the stations (each with at least
:data:`MIN_STATION_ROWS` rows, one row refused by name).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from pin_kpi_oed.data.measurements import MeasurementSet
from pin_kpi_oed.errors import InputError
from pin_kpi_oed.identification.identify_options import IdentifyOptions
from pin_kpi_oed.identification.problem import align_data
from pin_kpi_oed.model.tracker import TrackerModel
from pin_kpi_oed.validation.units import check_position_spread_m

__all__ = ["MIN_STATION_ROWS", "FitInputs", "check_inputs", "default_station_label"]

#: Fewest rows of a station: a rigid registration of its tracker pose needs 3 points.
MIN_STATION_ROWS = 3


def default_station_label(data: MeasurementSet) -> str:
    """Label of a data set without a station column: its file name without extension (or ``station``)."""
    return Path(data.source).stem if data.source and Path(data.source).stem else "station"


def check_duplicates(Q: np.ndarray, data: MeasurementSet) -> None:
    """Refuse rows with the same joint values and the same measured values.

    Raises:
        InputError: duplicate rows (the first group is named by its 1-based row numbers).
    """
    parts = [Q, data.position_m] + ([data.rotvec_rad] if data.rotvec_rad is not None else [])
    keys = np.ascontiguousarray(np.hstack(parts) + 0.0)
    _, first, inv, counts = np.unique(keys, axis=0, return_index=True, return_inverse=True, return_counts=True)
    if np.any(counts > 1):
        g = int(np.flatnonzero(counts > 1)[0])
        rows = np.flatnonzero(inv.ravel() == g) + 1
        raise InputError(f"{data.source or 'measurement set'}: duplicate measurements (same joint values and same "
                         f"measured values): rows {', '.join(map(str, rows[:5]))}; remove the copies")


@dataclass
class FitInputs:
    """Checked inputs of one identification."""

    src: str
    Q: np.ndarray
    pose6d: bool
    sigma: np.ndarray | None
    sigma_source: str
    labels: list[str]
    rows: list[np.ndarray]


def check_inputs(model: TrackerModel, data: MeasurementSet, opts: IdentifyOptions) -> FitInputs:
    """Step 1: joint columns, units, duplicates, weights, stations (at least 3 rows each)."""
    src = data.source or "measurement set"
    Q = align_data(model.robot, data)
    check_duplicates(Q, data)
    if opts.weights == "data" and data.sigma_m is None:
        raise InputError(f"{src}: weights='data' but the file has no sigma columns")
    use_data_sigma = data.sigma_m is not None and opts.weights in ("auto", "data")
    groups = data.station_rows(opts.station if opts.station is not None else default_station_label(data))
    for lab, rows in groups.items():
        where = f"{src}: station '{lab}'" if data.station is not None else src
        if rows.size == 1:
            raise InputError(f"{where} has only one row (row {int(rows[0]) + 1}): a station needs at least "
                             f"{MIN_STATION_ROWS} rows to determine its tracker pose; add rows or remove the station")
        if rows.size < MIN_STATION_ROWS:
            raise InputError(f"{where} has {rows.size} rows: too few to determine its tracker pose (at least "
                             f"{MIN_STATION_ROWS}, better many more)")
        check_position_spread_m(data.position_m[rows], model.robot.reach() + float(np.linalg.norm(model.reflector_m)),
                                where)
    return FitInputs(src, Q, bool(opts.use_orientation and data.rotvec_rad is not None),
                   np.asarray(data.sigma_m, float) if use_data_sigma else None,
                   "data" if use_data_sigma else "noise model", list(groups), list(groups.values()))
