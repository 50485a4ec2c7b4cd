"""URScript program: ``movej([...], a, v)`` through every target (rad), 6 revolute joints.

Each measurement point: ``textmsg("MEASURE k (design pose i)")`` and ``sleep(dwell_s)``. With the joint
speeds of the predicted motion time (:attr:`ProgramInfo.speeds`, v_j), each move's ``v`` is the leading
joint's speed max_j |Δq_j| / t with t = max_j |Δq_j| / v_j, so the robot takes the predicted time.
"""

from __future__ import annotations

import re

import numpy as np

from pin_kpi_oed.program.formats.base import (ProgramFormat, ProgramInfo, measure_marks, program_name,
                                              split_joints, step_marks)

__all__ = ["URScriptFormat"]


class URScriptFormat(ProgramFormat):
    """URScript: ``movej`` through every target (rad), ``textmsg`` + ``sleep`` at measurement points.

    Args:
        a: joint acceleration of every ``movej`` (rad/s²).
        v: joint speed of every ``movej`` when the program carries no joint speeds (rad/s).
    """

    name = "urscript"
    suffix = ".script"
    description = "Universal Robots URScript, movej in rad"

    def __init__(self, a: float = 1.4, v: float = 1.05) -> None:
        self.a, self.v = a, v

    def _speeds(self, Q: np.ndarray, info: ProgramInfo) -> tuple[list[float], str]:
        a, v = self.a, self.v
        if info.speeds is None:
            return [v] * len(Q), (f"rad (movej), a = {a:g} rad/s^2, v = {v:g} rad/s (the predicted motion time "
                                  "assumes the URDF speed limits instead)")
        sp = np.asarray(info.speeds, float)  # movej's v is the leading joint's speed: the one giving the time
        vs = [float(sp.min())]
        for qa, qb in zip(Q[:-1], Q[1:]):
            d = np.abs(qb - qa)
            t = float(np.max(d / sp))
            vs.append(float(d.max()) / t if t > 0 else float(sp.min()))
        return vs, (f"rad (movej), a = {a:g} rad/s^2, v per move = the leading joint's speed of the predicted "
                    f"motion time (joint speeds {', '.join(f'{x:.3g}' for x in sp)} rad/s; the first move "
                    f"{vs[0]:.3g} rad/s)")

    def write(self, Q: np.ndarray, kinds: list[str], poses: list[int], info: ProgramInfo) -> dict[str, str]:
        split_joints(info, self.name, allow_prismatic=False)
        name = program_name(info)
        vs, unit = self._speeds(Q, info)
        lines = [f"# {h}" for h in info.header_lines(unit)]
        lines.append(f"def {name}():")
        for i, (q, mark) in enumerate(zip(Q, step_marks(kinds, poses))):
            lines.append(f"  # step {i}: {mark}")
            lines.append(f"  movej([{', '.join(f'{x:.12f}' for x in q)}], a={self.a:g}, v={vs[i]:.6g})")
            if mark.startswith("MEASURE"):
                lines.append(f'  textmsg("{mark}")')
                lines.append(f"  sleep({info.dwell_s:g})")
        lines += ["end", f"{name}()"]
        return {".script": "\n".join(lines) + "\n"}

    def parse(self, texts: dict[str, str], revolute: np.ndarray) -> tuple[np.ndarray, list[int]]:
        t = texts[".script"]
        Q = np.array([[float(x) for x in m.group(1).split(",")] for m in re.finditer(r"movej\(\[([^\]]*)\]", t)])
        return Q, measure_marks(t, r'textmsg\("MEASURE \d+ \(design pose (\d+)\)"\)')
