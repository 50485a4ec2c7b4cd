"""``pin-kpi-oed view DESIGN_JSON``: meshcat preview of a design (see :mod:`pin_kpi_oed.viz.scene`).

    pin-kpi-oed view design.json                       # live meshcat viewer in the browser (Ctrl-C to stop)
    pin-kpi-oed view design.json --html out.html       # self-contained static page, opened in the browser
    pin-kpi-oed view design.json --html out.html --no-open
    pin-kpi-oed view design.json --figures figs/ --no-open --html out.html
    pin-kpi-oed view design.json --html pose.html --pose kpi:5   # page opens paused at the KPI design's pose 5
    pin-kpi-oed view design.json --html all.html --all-ghosts     # ghost every pose (default: designs of <= 8 poses)
    pin-kpi-oed view design.json --html paper.html --sigma paper  # the paper's C_s (default: the honest one when the
                                                                  # file has it: design --model, discrepancy included)
"""

from __future__ import annotations

import argparse
import signal
import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from pin_kpi_oed.errors import IdentifiabilityError, InputError

if TYPE_CHECKING:
    from pin_kpi_oed.design.design_file import DesignFile
    from pin_kpi_oed.viz.scene import Scene


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``view`` subcommand."""
    p = subparsers.add_parser(
        "view", help="meshcat preview of a design: cell, poses, laser beam, KPI confidence ellipsoids",
        description="Show a design JSON (pin-kpi-oed design --json) in meshcat: the cell, the robot stepping "
                    "through the measurement configurations (Animations panel) and all of them ghosted, its "
                    "capsules (toggle), the laser beam and the TCP's confidence ellipsoid of every design at "
                    "each working configuration, magnified by the factor shown.")
    p.add_argument("design", metavar="DESIGN_JSON", help="design JSON (robot, tracker_T_base, q_work, designs, ...)")
    p.add_argument("--html", default=None, metavar="OUT.html",
                   help="write a self-contained static page (opens offline) instead of starting a live viewer")
    p.add_argument("--no-open", action="store_true", help="do not open a browser")
    p.add_argument("--criteria", default=None, help="comma-separated designs to show (default all)")
    p.add_argument("--scale", type=float, default=None,
                   help="magnification of the ellipsoids (default: a 1-2-5 number making them visible)")
    p.add_argument("--level", type=float, default=0.95, help="confidence level of the ellipsoids (default 0.95)")
    p.add_argument("--no-ghosts", action="store_true", help="do not draw the measurement configurations at once")
    p.add_argument("--all-ghosts", action="store_true",
                   help="ghost every measurement configuration of every design (default: only designs of at most "
                        "8 poses; the others show a dot per pose and the animated current pose)")
    p.add_argument("--capsules", action="store_true", help="show the robot's capsules initially")
    p.add_argument("--pose", default=None, metavar="CRITERION:K",
                   help="open the static page with the robot at measurement configuration K (0-based) of a design")
    p.add_argument("--sigma", default=None, metavar="honest|paper",
                   help="which C_s the ellipsoids show: honest (model discrepancy included, the same sigma as "
                        "predict; written by design --model) or paper (tracker noise only); default honest when "
                        "every design of the file has it, else paper")
    p.add_argument("--figures", default=None, metavar="DIR",
                   help="also write the report figures (ellipsoid projections, designs, poses; the sigma profile "
                        "along the working paths when the design has paths) as PNG to DIR")
    p.set_defaults(func=run)


def _check_args(args: argparse.Namespace) -> None:
    """Raises InputError on a bad --level, --scale, --sigma or --html folder."""
    if not (0.0 < args.level < 1.0):
        raise InputError(f"--level must be in (0, 1), got {args.level}")
    if args.scale is not None and not args.scale > 0:
        raise InputError(f"--scale must be > 0, got {args.scale}")
    if args.sigma is not None and args.sigma not in ("honest", "paper"):
        raise InputError(f"--sigma: must be honest or paper, got '{args.sigma}'")
    if args.html is not None and not Path(args.html).resolve().parent.is_dir():
        raise InputError(f"--html {args.html}: folder {Path(args.html).parent} does not exist")


def _print_designs(df: DesignFile, scene: Scene, level: float) -> None:
    """One line per design: poses, tr(C_s) (mm², as ``pin-kpi-oed design``), TCP sigma (µm), colour; the C_s shown
    (honest: discrepancy included; paper: tracker noise only)."""
    from pin_kpi_oed.viz.ellipsoids import fmt_factor
    from pin_kpi_oed.viz.scene import SIGMA_TEXT

    t = df.q_work.shape[0]
    print(f"{df.robot.name}: {len(df.designs)} design(s), {t} working configuration(s); "
          f"{int(round(level * 100))} % TCP ellipsoids magnified x{fmt_factor(scene.scale)}; C_s {scene.sigma} "
          f"({SIGMA_TEXT[scene.sigma]})")
    held_any = 0.0
    for d in df.designs:
        tr = float(np.trace(d.cov_s_honest_m2)) if scene.sigma == "honest" else d.trace_cs_m2
        held = _held_trace_m2(d)
        held_any = max(held_any, held)
        print(f"  {d.label:<18} {d.q_meas.shape[0]:>4} poses  tr(C_s) = {tr * 1e6:.4e} mm^2  "
              f"TCP sigma = {((max(tr, 0.0) + held) / t) ** 0.5 * 1e6:10.4f} um  "
              f"colour #{scene.colours[d.criterion]:06x}"
              + ("  (C_s recomputed)" if d.cov_source == "computed" else ""))
    if held_any > 0.0:
        print(f"TCP sigma = sqrt((tr(C_s) + held) / t), as design states it: held {held_any * 1e6:.4g} mm^2 from "
              "parameters held at their tolerance, which no measurement of this reflector determines (the design "
              "file's held_line); the ellipsoids show C_s alone, the part the design controls")


def _held_trace_m2(d: Any) -> float:
    """The design entry's ``held_trace_m2`` (m²: what the parameters no measurement of the reflector determines add
    to tr C_s at the working configurations, as ``design`` wrote it), 0 for a file without one."""
    try:
        v = float(d.info.get("held_trace_m2") or 0.0)
    except (TypeError, ValueError):
        return 0.0
    return v if np.isfinite(v) and v > 0.0 else 0.0


def _write_figures(df: DesignFile, folder: str, sigma: str = "honest") -> None:
    """The report figures as PNG in an existing folder, with the same C_s as the viewer's ellipsoids."""
    from pin_kpi_oed.viz.figures import design_figures

    out = Path(folder)
    out.mkdir(exist_ok=True)  # checked before any work (validation.options); created like diagnose does
    for p in design_figures(df, out, sigma=sigma).values():
        print(f"wrote {p}")
    if df.raw.get("path_profiles"):  # a cell with working paths: the σ profile along them
        from pin_kpi_oed.viz.path_profile_plot import PROFILE_UNITS, plot_path_profiles

        shown = {d.criterion for d in df.designs}
        p = plot_path_profiles([e for e in df.raw["path_profiles"] if e.get("criterion") in shown],
                               out / "design_path_sigma.png",
                               title=f"{df.robot.name}: predicted sigma along the working paths (tracker noise "
                                     "only, unless a panel says the discrepancy is included)")
        print(f"wrote {p} ({PROFILE_UNITS})")


