"""The ``pin-kpi-oed`` command line: a thin layer over the Python API.

Subcommands of the core live here (``info``, ``evaluate``, ``demo``); each
topic module ``cli_<topic>.py`` adds its own with ``register(subparsers)``.
Every :class:`~pin_kpi_oed.errors.PinKpiOedError` becomes one line on stderr
and exit code 2, never a traceback; an interrupt (Ctrl-C), at any moment, one
line and exit code 130.
"""

from __future__ import annotations

import argparse
import importlib
import importlib.util
import os
import signal
import sys
from pathlib import Path

from pin_kpi_oed.cli import interrupts
from pin_kpi_oed.cli.commands import COMMANDS, command_in, topic_of
from pin_kpi_oed.errors import InputError, PinKpiOedError
from pin_kpi_oed.model.robot_names import ROBOT_HELP, TOOL_HELP

#: The topic modules of ``pin_kpi_oed.cli`` that declare subcommands (``register(subparsers)``), in ``--help`` order.
TOPICS = tuple(dict.fromkeys(topic for _, topic, _ in COMMANDS if topic is not None))


def cmd_info(args: argparse.Namespace) -> int:
    """``pin-kpi-oed info ROBOT|CELL.yaml``: joints, limits, parameter count, identifiable rank (of a cell's device)."""
    from pin_kpi_oed.cli.util import parse_floats
    from pin_kpi_oed.oed.identifiability import analyse
    from pin_kpi_oed.model.tracker import TrackerModel
    from pin_kpi_oed.model.robot import load_robot

    if Path(args.robot).suffix.lower() in (".yaml", ".yml"):
        return _info_cell(args)
    robot = load_robot(args.robot, args.tool, kinematics=args.kinematics)
    refl = parse_floats(args.reflector, 3, "--reflector")
    model = TrackerModel(robot, reflector_m=refl)
    ident = analyse(model, seed=args.seed)
    if args.json:
        import json

        out = {"robot": robot.summary(), "reflector_m": refl.tolist(), "identifiability": ident.to_dict()}
        print(json.dumps(out, indent=2))
        return 0
    print(f"robot: {robot.name}  ({robot.urdf_path})")
    print(f"tool frame: {robot.tool_frame}" + (f"   locked joints: {', '.join(robot.locked_joints)}"
                                               if robot.locked_joints else ""))
    for note in robot.notes:
        print(f"note: {note}")
    print("\n".join(robot.limits_table()))
    print(f"reflector in {robot.tool_frame}: {', '.join(f'{x * 1e3:.1f}' for x in refl)} mm")
    print(ident.summary())
    return 0


def _info_cell(args: argparse.Namespace) -> int:
    """``info CELL.yaml``: the identifiability of the cell's measuring device (tracker or camera) on configurations
    it measures (a camera's: seeded configurations around the working ones that see the whole board)."""
    from pin_kpi_oed.cell.cell import load_cell
    from pin_kpi_oed.oed.identifiability import analyse

    cell = load_cell(args.robot)
    model = cell.measurement_model()
    views = getattr(model, "views", None)
    Q = views(60, args.seed, cell.q_work) if views is not None else None
    ident = analyse(model, Q=Q, seed=args.seed)
    absorbed = [d["name"] for d in ident.dropped
                if d["confounded_with"] and all(c.split(".")[0] in model.target_groups for c in d["confounded_with"])]
    mounted = ", ".join(model.target_groups)
    if args.json:
        import json

        print(json.dumps({"cell": cell.name, "robot": cell.robot.summary(), "device": type(model).__name__,
                          "identifiability": ident.to_dict(), "absorbed_by_tool_mounted": absorbed}, indent=2))
        return 0
    print(cell.summary())
    print(f"robot: {cell.robot.name}  ({cell.robot.urdf_path}), tool frame {cell.robot.tool_frame}")
    print(f"device: {type(model).__name__}, the fixed frame '{model.frame_group}', on the tool '{mounted}'")
    print(ident.summary())
    if absorbed:
        print(f"  what the tool-mounted part ({mounted}) absorbs: {', '.join(absorbed)} (its fitted pose carries "
              "them: they move no measurement of their own)")
    return 0


