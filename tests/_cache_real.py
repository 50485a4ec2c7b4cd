"""Cached inputs of the real-data tests (the IPA UR10 series at ../shared/data/ipa_ur10).

Each series is imported once per test process (:func:`ipa_series` hands out a copy: a test may change its copy),
and the one expensive fit two tests share, the 6-D calibration of Series C's first half with the discrepancy
(:func:`series_c_6d_half`), is made once per process. With ``pytest -n 2 --dist loadgroup`` the tests sharing that
fit carry ``@pytest.mark.xdist_group(C6D_GROUP)``, so that they run in one worker and the fit is made once.
"""

from __future__ import annotations

import copy
import functools
from pathlib import Path
from typing import Any

import numpy as np
import pytest

_here = Path(__file__).resolve()
#: The IPA UR10 data: ../shared from the checkout, or one level further up from a worktree.
IPA = next((p / "shared" / "data" / "ipa_ur10" for p in (_here.parents[2], _here.parents[3])
            if (p / "shared" / "data" / "ipa_ur10").is_dir()), _here.parents[2] / "shared" / "data" / "ipa_ur10")
needs_ipa = pytest.mark.skipif(not IPA.is_dir(), reason=f"IPA data not found at {IPA}")
#: The xdist group of the tests that share :func:`series_c_6d_half`.
C6D_GROUP = "cache_real_series_c_6d_half"


@functools.cache
def _imported(series: str) -> Any:
    from pin_kpi_oed.data.ipa import import_ipa

    return import_ipa(IPA / f"Series_{series}")


def ipa_series(series: str) -> Any:
    """The IPA UR10 series ``series`` (``"B"``, ``"C"``, ``"D"``, ...) as :func:`pin_kpi_oed.data.ipa.import_ipa`
    reads it (SI units, 6-D rows, the files' sigma columns), imported once per process.

    Args:
        series: the letter of the series folder ``Series_<letter>``.

    Returns:
        A deep copy of the imported :class:`~pin_kpi_oed.data.measurements.MeasurementSet` (the caller may change it).
    """
    return copy.deepcopy(_imported(series))


@functools.cache
def _c6d_half() -> tuple[Any, Any, Any]:
    from pin_kpi_oed import NoiseModel, TrackerModel, load_robot
    from pin_kpi_oed.identification.identify import identify

    tr, te = _imported("C").split(0.5, seed=0)
    model = TrackerModel(load_robot("ur10"), reflector_m=np.array([0.0, 0.0, 0.109]),
                         noise=NoiseModel(sigma_xyz_m=(1e-4,) * 3, sigma_rot_rad=1e-4), pose6d=True)
    cm = identify(model, tr, discrepancy="auto", seed=0, raise_on_failure=False,
                  scale_covariance=True).calibrated_model()
    return tr, te, cm


def series_c_6d_half() -> tuple[Any, Any, Any]:
    """The 6-D calibration of the real UR10's Series C, first half (seeded split 0.5, seed 0): position and probe
    orientation, σ 0.1 mm and 0.1 mrad as relative weights (the covariance scaled by the reduced χ²), nominal
    reflector (0, 0, 0.109) m, the discrepancy ``auto`` (seed 0). Made once per process.

    Returns:
        (training half, held-out half, calibrated model): the halves are copies; the calibrated model is shared,
        read it only (predictions, registration into a new model).
    """
    tr, te, cm = _c6d_half()
    return copy.deepcopy(tr), copy.deepcopy(te), cm
