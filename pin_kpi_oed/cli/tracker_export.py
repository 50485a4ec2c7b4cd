"""CLI subcommand ``import-tracker`` of ``pin-kpi-oed``: a tracker-software point export + joint log -> measurement CSV.

Layouts: :mod:`pin_kpi_oed.data.tracker_export` (``//`` comments, ``Units: mm``, Collection, Group,
Target, X, Y, Z, Timestamp; the joint log: Target + one column per joint, degrees by default).

Example::

    pin-kpi-oed import-tracker export.txt --joints joints.csv --robot kr15 \\
        --columns joint_a1=A1,joint_a2=A2,joint_a3=A3,joint_a4=A4,joint_a5=A5,joint_a6=A6 --out meas.csv
"""

from __future__ import annotations

import argparse

from pin_kpi_oed.model.robot import TOOL_FRAME_HELP

__all__ = ["register", "run"]


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``import-tracker`` subcommand."""
    p = subparsers.add_parser("import-tracker", help="convert a tracker point export + joint log to a measurement CSV",
                              description="Join a tracker-software point export (names, X, Y, Z in mm, time "
                                          "stamps) and the robot's joint log (point name + joint values, degrees) "
                                          "by point name; write the package's measurement CSV (m, rad, s).")
    p.add_argument("export", help="tracker point export (text)")
    p.add_argument("--joints", required=True, help="joint log CSV: point name + one column per joint")
    p.add_argument("--robot", required=True, help="URDF path or robot name (its joints name the columns)")
    p.add_argument("--tool", default=None,
                   help=TOOL_FRAME_HELP + "; written into the output's tool header when given. The reflector and "
                        "the TCP are not measured here: identify takes them from --cell (or --reflector)")
    p.add_argument("--out", required=True, help="write the measurement CSV here")
    p.add_argument("--angle-unit", choices=("deg", "rad"), default="deg", help="unit of the joint log (default deg)")
    p.add_argument("--units", default=None, help="length unit of the export if it has no 'Units:' comment (default mm)")
    p.add_argument("--columns", default=None, help="name mapping ours=theirs for both files (joint_a1=A1,...)")
    p.add_argument("--quiet", action="store_true", help="print nothing")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Handler of ``pin-kpi-oed import-tracker``.

    The joint log is checked against the joint limits, and the points against the joint values: their
    spreads must agree in scale (a metre file read as mm, a joint log in rad read as degrees are refused,
    naming the unit that fits); the units assumed are printed.
    """
    from pin_kpi_oed.data.measurements import write_measurements
    from pin_kpi_oed.data.table import ANGLE_UNITS
    from pin_kpi_oed.data.tracker_export import import_tracker_export, read_point_export
    from pin_kpi_oed.model.robot import load_robot
    from pin_kpi_oed.validation.robot_checks import check_points_against_joints

    robot = load_robot(args.robot, args.tool)
    ms, names = import_tracker_export(args.export, args.joints, robot.joint_names, joint_units=robot.joint_units,
                                      angle_unit=args.angle_unit, units=args.units, columns=args.columns)
    exp = read_point_export(args.export, units=args.units, columns=args.columns, strict=False)
    robot.check_units(ms.q, f"{args.joints} ({args.angle_unit})", first_row=1)
    robot.check_q(ms.q, f"{args.joints} ({args.angle_unit})")
    check_points_against_joints(robot, ms.q, ms.position_m, f"{args.export}", f"{args.joints}", exp.units,
                                args.angle_unit,
                                ANGLE_UNITS[args.angle_unit])
    from pin_kpi_oed.data.tool_header import ToolSpec
    from pin_kpi_oed.model.robot import portable_spec

    # the tool header: the robot, and the tool frame when --tool named it (the default frame is no statement)
    ms.tool = ToolSpec(robot=portable_spec(robot), tool_frame=args.tool or None, source=args.out)
    write_measurements(ms, args.out)
    if not args.quiet:
        print(f"joined {len(names)} points of {args.export} (lengths in {exp.units}: {exp.units_from}) with "
              f"{args.joints} (joint angles in {args.angle_unit}) -> {args.out} (m, rad, s)")
    return 0