def cmd_evaluate(args: argparse.Namespace) -> int:
    """``pin-kpi-oed evaluate DESIGN.json``: score given measurement configurations under every criterion."""
    from pin_kpi_oed.design.camera_design_file import is_camera_design
    from pin_kpi_oed.oed.evaluate import evaluate_file

    if is_camera_design(args.design):  # its stand-in tracker fields would score a tracker, not the camera
        raise InputError(f"evaluate {args.design}: a camera's design file; evaluate scores a laser tracker's poses "
                         "(the camera design's scores are in the file: designs[0].trace_cs_m2, tcp_sigma_m)")
    score = evaluate_file(Path(args.design), Path(args.json) if args.json else None)
    print(score.summary())
    return 0


def cmd_demo(args: argparse.Namespace) -> int:
    """``pin-kpi-oed demo``: the main job on the embedded default cell (KR 15): heuristic, A on C_p and KPI designs of
    60 poses, the paper's zero margins, the certificate; the same library calls as ``design``."""
    from pin_kpi_oed.cell.cell import load_cell
    from pin_kpi_oed.cli.design import print_header, print_results
    from pin_kpi_oed.design.runner import DesignSettings, design_run
    from pin_kpi_oed.design.declare import design_problem
    from pin_kpi_oed.design.design_writer import write_design

    cell = load_cell("kr15")
    settings = DesignSettings(criteria=("random", "param", "kpi"), measurements=60, seed=args.seed, certificate=True)
    problem = design_problem(cell, settings)
    print_header(cell, problem, 60, args.seed, True, settings.n_starts)
    run = design_run(cell, settings, problem)
    print_results(list(run.results), list(settings.criteria), run.certificate, run.m, None, False, cell, cell,
                  run.margins, run.true_checks)
    if args.json:
        write_design(args.json, run)
        print(f"wrote {args.json}")
    return 0


class OneLineParser(argparse.ArgumentParser):
    """An argument parser whose usage errors are one line (``prog: error: message; see prog --help``) and exit 2,
    like every other bad input of the command line (argparse prints the whole usage block first)."""

    def error(self, message: str):  # noqa: D401 - argparse's hook
        self.exit(2, f"{self.prog}: error: {message}; see {self.prog} --help\n")


def build_parser(command: str | None = None, lazy: bool = False) -> argparse.ArgumentParser:
    """The argument parser of ``pin-kpi-oed`` (its usage errors: one line, exit 2).

    Args:
        command: with ``lazy``, the subcommand to run (:func:`~pin_kpi_oed.cli.commands.command_in`; None: none).
        lazy: declare in full only ``command``'s topic module's subcommands (the others by their name and help
            line, their modules not imported: what :func:`main` runs); False: every subcommand in full.
    """
    parser = OneLineParser(prog="pin-kpi-oed", description=__doc__.splitlines()[0])
    parser.add_argument("--threads", type=int, default=None,
                        help="BLAS / OpenMP threads inside the package (default 1, or PIN_KPI_OED_THREADS)")
    sub = parser.add_subparsers(dest="command", required=True)
    _add_core(sub)
    chosen = topic_of(command) if command else None
    declared: set[str] = set()
    for name, topic, help_line in COMMANDS:
        if topic is None or topic in declared or importlib.util.find_spec(f"pin_kpi_oed.cli.{topic}") is None:
            continue
        if not lazy or topic == chosen:
            importlib.import_module(f"pin_kpi_oed.cli.{topic}").register(sub)
            declared.add(topic)
        else:
            sub.add_parser(name, help=help_line, add_help=False)
    return parser


