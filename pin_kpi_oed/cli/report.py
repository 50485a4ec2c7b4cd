"""CLI subcommand ``report`` of ``pin-kpi-oed``: the calibration certificate (HTML, JSON, PDF).

Examples::

    pin-kpi-oed report --model model.json --train c_train.csv --validate c_test.csv --html cert.html --json cert.json
    pin-kpi-oed report --model model.json --train C.csv --validate D.csv --register-rows 60 --html cert_d.html
    pin-kpi-oed report --model cam_model.json --train corners.csv --validate corners_test.csv --html cam.html

A camera's corner files (``--train CORNERS.csv``) get a camera's certificate (:mod:`pin_kpi_oed.report.camera`):
the fit in px on training and held-out images, the TCP's U (k = 2) with its budget, the hand-eye transform and the
board with their sigma; ``--required-accuracy`` is then about the TCP's position (its largest U); the options about a
tracker's measured positions are refused by name.

Every figure is the one ``identify --validate`` / ``predict`` / ``diagnose`` compute for the same inputs
(:mod:`pin_kpi_oed.report`). Bad input (no held-out data, training files other than the model file recorded,
a kinematics file of another robot or hash): one line, exit 2, nothing written.
"""

from __future__ import annotations

import argparse
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from pin_kpi_oed.report.content import CertificateOptions

__all__ = ["register", "run"]


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``report`` subcommand."""
    from pin_kpi_oed.cli.util import add_table_options

    p = subparsers.add_parser(
        "report", help="calibration certificate (HTML with embedded figures, JSON, PDF) of a model file",
        description="One self-contained certificate of a calibration: what was calibrated (robot, URDF hash, tool, "
                    "stations, data files with rows and SHA-256, versions, commands), the parameters with their "
                    "std and correlations, accuracy before / after on held-out rows, the fit-quality verdict, the "
                    "honest sigma, the trust map and ISO 9283 AP / vAP / RP where the data hold them.")
    p.add_argument("--model", required=True, help="calibrated model file (identify / diagnose --model-out)")
    p.add_argument("--train", required=True, action="append", help="training measurement CSV (repeat for several)")
    p.add_argument("--validate", default=None, help="held-out measurement CSV (required)")
    p.add_argument("--register-rows", type=int, default=None,
                   help="another session: re-register the set-up on this many seeded rows of --validate, "
                        "score the rest")
    p.add_argument("--register-data", default=None, help="another session: re-register the set-up on this CSV")
    p.add_argument("--seed", type=int, default=0, help="seed of the registration rows")
    p.add_argument("--kinematics", default=None,
                   help="UR kinematics file the model's nominal robot must have (checked)")
    p.add_argument("--html", default=None, help="write the certificate (HTML) here")
    p.add_argument("--json", default=None, help="write its content (JSON, SI units) here")
    p.add_argument("--pdf", default=None,
                   help="print it to PDF here (headless Chromium; skipped with a note if absent)")
    p.add_argument("--lab", default=None,
                   help="lab file (YAML: organisation, operator, customer, robot_serial, instrument make / model / "
                        "serial / calibration_date / calibration_certificate); without it the page is a draft")
    p.add_argument("--required-accuracy", type=float, default=None,
                   help="required accuracy (m, at most 0.01) of --accuracy-figure: ISO 14253-1 conformity "
                        "statement (undetermined where the TCP's U at the working configurations exceeds it; camera "
                        "data: of the TCP's position, on its largest U at the working configurations)")
    p.add_argument("--accuracy-figure", default="p95", choices=["p95", "rms", "mean", "max"],
                   help="the held-out figure the required accuracy is about (default p95)")
    p.add_argument("--work", default=None,
                   help="working configurations (joint-space program CSV) the uncertainty budget is stated at "
                        "(default: the model's)")
    p.add_argument("--cell", default=None,
                   help="a work cell (shipped name or YAML) whose working paths the TCP's expanded uncertainty is "
                        "stated along (its TCP; the cell's robot must be the model's)")
    p.add_argument("--goal-radius", type=float, default=1e-3,
                   help="ISO 9283: rows whose goal lies within this distance (m) of a position's first goal are "
                        "that commanded position (default 0.001)")
    p.add_argument("--commanded-tcp", default=None,
                   help="ISO 9283: the point x,y,z (m, tool frame) the goal columns command (default: the "
                        "measured point)")
    p.add_argument("--monte-carlo", type=int, default=0,
                   help="draws of the Monte-Carlo check of the uncertainty budget (0: none)")
    p.add_argument("--quiet", action="store_true", help="print nothing")
    add_table_options(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Handler of ``pin-kpi-oed report``."""
    from pin_kpi_oed.cli.util import table_options
    from pin_kpi_oed.data.provenance import command_line
    from pin_kpi_oed.errors import InputError
    from pin_kpi_oed.report.content import build_certificate
    from pin_kpi_oed.report.write import write_certificate

    if not (args.html or args.json or args.pdf):
        raise InputError("give --html FILE, --json FILE and/or --pdf FILE")
    if args.register_rows is not None and args.register_data:
        raise InputError("give --register-rows or --register-data, not both")
    from pin_kpi_oed.cli.camera_pipeline import is_camera_data

    if is_camera_data(list(args.train)):
        return _camera_report(args)
    if args.validate:  # the data files' tool headers against the model: robot, tool frame, TCP
        from pin_kpi_oed.cli.tool import model_tool
        from pin_kpi_oed.calibrated.model_file import load_model_file

        model_tool(args, load_model_file(args.model), args.model,
                   [*args.train, args.validate, *([args.register_data] if args.register_data else [])])
    cert = build_certificate(args.model, args.train, args.validate, register_rows=args.register_rows,
                             register_data_path=args.register_data, seed=args.seed, table_opts=table_options(args),
                             kinematics=args.kinematics, command=command_line(getattr(args, "argv", None) or []),
                             figures=bool(args.html or args.pdf), options=_options(args))
    out = write_certificate(cert, html=args.html, json_path=args.json, pdf=args.pdf)
    if not args.quiet:
        a = cert.data["accuracy"]
        print(f"held-out RMS {a['before']['rms_m'] * 1e3:.4f} mm before, {a['after']['rms_m'] * 1e3:.4f} mm after "
              f"({a['after']['n']} rows); {cert.data['fit_quality'].get('message')}")
        if out["pdf_skipped"]:
            print(out["pdf_skipped"])
        s = cert.data["summary"]
        print(f"{s['status']['kind']}: {s['verdict']['text']}")
        print("wrote " + ", ".join(out["written"]))
    return 0


