"""Real UR10: straight lines of Series A's lattice held out as working paths; the path KPI's poses against the point
KPI at the paths' end points and random poses, on the measured error along the held-out paths.

Series A of the IPA UR10 data commands the TCP to a lattice of positions (x 8 values, y 13, z 6, 0.05–0.1 m apart)
in about 19 orientations each (11,911 rows). Per seeded split:

1. the held-out paths: ``--paths`` straight lines of the lattice (one per axis in turn: along y 13 positions, along x
   8, along z 6; the other two coordinates drawn at random), each in one commanded orientation measured at most of
   its positions; a path's samples are the rows at its positions in that orientation, ordered along the line;
2. the pool: every row whose commanded position lies on none of the held-out lines (all orientations of those
   positions leave the pool);
3. the design model: the nominal UR10 with the set-up (tracker pose, reflector) fitted to the pool
   (:func:`~pin_kpi_oed.studies.design_trials.position_design_model`), σ = 0.1 mm per axis;
4. m ∈ ``--sizes`` poses chosen from the pool by
   * ``kpi_path``: the mean tr C_s over the paths' samples (``kpi_path``'s pool form K = E_path/√S; relaxation,
     rounding, exchange: :func:`~pin_kpi_oed.oed.pool.select`),
   * ``kpi_ends``: the point KPI at the paths' end samples (two per path),
   * ``random``: m seeded pool rows;
5. every set calibrated the same way (geometry and set-up by least squares, position rows,
   ``identify(..., discrepancy="none")``), then the measured error along the held-out paths: the mean 3-D error over
   the paths' samples and the mean over the paths of each path's worst sample.

Paired over the splits (Wilcoxon signed-rank, two-sided): ``kpi_path`` against ``kpi_ends`` and ``random`` per m.
The KPI is the measured point (the T-Mac's reflector), as in
:func:`~pin_kpi_oed.studies.design_trials.real_data_validation`.

Run: ``OMP_NUM_THREADS=1 python -m benchmarks.paths_real [--splits 20] [--sizes 12,20,60] [--paths 3]
[--json out.json]`` (IPA data: ``$PIN_KPI_OED_IPA_DATA`` or ``shared/data/ipa_ur10`` above the repository; progress per
split on stderr).
"""

from __future__ import annotations

import argparse
import os
import sys
import time

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

METHODS = ("kpi_path", "kpi_ends", "random")
SCORES = ("mean_error_m", "worst_error_m")
#: commanded positions of the lattice's lines per axis (x, y, z): the lines held out are full ones
LINE_AXES = (1, 0, 2)


