"""CLI subcommand ``compensate`` of ``pin-kpi-oed``: joint values for the real robot from a calibrated model.

The controller keeps its nominal kinematics; ``compensate`` tells it other joint values so that the
real TCP lands on the target according to the calibrated model (geometry + effects), by inverse
kinematics on that model started from the nominal solution
(:mod:`pin_kpi_oed.compensation.compensator`). Per target it reports the predicted correction
(mm) and flags targets that are unreachable, off the branch of their joint hint / the model's working
configurations, at a joint limit, in collision (``--cell``), near a singularity, or outside the calibration's
joint-space coverage (``extrapolated``, with the widened σ ``predict`` gives there). The TCP (``--tcp``) is in the
model's tool frame, which the summary names.

Examples::

    pin-kpi-oed compensate --model model.json --targets targets.csv --out joints.csv            # tracker frame
    pin-kpi-oed compensate --model model.json --targets targets.csv --frame base --out joints.csv
    pin-kpi-oed compensate --model model.json --program prog.csv --out prog_compensated.csv
"""

from __future__ import annotations

import argparse

import numpy as np

from pin_kpi_oed.cli.tool import model_cell_tool
from pin_kpi_oed.cli.util import add_table_options, parse_floats, table_options
from pin_kpi_oed.errors import InputError

