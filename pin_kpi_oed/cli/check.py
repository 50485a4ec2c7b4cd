"""CLI subcommand ``check`` of ``pin-kpi-oed``: does a calibration still hold, and if not, what changed.

``check`` takes the measured check rows, re-registers the set-up with the robot held and tests the residuals
against the model's honest σ: a change counts only when it is shown to move the working TCPs by more than
``--tolerance`` (m, RMS over the working configurations); the whole verdict's false-alarm rate is ``--alpha``.
*holds* (a significant change below the tolerance is stated in it) / *set-up moved* / *the robot changed* (which
group, by how much ± σ, the re-fitted model written with ``--model-out``) / *the discrepancy's level* /
*re-calibrate* (and by how much a re-calibration beats a re-fit on the expected TCP error), in one line and in JSON;
the exit code says it: :data:`EXIT_HELP`. ``check design`` chooses the few poses (default 10) that give the
check the largest power against a change of any group that moves the TCP by ``--tolerance`` (m, RMS over the
working configurations), feasible in ``--cell``, written as a joint CSV (``--out``: measure it and give it back as
``--data``) and as a robot program (``--program`` with ``--format``).

Examples::

    pin-kpi-oed check design --model model.json --cell cell.yaml --tolerance 1e-4 --out check_poses.csv \\
        --program check.script --format urscript
    pin-kpi-oed check --model model.json --data check_rows.csv --json verdict.json --model-out refit.json
"""

from __future__ import annotations

import argparse

import numpy as np

from pin_kpi_oed.cli.tool import model_tool
from pin_kpi_oed.cli.util import add_table_options, table_options

__all__ = ["register", "run_check", "run_monitor", "EXIT_HELP"]

#: The exit codes of ``check`` and ``monitor`` (their --help's epilog).
EXIT_HELP = ("exit codes: 0 the calibration holds; 1 changed: the set-up moved or the robot changed (the re-registered "
             "or re-fitted model is what --model-out writes); 3 re-calibrate (or the discrepancy's level changed); "
             "2 bad input (one line naming the file, field or value)")
