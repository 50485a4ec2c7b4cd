"""CLI subcommands ``register`` and ``predict`` of ``pin-kpi-oed``: use a calibration on another day.

``register`` re-fits only the measurement set-up (tracker pose, reflector offset) of a calibrated
model file on the given rows, with the robot (geometry + effects) held, and writes a new model
file; ``predict`` writes, per row of a CSV, the reflector position the full model predicts
(x, y, z in m, tracker frame), and the measured position and the error when the file has them; a 6-D model also the
probe orientation (rad) with its σ and the σ it causes at ``--tool-length`` along the tool axis (m).
Errors are :class:`~pin_kpi_oed.errors.PinKpiOedError` with one-line messages (exit code 2);
files are written atomically, after everything has been computed and checked.

Examples::

    pin-kpi-oed identify --robot ur10 --data B.csv --reflector 0,0,0.109 --sigma 1e-4 --model-out model.json
    pin-kpi-oed register --model model.json --data reg.csv --model-out model2.json
    pin-kpi-oed predict --model model2.json --data held.csv --out pred.csv
    pin-kpi-oed predict --model model2.json --data use.csv --out pred.csv --figure trust.png
"""

from __future__ import annotations

import argparse
from typing import Any

import numpy as np

from pin_kpi_oed.cli.flags import in_flags, in_flags_all
from pin_kpi_oed.cli.tool import model_tool
from pin_kpi_oed.cli.util import add_table_options, parse_floats, table_options

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
    r.add_argument("--cell", default=None, help="cell YAML file or shipped cell name: its robot, tool frame and TCP "
                                                "must be the model's (a contradiction is refused)")
    r.add_argument("--json", default=None, help="write the registration result (set-up, rows, RMS) here")
    r.add_argument("--accept-poor-fit", dest="accept_poor_fit", action="store_true",
                   help="write the model even when the registration is poor (too few rows, residuals far above "
                        "the noise, a mirrored frame)")
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
    p.add_argument("--figure", default=None, metavar="OUT.png",
                   help="also write the trust map (PNG): the rows' reflector positions (robot base frame, top and "
                        "side view) coloured by the predicted sigma (mm), the rows outside the measured coverage "
                        "marked, the discrepancy's training configurations in grey")
    p.add_argument("--at", choices=("reflector", "tcp"), default="reflector",
                   help="predict the reflector (default: what the tracker measures, compared with x, y, z when the "
                        "file has them) or the model's TCP: its position and sigma with the joint-placement "
                        "parameters no reflector measurement determines (columns sigma_tcp, sigma_held; the sigma "
                        "identify prints and compensate states)")
    p.add_argument("--tcp", default=None, metavar="X,Y,Z",
                   help="with --at tcp: the TCP point (m) in the model's tool frame; default the model's TCP (its "
                        "cell or data stated it)")
    p.add_argument("--tool-length", dest="tool_length", type=float, default=0.2, metavar="M",
                   help="6-D models: the length along the tool axis (m) at which the orientation sigma is also "
                        "stated as the position sigma it causes there (column sigma_at_length; default 0.2 m)")
    p.add_argument("--quiet", action="store_true", help="print nothing")
    add_table_options(p)
    p.set_defaults(func=run_predict)


def run_register(args: argparse.Namespace) -> int:
    """Handler of ``pin-kpi-oed register``: the set-up re-fitted, gated like ``identify`` (enough rows,
    residuals near the noise, a proper frame; the points' scale against the joint values before the fit)."""
    from pin_kpi_oed.data.atomic import atomic_write_json
    from pin_kpi_oed.data.measurements import read_measurements
    from pin_kpi_oed.errors import InputError
    from pin_kpi_oed.calibrated.model_file import load_model_file
    from pin_kpi_oed.upkeep.transfer import register_setup
    from pin_kpi_oed.validation.robot_checks import check_points_against_joints

    model = load_model_file(args.model)
    model_tool(args, model, args.model, [args.data])  # the data's tool header and --cell against the model
    data = read_measurements(args.data, joint_names=model.robot.joint_names, reach_m=model.robot.reach(),
                             **table_options(args, model.robot))
    check_points_against_joints(model.robot, data.q, data.position_m, args.data, args.data,
                                    **_declared_units(args))
    existing = dict(model.setups)
    res = register_setup(model, data, station=args.station, hold_reflector=args.hold_reflector)
    gates = res.quality
    replaced = [lab for lab in res.stations if lab in existing]
    model_dict = res.model.to_dict()
    quality = [in_flags_all(g.to_dict()) for g in gates]  # the gates' advice in the options' words
    out = ({**res.to_dict(), "model": args.model, "data": args.data, "quality": quality,
            "replaced_stations": replaced} if args.json else None)
    poor = [g for g in gates if g.poor]
    if poor and not args.accept_poor_fit:
        if out is not None:
            atomic_write_json(args.json, out)
        raise InputError(f"{args.data}: {poor[0].line()}; model not written (--accept-poor-fit writes it anyway)")
    atomic_write_json(args.model_out, model_dict)
    if out is not None:
        atomic_write_json(args.json, out)
    if not args.quiet:
        print(in_flags(res.summary()))  # the gate's line of every station included, in the options' words
        for lab in replaced:
            old = existing[lab]
            print(f"station '{lab}' replaced: it was fitted by {old.fitted_by} on {old.n_rows} rows of "
                  f"{old.source or 'unknown data'}; the new set-up is in {args.model_out} (give --station NAME to "
                  "keep both)")
        print("wrote " + ", ".join(f for f in (args.model_out, args.json) if f))
    return 0


