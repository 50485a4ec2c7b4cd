"""Session caches of the static-check, hostile-input and environment tests: the IPA UR10 series, imported once per
test process (tests/test_io.py and tests/test_iso9283_vectorised.py read Series A, 11,911 rows, three times).

The tests that read Series A are marked ``xdist_group(IPA_GROUP)``: on one worker, the series is imported once.
"""

from __future__ import annotations

import copy
import functools
from pathlib import Path

#: the xdist group of the tests that read the IPA Series A
IPA_GROUP = "g_ipa_series_a"


@functools.cache
def _imported(path: str):
    from pin_kpi_oed.data.ipa import import_ipa

    return import_ipa(path)


def ipa_series(path: Path):
    """The :class:`~pin_kpi_oed.data.measurements.MeasurementSet` of ``import_ipa(path)`` (a series folder or its
    file), imported on the first call for that path; each call gets its own copy (a test that wrote into its arrays
    changes no other test's)."""
    return copy.deepcopy(_imported(str(Path(path).resolve())))
