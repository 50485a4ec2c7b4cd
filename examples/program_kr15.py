"""From a KPI design to a robot program on the KR 15 cell: margins, ordering, safe moves, export.

1. KPI design with a 20 mm clearance margin and a 1 deg incidence margin (the optimiser's cell is
   tightened; the independent check reports the true clearance and incidence of every pose);
2. the poses ordered for the least predicted cycle time (OR-Tools; move time max_j |dq_j| / v_j with
   the URDF's joint speeds), every move checked densely (<= 1 deg, Coal, capsules + 10 mm), colliding
   moves routed through safe via poses;
3. the program exported as CSV, URScript, KUKA KRL (.src + .dat) and ABB RAPID into the current folder.

Run: python examples/program_kr15.py [--measurements 60]
The same from the command line:
    pin-kpi-oed design --cell kr15 --criteria kpi --json design.json
    pin-kpi-oed export design.json --format krl --out kpi_kr15.src
"""

from __future__ import annotations

import argparse
import os
import sys

import numpy as np

from pin_kpi_oed.cell.cell import load_cell
from pin_kpi_oed.cell.feasibility import FeasibilityChecker
from pin_kpi_oed.data.atomic import atomic_write_text
from pin_kpi_oed.design.margins import with_margins
from pin_kpi_oed.design.optimize import DesignOptions, DesignProblem, ipopt_options, run_designs
from pin_kpi_oed.program.export import FORMATS, ProgramInfo, write_program
from pin_kpi_oed.program.ordering import ProgramOptions, plan_program

#: --quick (or PIN_KPI_OED_QUICK=1): smaller sizes, the same steps (the tests' run)
QUICK = os.environ.get("PIN_KPI_OED_QUICK") == "1" or "--quick" in sys.argv[1:]

ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
ap.add_argument("--quick", action="store_true", help="smaller sizes, the same steps")
ap.add_argument("--measurements", type=int, default=15 if QUICK else 60)
ap.add_argument("--seed", type=int, default=0)
a = ap.parse_args()

cell = load_cell("kr15")
design_cell = with_margins(cell, clearance_margin_m=0.02, incidence_margin_deg=1.0)
problem = DesignProblem(design_cell)
# quick: one start from a pool of 150 candidates, at most 20 Ipopt iterations
opts = (DesignOptions(n_starts=1, pool_size=150, ipopt=ipopt_options(max_iter=20)) if QUICK
        else DesignOptions(n_starts=2, ipopt=ipopt_options(max_iter=500)))
kpi = run_designs(design_cell, ["kpi"], a.measurements, a.seed, opts, problem)[-1]
rep = FeasibilityChecker(cell).check(kpi.q_meas)  # the true cell
print(f"KPI design: {a.measurements} poses, TCP sigma {kpi.tcp_sigma_m * 1e6:.3f} um; true clearance >= "
      f"{rep.clearance_m.min() * 1e3:.1f} mm, incidence <= {rep.incidence_deg.max():.1f} deg (limit 30)")

# quick: fewer safe via poses sampled for the repairs of colliding moves
prog = plan_program(cell, kpi.q_meas, ProgramOptions(margin_m=0.01, seed=a.seed, via_pool=100 if QUICK else 300))
print(prog.summary())
info = ProgramInfo(cell=cell.name, design=f"examples/program_kr15.py (kpi, seed {a.seed})", robot=cell.robot.name,
                   joint_names=list(cell.robot.joint_names), revolute=np.asarray(cell.robot.is_revolute, bool),
                   cycle_time_s=prog.cycle_time_s, name="kpi_kr15")
for fmt in FORMATS:
    texts = write_program(fmt, prog.path, [w.kind for w in prog.waypoints], [w.pose for w in prog.waypoints], info)
    for suffix, text in texts.items():
        atomic_write_text(f"kpi_kr15{suffix}", text)
        print(f"wrote kpi_kr15{suffix} ({len(text.splitlines())} lines)")
