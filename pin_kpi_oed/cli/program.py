"""``pin-kpi-oed export``: a design as an ordered, collision-checked robot program (CSV, URScript, KRL, RAPID).

Example::

    pin-kpi-oed design --cell kr15 --criteria kpi --clearance-margin 0.02 --json design.json
    pin-kpi-oed export design.json --format krl --out kpi_kr15.src      # writes kpi_kr15.src + kpi_kr15.dat

orders the design's poses for the least predicted cycle time (OR-Tools; move time = max_j |Δq_j|/v_j
with the URDF speed limits), checks every move densely (≤ 1° joint steps, Coal, the cell's capsules
plus the margin: default half the design's ``--clearance-margin``, since the poses sit at that margin), routes colliding moves through safe via poses, prints the cycle time against the
as-designed order and the true clearance / incidence of every pose (independent check), and writes
the program atomically. Nothing is written when a move still collides (unless ``--force``) or the
input is bad (one line, exit code 2).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

__all__ = ["register", "run_export"]


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``export`` subcommand."""
    from pin_kpi_oed.program.export import FORMATS

    p = subparsers.add_parser("export", help="ordered, collision-checked robot program of a design "
                              "(csv, urscript, krl, rapid)", description=__doc__.splitlines()[0])
    p.add_argument("design", help="design JSON (pin-kpi-oed design --json)")
    p.add_argument("--format", required=True, help="one of " + ", ".join(FORMATS))
    p.add_argument("--out", required=True, help="program file (krl: the .src; the .dat is written beside it)")
    p.add_argument("--design-name", dest="design_name", default=None,
                   help="which design of the file (default: the file's q_meas design)")
    p.add_argument("--margin", type=float, default=None,
                   help="clearance every move keeps (m; default: half the design's --clearance-margin, which "
                        "the poses keep; 0 for designs made without one)")
    p.add_argument("--speed-override", dest="speed_override", type=float, default=1.0,
                   help="share of the URDF joint speed limits used for the cycle time (0, 1]")
    p.add_argument("--dwell", type=float, default=0.5, help="wait at every measurement point (s)")
    p.add_argument("--seed", type=int, default=0, help="seed of the via-pose pool")
    p.add_argument("--json", default=None, help="also write the program (order, waypoints, checks) as JSON")
    p.add_argument("--html", default=None, help="also write a self-contained page animating the program "
                   "(moves, via poses, the beam at each measurement point)")
    p.add_argument("--force", action="store_true", help="write even if a move still collides")
    p.add_argument("--quiet", action="store_true", help="print nothing")
    p.set_defaults(func=run_export)


def _targets(fmt: str, out: str) -> dict[str, Path]:
    """Files a format writes, by suffix (checked writable before any work)."""
    from pin_kpi_oed.data.atomic import check_writable
    from pin_kpi_oed.errors import InputError
    from pin_kpi_oed.program.export import FORMATS, SUFFIX

    if fmt not in FORMATS:
        raise InputError(f"--format: unknown format '{fmt}' (known: {', '.join(FORMATS)})")
    path = Path(out)
    files = {SUFFIX[fmt]: path}
    if fmt == "krl":
        files = {".src": path if path.suffix.lower() == ".src" else path.with_name(path.name + ".src")}
        files[".dat"] = files[".src"].with_suffix(".dat")
    for f in files.values():
        check_writable(f)
    return files


def run_export(args: argparse.Namespace) -> int:
    """Handler of ``pin-kpi-oed export`` (returns the exit code).

    Raises:
        PinKpiOedError: unknown format, unwritable output, bad design file, a move that still collides.
    """
    from pin_kpi_oed.cell.feasibility import FeasibilityChecker
    from pin_kpi_oed.data.atomic import atomic_write_json, atomic_write_text
    from pin_kpi_oed.design.design_file import load_design
    from pin_kpi_oed.errors import InfeasibleError, InputError
    from pin_kpi_oed.program.export import ProgramInfo, write_program
    from pin_kpi_oed.program.ordering import ProgramOptions, plan_program

    fmt = str(args.format).lower()
    files = _targets(fmt, args.out)
    if getattr(args, "html", None):
        from pin_kpi_oed.data.atomic import check_writable

        check_writable(args.html)
    if args.dwell < 0:
        raise InputError(f"--dwell: must be >= 0 s, got {args.dwell}")
    df = load_design(args.design)
    name = args.design_name or df.raw.get("q_meas_criterion") or df.designs[-1].criterion
    entry = df.design(name)
    # poses sit at the design's margin (an active constraint): moves leaving them keep half of it
    margin = args.margin if args.margin is not None else 0.5 * float(df.raw.get("clearance_margin_m", 0.0) or 0.0)
    if margin < 0:
        raise InputError(f"--margin: must be >= 0 m, got {margin}")
    prog = plan_program(df.cell, entry.q_meas, ProgramOptions(margin_m=margin, speed_override=args.speed_override,
                                                               seed=args.seed))
    rep = FeasibilityChecker(df.cell).check(entry.q_meas)
    quiet = bool(getattr(args, "quiet", False))
    if not quiet:
        print(prog.summary())
        print(f"poses (independent check, true values): clearance {rep.clearance_m.min() * 1e3:.1f} .. "
              f"{rep.clearance_m.max() * 1e3:.1f} mm, incidence {rep.incidence_deg.min():.1f} .. "
              f"{rep.incidence_deg.max():.1f} deg (limit {df.cell.incidence_max_deg:g}); "
              f"{int(np.sum(~rep.feasible))} infeasible pose(s)")
    if not prog.success and not getattr(args, "force", False):
        raise InfeasibleError(f"{args.design}: {prog.message}; nothing written (--force writes it anyway)")
    path = prog.path
    texts = write_program(fmt, path, [w.kind for w in prog.waypoints], [w.pose for w in prog.waypoints],
                          ProgramInfo(cell=df.cell.name, design=f"{Path(args.design).name} ({name})",
                                      robot=df.robot.name, joint_names=list(df.robot.joint_names),
                                      revolute=np.asarray(df.robot.is_revolute, bool),
                                      cycle_time_s=prog.cycle_time_s, dwell_s=args.dwell,
                                      name=files[next(iter(files))].stem))
    for suffix in sorted(texts, key=lambda s: s != ".dat"):  # KRL: the data list first, the program last
        atomic_write_text(files[suffix], texts[suffix])
    if getattr(args, "json", None):
        atomic_write_json(args.json, {**prog.to_dict(), "design": str(args.design), "criterion": name,
                                      "pose_clearance_m": rep.clearance_m, "pose_incidence_deg": rep.incidence_deg,
                                      "incidence_max_deg": df.cell.incidence_max_deg})
    if getattr(args, "html", None):
        _write_animation(args.design, name, prog, args.html)
    if not quiet:
        print("wrote " + ", ".join(str(files[s]) for s in texts) + (f", {args.html}" if getattr(args, "html", None)
                                                                    else ""))
    return 0


def _write_animation(design: str, name: str, prog, html: str) -> None:
    """The design's meshcat scene (one design, ghosts only for a handful of poses) animating the program."""
    from pin_kpi_oed.data.atomic import check_writable
    from pin_kpi_oed.design.design_file import load_design
    from pin_kpi_oed.viz.program_animation import animate_program
    from pin_kpi_oed.viz.scene import SceneOptions, build_scene

    check_writable(html)
    df = load_design(design, criteria=[name])
    scene = build_scene(df, SceneOptions(ghosts=len(prog.order) <= 8, animate=False))
    animate_program(scene, prog.path, [w.kind for w in prog.waypoints])
    scene.write_html(html)
