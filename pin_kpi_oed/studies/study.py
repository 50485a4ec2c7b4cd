"""The paper's studies at scale (section 3.3, Tables 6–8, Figures 7–8).

* ``kuka``: the three KUKA cells (KR 15, KR 300, KR 500) × {heuristic, A on C_p, A on C_s}
  × {with, without collision avoidance} × seeds: a Table-6-like table and a
  Figure-7-like plot (95 % TCP confidence ellipsoid projected on the three
  coordinate planes, heuristic vs KPI design).
* ``notional90``: the 90 notional KR 15/2-like arms (segment two a2 = λ ∈
  {0.65 … 1.10} m, segment four d4 = μ ∈ {0.60 … 1.00} m) in the KR 15 cell; per
  arm the three designs; a Tables-7/8-like summary and a Figure-8-like plot
  (improvement of the KPI design over the heuristic and over A on C_p, per arm).

Each arm's working configuration is the KR 15 cell's TCP pose over the car,
reached by the arm's own inverse kinematics (Pinocchio CLIK). Every task
writes its own JSON file atomically under ``OUT/tasks/``; a restarted study
skips finished tasks (resumable; a killed run leaves no half-written file).
Tasks run on a local process pool, or on a Dask cluster (``dask.distributed``)
when a scheduler address is given.
"""

from __future__ import annotations

import copy
import json
import os
import time
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass
from pathlib import Path
from typing import Any
from collections.abc import Callable

import numpy as np
import pinocchio as pin

from pin_kpi_oed.errors import InfeasibleError, InputError, PinKpiOedError
from pin_kpi_oed.data.atomic import atomic_write_json, atomic_write_text
from pin_kpi_oed.data.lock import folder_lock
from pin_kpi_oed.progress import progress

#: Version of the task files: a restarted study recomputes tasks written by another version.
TASK_VERSION = 1


# ---------------------------------------------------------------------- inverse kinematics
@dataclass(frozen=True)
class IkOptions:
    """Numerical knobs of :func:`solve_ik`.

    Attributes:
        tol: stop when the pose error ‖log6‖ is below this (m and rad).
        max_iter: iteration limit.
        damping: damping of the least-squares step (m², rad²).
    """

    tol: float = 1e-10
    max_iter: int = 500
    damping: float = 1e-8


def solve_ik(model: pin.Model, frame_id: int, oMdes: pin.SE3, q0: np.ndarray, lower: np.ndarray,
             upper: np.ndarray, options: IkOptions | None = None) -> np.ndarray:
    """Closed-loop inverse kinematics of a frame pose (Pinocchio's CLIK, damped least squares).

    Args:
        model: the Pinocchio model.
        frame_id: the frame to place.
        oMdes: its desired pose in the model's world frame.
        q0: start configuration (rad, m for prismatic joints).
        lower, upper: joint bounds the iterates are clipped to.
        options: tolerances (default :class:`IkOptions`).

    Returns:
        The configuration, within the bounds.

    Raises:
        InfeasibleError: no solution within the joint bounds from ``q0``.
    """
    opts = options or IkOptions()
    tol, max_iter, damping = opts.tol, opts.max_iter, opts.damping
    data = model.createData()
    q = np.array(q0, float)
    for _ in range(max_iter):
        pin.framesForwardKinematics(model, data, q)
        err = pin.log6(data.oMf[frame_id].actInv(oMdes)).vector
        if np.linalg.norm(err) < tol:
            break
        J = pin.computeFrameJacobian(model, data, q, frame_id, pin.LOCAL)
        J = -pin.Jlog6(data.oMf[frame_id].actInv(oMdes)) @ J
        dq = -J.T @ np.linalg.solve(J @ J.T + damping * np.eye(6), err)
        q = np.clip(q + dq, lower, upper)
    else:
        raise InfeasibleError(f"inverse kinematics did not converge (pose error {np.linalg.norm(err):.3g})")
    if np.linalg.norm(err) > 1e-6:
        raise InfeasibleError(f"working pose not reachable within the joint bounds (error {np.linalg.norm(err):.3g})")
    return q


