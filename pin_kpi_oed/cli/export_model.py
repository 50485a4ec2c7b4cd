"""CLI subcommand ``export-model`` of ``pin-kpi-oed``: a calibrated model in the formats robots and ROS read.

Examples::

    pin-kpi-oed export-model --model model.json --format ur-yaml --out my_robot_calibration.yaml
    pin-kpi-oed export-model --model model.json --format urdf --out calibrated.urdf --tcp 0,0,0.15

``ur-yaml`` writes ``ur_description``'s ``default_kinematics.yaml`` layout (UR ROS drivers, MoveIt:
``kinematics_params:=...``); ``urdf`` the calibrated URDF with the set-up frames. Each file is read back and
written only when it reproduces the calibrated tool frame within 1e-9 m; what it cannot carry is printed.
A robot without such a file (KUKA, ABB, Franka) uses the model through ``compensate``: compensated
targets and programs.
"""

from __future__ import annotations

import argparse

__all__ = ["register", "run"]


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``export-model`` subcommand."""
    from pin_kpi_oed.calibrated.formats.registry import MODEL_FORMATS

    p = subparsers.add_parser(
        "export-model", help="write a calibrated model as a UR kinematics file or a calibrated URDF",
        description="Write the calibrated geometry of a model file in a format robots and ROS read: "
                    + "; ".join(f"{f.name}: {f.description}" for f in MODEL_FORMATS.values())
                    + ". The file is read back and written only if it reproduces the calibrated tool frame within "
                      "1e-9 m; what it cannot carry (effects, set-ups, covariance) is printed.")
    p.add_argument("--model", required=True, help="calibrated model file (identify / register --model-out)")
    p.add_argument("--format", required=True, choices=tuple(MODEL_FORMATS), help="output format")
    p.add_argument("--out", required=True, help="output file")
    p.add_argument("--tcp", default=None, help="urdf: TCP point x,y,z in the tool frame (m) for the 'tcp' frame")
    p.add_argument("--no-frames", action="store_true", help="urdf: leave out the tracker / reflector / TCP frames")
    p.add_argument("--quiet", action="store_true", help="print nothing")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Handler of ``pin-kpi-oed export-model``."""
    from pin_kpi_oed.cli.util import parse_floats
    from pin_kpi_oed.calibrated.model_file import load_model_file
    from pin_kpi_oed.calibrated.formats.registry import export_model

    tcp = parse_floats(args.tcp, 3, "--tcp") if args.tcp else None
    cm = load_model_file(args.model)
    rep = export_model(cm, args.out, args.format, tcp_m=tcp, frames=not args.no_frames, source=str(args.model))
    if not args.quiet:
        print(rep.summary())
    return 0
