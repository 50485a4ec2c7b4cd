"""A measurement cell built from files: an environment URDF and mesh, Cartesian working targets.

Writes, into a folder, a fixture mesh (STL, in mm as CAD exports it) and a cell YAML for the KR 15 that
reads it (`environment:`; a URDF of boxes / meshes works the same way, see the shipped ur10 cell and
cells/ur10_table.urdf) and gives the working configuration as a TCP target (`working_targets:`, solved
by IK). Then it shows what the optimiser gets (enclosing capsules), what the independent check gets (the
mesh itself), the IK solution, and runs a KPI design in the cell: its closest approach to the mesh is
what the capsules' conservatism leaves (the capsules enclose the mesh).

Run: python examples/cell_from_files.py [--out cell_from_files] [--measurements 60]
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

import numpy as np
import trimesh
import yaml

from pin_kpi_oed.cell.cell import CELL_DIR, load_cell
from pin_kpi_oed.cell.feasibility import FeasibilityChecker
from pin_kpi_oed.design.optimize import DesignOptions, ipopt_options, run_designs

#: --quick (or PIN_KPI_OED_QUICK=1): smaller sizes, the same steps (the tests' run)
QUICK = os.environ.get("PIN_KPI_OED_QUICK") == "1" or "--quick" in sys.argv[1:]

ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
ap.add_argument("--quick", action="store_true", help="smaller sizes, the same steps")
ap.add_argument("--out", default="cell_from_files", help="folder for the mesh and the cell file")
ap.add_argument("--measurements", type=int, default=30 if QUICK else 60)
a = ap.parse_args()
out = Path(a.out)
out.mkdir(exist_ok=True)

# 1. a fixture as CAD exports it: an L-shaped bracket in mm (non-convex)
bracket = trimesh.util.concatenate([
    trimesh.creation.box([600.0, 150.0, 300.0]),
    trimesh.creation.box([150.0, 600.0, 300.0], transform=trimesh.transformations.translation_matrix([-225, 225, 0]))])
bracket.export(out / "bracket.stl")

# 2. the shipped KR 15 cell, plus the bracket hanging beside the working position, and the working configuration as a TCP target
d = yaml.safe_load((CELL_DIR / "kr15.yaml").read_text())
d["robot"] = "kr15"
d.pop("working_configurations_deg")
d["environment"] = [{"name": "bracket", "mesh": "bracket.stl", "scale": 0.001,  # mm -> m
                     "pose": {"xyz_m": [0.8, 0.8, 1.2], "rpy_deg": [0.0, 0.0, 30.0]}, "max_radius_m": 0.2}]
d["working_targets"] = [{"xyz_m": [1.1, 0.0, 1.65], "rpy_deg": [180.0, 0.0, 180.0]}]
(out / "cell.yaml").write_text(yaml.safe_dump(d, sort_keys=False))

cell = load_cell(out / "cell.yaml")
print(cell.summary())
env = cell.environment[0]
print(f"environment '{env.name}': {len(env.solids)} solid(s) for the check "
      f"({'convex' if env.solids[0].convex else 'non-convex BVH mesh'}), {len(env.capsules)} enclosing capsules "
      f"for the optimiser, radii {min(c.radius for c in env.capsules) * 1e3:.0f}.."
      f"{max(c.radius for c in env.capsules) * 1e3:.0f} mm")
q = cell.q_work[0]
tcp = (cell.W_T_base * cell.robot.oMtool(q)).act(cell.tcp_m)
print(f"working target solved by IK: q = {np.round(np.degrees(q), 2).tolist()} deg, "
      f"TCP error {np.linalg.norm(tcp - np.array(d['working_targets'][0]['xyz_m'])) * 1e9:.3f} nm")

# 3. a KPI design in this cell; the independent check sees the bracket itself
# quick: a smaller pool for the first start and fewer Ipopt iterations (the full run: the defaults)
opts = DesignOptions(pool_size=150, ipopt=ipopt_options(max_iter=20)) if QUICK else None
results = run_designs(cell, ["random", "kpi"], a.measurements, 0, opts)
chk = FeasibilityChecker(cell)
for r in results:
    dist = chk.distances(r.q_meas)
    cols = [k for k, n in enumerate(chk.names) if "bracket" in n]
    print(f"{r.criterion:<7} tr(C_s) = {r.trace_cs_m2 * 1e6:.4e} mm^2, feasible {r.feasible}, "
          f"closest approach to the bracket mesh {dist[:, cols].min() * 1e3:.1f} mm")