def notional_cell_dict(lambda_m: float, mu_m: float, out_dir: Path, base: str = "kr15") -> dict:
    """Cell mapping of a notional arm in the KR 15 cell, its URDF written under ``out_dir/urdf``.

    The working configuration puts the arm's tool0 at the KR 15 cell's working pose.
    """
    import yaml

    from pin_kpi_oed.cell.cell import load_cell, resolve_cell
    from pin_kpi_oed.model.kuka import write_urdf
    from pin_kpi_oed.model.notional_arms import notional_arm
    from pin_kpi_oed.model.robot import load_robot

    geom = notional_arm(lambda_m, mu_m)
    urdf = Path(out_dir) / "urdf" / f"{geom.name}.urdf"
    if not urdf.exists():
        write_urdf(geom, urdf)
    d = yaml.safe_load(resolve_cell(base).read_text())
    ref = load_cell(base)
    pin.framesForwardKinematics(ref.robot.model, ref.robot.data, ref.q_work[0])
    oMdes = ref.robot.data.oMf[ref.robot.tool_frame_id].copy()  # in the robot base frame (same base pose)
    rb = load_robot(urdf, ref.robot.tool_frame)
    q = solve_ik(rb.model, rb.tool_frame_id, oMdes, ref.q_work[0], ref.q_lower, ref.q_upper)
    d = copy.deepcopy(d)
    d["name"] = f"{geom.name}_fms"
    d["robot"] = str(urdf.resolve())
    d["working_configurations_deg"] = [np.degrees(q).tolist()]
    return d


# ---------------------------------------------------------------------- tasks
@dataclass
class Task:
    """One unit of work: the designs of one cell, seed and collision setting."""

    key: str
    cell: str | dict
    criteria: tuple[str, ...]
    m: int
    seed: int
    collision: bool
    n_starts: int
    meta: dict

    def to_dict(self) -> dict:
        """Plain dict (also the identity checked on resume)."""
        return {"key": self.key, "criteria": list(self.criteria), "m": self.m, "seed": self.seed,
                "collision": self.collision, "n_starts": self.n_starts, "meta": self.meta, "version": TASK_VERSION}


def run_task(task: Task, out_dir: str) -> dict:
    """Compute a task's designs and write ``out_dir/tasks/<key>.json`` atomically. Returns the record."""
    from pin_kpi_oed.cell.cell import cell_from_dict, load_cell
    from pin_kpi_oed.design.optimize import DesignOptions, DesignProblem, run_designs
    from pin_kpi_oed.oed.evaluate import score_design

    t0 = time.perf_counter()
    rec: dict[str, Any] = task.to_dict()
    try:
        cell = cell_from_dict(task.cell, source=task.key) if isinstance(task.cell, dict) else load_cell(task.cell)
        problem = DesignProblem(cell, collision=task.collision)
        results = run_designs(cell, list(task.criteria), task.m, task.seed,
                              DesignOptions(collision=task.collision, n_starts=task.n_starts), problem)
        rec["designs"] = []
        for r in results:
            d = {k: v for k, v in r.to_dict().items() if k not in ("starts", "check")}
            d["cov_s_m2"] = score_design(problem.model, r.q_meas, cell.q_work, problem.ident).cov_s_m2.tolist()
            rec["designs"].append(d)
        rec["q_work"] = cell.q_work.tolist()
        rec["ok"] = True
    except PinKpiOedError as exc:
        rec["ok"] = False
        rec["error"] = str(exc)
    rec["wall_time_s"] = time.perf_counter() - t0
    atomic_write_json(Path(out_dir) / "tasks" / f"{task.key}.json", rec)
    return rec


def task_finished(out_dir: Path, task: Task) -> dict | None:
    path = out_dir / "tasks" / f"{task.key}.json"
    if not path.exists():
        return None
    try:
        rec = json.loads(path.read_text())
    except (json.JSONDecodeError, OSError):
        return None  # unreadable: recompute (files are written atomically, so this is foreign damage)
    ident = task.to_dict()
    if any(rec.get(k) != ident[k] for k in ("criteria", "m", "seed", "collision", "n_starts", "version")):
        return None
    if rec.get("ok"):  # a damaged or hand-edited record (no designs, a criterion missing): recompute
        designs = rec.get("designs")
        if not isinstance(designs, list) or not all(isinstance(d, dict) for d in designs) or \
                {d.get("criterion") for d in designs} < set(ident["criteria"]):
            return None
    return rec


