"""ABB RAPID program: a module with a ``CONST jointtarget`` per target and ``MoveAbsJ`` through them.

robax in degrees, prismatic joints in eax_a… (mm), 9E9 for an unused external axis. Each measurement point:
a ``! step k: MEASURE ..`` comment and ``WaitTime dwell_s``.
"""

from __future__ import annotations

import math
import re

import numpy as np

from pin_kpi_oed.program.formats.base import (ProgramFormat, ProgramInfo, measure_marks, program_name,
                                              split_joints, step_marks)

__all__ = ["RapidFormat"]


class RapidFormat(ProgramFormat):
    """ABB RAPID: ``CONST jointtarget`` + ``MoveAbsJ``.

    Args:
        speed: the ``speeddata`` of every move (e.g. ``v1000``).
        tool: the ``tooldata`` of every move.
    """

    name = "rapid"
    suffix = ".mod"
    description = "ABB RAPID module, robax in degrees, extax in mm"

    def __init__(self, speed: str = "v1000", tool: str = "tool0") -> None:
        self.speed, self.tool = speed, tool

    def write(self, Q: np.ndarray, kinds: list[str], poses: list[int], info: ProgramInfo) -> dict[str, str]:
        rev, ext = split_joints(info, self.name)
        name = program_name(info)
        lines = [f"MODULE {name}"]
        lines += [f"  ! {h}" for h in info.header_lines("robax in degrees, extax (linear axes) in millimetres, "
                                                         "9E9 = no axis")]
        for i, q in enumerate(Q):
            rob = ",".join(f"{math.degrees(q[j]):.6f}" for j in rev)
            eax = ",".join(f"{q[ext[k]] * 1e3:.6f}" if k < ext.size else "9E9" for k in range(6))
            lines.append(f"  CONST jointtarget jP{i + 1}:=[[{rob}],[{eax}]];")
        lines.append("  PROC main()")
        for i, mark in enumerate(step_marks(kinds, poses)):
            lines.append(f"    ! step {i}: {mark}")
            lines.append(f"    MoveAbsJ jP{i + 1}, {self.speed}, fine, {self.tool};")
            if mark.startswith("MEASURE"):
                lines.append(f"    WaitTime {info.dwell_s:g};")
        lines += ["  ENDPROC", "ENDMODULE"]
        return {".mod": "\n".join(lines) + "\n"}

    def parse(self, texts: dict[str, str], revolute: np.ndarray) -> tuple[np.ndarray, list[int]]:
        revolute = np.asarray(revolute, bool)
        rev, ext = np.flatnonzero(revolute), np.flatnonzero(~revolute)
        t = texts[".mod"]
        pts = {}
        for m in re.finditer(r"CONST jointtarget jP(\d+):=\[\[([^\]]*)\],\[([^\]]*)\]\];", t):
            q = np.zeros(revolute.size)
            q[rev] = np.radians([float(x) for x in m.group(2).split(",")])
            q[ext] = [float(x) * 1e-3 for x in m.group(3).split(",")[:ext.size]]
            pts[int(m.group(1))] = q
        order = [int(k) for k in re.findall(r"MoveAbsJ jP(\d+),", t)]
        return np.array([pts[k] for k in order]), measure_marks(t, r"! step \d+: MEASURE \d+ \(design pose (\d+)\)")