def run_predict(args: argparse.Namespace) -> int:
    """Handler of ``pin-kpi-oed predict``."""
    from pin_kpi_oed.data.measurements import read_measurements
    from pin_kpi_oed.errors import InputError
    from pin_kpi_oed.calibrated.model_file import load_model_file
    from pin_kpi_oed.upkeep.transfer import predict_table, write_predictions
    from pin_kpi_oed.validation.options import check_tool_length
    from pin_kpi_oed.validation.robot_checks import check_points_against_joints

    model = load_model_file(args.model)
    check_tool_length(args, model.pose6d, args.model)
    model_tool(args, model, args.model, [args.data])
    camera_rows = _camera_poses(args, model)
    if camera_rows is not None:  # a camera's corners file: its images' joint values, the TCP at each
        return _predict_tcp(args, model, camera_rows)
    data = read_measurements(args.data, joint_names=model.robot.joint_names, reach_m=model.robot.reach(),
                             require_position=False, **table_options(args, model.robot))
    if data.position_m is not None and np.all(np.isfinite(data.position_m)):
        check_points_against_joints(model.robot, data.q, data.position_m, args.data, args.data,
                                    **_declared_units(args))
    if args.at == "tcp":
        return _predict_tcp(args, model, data)
    from pin_kpi_oed.identification.camera_identify import camera_device

    if camera_device(model) is not None:
        raise InputError(f"predict --model {args.model}: a camera's model predicts the TCP (--at tcp); the camera "
                         "measures pixels, not a reflector")
    if args.tcp:
        raise InputError("--tcp states the point of --at tcp: give both, or neither")
    cols, table = predict_table(model, data, station=args.station, tool_length_m=args.tool_length)
    if args.figure:  # the same predict_with_sigma as the table's sigma columns
        from pin_kpi_oed.identification.problem import align_data
        from pin_kpi_oed.viz.trust_map import plot_trust_map

        tm = plot_trust_map(model, align_data(model.robot, data, need_position=False), data, args.station,
                            out=args.figure)
    write_predictions(args.out, data, cols, table)
    if not args.quiet:
        msg = (f"predicted {len(data)} rows of {args.data} with {args.model} (the station's reflector in tool "
               f"frame {model.robot.tool_frame})")
        if "error" in cols:
            e = table[:, cols.index("error")]
            msg += (f": error mean {e.mean() * 1e3:.4f} mm, RMS {np.sqrt(np.mean(e ** 2)) * 1e3:.4f} mm, "
                    f"max {e.max() * 1e3:.4f} mm")
        print(msg + f" -> {args.out}")
        from pin_kpi_oed.calibrated.prediction_sigma import sigma_contents
        s3 = np.linalg.norm(table[:, [cols.index(c) for c in ("sigma_x", "sigma_y", "sigma_z")]], axis=1)
        far = int(np.sum(table[:, cols.index("extrapolation")] > 0))
        print(f"predicted sigma (3-D): median {np.median(s3) * 1e3:.4f} mm, max {s3.max() * 1e3:.4f} mm "
              f"({sigma_contents(model)}); {far} of {len(data)} rows outside the calibration's joint-space coverage"
              + (" (extrapolation column 1: the model was not measured near them)" if far else ""))
        if model.pose6d:
            print(_orientation_line(cols, table, args.tool_length))
        if args.figure:
            print(f"trust map: predicted sigma median {np.median(tm.sigma_m) * 1e3:.4f} mm, max "
                  f"{tm.sigma_m.max() * 1e3:.4f} mm; {tm.n_extrapolated} of {len(data)} rows outside the measured "
                  f"coverage -> {args.figure}")
    return 0


