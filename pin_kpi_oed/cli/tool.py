"""The tool of a command (robot, tool frame, reflector, TCP, working configurations), from one source of truth.

``identify``, ``diagnose``, ``register`` and ``simulate`` take the tool from, in this order, their options
(``--robot``, ``--tool``, ``--reflector``), the cell file (``--cell``) and the tool header of the data files
(:mod:`pin_kpi_oed.data.tool_header`); a field two of them give differently is refused in one line naming
both (exit 2). The robot is loaded with the tool frame they agree on.
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass
from typing import Any
from collections.abc import Sequence

from pin_kpi_oed.data.tool_header import ToolSpec, resolve_tool
from pin_kpi_oed.errors import InputError

__all__ = ["CELL_HELP", "CommandTool", "add_cell_arg", "command_tool", "cell_tool_spec", "canonical_robot",
           "model_tool", "model_cell_tool"]

#: Help of every ``--cell`` option that supplies the tool.
CELL_HELP = ("cell YAML file or shipped cell name: the robot, its tool frame, the reflector, the TCP and the "
             "working configurations come from it (an option or a data header that contradicts it is refused)")


@dataclass
class CommandTool:
    """What a command works with.

    Attributes:
        robot: the robot, loaded with the agreed tool frame.
        tool: the agreed fields (``source`` names where each came from).
        cell: the cell of ``--cell``, or None.
    """

    robot: Any
    tool: ToolSpec
    cell: Any = None

    def line(self) -> str:
        """One line for the terminal: the tool frame, reflector and TCP in use and where they come from."""
        parts = [f"tool frame {self.robot.tool_frame}"
                 + ("" if self.tool.tool_frame else f" (the default of robot {self.robot.name}; --tool or --cell to "
                                                    "name another)")]
        rest = ToolSpec(reflector_m=self.tool.reflector_m, tcp_m=self.tool.tcp_m).describe()
        return "tool: " + ", ".join(parts + ([rest] if rest else [])) + (f" ({self.tool.source})"
                                                                         if self.tool.source else "")


def add_cell_arg(p: argparse.ArgumentParser) -> None:
    """``--cell``: the tool (and robot) from a cell file."""
    p.add_argument("--cell", default=None, help=CELL_HELP)


def cell_tool_spec(cell: Any, source: str) -> ToolSpec:
    """The tool fields a cell states (robot URDF, tool frame, reflector, TCP, working configurations)."""
    return cell.tool_spec(source)


def canonical_robot(spec: ToolSpec | None) -> ToolSpec | None:
    """The spec with its robot as a resolved URDF path (names and paths of one URDF compare equal)."""
    if spec is None or spec.robot is None:
        return spec
    from pathlib import Path

    from pin_kpi_oed.errors import RobotLoadError
    from pin_kpi_oed.model.robot import resolve_robot

    try:
        path = Path(resolve_robot(spec.robot)[0]).resolve()
    except RobotLoadError:
        path = Path(spec.robot).resolve()
    spec.robot = str(path)
    return spec


def command_tool(args: argparse.Namespace, data_paths: Sequence[str], *, other_paths: Sequence[str] = (),
                 reflector_option: str | None = None, per_station_reflector: bool = False) -> CommandTool:
    """Resolve the tool of a command and load its robot.

    Args:
        args: the parsed options (``robot``, ``tool``, ``cell`` where the command has them).
        data_paths: the measurement files of the fit (their headers must agree with each other).
        other_paths: files of the same robot in another set-up (validation, registration rows): robot, tool
            frame and TCP compared, reflector and working configurations not.
        reflector_option: the ``--reflector`` text, if the command has one and it was given.
        per_station_reflector: every data file may have its own reflector (not compared between files).

    Returns:
        The :class:`CommandTool`.

    Raises:
        InputError: no robot anywhere, or a contradiction (one line naming both sources).
        RobotLoadError: the robot or its tool frame cannot be loaded.
    """
    from pin_kpi_oed.cli.util import parse_floats
    from pin_kpi_oed.data.measurements import read_measurement_tool
    from pin_kpi_oed.errors import RobotLoadError
    from pin_kpi_oed.model.robot import load_robot

    specs: list[ToolSpec | None] = []
    robot_opt = getattr(args, "robot", None)
    if robot_opt:
        specs.append(ToolSpec(robot=str(robot_opt), source=f"--robot {robot_opt}"))
    if getattr(args, "tool", None):
        specs.append(ToolSpec(tool_frame=args.tool, source=f"--tool {args.tool}"))
    if reflector_option:
        specs.append(ToolSpec(reflector_m=parse_floats(reflector_option, 3, "--reflector"),
                              source=f"--reflector {reflector_option}"))
    cell = None
    if getattr(args, "cell", None):
        from pin_kpi_oed.cell.cell import load_cell

        cell = load_cell(args.cell)
        specs.append(cell_tool_spec(cell, f"--cell {args.cell}"))
    headers = [read_measurement_tool(p) for p in data_paths]
    skip = ("reflector_m", "q_work") if per_station_reflector else ()
    main = resolve_tool([canonical_robot(s) for s in specs + headers], skip=skip)
    others = [canonical_robot(read_measurement_tool(p)) for p in other_paths]
    resolve_tool([main] + others, skip=("reflector_m", "q_work"))
    if main.robot is None:
        raise InputError("no robot: give --robot ROBOT or --cell CELL (or data files whose header names the robot)")
    if cell is not None and main.tool_frame == cell.robot.tool_frame and not getattr(args, "kinematics", None):
        robot = cell.robot
    else:
        try:
            robot = load_robot(robot_opt if robot_opt else main.robot, main.tool_frame,
                               kinematics=getattr(args, "kinematics", None))
        except RobotLoadError as exc:
            where = [part for part in main.source.split(", ") if part.startswith(("tool_frame", "robot"))]
            raise RobotLoadError(f"{exc} ({'; '.join(where)})" if where else str(exc)) from None
    if main.q_work is not None:
        main.q_work = robot.check_q(main.q_work, f"working configurations ({main.source})")
    return CommandTool(robot=robot, tool=main, cell=cell)


def model_tool(args: argparse.Namespace, model: Any, model_path: str, data_paths: Sequence[str] = ()) -> ToolSpec:
    """The tool of a calibrated model checked against ``--cell`` (if the command has it) and the data headers.

    Args:
        args: the parsed options (``cell`` where the command has it).
        model: the :class:`~pin_kpi_oed.calibrated.model_file.CalibratedModel`.
        model_path: its file (for messages).
        data_paths: measurement files used with it (their headers are compared).

    Returns:
        The agreed fields (the model's first; working configurations of the model, else of the cell).

    Raises:
        InputError: the cell or a data header names another robot, tool frame or TCP than the model.
    """
    from pin_kpi_oed.data.measurements import read_measurement_tool

    rb = model.robot
    specs: list[ToolSpec | None] = [ToolSpec(robot=str(rb.urdf_path), tool_frame=rb.tool_frame,
                                             tcp_m=model.tcp_m if model.tool_source else None,
                                             q_work=model.q_work, source=f"--model {model_path}")]
    if getattr(args, "cell", None):
        from pin_kpi_oed.cell.cell import load_cell

        specs.append(cell_tool_spec(load_cell(args.cell), f"--cell {args.cell}"))
    specs += [read_measurement_tool(p) for p in data_paths]
    return resolve_tool([canonical_robot(s) for s in specs], skip=("reflector_m", "q_work"))


def model_cell_tool(model: Any, model_path: str, cell: Any, cell_name: str) -> ToolSpec:
    """:func:`model_tool` against a cell already loaded (``design --model``): the same robot, tool frame and TCP.

    Raises:
        InputError: the cell names another robot, tool frame or TCP than the model (both named).
    """
    rb = model.robot
    specs = [ToolSpec(robot=str(rb.urdf_path), tool_frame=rb.tool_frame,
                      tcp_m=model.tcp_m if model.tool_source else None, source=f"--model {model_path}"),
             cell_tool_spec(cell, f"--cell {cell_name}")]
    return resolve_tool([canonical_robot(s) for s in specs], skip=("reflector_m", "q_work"))
