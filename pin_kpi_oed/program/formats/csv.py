"""CSV program: one row per target, every joint in degrees and in radians (metres for prismatic joints).

Columns ``step, kind, pose, <joint>_deg.. , <joint>_rad..`` (prismatic joints ``<joint>_m`` in both blocks);
``pose`` is the design index of a measurement point (-1 otherwise). The parser reads the last n joint
columns (rad / m).
"""

from __future__ import annotations

import numpy as np

from pin_kpi_oed.program.formats.base import ProgramFormat, ProgramInfo

__all__ = ["CsvFormat"]


class CsvFormat(ProgramFormat):
    """CSV: step, kind, pose, every joint in deg (m) and in rad (m)."""

    name = "csv"
    suffix = ".csv"
    description = "one row per target, joints in degrees and radians (prismatic: metres)"

    def write(self, Q: np.ndarray, kinds: list[str], poses: list[int], info: ProgramInfo) -> dict[str, str]:
        rev = np.asarray(info.revolute, bool)
        lines = [f"# {h}" for h in info.header_lines("<joint>_deg in degrees and <joint>_rad in radians (prismatic "
                                                     "joints: <joint>_m in metres, both columns); pose = design "
                                                     "index")]
        cols = [f"{n}_deg" if r else f"{n}_m" for n, r in zip(info.joint_names, rev)]
        cols += [f"{n}_rad" if r else f"{n}_m" for n, r in zip(info.joint_names, rev)]
        lines.append(",".join(["step", "kind", "pose", *cols]))
        for i, (q, kind, p) in enumerate(zip(Q, kinds, poses)):
            deg = np.where(rev, np.degrees(q), q)
            lines.append(",".join([str(i), kind, str(p), *(f"{x:.9f}" for x in deg), *(f"{x:.12f}" for x in q)]))
        return {".csv": "\n".join(lines) + "\n"}

    def parse(self, texts: dict[str, str], revolute: np.ndarray) -> tuple[np.ndarray, list[int]]:
        n = np.asarray(revolute, bool).size
        rows = [r for r in texts[".csv"].splitlines() if r and not r.startswith("#")]
        head = rows[0].split(",")
        cols = [k for k, h in enumerate(head) if h.endswith("_rad") or h.endswith("_m")][-n:]
        data = [r.split(",") for r in rows[1:]]
        Q = np.array([[float(d[k]) for k in cols] for d in data])
        return Q, [int(d[2]) for d in data if d[1] == "measure"]