def run_tasks(tasks: list[Task], out_dir: Path, workers: int | None = None, scheduler: str | None = None,
              desc: str = "study") -> tuple[list[dict], int]:
    """Run tasks (skipping finished ones) on a process pool or a Dask cluster.

    Args:
        tasks: the tasks.
        out_dir: output folder (``tasks/`` below it holds one JSON per task).
        workers: local processes (default: all cores).
        scheduler: ``tcp://host:port`` of a Dask scheduler, or ``local-dask`` for an in-process
            ``LocalCluster``; None = local process pool.

    Returns:
        (records in task order, number of tasks computed now).
    """
    with folder_lock(out_dir, "study folder"):  # two studies in one folder would compute every task twice
        return _run_tasks_locked(tasks, Path(out_dir), workers, scheduler, desc)


def _run_tasks_locked(tasks: list[Task], out_dir: Path, workers: int | None, scheduler: str | None,
                      desc: str) -> tuple[list[dict], int]:
    (out_dir / "tasks").mkdir(parents=True, exist_ok=True)
    for stale in (out_dir / "tasks").glob(".*.tmp"):  # left by a run killed while writing: never a result
        stale.unlink(missing_ok=True)
    done = {t.key: r for t in tasks if (r := task_finished(out_dir, t)) is not None}
    todo = [t for t in tasks if t.key not in done]
    if todo:
        if scheduler:
            done.update(_run_dask(todo, out_dir, scheduler, workers, desc))
        elif (workers or os.cpu_count() or 1) == 1:
            for t in progress(todo, desc=desc):
                done[t.key] = run_task(t, str(out_dir))
        else:
            with ProcessPoolExecutor(max_workers=workers) as pool:
                futs = {pool.submit(run_task, t, str(out_dir)): t.key for t in todo}
                for f in progress(as_completed(futs), desc=desc, total=len(futs)):
                    done[futs[f]] = f.result()
    return [done[t.key] for t in tasks], len(todo)


#: What a local Dask cluster's workers are started without: Dask's default ``MALLOC_TRIM_THRESHOLD_`` (64 KiB) makes
#: glibc return freed memory to the system at once and fixes the size above which it maps each allocation afresh,
#: so that the arrays of a design are mapped, faulted in and unmapped again and again: with it a worker spent about
#: 9 % more CPU on the same task (one arm of the notional study: 0.5 s of system time instead of 0.15 s; median of 6
#: pairs, 6 of 6 with it, ``python -m benchmarks.dask_worker``). The value None drops
#: the variable from Dask's ``distributed.nanny.pre-spawn-environ`` (which the nanny also writes into this process's
#: environment, for every process it starts later); a value exported in the environment is still inherited.
LOCAL_DASK_CONFIG = {"distributed.nanny.pre-spawn-environ.MALLOC_TRIM_THRESHOLD_": None}


def local_dask_cluster(workers: int):
    """The local Dask cluster of ``--scheduler local-dask``: ``workers`` processes of one thread each, no dashboard,
    started with :data:`LOCAL_DASK_CONFIG`.

    Args:
        workers: worker processes.

    Returns:
        A started ``dask.distributed.LocalCluster`` (close it when done).
    """
    import dask
    from dask.distributed import LocalCluster

    with dask.config.set(LOCAL_DASK_CONFIG):  # read once by each worker's nanny, at its start: restarts keep it
        return LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=None)


