"""KPI optimum experimental design on the KR 15 measurement cell (paper section 3.2), with a certificate.

Heuristic (random feasible poses), the state of the art (A on C_p) and the KPI design (A on C_s), all
collision-free, visible and within bounds by the independent check; then the approximate-design bound.

Run: python examples/design_kr15.py [--measurements 60]
"""

from __future__ import annotations

import argparse
import os
import sys

from pin_kpi_oed.cell.cell import load_cell
from pin_kpi_oed.design.optimality import certify
from pin_kpi_oed.design.optimize import DesignOptions, DesignProblem, ipopt_options, run_designs

#: --quick (or PIN_KPI_OED_QUICK=1): smaller sizes, the same steps (the tests' run)
QUICK = os.environ.get("PIN_KPI_OED_QUICK") == "1" or "--quick" in sys.argv[1:]

ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
ap.add_argument("--quick", action="store_true", help="smaller sizes, the same steps")
ap.add_argument("--measurements", type=int, default=20 if QUICK else 60)
ap.add_argument("--seed", type=int, default=0)
a = ap.parse_args()

cell = load_cell("kr15")  # or a path to your own cell YAML
print(cell.summary())
problem = DesignProblem(cell)
# quick: the first start from the heuristic design (no pool selection) and fewer Ipopt iterations (the full run:
# the defaults)
opts = DesignOptions(start="random", ipopt=ipopt_options(max_iter=20)) if QUICK else None
results = run_designs(cell, ["random", "param", "kpi"], a.measurements, a.seed, opts, problem)
cert = certify(problem, a.measurements, pool_size=500 if QUICK else 5000, seed=a.seed,
               extra=[r.q_meas for r in results])
heur = results[0]
for r in results:
    print(f"{r.criterion:<7} tr(C_s) = {r.trace_cs_m2 * 1e6:.4e} mm^2  TCP sigma = {r.tcp_sigma_m * 1e6:6.3f} um  "
          f"vs random {-r.improvement_over(heur):+6.1f} %  efficiency {100 * cert.efficiency(r.trace_cs_m2):5.1f} %  "
          f"min clearance {r.min_clearance_m * 1e3:5.1f} mm  max incidence {r.max_incidence_deg:4.1f} deg  "
          f"feasible {r.feasible}")
print(f"certificate: tr(C_s) >= {cert.lower_bound_trace_cs_m2 * 1e6:.4e} mm^2 for any {a.measurements}-pose design "
      f"from {cert.pool_size} feasible poses")
