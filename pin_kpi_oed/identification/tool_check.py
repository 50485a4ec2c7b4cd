"""The data's tool against the model's: the measurement header (:mod:`pin_kpi_oed.data.tool_header`) must name the
robot, tool frame and TCP the model uses, or the fit calibrates another point than the one measured.

A field the header leaves out is not compared; a TCP at the tool-frame origin in the model is "not stated".
"""

from __future__ import annotations

import numpy as np

from pin_kpi_oed.data.measurements import MeasurementSet
from pin_kpi_oed.data.tool_header import SAME_TOL
from pin_kpi_oed.errors import InputError
from pin_kpi_oed.model.robot import Robot, same_robot

__all__ = ["check_tool"]


def check_tool(robot: Robot, tcp_m: np.ndarray | None, data: MeasurementSet, what: str = "the model") -> None:
    """Refuse measurements whose tool header contradicts the robot or TCP they are used with.

    Args:
        robot: the robot (URDF and tool frame) of the fit or model.
        tcp_m: its TCP in the tool frame (m); None or the origin: not compared.
        data: the measurements (:attr:`MeasurementSet.tool` from the file's header).
        what: the model's name in the message.

    Raises:
        InputError: another robot, tool frame or TCP (one line naming the file, both values and the fix).
    """
    t = data.tool
    if t is None:
        return
    src = t.source or data.source or "measurements"
    if t.robot is not None and not same_robot(t.robot, robot.urdf_path):
        raise InputError(f"{src}: measured with robot '{t.robot}' (its header), {what} uses {robot.urdf_path}: "
                         "calibrate the robot that was measured")
    if t.tool_frame is not None and t.tool_frame != robot.tool_frame:
        raise InputError(f"{src}: measured in tool frame '{t.tool_frame}' (its header), {what} uses "
                         f"'{robot.tool_frame}': load the robot with tool frame '{t.tool_frame}' "
                         "(CLI: --tool or --cell; Python: load_robot(..., tool_frame=...))")
    tcp = None if tcp_m is None else np.asarray(tcp_m, float)
    if t.tcp_m is not None and tcp is not None and np.any(tcp != 0) and np.any(np.abs(tcp - t.tcp_m) > SAME_TOL):
        raise InputError(f"{src}: TCP {t.tcp_m.tolist()} m in its header, {what} uses {tcp.tolist()} m "
                         f"(both in tool frame {robot.tool_frame}): give the TCP of the cell")