def _run_dask(todo: list[Task], out_dir: Path, scheduler: str, workers: int | None, desc: str) -> dict:
    from dask.distributed import Client, as_completed as dask_completed

    cluster = None
    if scheduler == "local-dask":
        cluster = local_dask_cluster(workers or 2)
        client = Client(cluster)
    else:
        try:
            client = Client(scheduler, timeout="10s")
        except (OSError, TimeoutError) as exc:
            raise InputError(f"scheduler='{scheduler}': cannot connect to the Dask scheduler within 10 s "
                             f"({str(exc).splitlines()[0] if str(exc) else type(exc).__name__})") from None
    try:
        futs = client.map(run_task, todo, out_dir=str(out_dir), pure=False)
        key_of = {f.key: t.key for f, t in zip(futs, todo)}
        out = {}
        for f in progress(dask_completed(futs), desc=desc, total=len(futs)):
            out[key_of[f.key]] = f.result()
        return out
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


# ---------------------------------------------------------------------- the two studies
def _trace(rec: dict, crit: str) -> float:
    return next(d["trace_cs_m2"] for d in rec["designs"] if d["criterion"] == crit)


def notional_study(out_dir: Path, m: int = 60, seed: int = 0, arms: int | None = None, workers: int | None = None,
                   scheduler: str | None = None, n_starts: int = 1,
                   plot: Callable[[list[dict], Path], None] | None = None) -> dict:
    """The 90 notional arms (or the first ``arms`` of them): per arm heuristic, A on C_p, A on C_s.

    ``plot(rows, path)`` draws Figure 8 (``notional90.png``) when given, e.g.
    :func:`pin_kpi_oed.viz.figures.plot_notional` (the study itself draws nothing: viz is downstream).

    Writes ``summary.json``, ``arms.csv`` and ``notional90.png`` to ``out_dir``.
    """
    from pin_kpi_oed.model.notional_arms import notional_arms

    t0 = time.perf_counter()
    out_dir = Path(out_dir)
    geoms = notional_arms()[:arms] if arms else notional_arms()
    tasks = []
    for g in geoms:
        cell = notional_cell_dict(g.a2, g.d4, out_dir)
        tasks.append(Task(key=f"{g.name}_m{m}_s{seed}", cell=cell, criteria=("random", "param", "kpi"), m=m,
                          seed=seed, collision=True, n_starts=n_starts,
                          meta={"arm": g.name, "a2_m": g.a2, "d4_m": g.d4}))
    recs, computed = run_tasks(tasks, out_dir, workers, scheduler, desc="notional arms")
    rows, failed = [], []
    for r in recs:
        if not r.get("ok"):
            failed.append({"arm": r["meta"]["arm"], "error": r.get("error")})
            continue
        tr = {c: _trace(r, c) for c in ("random", "param", "kpi")}
        feas = all(d["feasible"] for d in r["designs"])
        rows.append({"arm": r["meta"]["arm"], "a2_m": r["meta"]["a2_m"], "d4_m": r["meta"]["d4_m"],
                     **{f"trace_cs_{c}_m2": v for c, v in tr.items()},
                     "improvement_vs_heuristic": 1 - tr["kpi"] / tr["random"],
                     "improvement_vs_param": 1 - tr["kpi"] / tr["param"],
                     "improvement_param_vs_heuristic": 1 - tr["param"] / tr["random"],
                     "all_feasible": feas, "wall_time_s": r["wall_time_s"]})
    summary = _notional_summary(rows, failed, m, seed, time.perf_counter() - t0, computed)
    _write_csv(out_dir / "arms.csv", rows)
    if rows and plot is not None:
        plot(rows, out_dir / "notional90.png")
    atomic_write_json(out_dir / "summary.json", summary)
    return summary


def _notional_pairs(rows: list[dict]) -> dict:
    """The paired comparisons over the arms (:func:`~pin_kpi_oed.studies.paired.paired_comparison` of tr C_s): the
    KPI design against random and against A on C_p, A on C_p against random; empty with fewer than one arm."""
    from pin_kpi_oed.studies.paired import paired_comparison

    if not rows:
        return {}
    col = {c: [r[f"trace_cs_{c}_m2"] for r in rows] for c in ("random", "param", "kpi")}
    return {"kpi_vs_random": paired_comparison(col["kpi"], col["random"]),
            "kpi_vs_param": paired_comparison(col["kpi"], col["param"]),
            "param_vs_random": paired_comparison(col["param"], col["random"])}