#: monitor --fail-on: the verdicts whose exit code the monitor ends with.
FAIL_ON = {"never": 99, "changed": 1, "recalibrate": 3}


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``check`` subcommand (``check`` and ``check design``)."""
    p = subparsers.add_parser("check", help="does a calibration still hold? (check design: the poses to measure)",
                              description="On measured check rows: re-register the set-up, test the residuals "
                                          "against the model's honest sigma; the verdict in one line and JSON. "
                                          "'check design': the poses that give that test the largest power.",
                              epilog=EXIT_HELP)
    p.add_argument("action", nargs="?", choices=["design"], default=None,
                   help="'design': choose the check poses instead of judging measured ones")
    p.add_argument("--model", required=True, help="calibrated model file (identify / register --model-out)")
    p.add_argument("--data", default=None, help="the measured check rows: CSV with joint columns and x, y, z (m)")
    p.add_argument("--station", default=None, help="the model's station the set-up is compared with (default: "
                                                   "the model's default station)")
    p.add_argument("--alpha", type=float, default=0.05,
                   help="the false-alarm rate of the whole verdict: the probability it says anything but 'holds' on "
                        "an unchanged robot (its two tests, residuals and set-up, each at 1 - (1 - alpha)^(1/2); "
                        "default 0.05)")
    p.add_argument("--tolerance", type=float, default=1e-4,
                   help="the RMS change of the TCP at the working configurations that matters, in m (default 1e-4 = "
                        "0.1 mm): a change is reported only when shown to exceed it; check design sizes the poses "
                        "for that decision")
    p.add_argument("--cell", default=None, help="cell YAML file or shipped cell name: check design's poses are "
                                                "feasible in it; its working configurations when the model has none")
    p.add_argument("--measurements", "-m", type=int, default=10, help="check design: number of poses (default 10)")
    p.add_argument("--pool-size", dest="pool_size", type=int, default=400,
                   help="check design: feasible candidate poses (default 400)")
    p.add_argument("--seed", type=int, default=0, help="seed of the candidate poses and the reference poses")
    p.add_argument("--out", default=None, help="check design: write the poses here (CSV, joint columns in rad)")
    p.add_argument("--program", default=None, help="check design: also write a robot program here (--format)")
    p.add_argument("--format", default="csv", help="program format: csv, urscript, krl, rapid (default csv)")
    p.add_argument("--model-out", dest="model_out", default=None,
                   help="check: write the re-registered model (the re-fitted one when the robot changed) here")
    p.add_argument("--json", default=None, help="write the verdict / the design as JSON here")
    p.add_argument("--quiet", action="store_true", help="print nothing")
    add_table_options(p)
    p.set_defaults(func=run_check)

    mo = subparsers.add_parser("monitor", help="rows measured during work (a file, or followed as it grows): each "
                                                "predicted first, the set-up followed, a check every few rows",
                               description="Take a measurement file's rows in their order (time order; --follow: "
                                           "as the file grows): each row is predicted with its honest sigma and the "
                                           "set-up filter's before it is used (standardised RMS over the replay), the "
                                           "set-up followed by a Kalman filter whose drift level is estimated from the "
                                           "rows, every --every rows a check (set-up re-registered, chi2 at --alpha; "
                                           "--refit: also follow a re-fitted group); poses asked for when the rows "
                                           "cannot tell. One line per event.", epilog=EXIT_HELP + "; monitor ends "
                               "with the largest code of its checks' verdicts that --fail-on counts")
    mo.add_argument("--model", required=True, help="calibrated model file")
    mo.add_argument("--data", required=True, help="rows measured during work: CSV with joint columns and x, y, z (m)")
    mo.add_argument("--every", type=int, default=10, help="rows per check (default 10)")
    mo.add_argument("--alpha", type=float, default=0.05, help="false-alarm rate of each check's verdict (default 0.05)")
    mo.add_argument("--tolerance", type=float, default=1e-4,
                    help="RMS TCP change at the working configurations that matters, m (default 1e-4)")
    mo.add_argument("--fail-on", dest="fail_on", choices=list(FAIL_ON), default="recalibrate",
                    help="which verdicts set the exit code at the end: 'recalibrate' (default: exit 3 when a check "
                         "said re-calibrate or the discrepancy's level changed), 'changed' (also exit 1 when a check "
                         "said the set-up moved or the robot changed), 'never' (exit 0)")
    mo.add_argument("--station", default=None, help="the model's station of the first rows (default station)")
    mo.add_argument("--refit", action="store_true",
                    help="also follow a re-fitted group of the robot (default: only a moved set-up; a robot change "
                         "asks for check design's poses)")
    mo.add_argument("--follow", action="store_true",
                    help="follow the file while it grows (rows appended during work): read it every --poll s, stop "
                         "after --idle s without a new row (or Ctrl-C); a truncated or rewritten file is a warning, "
                         "the rows used before are kept")
    mo.add_argument("--poll", type=float, default=1.0, help="--follow: seconds between reads (default 1)")
    mo.add_argument("--idle", type=float, default=60.0,
                    help="--follow: stop after this many seconds without a new row (default 60)")
    mo.add_argument("--model-out", dest="model_out", default=None, help="write the model at the end of the replay")
    mo.add_argument("--json", default=None, help="write the log (per row error and sigma, per check the verdict)")
    mo.add_argument("--quiet", action="store_true", help="print nothing")
    add_table_options(mo)
    mo.set_defaults(func=run_monitor)


def run_monitor(args: argparse.Namespace) -> int:
    """Handler of ``pin-kpi-oed monitor``."""
    from pin_kpi_oed.data.atomic import atomic_write_json, to_jsonable
    from pin_kpi_oed.data.measurements import read_measurements
    from pin_kpi_oed.calibrated.model_file import load_model_file
    from pin_kpi_oed.upkeep.monitoring import Monitor, monitor

    model = load_model_file(args.model)
    model_tool(args, model, args.model, [args.data])
    read = dict(joint_names=model.robot.joint_names, reach_m=model.robot.reach(), **table_options(args, model.robot))
    opts = dict(every=args.every, alpha=args.alpha, tolerance_m=args.tolerance, station=args.station,
                refit=args.refit, echo=None if args.quiet else print)
    if args.follow:
        mon = Monitor(model, **opts)
        _follow(mon, args.data, read, args.poll, args.idle, args.quiet)
        mon.flush()
        log = mon.log()
    else:
        log = monitor(model, read_measurements(args.data, **read), **opts)
    if args.model_out:
        atomic_write_json(args.model_out, log.model.to_dict())
    if args.json:
        atomic_write_json(args.json, to_jsonable({**log.to_dict(), "model": args.model, "data": args.data}))
    if not args.quiet:
        print(log.summary())
        if log.blocks:
            print(log.block_text())
    return log.exit_code(FAIL_ON[args.fail_on])


def _follow(mon, path: str, read: dict, poll_s: float, idle_s: float, quiet: bool) -> None:
    """Feed ``mon`` the rows appended to ``path`` until ``idle_s`` pass without one (or Ctrl-C); warnings (a file
    truncated or rewritten while read, a line that cannot be read yet) on stderr, one line each."""
    import sys
    import time

    from pin_kpi_oed.data.measurement_follow import FollowedFile

    f = FollowedFile(path, read)
    last = time.monotonic()
    try:
        while time.monotonic() - last < idle_s:
            rows, warning = f.poll()
            if warning and not quiet:
                print(f"warning: {warning}", file=sys.stderr)
            if rows is not None:
                mon.feed(rows)
                last = time.monotonic()
            else:
                time.sleep(poll_s)
    except KeyboardInterrupt:
        from pin_kpi_oed.cli.interrupts import consume

        consume()  # Ctrl-C is how following ends: the command goes on to write what was seen
        if not quiet:
            print("monitor: stopped (Ctrl-C); writing what was seen", file=sys.stderr)


def run_check(args: argparse.Namespace) -> int:
    """Handler of ``pin-kpi-oed check`` and ``check design``."""
    from pin_kpi_oed.errors import InputError
    from pin_kpi_oed.calibrated.model_file import load_model_file

    model = load_model_file(args.model)
    from pin_kpi_oed.identification.camera_identify import camera_device

    if camera_device(model) is not None:
        return _camera_verdict(args, model)
    if args.action == "design":
        if args.data or args.model_out:
            raise InputError("check design: --data and --model-out belong to the check itself (without 'design')")
        if not (args.out or args.json or args.program):
            raise InputError("check design: give --out (the poses, CSV), --program or --json; nothing would be "
                             "written")
        return _design(args, model)
    if not args.data:
        raise InputError("check: give --data (the measured check rows), or 'check design' to choose them")
    if args.out or args.program:
        raise InputError("check: --out and --program belong to 'check design'")
    return _verdict(args, model)


def _camera_verdict(args: argparse.Namespace, model) -> int:
    """``check --model CAMERA_MODEL --data CHECK_CORNERS.csv`` (:mod:`pin_kpi_oed.upkeep.camera_check`)."""
    from pin_kpi_oed.data.atomic import atomic_write_json, to_jsonable
    from pin_kpi_oed.data.corner_measurements import read_corners
    from pin_kpi_oed.errors import InputError
    from pin_kpi_oed.upkeep.camera_check import check_camera

    if args.action == "design":
        raise InputError(f"check design --model {args.model}: not for a camera's model yet (its poses must see the "
                         "board); take check images at the calibration's working configurations")
    if not args.data:
        raise InputError("check: give --data (the check images' corners, import-images' CSV)")
    for opt, v in (("--model-out", args.model_out), ("--out", args.out), ("--program", args.program),
                   ("--station", args.station)):
        if v:
            raise InputError(f"check {opt}: not for a camera's model (a camera check re-fits nothing it writes)")
    res = check_camera(model, read_corners(args.data), alpha=args.alpha, source=args.data)
    if args.json:
        atomic_write_json(args.json, to_jsonable({**res.to_dict(), "model": args.model, "data": args.data}))
    if not args.quiet:
        print(res.summary())
    return res.exit_code


def _verdict(args: argparse.Namespace, model) -> int:
    from pin_kpi_oed.data.atomic import atomic_write_json, to_jsonable
    from pin_kpi_oed.data.measurements import read_measurements
    from pin_kpi_oed.upkeep.check import check_calibration
    from pin_kpi_oed.validation.robot_checks import check_points_against_joints

    spec = model_tool(args, model, args.model, [args.data])
    data = read_measurements(args.data, joint_names=model.robot.joint_names, reach_m=model.robot.reach(),
                             **table_options(args, model.robot))
    check_points_against_joints(model.robot, data.q, data.position_m, args.data, args.data)
    res = check_calibration(model, data, station=args.station, alpha=args.alpha, tolerance_m=args.tolerance,
                            q_work=getattr(spec, "q_work", None), seed=args.seed)
    doc = {**res.to_dict(), "model": args.model, "data": args.data, "model_out": args.model_out}
    if args.model_out:
        atomic_write_json(args.model_out, res.model.to_dict())
    if args.json:
        atomic_write_json(args.json, to_jsonable(doc))  # strict JSON: what was not computed is null
    if not args.quiet:
        print(res.summary())
        written = [f for f in (args.model_out, args.json) if f]
        if written:
            print("wrote " + ", ".join(written))
    return res.exit_code


def _design(args: argparse.Namespace, model) -> int:
    from pin_kpi_oed.data.atomic import atomic_write_json, atomic_write_text, to_jsonable
    from pin_kpi_oed.upkeep.check_design import design_check
    from pin_kpi_oed.errors import InputError
    from pin_kpi_oed.program.export import ProgramInfo, write_program

    cell = None
    if args.cell:
        from pin_kpi_oed.cell.cell import load_cell

        model_tool(args, model, args.model)
        cell = load_cell(args.cell)
    d = design_check(model, m=args.measurements, tolerance_m=args.tolerance, alpha=args.alpha, cell=cell,
                     pool_size=args.pool_size, seed=args.seed, station=args.station)
    rb = model.robot
    texts = {}
    if args.out:
        head = ",".join(rb.joint_names)
        texts[args.out] = head + "\n" + "".join(",".join(repr(float(v)) for v in q) + "\n" for q in d.Q)
    if args.program:
        info = ProgramInfo(cell=getattr(cell, "name", "") or "none", design=f"check design of {args.model}",
                           robot=rb.name, joint_names=list(rb.joint_names), revolute=np.asarray(rb.revolute, bool),
                           name="pko_check")
        prog = write_program(args.format, d.Q, ["measure"] * len(d.Q), list(range(len(d.Q))), info)
        if len(prog) != 1:
            raise InputError(f"--format {args.format}: writes several files; use csv, urscript or rapid for a "
                             "check program")
        texts[args.program] = next(iter(prog.values()))
    for path, text in texts.items():
        atomic_write_text(path, text)
    if args.json:
        atomic_write_json(args.json, to_jsonable({**d.to_dict(), "model": args.model, "cell": args.cell}))
    if not args.quiet:
        print(d.summary())
        print("wrote " + ", ".join(f for f in (args.out, args.program, args.json) if f))
    return 0

