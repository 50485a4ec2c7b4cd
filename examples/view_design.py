"""Preview a measurement design before running it on the robot: a meshcat page and the report figures.

Run:
    python examples/view_design.py                 # designs the KR 15 cell first (pin-kpi-oed design)
    python examples/view_design.py design.json     # any design JSON (pin-kpi-oed design --json)
    python examples/view_design.py design.json --open

Writes ``view_design.html`` (a self-contained meshcat page: open it in a browser, offline; the
Animations panel steps the robot through the poses, the scene tree toggles capsules and ghosts) and
three PNGs (ellipsoid projections, designs compared, clearance / incidence per pose) in the current
folder. The same from the command line: ``pin-kpi-oed view design.json --html view.html --figures .``
"""

import json
import os
import sys
import tempfile
from pathlib import Path

from pin_kpi_oed.design.design_file import load_design
from pin_kpi_oed.design.stand_in import stand_in_design
from pin_kpi_oed.viz.ellipsoids import fmt_factor
from pin_kpi_oed.viz.figures import design_figures
from pin_kpi_oed.viz.scene import build_scene

#: --quick (or PIN_KPI_OED_QUICK=1): the examples test runs a smaller problem (fewer poses, one IPOPT start)
quick = os.environ.get("PIN_KPI_OED_QUICK") == "1" or "--quick" in sys.argv[1:]
args = [a for a in sys.argv[1:] if not a.startswith("--")]
if args:
    design_json = Path(args[0])
else:
    design_json = Path(tempfile.mkdtemp()) / "design.json"
    try:  # the KPI design of the shipped KR 15 cell
        from pin_kpi_oed.cli.app import main as cli

        m = 12 if quick else 60
        # quick: one IPOPT start from the heuristic design (no pool selection), fewer iterations
        knobs = ["--starts", "1", "--start", "random", "--max-iter", "15"] if quick else []
        rc = cli(["design", "--cell", "kr15", "--criteria", "random,param,kpi", "--measurements", str(m),
                  "--seed", "0", "--json", str(design_json), *knobs])
    except Exception as exc:  # the design optimiser is not available: preview random designs instead
        print(f"design step not available ({exc}); using a stand-in")
        rc = 1
    if rc != 0 or not design_json.exists():
        design_json.write_text(json.dumps(stand_in_design("kr15", m=20 if quick else 40, seed=0)))
        print("stand-in design: random configurations, not optimised (pin_kpi_oed.design.stand_in)")

df = load_design(design_json)
for note in df.notes:
    print("note:", note)
scene = build_scene(df)  # drawn into an in-process recorder: no server, no ports
page = scene.write_html("view_design.html")
print(f"wrote {page} ({page.stat().st_size / 1e6:.1f} MB): {df.robot.name}, {len(df.designs)} designs, "
      f"ellipsoids x{fmt_factor(scene.scale)}")
t = df.q_work.shape[0]
for d in df.designs:
    clr = df.pose_clearance(d.q_meas)  # the independent check of the design's cell, the beam included
    inc = df.incidence_deg(d.q_meas)
    print(f"  {d.label:<16} tr(C_s) = {d.trace_cs_m2 * 1e6:.4e} mm^2   TCP sigma = "
          f"{(d.trace_cs_m2 / t) ** 0.5 * 1e6:6.3f} um   min clearance {clr.min() * 1e3:6.1f} mm   "
          f"max incidence {inc.max():5.1f} deg")
for name, path in design_figures(df, ".", prefix="view_design").items():
    print(f"wrote {path}")
if "--open" in sys.argv:
    import webbrowser

    webbrowser.open(page.resolve().as_uri())