#: report options about a tracker's held-out positions (ISO 9283, re-registration, paths): dest -> default
_CAMERA_REFUSED = {"register_rows": None, "register_data": None, "goal_radius": 1e-3, "commanded_tcp": None,
                   "cell": None, "accuracy_figure": "p95", "kinematics": None}


def _camera_report(args: argparse.Namespace) -> int:
    """``report --train CORNERS.csv``: a camera calibration's certificate (:mod:`pin_kpi_oed.report.camera`).

    Raises:
        InputError: an option about a tracker's positions (named), as :func:`build_camera_certificate`.
    """
    from pin_kpi_oed.data.provenance import command_line
    from pin_kpi_oed.errors import InputError
    from pin_kpi_oed.report.camera import build_camera_certificate
    from pin_kpi_oed.report.write import write_certificate

    for dest, default in _CAMERA_REFUSED.items():
        if getattr(args, dest, default) != default:
            raise InputError(f"report --{dest.replace('_', '-')}: not for camera measurements (it is about a "
                             "tracker's measured positions); leave it out")
    cert = build_camera_certificate(args.model, list(args.train), args.validate, seed=args.seed,
                                    command=command_line(getattr(args, "argv", None) or []), options=_options(args))
    out = write_certificate(cert, html=args.html, json_path=args.json, pdf=args.pdf)
    if not args.quiet:
        d = cert.data
        f, u = d["fit"], d["uncertainty"]
        print(f"reprojection RMS {f['training']['rms_px']:.3f} px training, {f['held_out']['rms_px']:.3f} px held-out "
              f"({f['held_out']['images']} images); TCP U (k = 2) median {u['U_median_m'] * 1e3:.4f} mm, largest "
              f"{u['U_max_m'] * 1e3:.4f} mm at {u['n']} configurations; {u['held_statement']}")
        if out["pdf_skipped"]:
            print(out["pdf_skipped"])
        s = d["summary"]
        print(f"{s['status']['kind']}: {s['verdict']['text']}")
        print("wrote " + ", ".join(out["written"]))
    return 0


def _options(args: argparse.Namespace) -> CertificateOptions:
    """The :class:`CertificateOptions` of the command line (lengths checked in m)."""
    import numpy as np

    from pin_kpi_oed.errors import InputError
    from pin_kpi_oed.report.content import CertificateOptions

    for flag, v, top in (("--required-accuracy", args.required_accuracy, 0.01), ("--goal-radius", args.goal_radius,
                                                                                  0.1)):
        if v is not None and not (np.isfinite(v) and 0 < v <= top):
            raise InputError(f"{flag} {v!r}: a positive length of at most {top:g} m (the option is in metres"
                             + (f": {v:g} mm is {v * 1e-3:g})" if np.isfinite(v) and v > top else ")"))
    tcp = None
    if args.commanded_tcp:
        try:
            tcp = np.array([float(x) for x in args.commanded_tcp.split(",")])
        except ValueError:
            tcp = np.zeros(0)
        if tcp.shape != (3,) or not np.all(np.isfinite(tcp)) or np.abs(tcp).max() > 2.0:
            raise InputError(f"--commanded-tcp {args.commanded_tcp!r}: three numbers x,y,z in m")
    work = None
    if args.work:
        from pin_kpi_oed.calibrated.model_file import load_model_file
        from pin_kpi_oed.data.targets import read_targets

        rb = load_model_file(args.model).robot
        work = read_targets(args.work, rb.joint_names, program=True, revolute=rb.is_revolute).q
    cell = _cell(args.cell, args.model) if args.cell else None
    if args.monte_carlo < 0:
        raise InputError(f"--monte-carlo {args.monte_carlo}: a number of draws >= 0")
    return CertificateOptions(lab_path=args.lab, required_accuracy_m=args.required_accuracy,
                              accuracy_figure=f"{args.accuracy_figure}_m", work_q=work, goal_radius_m=args.goal_radius,
                              commanded_tcp_m=tcp, mc_draws=args.monte_carlo, cell=cell)


def _cell(spec: str, model: str) -> Any:
    """The cell of ``--cell``; its robot's joints must be the model's.

    Raises:
        InputError: a cell of another robot (naming both).
    """
    from pin_kpi_oed.calibrated.model_file import load_model_file
    from pin_kpi_oed.cell.cell import load_cell
    from pin_kpi_oed.errors import InputError

    cell = load_cell(spec)
    rb = load_model_file(model).robot
    if list(cell.robot.joint_names) != list(rb.joint_names):
        raise InputError(f"--cell {spec}: its robot {cell.robot.name} has joints {', '.join(cell.robot.joint_names)}, "
                         f"the model {model} {', '.join(rb.joint_names)}")
    return cell