def _pose(args: argparse.Namespace, scene: Scene) -> tuple[str, int] | None:
    """The --pose CRITERION:K to open the page at (checked against the scene's animation)."""
    if not args.pose:
        return None
    crit, _, k = args.pose.rpartition(":")
    if not crit or not k.isdigit():
        raise InputError(f"--pose: expected CRITERION:K (e.g. kpi:0), got '{args.pose}'")
    scene.pose_time(crit, int(k))  # raises on an unknown design or index
    if args.html is None:
        raise InputError("--pose needs --html (the live viewer has its own time slider)")
    return crit, int(k)


def _serve_until_stopped(scene: Scene, open_browser: bool) -> int:
    """Replay the scene into a live meshcat server and wait for Ctrl-C (or SIGTERM); stops the server."""
    from pin_kpi_oed.viz.render import serve

    def _stop(signum, frame):  # SIGTERM ends like Ctrl-C, so that meshcat's atexit stops its server
        raise KeyboardInterrupt

    old = signal.signal(signal.SIGTERM, _stop)
    live = None
    try:
        live = serve(scene, open_browser=open_browser)
        print(f"meshcat viewer at {live.url()}  (Ctrl-C to stop)", flush=True)
        while True:
            time.sleep(3600)
    except KeyboardInterrupt:
        from pin_kpi_oed.cli.interrupts import consume

        consume()  # Ctrl-C (or SIGTERM) is how serving ends
        return 0
    finally:
        signal.signal(signal.SIGTERM, old)
        proc = getattr(getattr(live, "window", None), "server_proc", None)
        if proc is not None and proc.poll() is None:
            proc.kill()
            proc.wait()


