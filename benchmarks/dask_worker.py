"""The CPU a local Dask cluster's worker spends on one study task, started as ``--scheduler local-dask`` starts it
(the package's :data:`~pin_kpi_oed.studies.study.LOCAL_DASK_CONFIG`) against Dask's defaults (its
``MALLOC_TRIM_THRESHOLD_`` of 64 KiB).

Each pair: one cluster of one worker per variant (alternating which goes first), the same task (the first notional
arm, 12 measurements, seed 0, the three designs) in a fresh folder; the figure is the worker's own CPU time
(user + system, read inside the worker) from before the task to after it, imports included. The records of the two
variants must be equal (the same designs). Paired median of the ratios with the sign test.

Run: ``python -m benchmarks.dask_worker [pairs]`` (default 6 pairs, the fewest whose sign test can reach p < 0.05;
about 1 min CPU).
"""

from __future__ import annotations

import os
import sys
import tempfile
from pathlib import Path


def _worker_cpu() -> tuple[float, float]:
    """(user, system) CPU s of the process it runs in (a worker)."""
    import resource

    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime, r.ru_stime


def _one(config: dict, task, out: Path) -> tuple[float, float, dict]:
    """(worker user s, worker system s, the task's record) of ``task`` on a fresh one-worker cluster."""
    import dask
    from dask.distributed import Client, LocalCluster

    from pin_kpi_oed.studies.study import run_task

    (out / "tasks").mkdir(parents=True)
    environ = dict(os.environ)
    with dask.config.set(config):
        cluster = LocalCluster(n_workers=1, threads_per_worker=1, processes=True, dashboard_address=None)
    client = Client(cluster)
    try:
        u0, s0 = client.submit(_worker_cpu, pure=False).result()
        rec = client.submit(run_task, task, str(out), pure=False).result()
        u1, s1 = client.submit(_worker_cpu, pure=False).result()
    finally:
        client.close()
        cluster.close()
        os.environ.clear()  # the nanny writes its pre-spawn variables into this process's environment too: the
        os.environ.update(environ)  # next cluster's worker would inherit them
    return u1 - u0, s1 - s0, rec


def main(pairs: int = 6) -> None:
    from pin_kpi_oed.model.notional_arms import notional_arms
    from pin_kpi_oed.studies.paired import paired_comparison, paired_text
    from pin_kpi_oed.studies.study import LOCAL_DASK_CONFIG, Task, notional_cell_dict

    variants = {"package": LOCAL_DASK_CONFIG, "dask default": {}}
    cpu: dict[str, list[float]] = {k: [] for k in variants}
    with tempfile.TemporaryDirectory() as tmp:
        g = notional_arms()[0]
        task = Task(key=f"{g.name}_m12_s0", cell=notional_cell_dict(g.a2, g.d4, Path(tmp)),
                    criteria=("random", "param", "kpi"), m=12, seed=0, collision=True, n_starts=1,
                    meta={"arm": g.name})
        for i in range(pairs):
            order = list(variants) if i % 2 == 0 else list(variants)[::-1]
            recs = {}
            for name in order:
                user, system, recs[name] = _one(variants[name], task, Path(tmp) / f"{i}_{name}")
                cpu[name].append(user + system)
                print(f"pair {i}: {name:<13} worker {user:6.2f} s user + {system:5.2f} s system", flush=True)
            same = [d["trace_cs_m2"] for d in recs["package"]["designs"]] == \
                [d["trace_cs_m2"] for d in recs["dask default"]["designs"]]
            print(f"pair {i}: same designs (tr C_s of each) in both: {same}")
    c = paired_comparison(cpu["package"], cpu["dask default"])
    print(f"worker CPU, package against Dask's defaults, {pairs} pairs: {paired_text(c)}")


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 6)
