"""The model formats ``export-model --format`` knows: one line per format."""

from __future__ import annotations

import os

import numpy as np

from pin_kpi_oed.errors import InputError
from pin_kpi_oed.calibrated.formats.base import ExportReport, ModelFormat
from pin_kpi_oed.calibrated.formats.ur_yaml import UrYamlFormat
from pin_kpi_oed.calibrated.formats.urdf import UrdfFormat

__all__ = ["MODEL_FORMATS", "export_model"]

#: name -> format (one line per format).
MODEL_FORMATS: dict[str, ModelFormat] = {f.name: f for f in (
    UrdfFormat(),
    UrYamlFormat(),
)}


def export_model(cm, path: str | os.PathLike, fmt: str, *, tcp_m: np.ndarray | None = None, frames: bool = True,
                 source: str = "") -> ExportReport:
    """Write a calibrated model in format ``fmt`` (a key of :data:`MODEL_FORMATS`).

    Raises:
        InputError: an unknown format, or a model the format cannot hold.
        SolverError: the written file would not reproduce the calibrated kinematics (nothing written).
    """
    if fmt not in MODEL_FORMATS:
        raise InputError(f"model_format: unknown model format '{fmt}' (known: {', '.join(MODEL_FORMATS)})")
    return MODEL_FORMATS[fmt].write(cm, path, tcp_m=tcp_m, frames=frames, source=source)
