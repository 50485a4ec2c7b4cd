"""The path KPI and the 6-D KPI: KR 15 cell with a weld seam on the car body (the shipped ``kr15_seam``).

The seam is a working path of the cell file (0.8 m, a TCP pose every 5 mm, IK on one branch). Four designs: the
heuristic (random feasible poses), the point KPI at the seam's end points (``kpi``), the mean TCP covariance along
the seam (``kpi_path``) and the 6-D KPI with the torch orientation at 200 mm (``kpi6``); each scored by the
predicted sigma along the seam. A path the robot cannot follow is refused naming the sample (shown at the end).

Run: python examples/design_weld_seam.py [--measurements 60]
"""

from __future__ import annotations

import argparse
import os
import sys

import yaml

from pin_kpi_oed.cell.cell import CELL_DIR, cell_from_dict, load_cell
from pin_kpi_oed.design.optimize import DesignOptions, DesignProblem, ipopt_options, run_designs
from pin_kpi_oed.design.path_profile import path_profile
from pin_kpi_oed.errors import InputError

#: --quick (or PIN_KPI_OED_QUICK=1): smaller sizes, the same steps (the tests' run)
QUICK = os.environ.get("PIN_KPI_OED_QUICK") == "1" or "--quick" in sys.argv[1:]

ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
ap.add_argument("--quick", action="store_true", help="smaller sizes, the same steps")
ap.add_argument("--measurements", type=int, default=20 if QUICK else 60)
ap.add_argument("--seed", type=int, default=0)
a = ap.parse_args()

cell = load_cell("kr15_seam")
print(cell.summary())
problem = DesignProblem(cell)
# quick: the first start from the heuristic design (no pool selection) and fewer Ipopt iterations (the full run:
# the defaults)
opts = DesignOptions(start="random", ipopt=ipopt_options(max_iter=20)) if QUICK else None
results = run_designs(cell, ["random", "kpi", "kpi_path", "kpi6"], a.measurements, a.seed, opts, problem)
for r in results:
    p = path_profile(problem, r.q_meas, cell.q_path, cell.orientation_length_m)
    print(f"{r.criterion:<9} along the seam: TCP sigma RMS {p['rms_sigma_pos_m'] * 1e6:6.3f} um, worst "
          f"{p['worst_sigma_pos_m'] * 1e6:6.3f} um; orientation RMS {p['rms_sigma_rot_rad'] * 1e6:6.3f} urad; "
          f"at 200 mm RMS {p['rms_sigma_at_length_m'] * 1e6:6.3f} um; feasible {r.feasible}")

# a seam moved into the car body cannot be welded: refused naming the sample and the fix
d = yaml.safe_load((CELL_DIR / "kr15_seam.yaml").read_text())
d["working_paths"][0]["waypoints"][1]["xyz_m"] = [1.3, 0.4, 0.9]
try:
    cell_from_dict(d, "seam_into_the_car", CELL_DIR)
except InputError as exc:
    print(f"refused: {exc}")
