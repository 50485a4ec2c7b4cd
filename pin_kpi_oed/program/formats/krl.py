"""KUKA KRL program: ``PTP XPk`` in the ``.src``, ``DECL E6AXIS XPk={A1 .., E1 ..}`` in the ``.dat``.

The 6 revolute joints as A1–A6 in degrees, prismatic joints (a linear track) as E1… in millimetres
(unused E axes 0). Each measurement point: a ``;step k: MEASURE ..`` comment and ``WAIT SEC dwell_s``.
"""

from __future__ import annotations

import math
import os
import re
from pathlib import Path

import numpy as np

from pin_kpi_oed.program.formats.base import (NUM, ProgramFormat, ProgramInfo, measure_marks, program_name,
                                              split_joints, step_marks)

__all__ = ["KrlFormat"]


class KrlFormat(ProgramFormat):
    """KUKA KRL: ``.src`` (PTP to every E6AXIS point, MEASURE comments, WAIT) and ``.dat`` (the points)."""

    name = "krl"
    suffix = ".src"
    description = "KUKA KRL, .src + .dat, A1-A6 in degrees, E1.. in mm"

    def files(self, out: str | os.PathLike) -> dict[str, Path]:
        """The ``.src`` (``.src`` added when missing) and the ``.dat`` beside it."""
        path = Path(out)
        src = path if path.suffix.lower() == ".src" else path.with_name(path.name + ".src")
        return {".src": src, ".dat": src.with_suffix(".dat")}

    def write(self, Q: np.ndarray, kinds: list[str], poses: list[int], info: ProgramInfo) -> dict[str, str]:
        rev, ext = split_joints(info, self.name)
        name = program_name(info)
        head = [f";{h}" for h in info.header_lines("A1-A6 in degrees, E1.. (linear axes) in millimetres")]
        src = ["&ACCESS RVP", "&REL 1", *head, f"DEF {name}( )", "BAS(#INITMOV, 0)", "BAS(#VEL_PTP, 100)"]
        dat = ["&ACCESS RVP", "&REL 1", *head, f"DEFDAT {name} PUBLIC"]
        for i, (q, mark) in enumerate(zip(Q, step_marks(kinds, poses))):
            src.append(f";step {i}: {mark}")
            src.append(f"PTP XP{i + 1}")
            if mark.startswith("MEASURE"):
                src.append(f"WAIT SEC {info.dwell_s:g}")
            ax = [f"A{k + 1} {math.degrees(q[j]):.6f}" for k, j in enumerate(rev)]
            ax += [f"E{k + 1} {(q[ext[k]] * 1e3 if k < ext.size else 0.0):.6f}" for k in range(6)]
            dat.append(f"DECL E6AXIS XP{i + 1}={{{','.join(ax)}}}")
        src.append("END")
        dat.append("ENDDAT")
        return {".src": "\n".join(src) + "\n", ".dat": "\n".join(dat) + "\n"}

    def parse(self, texts: dict[str, str], revolute: np.ndarray) -> tuple[np.ndarray, list[int]]:
        revolute = np.asarray(revolute, bool)
        rev, ext = np.flatnonzero(revolute), np.flatnonzero(~revolute)
        pts = {}
        for m in re.finditer(r"DECL E6AXIS XP(\d+)=\{([^}]*)\}", texts[".dat"]):
            vals = dict((k, float(v)) for k, v in re.findall(rf"([AE]\d) ({NUM})", m.group(2)))
            q = np.zeros(revolute.size)
            q[rev] = np.radians([vals[f"A{k + 1}"] for k in range(rev.size)])
            q[ext] = [vals[f"E{k + 1}"] * 1e-3 for k in range(ext.size)]
            pts[int(m.group(1))] = q
        order = [int(k) for k in re.findall(r"^PTP XP(\d+)", texts[".src"], re.M)]
        return np.array([pts[k] for k in order]), measure_marks(texts[".src"],
                                                                r";step \d+: MEASURE \d+ \(design pose (\d+)\)")