def lattice(ms) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(commanded position index per row, the positions (P, 3) m, commanded orientation index per row)."""
    G = np.column_stack([ms.extra[k] for k in ("goal_x", "goal_y", "goal_z")])
    rpy = np.column_stack([ms.extra[k] for k in ("goal_roll", "goal_pitch", "goal_yaw")])
    P, pos = np.unique(np.round(G, 4), axis=0, return_inverse=True)
    _, ori = np.unique(np.round(rpy, 4), axis=0, return_inverse=True)
    return pos.ravel(), P, ori.ravel()


def lines_along(P: np.ndarray, axis: int, min_points: int = 5) -> list[np.ndarray]:
    """The lattice's straight lines along ``axis``: position indices sharing the two other coordinates, sorted
    along the axis, with at least ``min_points`` positions."""
    others = [a for a in range(3) if a != axis]
    keys, inv = np.unique(np.round(P[:, others], 4), axis=0, return_inverse=True)
    out = []
    for k in range(len(keys)):
        idx = np.flatnonzero(inv.ravel() == k)
        if idx.size >= min_points:
            out.append(idx[np.argsort(P[idx, axis])])
    return out


def choose_paths(rng: np.random.Generator, pos: np.ndarray, P: np.ndarray, ori: np.ndarray, n_paths: int
                 ) -> tuple[list[np.ndarray], np.ndarray]:
    """(per held-out path its rows ordered along the line, the positions on the held-out lines)."""
    paths: list[np.ndarray] = []
    used: list[int] = []
    for j in range(n_paths):
        axis = LINE_AXES[j % 3]
        cands = [ln for ln in lines_along(P, axis) if not set(ln.tolist()) & set(used)]
        line = cands[int(rng.integers(len(cands)))]
        on = np.isin(pos, line)
        counts = np.bincount(ori[on], minlength=ori.max() + 1)
        good = np.flatnonzero(counts >= 0.8 * line.size)
        o = int(rng.choice(good))
        rows = [np.flatnonzero((pos == p) & (ori == o)) for p in line]
        paths.append(np.array([r[0] for r in rows if r.size], int))
        used += line.tolist()
    return paths, np.array(used, int)


def run_split(model, ms, pos, P, ori, seed: int, sizes: tuple[int, ...], n_paths: int) -> dict:
    """The designs of one split and the measured error along its held-out paths (module docstring)."""
    from pin_kpi_oed.identification.identify import identify
    from pin_kpi_oed.oed.identifiability import analyse
    from pin_kpi_oed.oed.pool import select
    from pin_kpi_oed.studies.design_trials import position_design_model

    rng = np.random.default_rng(seed)
    paths, held_pos = choose_paths(rng, pos, P, ori, n_paths)
    pool = np.flatnonzero(~np.isin(pos, held_pos))
    dm = position_design_model(model, ms.subset(pool))
    b = analyse(dm).base
    p0 = np.zeros(dm.n_params)
    Fp = dm.weighted_jacobian(p0, ms.q[pool])[:, :, b]
    path_rows = np.concatenate(paths)
    E_path = dm.jacobian(p0, ms.q[path_rows])[:, :3, :][:, :, b].reshape(-1, b.size)
    ends = np.concatenate([[p[0], p[-1]] for p in paths])
    E_ends = dm.jacobian(p0, ms.q[ends])[:, :3, :][:, :, b].reshape(-1, b.size)
    K = {"kpi_path": E_path / np.sqrt(path_rows.size), "kpi_ends": E_ends}
    held = ms.subset(path_rows)
    bounds = np.cumsum([0] + [p.size for p in paths])
    rec: dict = {"seed": seed, "paths": [{"rows": p.tolist(), "samples": int(p.size)} for p in paths],
                 "pool": int(pool.size), "sizes": {}}
    for m in sizes:
        rec["sizes"][m] = {}
        for meth in METHODS:
            if meth == "random":
                chosen = rng.choice(pool, m, replace=False)
            else:
                chosen = pool[select(Fp, m, K[meth], seed=seed).indices]
            res = identify(model, ms.subset(chosen), use_orientation=False, raise_on_failure=False,
                           discrepancy="none", on_poor_fit="ignore")
            cm = res.calibrated_model()
            e = np.linalg.norm(held.position_m - cm.predict(held.q, held), axis=1)
            worst = [float(e[bounds[k]:bounds[k + 1]].max()) for k in range(len(paths))]
            rec["sizes"][m][meth] = {"mean_error_m": float(e.mean()), "worst_error_m": float(np.mean(worst)),
                                     "rows": chosen.tolist()}
    return rec


def summarise(recs: list[dict], sizes: tuple[int, ...]) -> dict:
    """Means over the splits and the paired tests of ``kpi_path`` against the others, per m and score."""
    from benchmarks.common import paired_by_size

    return paired_by_size(recs, sizes, METHODS, SCORES)


def table(summary: dict, n_splits: int, n_paths: int) -> str:
    """The table (mm) and the paired tests."""
    from benchmarks.common import paired_lines

    lines = [f"Series A, {n_splits} splits, {n_paths} held-out lattice lines per split; measured error along the "
             "held-out paths (mm): mean over the samples / mean of each path's worst sample",
             f"{'m':>4} " + "".join(f"{meth:>24}" for meth in METHODS)]
    for m, s in summary.items():
        lines.append(f"{m:>4} " + "".join(f"{s['means'][meth]['mean_error_m'] * 1e3:>12.4f} / "
                                          f"{s['means'][meth]['worst_error_m'] * 1e3:<8.4f}" for meth in METHODS))
    return "\n".join(lines + paired_lines(summary))


def main(argv: list[str] | None = None) -> int:
    from benchmarks.common import ipa_folder_or_say, ipa_ur10_model
    from pin_kpi_oed.data.atomic import atomic_write_json
    from pin_kpi_oed.data.ipa import import_ipa
    from pin_kpi_oed.data.measurements import MeasurementSet

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--splits", type=int, default=20)
    ap.add_argument("--sizes", default="12,20,60")
    ap.add_argument("--paths", type=int, default=3, help="held-out lattice lines per split")
    ap.add_argument("--seed", type=int, default=0, help="seed of the first split")
    ap.add_argument("--json", default=None)
    a = ap.parse_args(argv)
    folder = ipa_folder_or_say("A")
    if folder is None:
        return 0
    sizes = tuple(int(s) for s in a.sizes.split(","))
    full = import_ipa(folder / "Series_A")
    ms = MeasurementSet(full.joint_names, full.q, full.position_m, temperature_c=full.temperature_c,
                        source="A.csv")
    pos, P, ori = lattice(full)
    model = ipa_ur10_model()
    t0, c0 = time.perf_counter(), time.process_time()
    recs = []
    for k in range(a.splits):
        recs.append(run_split(model, ms, pos, P, ori, a.seed + k, sizes, a.paths))
        print(f"split {k + 1}/{a.splits} done ({time.perf_counter() - t0:.0f} s)", file=sys.stderr, flush=True)
    summary = summarise(recs, sizes)
    print(table(summary, a.splits, a.paths))
    print(f"wall {time.perf_counter() - t0:.0f} s, CPU {time.process_time() - c0:.0f} s")
    if a.json:
        atomic_write_json(a.json, {"benchmark": "paths_real", "splits": a.splits, "paths_per_split": a.paths,
                                   "sizes": list(sizes), "summary": summary, "records": recs})
    return 0


if __name__ == "__main__":
    sys.exit(main())