def _add_core(sub: argparse._SubParsersAction) -> None:
    """Declare the core's own subcommands: ``info``, ``evaluate``, ``demo``."""
    p = sub.add_parser("info", help="joints, limits, parameter count and identifiable rank of a robot")
    p.add_argument("robot", help=ROBOT_HELP + "; or a cell file (.yaml): its measuring device's identifiability")
    p.add_argument("--tool", default=None, help=TOOL_HELP)
    p.add_argument("--kinematics", default=None, help="UR kinematics file (ur_description layout) of a UR robot")
    p.add_argument("--reflector", default="0.05,0.0,0.05", help="reflector offset x,y,z in the tool frame (m)")
    p.add_argument("--seed", type=int, default=0, help="seed of the random excitation")
    p.add_argument("--json", action="store_true", help="print JSON instead of text")
    p.set_defaults(func=cmd_info)
    p = sub.add_parser("evaluate", help="score measurement configurations (JSON in) under every criterion")
    p.add_argument("design", help="JSON with robot, tracker_T_base, reflector_m, noise, q_meas, q_work")
    p.add_argument("--json", default=None, help="write the scores to this JSON file")
    p.set_defaults(func=cmd_evaluate)
    p = sub.add_parser("demo", help="the main job on the embedded default cell (KR 15)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--json", default=None, help="write the result JSON here")
    p.set_defaults(func=cmd_demo)


def main(argv: list[str] | None = None) -> int:
    """Entry point of ``pin-kpi-oed``; returns the exit code.

    Options are checked (ranges, units, output paths) before any work; a
    :class:`PinKpiOedError` or an operating-system error becomes one line and exit code 2. An interrupt at any
    moment after this module is loaded (the command's imports included) prints ``interrupted`` and returns 130.
    """
    previous = interrupts.watch()
    try:
        from pin_kpi_oed.validation.options import join_negative_values

        given = list(sys.argv[1:] if argv is None else argv)
        args = build_parser(command_in(given), lazy=True).parse_args(join_negative_values(given))
        args.argv = given  # the command as given (model files record it)
        code = _run(args)
        # an interrupt whose KeyboardInterrupt a library swallowed (seen inside NumPy's lazy imports) is still one
        return _interrupted() if interrupts.SIGNALLED else code
    except KeyboardInterrupt:
        return _interrupted()
    except Exception:
        # a compiled module interrupted while it initialises reports another error ("initialization failed",
        # "could not import module datetime"): the interrupt is the cause when the signal came
        if not interrupts.SIGNALLED:
            raise
        return _interrupted()
    finally:
        if previous is not None:
            signal.signal(signal.SIGINT, previous)


#: Set when :func:`main` ended on an interrupt (:func:`run` then leaves without the interpreter's exit path).
_INTERRUPTED: list[bool] = []


def _interrupted() -> int:
    """The one line of an interrupt; exit code 130."""
    print("interrupted", file=sys.stderr)
    _INTERRUPTED.append(True)
    return 130


def run() -> None:
    """The console entry point (``pin-kpi-oed``, ``python -m pin_kpi_oed``): :func:`main`'s exit code as the process's.

    After an interrupt the process leaves at once with code 130 (its output flushed, the command's outputs already
    released): CPython ends a process by SIGINT instead (code -2, after a traceback-free "interrupted") when the
    interrupt was raised inside Python code that a compiled extension ran, even though the command caught it.
    """
    code = main()
    if _INTERRUPTED:
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(130)
    sys.exit(code)


def _run(args: argparse.Namespace) -> int:
    """Run the parsed command: its options checked, threads limited; errors as one line and exit code 2."""
    from pin_kpi_oed.validation.options import check_args
    from pin_kpi_oed.validation.paths import release_outputs

    try:
        if args.threads is not None:
            from pin_kpi_oed.threads import set_max_threads

            set_max_threads(args.threads)
        from pin_kpi_oed.threads import limit_process_threads

        # the thread variables set before the option checks load NumPy: its BLAS starts with them (no threadpoolctl)
        with limit_process_threads():
            check_args(args)
            if interrupts.SIGNALLED:  # swallowed in the imports so far: stop before the work
                raise KeyboardInterrupt
            return int(args.func(args) or 0)
    except PinKpiOedError as exc:
        from pin_kpi_oed.cli.flags import in_flags

        print(f"pin-kpi-oed {args.command}: error: {in_flags(str(exc))}", file=sys.stderr)
        return 2
    except OSError as exc:  # read-only folder, disk full, a folder where a file belongs, ...
        where = f"{exc.filename}: " if getattr(exc, "filename", None) else ""
        print(f"pin-kpi-oed {args.command}: error: {where}{exc.strerror or exc}", file=sys.stderr)
        return 2
    finally:
        release_outputs()  # the command's claims on its outputs end with it


if __name__ == "__main__":
    run()
