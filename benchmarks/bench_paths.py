"""Working paths: IK of a 200-sample weld seam (target <= 1 s) and the path-KPI design against the plain 60-pose
KPI design in the KR 15 seam cell (target <= 2x).

Run: ``python -m benchmarks bench_paths``.
"""

from __future__ import annotations

import numpy as np
import yaml

from benchmarks.common import median_time, timed
from pin_kpi_oed.cell.cell import CELL_DIR, load_cell
from pin_kpi_oed.cell.paths import read_working_paths
from pin_kpi_oed.design.optimize import DesignOptions, DesignProblem, run_designs

IK_TARGET_S = 1.0
DESIGN_RATIO_TARGET = 2.0


def main() -> None:
    cell = load_cell("kr15_seam")
    entry = yaml.safe_load((CELL_DIR / "kr15_seam.yaml").read_text())["working_paths"][0]
    entry = {**{k: v for k, v in entry.items() if k != "step_m"}, "samples": 200}
    t_ik = median_time(lambda: read_working_paths(cell, [entry]), repeat=5, warmup=1)
    path = read_working_paths(cell, [entry])[0]
    print(f"IK of a 200-sample seam (solve, continuity, collision check): {t_ik.words()} "
          f"(target <= {IK_TARGET_S:g} s: {'met' if t_ik <= IK_TARGET_S else 'MISSED'}); largest joint step "
          f"{np.abs(np.diff(path.Q, axis=0)).max():.4f} rad")
    cell.paths = [path]
    problem = DesignProblem(cell)
    times = {}
    for crit in ("kpi", "kpi_path"):
        t, res = timed(lambda c=crit: run_designs(cell, [c], 60, 0, DesignOptions(), problem))
        times[crit] = t
        r = next(x for x in res if x.criterion == crit)
        print(f"60-pose {crit} design (pool start + 1 IPOPT start, 200 path samples): {t.words()}, value "
              f"{r.value:.4e} {r.criterion == 'kpi' and 'm^2' or 'm^2 (mean per sample)'}, feasible {r.feasible}")
    ratio = float(times["kpi_path"]) / float(times["kpi"])
    print(f"path design / plain design wall time: {ratio:.2f} (target <= {DESIGN_RATIO_TARGET:g}: "
          f"{'met' if ratio <= DESIGN_RATIO_TARGET else 'MISSED'})")


if __name__ == "__main__":
    main()