def _camera_poses(args: argparse.Namespace, model: Any) -> Any:
    """The joint values of the images of a camera's corners file (``pose, corner, u_px, v_px`` and the joints), one
    row per image in the file's order, as a :class:`~pin_kpi_oed.data.measurement_set.MeasurementSet` without
    positions; None when ``--data`` is not a corners file.

    Raises:
        InputError: a corners file for a model that is not a camera's, or without ``--at tcp`` (a camera measures
            pixels: the TCP is what its model predicts), or whose joints are not the model's robot's.
    """
    from pin_kpi_oed.cli.camera_pipeline import is_camera_data

    if not is_camera_data([args.data]):
        return None
    # the camera's modules only for a corners file: a tracker's prediction does not load them (0.3 s)
    from pin_kpi_oed.data.corner_measurements import read_corners
    from pin_kpi_oed.data.measurement_set import MeasurementSet
    from pin_kpi_oed.errors import InputError
    from pin_kpi_oed.identification.camera_identify import camera_device

    if camera_device(model) is None:
        raise InputError(f"{args.data}: a camera's corners file (pose, corner, u_px, v_px); {args.model} is a "
                         "tracker's calibration: give a measurement CSV (joints, x, y, z) or the joint values alone")
    if args.at != "tcp":
        raise InputError(f"predict --model {args.model}: a camera's model predicts the TCP: give --at tcp (the "
                         f"joint values of {args.data}'s images are used)")
    cs = read_corners(args.data)
    names = list(model.robot.joint_names)
    if sorted(cs.joint_names) != sorted(names):
        raise InputError(f"{args.data}: joint columns {', '.join(cs.joint_names)} are not the joints of "
                         f"{args.model}'s robot {model.robot.name} ({', '.join(names)})")
    first = {lab: k for k, lab in reversed(list(enumerate(cs.pose.tolist())))}
    rows = [first[lab] for lab in cs.poses]
    Q = cs.q[rows][:, [cs.joint_names.index(n) for n in names]]
    return MeasurementSet(names, Q, np.full((len(Q), 3), np.nan), source=args.data)


def _predict_tcp(args: argparse.Namespace, model: Any, data: Any) -> int:
    """``predict --at tcp``: the TCP's position and its σ per row (:func:`~pin_kpi_oed.upkeep.transfer.tcp_table`).

    Raises:
        InputError: the model states no TCP (neither a cell nor the data's tool header gave one), or ``--figure``.
    """
    from pin_kpi_oed.errors import InputError
    from pin_kpi_oed.upkeep.transfer import predict_table, write_predictions

    tcp = parse_floats(args.tcp, 3, "--tcp") if args.tcp else None
    if tcp is None and not model.tool_source:
        raise InputError(f"{args.model}: the model states no TCP (no cell or tool header gave one when it was "
                         "identified): give --tcp X,Y,Z (m, tool frame) with --at tcp")
    if args.figure:
        raise InputError("--figure draws the reflector's sigma: leave it out with --at tcp")
    cols, table = predict_table(model, data, station=args.station, at="tcp", tcp_m=tcp)
    write_predictions(args.out, data, cols, table)
    if not args.quiet:
        s, h = table[:, cols.index("sigma_tcp")], table[:, cols.index("sigma_held")]
        far = int(np.sum(table[:, cols.index("extrapolation")] > 0))
        print(f"predicted the TCP {np.array2string(model.tcp_m if tcp is None else tcp, precision=4)} m (tool frame "
              f"{model.robot.tool_frame}) at {len(data)} rows of {args.data} with {args.model} -> {args.out}")
        print(f"TCP sigma (3-D): RMS {np.sqrt(np.mean(s ** 2)) * 1e3:.4f} mm, max {s.max() * 1e3:.4f} mm, of which "
              f"the joint-placement parameters no reflector measurement determines RMS "
              f"{np.sqrt(np.mean(h ** 2)) * 1e3:.4f} mm; {far} of {len(data)} rows outside the calibration's "
              "joint-space coverage")
    return 0


def _orientation_line(cols: list[str], table: np.ndarray, length_m: float) -> str:
    """The orientation σ of a 6-D model's predictions (mrad, 3-D) and the σ it causes at ``length_m`` along the tool
    axis (mm); the orientation error against the data's when it has orientations."""
    sw = np.linalg.norm(table[:, [cols.index(c) for c in ("sigma_rx", "sigma_ry", "sigma_rz")]], axis=1)
    sl = table[:, cols.index("sigma_at_length")]
    line = (f"predicted orientation sigma (3-D): median {np.median(sw) * 1e3:.4f} mrad, max {sw.max() * 1e3:.4f} mrad;"
            f" at {length_m * 1e3:g} mm along the tool axis it moves the tool by sigma median "
            f"{np.median(sl) * 1e3:.4f} mm, max {sl.max() * 1e3:.4f} mm")
    if "rot_error" in cols:
        e = table[:, cols.index("rot_error")]
        line += f"; orientation error RMS {np.sqrt(np.mean(e ** 2)) * 1e3:.4f} mrad, max {e.max() * 1e3:.4f} mrad"
    return line


def _declared_units(args: argparse.Namespace) -> dict:
    """The units a CSV was read in (``--units``) for the unit-scale check of its points and joints, whose advice
    then names ``--units`` (the option these commands have)."""
    from pin_kpi_oed.data.table import parse_units

    u = parse_units(getattr(args, "units", None))
    return {"length_unit": u.length, "angle_unit": u.angle, "angle_scale": u.angle_rad, "options": "table"}
