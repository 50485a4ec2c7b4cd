"""``pin-kpi-oed export``: a design as an ordered, collision-checked robot program (CSV, URScript, KRL, RAPID).

Example::

    pin-kpi-oed design --cell kr15 --criteria kpi --clearance-margin 0.02 --json design.json
    pin-kpi-oed export design.json --format krl --out kpi_kr15.src      # writes kpi_kr15.src + kpi_kr15.dat

orders the design's poses for the least predicted cycle time (OR-Tools; move time = max_j |Δq_j|/v_j
with the URDF speed limits), checks every move densely (≤ 1° joint steps, Coal, the cell's capsules
plus the margin: default half the design's ``--clearance-margin``, since the poses sit at that margin), routes colliding
moves through safe via poses, prints the cycle time against the
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
                              f"({', '.join(FORMATS)})", description=__doc__.splitlines()[0])
    p.add_argument("design", help="design JSON (pin-kpi-oed design --json)")
    p.add_argument("--format", required=True, help="one of " + ", ".join(FORMATS)
                   + " (the program format registry, pin_kpi_oed.program.formats)")
    p.add_argument("--out", required=True, help="program file (krl: the .src; the .dat is written beside it)")
    p.add_argument("--design-name", dest="design_name", default=None,
                   help="which design of the file (default: the file's q_meas design, the one simulate --design and "
                        "evaluate take: the kpi design, else the file's last)")
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
    p.set_defaults(func=run_export, output_files=_output_files)


def _targets(fmt: str, out: str) -> dict[str, Path]:
    """Files a format writes, by suffix (checked with the inputs by the option checks before any work)."""
    from pin_kpi_oed.program.export import program_files

    return program_files(fmt, out)


def _output_files(args: argparse.Namespace) -> list[tuple[str, str]]:
    """(option, path) of every file ``--out`` writes (KRL: the .src and the .dat beside it), for the
    output-path check before any work (:func:`pin_kpi_oed.validation.options.check_args`)."""
    files = _targets(str(args.format).lower(), args.out)
    return [("--out" if f == Path(args.out) else f"--out ({suffix} beside it)", str(f)) for suffix, f in files.items()]


def _refusals(df, Q: np.ndarray, rep, design: str) -> list[str]:
    """What makes the design unsafe to run as is: working configurations in collision, poses in collision,
    poses beyond a joint limit with no 2π-equivalent inside it (loading a design never widens what is allowed)."""
    from pin_kpi_oed.program.transitions import equivalents

    cell, rob = df.cell, df.robot
    out = list(df.work_collisions)
    rev = np.asarray(rob.is_revolute, bool)
    for i, q in enumerate(Q):
        reps = equivalents(q, cell.q_lower, cell.q_upper, rev)
        if not np.any(np.all((reps >= cell.q_lower - 1e-9) & (reps <= cell.q_upper + 1e-9), axis=1)):
            j = int(np.argmax(np.maximum(cell.q_lower - q, q - cell.q_upper)))
            lo, hi = cell.q_lower[j], cell.q_upper[j]
            unit = (lambda x: f"{x:.4g} rad ({np.degrees(x):.1f}°)") if rev[j] else (lambda x: f"{x:.4g} m")
            out.append(f"design pose {i}: {rob.joint_names[j]} = {unit(q[j])} is outside its limits "
                       f"[{unit(lo)}, {unit(hi)}]")
    bad = np.flatnonzero(~rep.collision_free)
    for i in bad[:3]:
        out.append(f"design pose {i}: collides ({rep.worst[i]} at {rep.clearance_m[i] * 1e3:.1f} mm)")
    if bad.size > 3:
        out.append(f"{bad.size - 3} more colliding pose(s)")
    return out


def run_export(args: argparse.Namespace) -> int:
    """Handler of ``pin-kpi-oed export`` (returns the exit code).

    Raises:
        PinKpiOedError: unknown format, unwritable output, bad design file, a working configuration or a
            pose in collision or beyond a joint limit, a move that still collides (unless ``--force``).
    """
    from pin_kpi_oed.cell.feasibility import FeasibilityChecker
    from pin_kpi_oed.data.atomic import atomic_write_json, atomic_write_text
    from pin_kpi_oed.design.design_file import load_design
    from pin_kpi_oed.errors import InfeasibleError, InputError
    from pin_kpi_oed.program.export import ProgramInfo, write_program
    from pin_kpi_oed.program.ordering import ProgramOptions, plan_program

    fmt = str(args.format).lower()
    files = _targets(fmt, args.out)
    if not (np.isfinite(args.dwell) and args.dwell >= 0):
        raise InputError(f"--dwell: must be a finite number >= 0 s, got {args.dwell}")
    df = load_design(args.design)
    name = args.design_name or df.default_criterion
    entry = df.design(name)
    force = bool(getattr(args, "force", False))
    quiet = bool(getattr(args, "quiet", False))
    rep = FeasibilityChecker(df.cell).check(entry.q_meas)
    problems = _refusals(df, entry.q_meas, rep, args.design)
    if problems and not force:
        raise InfeasibleError(f"{args.design}: {'; '.join(problems)}; nothing written (--force writes it anyway)")
    # poses sit at the design's margin (an active constraint): moves leaving them keep half of it
    margin = args.margin if args.margin is not None else 0.5 * float(df.raw.get("clearance_margin_m", 0.0) or 0.0)
    if not (np.isfinite(margin) and margin >= 0):
        raise InputError(f"--margin: must be a finite number >= 0 m, got {margin}")
    if args.margin is not None and rep.collision_free.all() and margin > float(rep.clearance_m.min()) + 1e-9:
        raise InputError(f"--margin {margin:g} m: more than the design poses keep (smallest pose clearance "
                         f"{rep.clearance_m.min() * 1e3:.1f} mm): no move leaving that pose can keep it; give at "
                         f"most {rep.clearance_m.min():.4g} m")
    prog = plan_program(df.cell, entry.q_meas, ProgramOptions(margin_m=margin, speed_override=args.speed_override,
                                                               seed=args.seed))
    _check_same_poses(prog, entry.q_meas, np.asarray(df.robot.is_revolute, bool), args.design)
    if not quiet:
        print(prog.summary())
        if df.raw.get("device") == "camera":  # no beam nor incidence: the design's check saw the board
            print(f"poses (independent check, true values): clearance {rep.clearance_m.min() * 1e3:.1f} .. "
                  f"{rep.clearance_m.max() * 1e3:.1f} mm; {int(np.sum(~rep.collision_free))} colliding pose(s) "
                  "(a camera design: every pose's view of the board was checked by design)")
        else:
            print(f"poses (independent check, true values): clearance {rep.clearance_m.min() * 1e3:.1f} .. "
                  f"{rep.clearance_m.max() * 1e3:.1f} mm, incidence {rep.incidence_deg.min():.1f} .. "
                  f"{rep.incidence_deg.max():.1f} deg (limit {df.cell.incidence_max_deg:g}); "
                  f"{int(np.sum(~rep.feasible))} infeasible pose(s)")
        for p in problems:
            print(f"warning (--force): {p}")
    if not prog.success and not force:
        raise InfeasibleError(f"{args.design}: {prog.message}; nothing written (--force writes it anyway)")
    path = prog.path
    texts = write_program(fmt, path, [w.kind for w in prog.waypoints], [w.pose for w in prog.waypoints],
                          ProgramInfo(cell=df.cell.name, design=f"{Path(args.design).name} ({name})",
                                      robot=df.robot.name, joint_names=list(df.robot.joint_names),
                                      revolute=np.asarray(df.robot.is_revolute, bool),
                                      cycle_time_s=prog.cycle_time_s, dwell_s=args.dwell,
                                      name=files[next(iter(files))].stem, speeds=prog.speeds))
    page = _animation_page(args.design, name, prog, args.html) if getattr(args, "html", None) else None
    for suffix in sorted(texts, key=lambda s: s != ".dat"):  # KRL: the data list first, the program last
        atomic_write_text(files[suffix], texts[suffix])
    if getattr(args, "json", None):
        atomic_write_json(args.json, {**prog.to_dict(), "design": str(args.design), "criterion": name,
                                      "pose_clearance_m": rep.clearance_m, "pose_incidence_deg": rep.incidence_deg,
                                      "incidence_max_deg": df.cell.incidence_max_deg,
                                      "forced_problems": problems if force else []})
    if page is not None:  # built before the first file was written: a page that fails writes nothing
        atomic_write_text(args.html, page)
    if not quiet:
        print("wrote " + ", ".join(str(files[s]) for s in texts) + (f", {args.html}" if getattr(args, "html", None)
                                                                    else ""))
    return 0


def _check_same_poses(prog, Q: np.ndarray, revolute: np.ndarray, design: str) -> None:
    """Every measurement point of the program is its design pose, up to whole turns of revolute joints.

    Raises:
        SolverError: a measurement point that is another pose (a bug, never written).
    """
    from pin_kpi_oed.errors import SolverError

    for w in prog.waypoints:
        if w.kind != "measure":
            continue
        d = np.asarray(w.q, float) - Q[w.pose]
        d = np.where(revolute, (d + np.pi) % (2 * np.pi) - np.pi, d)
        if np.max(np.abs(d)) > 1e-9:
            raise SolverError(f"{design}: program point of design pose {w.pose} differs from the design by "
                              f"{np.max(np.abs(d)):.3g} (not a whole turn); nothing written")


def _animation_page(design: str, name: str, prog, html: str) -> str:
    """The page (self-contained HTML text) of the design's meshcat scene (one design, ghosts only for a handful of
    poses) animating the program, for ``html``."""
    from pin_kpi_oed.data.atomic import check_writable
    from pin_kpi_oed.design.design_file import load_design
    from pin_kpi_oed.viz.program_animation import animate_program
    from pin_kpi_oed.viz.scene import SceneOptions, build_scene

    check_writable(html)
    df = load_design(design, criteria=[name])
    scene = build_scene(df, SceneOptions(ghosts=len(prog.order) <= 8, animate=False))
    animate_program(scene, prog.path, [w.kind for w in prog.waypoints])
    return scene.static_html()
