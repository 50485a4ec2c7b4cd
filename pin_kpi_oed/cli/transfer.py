"""CLI subcommands ``register`` and ``predict`` of ``pin-kpi-oed``: use a calibration on another day.

``register`` re-fits only the measurement set-up (tracker pose, reflector offset) of a calibrated
model file on the given rows, with the robot (geometry + effects) held, and writes a new model
file; ``predict`` writes, per row of a CSV, the reflector position the full model predicts
(x, y, z in m, tracker frame), and the measured position and the error when the file has them.
Errors are :class:`~pin_kpi_oed.errors.PinKpiOedError` with one-line messages (exit code 2);
files are written atomically, after everything has been computed and checked.

Examples::

    pin-kpi-oed identify --robot ur10 --data B.csv --reflector 0,0,0.109 --sigma 1e-4 --model-out model.json
    pin-kpi-oed register --model model.json --data reg.csv --model-out model2.json
    pin-kpi-oed predict --model model2.json --data held.csv --out pred.csv
"""

from __future__ import annotations

import argparse

import numpy as np

from pin_kpi_oed.cli.util import add_table_options, table_options

__all__ = ["register", "run_register", "run_predict"]


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``register`` and ``predict`` subcommands."""
    r = subparsers.add_parser("register", help="re-fit only the set-up (tracker pose, reflector) of a calibrated model",
                              description="Re-fit the measurement set-up (tracker pose; reflector offset unless "
                                          "--hold-reflector) of a calibrated model file on the given rows, with the "
                                          "robot (geometry and effects) held; write a model file with the new "
                                          "set-up as its default station.")
    r.add_argument("--model", required=True, help="calibrated model file (identify --model-out)")
    r.add_argument("--data", required=True, help="registration rows: CSV with joint columns and x, y, z (m)")
    r.add_argument("--model-out", required=True, help="write the model with the registered set-up here")
    r.add_argument("--station", default=None,
                   help="label of the registered station (default: the data's 'station' column, else the file name)")
    r.add_argument("--hold-reflector", action="store_true", help="keep the model's reflector offset")
    r.add_argument("--json", default=None, help="write the registration result (set-up, rows, RMS) here")
    r.add_argument("--quiet", action="store_true", help="print nothing")
    add_table_options(r)
    r.set_defaults(func=run_register)

    p = subparsers.add_parser("predict", help="predicted reflector positions of a calibrated model, per CSV row",
                              description="Per row of a CSV (joint columns; x, y, z optional): the reflector position "
                                          "x, y, z (m, tracker frame) the full model (geometry + effects + set-up) "
                                          "predicts, and the measured position and error |measured - predicted| "
                                          "(m) when the file has them.")
    p.add_argument("--model", required=True, help="calibrated model file (identify / register --model-out)")
    p.add_argument("--data", required=True, help="CSV with the robot's joint columns (rad); x, y, z optional")
    p.add_argument("--out", required=True, help="write the predictions (CSV) here")
    p.add_argument("--station", default=None,
                   help="station whose set-up to use (default: the data's 'station' column, else the model's "
                        "default station)")
    p.add_argument("--quiet", action="store_true", help="print nothing")
    add_table_options(p)
    p.set_defaults(func=run_predict)


def run_register(args: argparse.Namespace) -> int:
    """Handler of ``pin-kpi-oed register``."""
    from pin_kpi_oed.data.atomic import atomic_write_json, check_writable
    from pin_kpi_oed.data.measurements import read_measurements
    from pin_kpi_oed.identification.model_file import load_model_file
    from pin_kpi_oed.identification.transfer import register_setup

    for f in (args.model_out, args.json):
        if f:
            check_writable(f)
    model = load_model_file(args.model)
    data = read_measurements(args.data, joint_names=model.robot.joint_names, reach_m=model.robot.reach(),
                             **table_options(args, model.robot))
    res = register_setup(model, data, station=args.station, hold_reflector=args.hold_reflector)
    model_dict = res.model.to_dict()
    out = {**res.to_dict(), "model": args.model, "data": args.data} if args.json else None
    atomic_write_json(args.model_out, model_dict)
    if out is not None:
        atomic_write_json(args.json, out)
    if not args.quiet:
        print(res.summary())
        print("wrote " + ", ".join(f for f in (args.model_out, args.json) if f))
    return 0


def run_predict(args: argparse.Namespace) -> int:
    """Handler of ``pin-kpi-oed predict``."""
    from pin_kpi_oed.data.atomic import check_writable
    from pin_kpi_oed.data.measurements import read_measurements
    from pin_kpi_oed.identification.model_file import load_model_file
    from pin_kpi_oed.identification.transfer import predict_table, write_predictions

    check_writable(args.out)
    model = load_model_file(args.model)
    data = read_measurements(args.data, joint_names=model.robot.joint_names, reach_m=model.robot.reach(),
                             require_position=False, **table_options(args, model.robot))
    cols, table = predict_table(model, data, station=args.station)
    write_predictions(args.out, data, cols, table)
    if not args.quiet:
        msg = f"predicted {len(data)} rows of {args.data} with {args.model}"
        if "error" in cols:
            e = table[:, cols.index("error")]
            msg += (f": error mean {e.mean() * 1e3:.4f} mm, RMS {np.sqrt(np.mean(e ** 2)) * 1e3:.4f} mm, "
                    f"max {e.max() * 1e3:.4f} mm")
        print(msg + f" -> {args.out}")
    return 0
