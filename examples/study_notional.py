"""The 90-notional-arm study (paper section 3.3.2) on a few arms: per arm heuristic, A on C_p, A on C_s.

The full study: ``pin-kpi-oed study notional90 --out out/notional90`` (resumable; --scheduler for Dask).

Run: python examples/study_notional.py [--arms 2] [--out study_out]
(--quick or PIN_KPI_OED_QUICK=1: the same steps on one arm and 10 poses; the paired comparison is then over one pair)
"""

from __future__ import annotations

import argparse
import os
import sys

from pin_kpi_oed.studies.study import format_notional_summary, notional_study

#: --quick (or PIN_KPI_OED_QUICK=1): smaller sizes, the same steps (the tests' run)
QUICK = os.environ.get("PIN_KPI_OED_QUICK") == "1" or "--quick" in sys.argv[1:]

ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
ap.add_argument("--quick", action="store_true", help="smaller sizes, the same steps")
ap.add_argument("--arms", type=int, default=1 if QUICK else 2)
ap.add_argument("--measurements", type=int, default=10 if QUICK else 60)
ap.add_argument("--out", default="study_out")
a = ap.parse_args()

summary = notional_study(a.out, m=a.measurements, seed=0, arms=a.arms, workers=1)
print(format_notional_summary(summary))