__all__ = ["register", "run"]


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``compensate`` subcommand."""
    p = subparsers.add_parser(
        "compensate", help="compensated joint values for Cartesian TCP targets or a joint-space program",
        description="Inverse kinematics on the calibrated model (geometry + effects), started from the nominal "
                    "solution: the joint values that put the real TCP on each target. --targets: CSV with x, y, z "
                    "(m; rx, ry, rz rad optional; name; joint columns as start hints optional) in the tracker frame "
                    "of the station (--frame tracker) or the robot base frame (--frame base). --program: CSV with "
                    "the joint columns of a nominal program; each pose's nominal TCP pose (base frame) becomes the "
                    "target. Writes the compensated joints, the nominal ones, the predicted correction (m), the "
                    "residual and a status per target (ok / unreachable / off_branch / joint_limit / collision / "
                    "near_singular / extrapolated: outside the calibration's joint-space coverage, with the widened "
                    "sigma predict gives there; measure poses near it); only ok is safe to send. The nominal IK "
                    "starts from the target's joint hint, "
                    "else the model's (or --cell's) working configuration nearest the target.")
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument("--targets", default=None, help="CSV of Cartesian TCP targets (x, y, z; rx, ry, rz optional)")
    src.add_argument("--program", default=None, help="CSV of a joint-space program (the robot's joint columns)")
    p.add_argument("--model", required=True, help="calibrated model file (identify / register --model-out)")
    p.add_argument("--out", required=True, help="write the compensated joints (CSV) here")
    p.add_argument("--frame", choices=("tracker", "base", "cell"), default="tracker",
                   help="frame of --targets: tracker = the tracker frame of the station (default), base = robot base "
                        "frame ('cell' is refused: a cell file's frame is neither)")
    p.add_argument("--station", default=None, help="station of the cell frame and default TCP (default: the model's)")
    p.add_argument("--tcp", default=None,
                   help="TCP point x,y,z (m) in the model's tool frame (printed; the frame the calibration used); "
                        "default the model's TCP when its cell or data stated one, else the TCP of --cell; a model "
                        "without either is refused (the reflector, what was measured, is not the TCP)")
    p.add_argument("--cell", default=None,
                   help="cell YAML file or shipped cell name: every compensated configuration is checked for "
                        "collisions in it (status 'collision'); its robot, tool frame and TCP must be the model's, "
                        "its working configurations give the branch of targets without joint hints")
    p.add_argument("--max-branch-step", dest="max_branch_step", type=float, default=0.05,
                   help="largest joint change (rad) compensation may make to the nominal solution; beyond it the "
                        "target is 'off_branch' (default 0.05)")
    p.add_argument("--position-only", action="store_true",
                   help="with --program: hold the TCP position only, leave the orientation free")
    p.add_argument("--tool-length", dest="tool_length", type=float, default=0.2, metavar="M",
                   help="6-D models: the tool orientation's sigma is also stated as the position sigma it causes "
                        "this far along the tool axis (m; default 0.2)")
    p.add_argument("--seed", type=int, default=0, help="seed of the random restarts of the nominal IK")
    p.add_argument("--json", default=None, help="write the full result (per target) as JSON here")
    p.add_argument("--quiet", action="store_true", help="print nothing")
    add_table_options(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Handler of ``pin-kpi-oed compensate``."""
    from pin_kpi_oed.data.atomic import atomic_write_json
    from pin_kpi_oed.data.targets import read_targets
    from pin_kpi_oed.errors import InfeasibleError
    from pin_kpi_oed.compensation.compensator import (SENDABLE, STATUSES, CompensationOptions, compensate,
                                                       compensate_program, write_compensation)
    from pin_kpi_oed.calibrated.model_file import load_model_file
    from pin_kpi_oed.validation.options import check_tool_length

    model = load_model_file(args.model)
    check_tool_length(args, model.pose6d, args.model)
    robot = model.robot
    cell = None
    if args.cell:  # collisions checked in it; its working configurations when the model has none
        from pin_kpi_oed.cell.cell import load_cell

        cell = load_cell(args.cell)
        model_cell_tool(model, args.model, cell, args.cell)  # the model's robot, tool frame and TCP are the cell's
    kw = table_options(args)
    tcp = parse_floats(args.tcp, 3, "--tcp") if args.tcp else None
    if tcp is None and not model.tool_source:  # the TCP of --cell, else refused: the reflector is not the TCP
        if cell is None:
            refl = model.setups[model.station(args.station)].reflector_m
            raise InputError(f"{args.model}: the model states no TCP (identified without --cell or a data header "
                             f"stating tcp_m; only the reflector {np.round(refl, 6).tolist()} m was measured): give "
                             f"--tcp x,y,z (m, in tool frame {robot.tool_frame}), or --cell CELL (its tcp_m), or "
                             "identify with --cell CELL so that --model-out keeps the TCP")
        tcp = np.asarray(cell.tcp_m, float).copy()
    frame = "cell" if args.frame == "tracker" else args.frame  # the library's name of the station's tracker frame
    opt = CompensationOptions(frame=frame, station=args.station, tcp_m=tcp, seed=args.seed, cell=cell,
                              max_branch_step_rad=args.max_branch_step, tool_length_m=args.tool_length)
    if args.program:
        prog = read_targets(args.program, robot.joint_names, program=True, revolute=robot.is_revolute,
                            joint_guard=robot.unit_guard.tolist(), **kw)
        res = compensate_program(model, prog, opt, orientation=not args.position_only)
    else:
        ts = read_targets(args.targets, robot.joint_names, revolute=robot.is_revolute,
                          joint_guard=robot.unit_guard.tolist(), **kw)
        res = compensate(model, ts, opt)
    if res.target_status and not set(SENDABLE) & set(res.target_status):  # nothing useful: exit 2
        n_un = res.target_status.count("unreachable")
        hint = (f"; the TCP {', '.join(f'{x:g}' for x in tcp)} m is {float(np.linalg.norm(tcp)):.3g} m from the tool "
                "frame" if tcp is not None else "")
        others = ", ".join(f"{res.target_status.count(k)} {k.replace('_', ' ')}" for k in STATUSES[2:]
                           if k in res.target_status)
        raise InfeasibleError(f"{args.program or args.targets}: none of the {len(res.target_status)} targets can be "
                              f"compensated ({n_un} unreachable" + (f", {others}" if others else "")
                              + f") with {args.model} (TCP in tool frame {robot.tool_frame}){hint}; check the frame "
                              f"(--frame {args.frame}) and units (m); nothing written")
    write_compensation(args.out, res)
    if args.json:
        from pin_kpi_oed.data.atomic import to_jsonable

        atomic_write_json(args.json, to_jsonable({**res.to_dict(), "model": args.model,  # JSON has no NaN: null
                                                  "input": args.program or args.targets}))
    if not args.quiet:
        print(res.summary())
        print("wrote " + ", ".join(f for f in (args.out, args.json) if f))
    return 0
