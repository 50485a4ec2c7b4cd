"""``pin-kpi-oed study kuka|notional90|paths``: the paper's studies (thin layer over :mod:`pin_kpi_oed.studies`)."""

from __future__ import annotations

import argparse
from pathlib import Path

from pin_kpi_oed.errors import InputError


def run(args: argparse.Namespace) -> int:
    """Run a study and print its table."""
    from pin_kpi_oed.studies import study
    from pin_kpi_oed.viz.figures import plot_notional, plot_study_figure7

    if args.measurements < 9:
        raise InputError(f"--measurements {args.measurements}: at least 9 are needed to identify 27 parameters")
    out = Path(args.out)
    if args.which == "kuka":
        seeds = tuple(range(args.seed, args.seed + args.seeds))
        s = study.kuka_study(out, m=args.measurements, seeds=seeds, workers=args.workers, scheduler=args.scheduler,
                             n_starts=args.starts, plot=plot_study_figure7)
        print(study.format_kuka_table(s))
        print(f"all designs with collision avoidance collision-free: {s['all_collision_free']}; "
              f"wall time {s['wall_time_s']:.0f} s; results in {out}")
    elif args.which == "paths":
        from pin_kpi_oed.studies.path_study import format_path_table, path_study

        seeds = tuple(range(args.seed, args.seed + args.seeds))
        s = path_study(out, m=args.measurements, seeds=seeds, n_starts=args.starts)
        print(format_path_table(s))
        print(f"all designs collision-free: {s['all_feasible']}; wall time {s['wall_time_s']:.0f} s; "
              f"results in {out / 'summary.json'}")
    else:
        s = study.notional_study(out, m=args.measurements, seed=args.seed, arms=args.arms, workers=args.workers,
                                 scheduler=args.scheduler, n_starts=args.starts, plot=plot_notional)
        print(study.format_notional_summary(s))
        print(f"results in {out} (summary.json, arms.csv, notional90.png)")
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``study`` subcommand."""
    p = sub.add_parser("study", help="reproduce the paper's studies (KUKA cells, 90 notional arms) and the weld-seam "
                                     "path KPI study")
    p.add_argument("which", choices=["kuka", "notional90", "paths"])
    p.add_argument("--out", required=True, help="output folder (resumable: finished tasks are kept)")
    p.add_argument("--measurements", type=int, default=60)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--seeds", type=int, default=3, help="kuka, paths: number of seeds (per cell)")
    p.add_argument("--arms", type=int, default=None, help="notional90: only the first N arms")
    p.add_argument("--starts", type=int, default=1, help="IPOPT starts per design")
    p.add_argument("--workers", type=int, default=None, help="local processes (default: all cores)")
    p.add_argument("--scheduler", default=None,
                   help="Dask scheduler tcp://host:port (or 'local-dask' for an in-process LocalCluster)")
    p.set_defaults(func=run)