def run(args: argparse.Namespace) -> int:
    """Handler of ``view``; returns the exit code (errors raise PinKpiOedError, printed by cli.app)."""
    from pin_kpi_oed.design.design_file import load_design
    from pin_kpi_oed.viz.scene import MAX_GHOSTS, SceneOptions, build_scene

    _check_args(args)
    from pin_kpi_oed.design.camera_design_file import is_camera_design

    if is_camera_design(args.design):
        return _run_camera(args)
    criteria = [c.strip() for c in args.criteria.split(",") if c.strip()] if args.criteria else None
    df = load_design(args.design, criteria=criteria)
    for n in df.notes:
        print(f"note: {n}", file=sys.stderr)
    singular = [e.criterion for e in df.designs if not np.all(np.isfinite(e.cov_s_m2))]
    if singular:  # never show a stored C_s the design's poses do not give
        raise IdentifiabilityError(f"{args.design}: design(s) {', '.join(singular)}: the q_meas do not determine "
                                   "C_s (singular information matrix; e.g. repeated poses) - run pin-kpi-oed evaluate "
                                   "for the details")
    scene = build_scene(df, SceneOptions(scale=args.scale, level=args.level, ghosts=not args.no_ghosts,
                                         max_ghosts=None if args.all_ghosts else MAX_GHOSTS,
                                         capsules_visible=args.capsules, sigma=args.sigma))
    _print_designs(df, scene, args.level)
    if args.figures:
        _write_figures(df, args.figures, scene.sigma)
    pose = _pose(args, scene)
    if args.html is None:
        return _serve_until_stopped(scene, open_browser=not args.no_open)
    scene.write_html(args.html, pose=pose)
    print(f"wrote {args.html} (self-contained; open it in any browser, offline)")
    if not args.no_open:
        import webbrowser

        webbrowser.open(Path(args.html).resolve().as_uri(), new=2)
    return 0


#: view options a camera's design has no use for (the tracker's ellipsoids, ghosts, capsules, figures)
_CAMERA_REFUSED = (("criteria", None), ("scale", None), ("level", 0.95), ("no_ghosts", False), ("all_ghosts", False),
                   ("capsules", False), ("pose", None), ("sigma", None), ("figures", None))


def _run_camera(args: argparse.Namespace) -> int:
    """``view CAMERA_DESIGN.json``: the robot, the board, and each pose's frustum and rays
    (:func:`~pin_kpi_oed.viz.camera_scene.camera_design_scene`), as a page (``--html``) or live."""
    from typing import cast

    from pin_kpi_oed.viz.camera_scene import camera_design_scene

    for dest, default in _CAMERA_REFUSED:
        if getattr(args, dest, default) != default:
            raise InputError(f"view --{dest.replace('_', '-')}: not for a camera's design (it draws the board, and "
                             "each pose's viewing frustum and rays; --html and --no-open apply)")
    rec, cd = camera_design_scene(args.design)
    print(f"{cd.cell.robot.name}: camera design {cd.criterion}, {len(cd.Q)} poses ({cd.cell.camera.mode}); "
          "camera/pose_k: the frustum and the rays to the board of pose k (the first shown)")
    if args.html is None:
        from types import SimpleNamespace

        return _serve_until_stopped(cast("Scene", SimpleNamespace(recorder=rec)), open_browser=not args.no_open)
    from pin_kpi_oed.data.atomic import atomic_write_text

    atomic_write_text(args.html, rec.get_scene(title=f"{cd.cell.name}: camera design"))
    print(f"wrote {args.html} (self-contained; open it in any browser, offline)")
    if not args.no_open:
        import webbrowser

        webbrowser.open(Path(args.html).resolve().as_uri(), new=2)
    return 0