def _notional_summary(rows: list[dict], failed: list[dict], m: int, seed: int, wall: float, computed: int) -> dict:
    def stats(key: str) -> dict:
        v = np.array([r[key] for r in rows])
        return {"min": float(v.min()), "mean": float(v.mean()), "max": float(v.max())} if v.size else {}

    avg_var = {c: stats(f"trace_cs_{c}_m2") for c in ("random", "param", "kpi")}
    for c in avg_var:  # the paper's "averaged three-dimensional variance": tr(C_s)/3
        avg_var[c] = {k: v / 3 for k, v in avg_var[c].items()}
    return {
        "study": "notional90", "arms": len(rows), "failed_arms": failed, "measurements": m, "seed": seed,
        "mean_improvement_vs_heuristic": (float(np.mean([r["improvement_vs_heuristic"] for r in rows]))
                                          if rows else None),
        "mean_improvement_vs_param": float(np.mean([r["improvement_vs_param"] for r in rows])) if rows else None,
        "mean_improvement_param_vs_heuristic": float(np.mean([r["improvement_param_vs_heuristic"] for r in rows]))
        if rows else None,
        "paired": _notional_pairs(rows),
        "improvement_vs_heuristic": stats("improvement_vs_heuristic"),
        "improvement_vs_param": stats("improvement_vs_param"),
        "averaged_tcp_variance_m2": avg_var,
        "all_collision_free": bool(rows) and all(r["all_feasible"] for r in rows) and not failed,
        "wall_time_s": wall, "tasks_computed_now": computed,
    }


def _write_csv(path: Path, rows: list[dict]) -> None:
    if not rows:
        atomic_write_text(path, "")
        return
    keys = list(rows[0])
    lines = [",".join(keys)] + [",".join(str(r[k]) for k in keys) for r in rows]
    atomic_write_text(path, "\n".join(lines) + "\n")


def kuka_study(out_dir: Path, m: int = 60, seeds: tuple[int, ...] = (0, 1, 2), cells: tuple[str, ...] = (
        "kr15", "kr300", "kr500"), workers: int | None = None, scheduler: str | None = None, n_starts: int = 1,
               plot: Callable[[dict, Path], None] | None = None) -> dict:
    """Three KUKA cells × {heuristic, A on C_p, A on C_s} × {with, without collision avoidance} × seeds.

    ``plot(task_record, path)`` draws Figure 7 per cell (``figure7_<cell>.png``) when given, e.g.
    :func:`pin_kpi_oed.viz.figures.plot_study_figure7`.

    Writes ``summary.json``, ``table6.csv`` and ``figure7_<cell>.png`` to ``out_dir``.
    """
    t0 = time.perf_counter()
    out_dir = Path(out_dir)
    tasks = [Task(key=f"{c}_m{m}_s{s}_{'coll' if col else 'nocoll'}", cell=c, criteria=("random", "param", "kpi"),
                  m=m, seed=s, collision=col, n_starts=n_starts, meta={"cell": c})
             for c in cells for s in seeds for col in (True, False)]
    recs, computed = run_tasks(tasks, out_dir, workers, scheduler, desc="KUKA cells")
    rows = []
    for c in cells:
        for col in (True, False):
            rs = [r for r in recs if r["meta"]["cell"] == c and r["collision"] == col and r.get("ok")]
            if not rs:
                continue
            row: dict[str, Any] = {"cell": c, "collision_avoidance": col, "seeds": len(rs)}
            for crit in ("random", "param", "kpi"):
                tr = np.array([_trace(r, crit) for r in rs])
                row[f"trace_cs_{crit}_m2"] = float(tr.mean())
                row[f"share_colliding_{crit}"] = float(np.mean(
                    [next(d["share_colliding"] for d in r["designs"] if d["criterion"] == crit) for r in rs]))
                row[f"feasible_{crit}"] = all(next(d["feasible"] for d in r["designs"] if d["criterion"] == crit)
                                              for r in rs)
            row["improvement_kpi_vs_heuristic"] = 1 - row["trace_cs_kpi_m2"] / row["trace_cs_random_m2"]
            row["improvement_kpi_vs_param"] = 1 - row["trace_cs_kpi_m2"] / row["trace_cs_param_m2"]
            row["improvement_param_vs_heuristic"] = 1 - row["trace_cs_param_m2"] / row["trace_cs_random_m2"]
            rows.append(row)
        rec = next((r for r in recs if r["meta"]["cell"] == c and r["collision"] and r.get("ok")), None)
        if rec is not None and plot is not None:
            plot(rec, out_dir / f"figure7_{c}.png")
    _write_csv(out_dir / "table6.csv", rows)
    with_coll = [r for r in rows if r["collision_avoidance"]]
    summary = {"study": "kuka", "rows": rows, "measurements": m, "seeds": list(seeds),
               "all_collision_free": bool(with_coll) and all(r[f"feasible_{c}"] for r in with_coll
                                                             for c in ("random", "param", "kpi")),
               "failed_tasks": [{"key": r["key"], "error": r.get("error")} for r in recs if not r.get("ok")],
               "wall_time_s": time.perf_counter() - t0, "tasks_computed_now": computed}
    atomic_write_json(out_dir / "summary.json", summary)
    return summary


