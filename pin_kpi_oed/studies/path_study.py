r"""The path and 6-D KPIs in the paper's KR 15 cell with a weld seam on the car body (the shipped ``kr15_seam``).

Protocol (the paper's Table 6: one IPOPT start from the pool selection, collision avoidance on, m poses, seeds):
for every seed, five designs of m poses

* ``random``: the paper's heuristic design (uniform random feasible poses),
* ``kpi``: the point KPI at the seam's two end points (the cell's working configurations),
* ``kpi_path``: the mean tr C_s over the seam's samples every 5 mm (:mod:`pin_kpi_oed.oed.path_kpi`),
* ``kpi_path_max``: the smooth worst tr C_s over the same samples (:mod:`pin_kpi_oed.oed.path_kpi_max`),
* ``kpi6``: the 6-D KPI at the end points, orientation at the cell's 200 mm (:mod:`pin_kpi_oed.oed.pose_kpi`),

scored along the seam by the predicted σ (:func:`~pin_kpi_oed.design.path_profile.path_profile`): the TCP's RMS
and worst sample (µm), the tool orientation's RMS (µrad) and the σ at 200 mm along the tool (position and
orientation, µm). Paired over the seeds (Wilcoxon signed-rank, :func:`~pin_kpi_oed.studies.kpi_withheld.
paired_summary`): ``kpi_path`` against ``kpi`` and ``random`` on the path σ, ``kpi_path_max`` against ``kpi_path``
and ``kpi`` on the path σ's RMS and worst sample, ``kpi6`` against ``kpi`` on the orientation σ. The predicted σ
along the seam of the first seed's ``kpi_path`` design is checked against a Monte-Carlo of identifications (random
true geometric errors within the tolerances, the cell's noise): realised / predicted trace over the path samples.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import numpy as np

from pin_kpi_oed.data.atomic import atomic_write_json
from pin_kpi_oed.progress import progress

__all__ = ["DESIGNS", "path_study", "format_path_table"]

#: the designs compared, in the table's order
DESIGNS = ("random", "kpi", "kpi_path", "kpi_path_max", "kpi6")
_SCORES = (("rms_sigma_pos_m", 1e6, "path sigma RMS um"), ("worst_sigma_pos_m", 1e6, "path sigma worst um"),
           ("rms_sigma_rot_rad", 1e6, "orientation RMS urad"), ("rms_sigma_at_length_m", 1e6, "at 200 mm RMS um"))


def _one_seed(problem: Any, m: int, seed: int, n_starts: int) -> dict:
    """The designs of one seed and their path profiles."""
    from pin_kpi_oed.design.optimize import DesignOptions, run_designs
    from pin_kpi_oed.design.path_profile import path_profile

    cell = problem.cell
    results = run_designs(cell, list(DESIGNS), m, seed, DesignOptions(n_starts=n_starts), problem)
    rec: dict[str, Any] = {"seed": seed, "designs": {}}
    for r in results:
        prof = path_profile(problem, r.q_meas, cell.q_path, cell.orientation_length_m)
        rec["designs"][r.criterion] = {"feasible": bool(r.feasible), "time_s": float(r.time_s),
                                       "q_meas": r.q_meas.tolist(),
                                       **{k: prof[k] for k, _, _ in _SCORES}}
    return rec


def path_study(out_dir: Path, m: int = 60, seeds: tuple[int, ...] = (0, 1, 2, 3, 4), n_starts: int = 1,
               mc_reps: int = 50, cell: str = "kr15_seam") -> dict:
    """Run the study (module docstring); writes ``out_dir/summary.json``.

    Args:
        out_dir: output folder.
        m: poses per design; seeds: the seeds; n_starts: IPOPT starts per design.
        mc_reps: Monte-Carlo identifications of the first seed's ``kpi_path`` design (0: none).
        cell: a shipped cell name or cell file with working paths.

    Returns:
        The summary (per-seed scores, means, paired tests, Monte-Carlo ratio, wall time).
    """
    from pin_kpi_oed.cell.cell import load_cell
    from pin_kpi_oed.design.optimize import DesignProblem
    from pin_kpi_oed.studies.kpi_withheld import paired_summary

    t0 = time.perf_counter()
    Path(out_dir).mkdir(parents=True, exist_ok=True)  # before the work: a folder that cannot be made fails now
    c = load_cell(cell)
    problem = DesignProblem(c)
    recs = [_one_seed(problem, m, s, n_starts) for s in progress(list(seeds), desc="path study seeds")]

    def col(design: str, key: str) -> np.ndarray:
        return np.array([r["designs"][design][key] for r in recs])

    means = {d: {k: float(col(d, k).mean()) for k, _, _ in _SCORES} for d in DESIGNS}
    pairs = {}
    if len(recs) >= 2:
        for a, b, key in (("kpi_path", "kpi", "rms_sigma_pos_m"), ("kpi_path", "kpi", "worst_sigma_pos_m"),
                          ("kpi_path", "random", "rms_sigma_pos_m"),
                          *(("kpi_path_max", b, k) for b in ("kpi_path", "kpi")
                            for k in ("worst_sigma_pos_m", "rms_sigma_pos_m")),
                          ("kpi6", "kpi", "rms_sigma_rot_rad"),
                          ("kpi6", "kpi", "rms_sigma_at_length_m"), ("kpi6", "kpi_path", "rms_sigma_at_length_m")):
            pairs[f"{a}_vs_{b}_{key}"] = paired_summary(col(a, key).tolist(), col(b, key).tolist())
    summary: dict[str, Any] = {"study": "paths", "cell": c.name, "measurements": m, "seeds": list(seeds),
                               "path_samples": int(len(c.q_path)), "orientation_length_m": c.orientation_length_m,
                               "means": means, "paired": pairs, "records": recs,
                               "all_feasible": all(d["feasible"] for r in recs for d in r["designs"].values())}
    atomic_write_json(Path(out_dir) / "summary.json", summary)  # the designs' scores kept before the Monte-Carlo
    if mc_reps:
        from pin_kpi_oed.studies.design_trials import monte_carlo

        Q = np.array(recs[0]["designs"]["kpi_path"]["q_meas"])
        mc = monte_carlo(problem.model, Q, c.q_path, n_rep=mc_reps, seed=seeds[0], show_progress=False)
        summary["monte_carlo"] = {"design": "kpi_path", "seed": seeds[0], "reps": mc_reps,
                                  "trace_ratio_realised_over_predicted": mc.trace_ratio, "failures": mc.failures}
    summary["wall_time_s"] = time.perf_counter() - t0
    atomic_write_json(Path(out_dir) / "summary.json", summary)
    return summary


def format_path_table(s: dict) -> str:
    """The study's table (means over the seeds) and its paired tests, as text with units."""
    from pin_kpi_oed.studies.paired import paired_text

    head = f"{'design':<10}" + "".join(f"{label:>22}" for _, _, label in _SCORES)
    lines = [f"{s['cell']}: {s['measurements']} poses, seeds {s['seeds']}, {s['path_samples']} path samples "
             f"(means over the seeds; predicted sigma, 1 um per axis)", head, "-" * len(head)]
    for d in DESIGNS:
        lines.append(f"{d:<10}" + "".join(f"{s['means'][d][k] * f:>22.4f}" for k, f, _ in _SCORES))
    for name, p in s["paired"].items():
        lines.append(f"{name}: {paired_text(p)}")
    if "monte_carlo" in s:
        mc = s["monte_carlo"]
        lines.append(f"Monte-Carlo ({mc['reps']} identifications of the seed-{mc['seed']} kpi_path design): realised / "
                     f"predicted trace along the path {mc['trace_ratio_realised_over_predicted']:.3f}, "
                     f"{mc['failures']} failures")
    return "\n".join(lines)