def format_kuka_table(summary: dict) -> str:
    """Table-6-like text: mean tr(C_s) (mm²) per design, signed changes of the KPI design (%, negative = more
    precise), colliding share without avoidance. "random" is the paper's heuristic design."""
    lines = [f"{'cell':<7}{'collisions':>11}{'random':>12}{'A on C_p':>12}{'A on C_s':>12}"
             f"{'KPI vs random':>14}{'KPI vs C_p':>11}{'colliding (rand/Cp/Cs)':>24}",
             f"{'':<7}{'':>11}{'(mm^2)':>12}{'(mm^2)':>12}{'(mm^2)':>12}{'(%)':>14}{'(%)':>11}{'(%)':>24}"]
    for r in summary["rows"]:
        col = "avoided" if r["collision_avoidance"] else "ignored"
        share = "/".join(f"{100 * r[f'share_colliding_{c}']:.0f}" for c in ("random", "param", "kpi"))
        lines.append(f"{r['cell']:<7}{col:>11}{r['trace_cs_random_m2'] * 1e6:>12.4e}"
                     f"{r['trace_cs_param_m2'] * 1e6:>12.4e}{r['trace_cs_kpi_m2'] * 1e6:>12.4e}"
                     f"{-100 * r['improvement_kpi_vs_heuristic']:>+14.1f}{-100 * r['improvement_kpi_vs_param']:>+11.1f}"
                     f"{share:>24}")
    return "\n".join(lines)


def format_notional_summary(s: dict) -> str:
    """Tables-7/8-like text."""
    lines = [f"notional arms: {s['arms']} (failed: {len(s['failed_arms'])}), {s['measurements']} measurements, "
             f"seed {s['seed']}, wall time {s['wall_time_s']:.0f} s",
             f"averaged TCP variance tr(C_s)/3 (mm^2): {'min':>12}{'mean':>12}{'max':>12}"]
    for c, name in (("random", "random"), ("param", "A on C_p"), ("kpi", "A on C_s")):
        v = s["averaged_tcp_variance_m2"].get(c) or {}
        if v:
            lines.append(f"  {name:<38}{v['min'] * 1e6:>12.4e}{v['mean'] * 1e6:>12.4e}{v['max'] * 1e6:>12.4e}")
    if s["arms"]:
        from pin_kpi_oed.studies.paired import paired_text

        names = {"kpi_vs_random": "A on C_s vs random", "kpi_vs_param": "A on C_s vs A on C_p",
                 "param_vs_random": "A on C_p vs random"}
        for key, label in names.items():
            if key in s.get("paired", {}):
                lines.append(f"tr(C_s), paired over the arms, {label}: {paired_text(s['paired'][key])}")
    lines.append(f"all designs collision-free (independent check): {s['all_collision_free']}")
    return "\n".join(lines)
