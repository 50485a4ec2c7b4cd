"""Robot programs from an ordered measurement program: CSV, URScript, KUKA KRL, ABB RAPID — and their parsers.

Every writer returns ``{suffix: text}`` (KRL: ``.src`` + ``.dat``; the others one file) with a header
naming the cell, the design, the robot, the units and the date, and every measurement instruction
point marked (``MEASURE k (design pose i)`` plus a wait of ``dwell_s`` for the tracker to settle and
measure). Joint values are the URDF's (rad / m in the model):

* CSV: one row per target, each joint in degrees and radians (metres for prismatic joints);
* URScript: ``movej([...], a, v)`` in rad, 6 revolute joints;
* KRL: ``PTP XPk`` in the ``.src``, ``DECL E6AXIS XPk={A1 .., E1 ..}`` in the ``.dat``: the 6
  revolute joints as A1–A6 in degrees, prismatic joints (a linear track) as E1… in millimetres;
* RAPID: ``CONST jointtarget`` + ``MoveAbsJ``: robax in degrees, prismatic joints in eax_a… (mm).

The parsers (:func:`parse_program`) read the same texts back to configurations in SI units: the
tests round-trip every format to 1e-6 rad. The controller's own sign and zero conventions of each
axis are not known to the package: check them against the robot's manual before running (the
header says so).
"""

from __future__ import annotations

import datetime as _dt
import math
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from pin_kpi_oed.errors import InputError

FORMATS = ("csv", "urscript", "krl", "rapid")
SUFFIX = {"csv": ".csv", "urscript": ".script", "krl": ".src", "rapid": ".mod"}


def program_files(fmt: str, out: str) -> dict[str, Path]:
    """Files a format writes, by suffix: the ``--out`` path (KRL: the ``.src``, ``.src`` added when missing,
    and the ``.dat`` beside it).

    Raises:
        InputError: unknown format.
    """
    if fmt not in FORMATS:
        raise InputError(f"--format: unknown format '{fmt}' (known: {', '.join(FORMATS)})")
    path = Path(out)
    if fmt != "krl":
        return {SUFFIX[fmt]: path}
    src = path if path.suffix.lower() == ".src" else path.with_name(path.name + ".src")
    return {".src": src, ".dat": src.with_suffix(".dat")}


@dataclass
class ProgramInfo:
    """What the header says.

    Attributes:
        cell: cell name.
        design: design file and criterion.
        robot: robot name.
        joint_names: joint names in model order.
        revolute: revolute mask of the joints.
        cycle_time_s: predicted motion time (s).
        date: ISO date-time (UTC) of the export (now if empty).
        dwell_s: wait at each measurement point (s).
        name: program name (KRL / RAPID module name).
        speeds: joint speeds the predicted motion time assumes (URDF limits × override; rad/s, m/s);
            URScript then moves each ``movej`` at the leading-joint speed that gives that time.
    """

    cell: str
    design: str
    robot: str
    joint_names: list[str]
    revolute: np.ndarray
    cycle_time_s: float = float("nan")
    date: str = ""
    dwell_s: float = 0.5
    name: str = "pko_program"
    speeds: np.ndarray | None = None

    def header_lines(self, units: str) -> list[str]:
        """Header lines (no comment prefix)."""
        date = self.date or _dt.datetime.now(_dt.timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ")
        return ["pin-kpi-oed measurement program", f"cell: {self.cell}", f"design: {self.design}",
                f"robot: {self.robot}; joints: {', '.join(self.joint_names)}", f"units: {units}",
                f"date: {date}", f"predicted motion time: {self.cycle_time_s:.2f} s (max_j |dq_j|/v_j per move, "
                "URDF speed limits, no ramps)",
                f"measurement points: marked MEASURE k (design pose i), wait {self.dwell_s:g} s each",
                "joint values are the URDF's: check the controller's axis signs and zeros before running"]


def _names(info: ProgramInfo) -> str:
    return re.sub(r"[^A-Za-z0-9_]", "_", info.name)[:24] or "pko_program"


def _split(info: ProgramInfo, fmt: str) -> tuple[np.ndarray, np.ndarray]:
    """Indices of the revolute (robot) and prismatic (external) joints; checks the format can hold them."""
    rev = np.flatnonzero(np.asarray(info.revolute, bool))
    ext = np.flatnonzero(~np.asarray(info.revolute, bool))
    if rev.size != 6 or (fmt == "urscript" and ext.size) or ext.size > 6:
        raise InputError(f"--format {fmt}: needs 6 revolute joints{' and no prismatic' if fmt == 'urscript' else ''}"
                         f" (up to 6 prismatic as external axes), robot {info.robot} has {rev.size} revolute and "
                         f"{ext.size} prismatic")
    return rev, ext


def _mark(kinds: list[str], poses: list[int]) -> list[str]:
    """Comment text of each target (``MEASURE k (design pose i)``, ``home``, ``via``)."""
    out, k = [], 0
    for kind, p in zip(kinds, poses):
        if kind == "measure":
            k += 1
            out.append(f"MEASURE {k} (design pose {p})")
        else:
            out.append(kind)
    return out


def write_csv(Q: np.ndarray, kinds: list[str], poses: list[int], info: ProgramInfo) -> dict[str, str]:
    """CSV: step, kind, pose, every joint in deg (m) and in rad (m)."""
    rev = np.asarray(info.revolute, bool)
    lines = [f"# {h}" for h in info.header_lines("<joint>_deg in degrees and <joint>_rad in radians (prismatic "
                                                 "joints: <joint>_m in metres, both columns); pose = design index")]
    cols = [f"{n}_deg" if r else f"{n}_m" for n, r in zip(info.joint_names, rev)]
    cols += [f"{n}_rad" if r else f"{n}_m" for n, r in zip(info.joint_names, rev)]
    lines.append(",".join(["step", "kind", "pose", *cols]))
    for i, (q, kind, p) in enumerate(zip(Q, kinds, poses)):
        deg = np.where(rev, np.degrees(q), q)
        lines.append(",".join([str(i), kind, str(p), *(f"{x:.9f}" for x in deg), *(f"{x:.12f}" for x in q)]))
    return {".csv": "\n".join(lines) + "\n"}


def write_urscript(Q: np.ndarray, kinds: list[str], poses: list[int], info: ProgramInfo, a: float = 1.4,
                   v: float = 1.05) -> dict[str, str]:
    """URScript: ``movej`` through every target (rad), ``textmsg`` + ``sleep`` at measurement points."""
    _split(info, "urscript")
    name = _names(info)
    if info.speeds is not None:  # movej's v is the leading joint's speed: the one that gives the predicted time
        sp = np.asarray(info.speeds, float)
        vs = [float(sp.min())]
        for qa, qb in zip(Q[:-1], Q[1:]):
            d = np.abs(qb - qa)
            t = float(np.max(d / sp))
            vs.append(float(d.max()) / t if t > 0 else float(sp.min()))
        unit = (f"rad (movej), a = {a:g} rad/s^2, v per move = the leading joint's speed of the predicted motion "
                f"time (joint speeds {', '.join(f'{x:.3g}' for x in sp)} rad/s; the first move "
                f"{vs[0]:.3g} rad/s)")
    else:
        vs = [v] * len(Q)
        unit = (f"rad (movej), a = {a:g} rad/s^2, v = {v:g} rad/s (the predicted motion time assumes the URDF "
                "speed limits instead)")
    lines = [f"# {h}" for h in info.header_lines(unit)]
    lines.append(f"def {name}():")
    for i, (q, mark) in enumerate(zip(Q, _mark(kinds, poses))):
        lines.append(f"  # step {i}: {mark}")
        lines.append(f"  movej([{', '.join(f'{x:.12f}' for x in q)}], a={a:g}, v={vs[i]:.6g})")
        if mark.startswith("MEASURE"):
            lines.append(f'  textmsg("{mark}")')
            lines.append(f"  sleep({info.dwell_s:g})")
    lines += ["end", f"{name}()"]
    return {".script": "\n".join(lines) + "\n"}


def write_krl(Q: np.ndarray, kinds: list[str], poses: list[int], info: ProgramInfo) -> dict[str, str]:
    """KUKA KRL: ``.src`` (PTP to every E6AXIS point, MEASURE comments, WAIT) and ``.dat`` (the points)."""
    rev, ext = _split(info, "krl")
    name = _names(info)
    head = [f";{h}" for h in info.header_lines("A1-A6 in degrees, E1.. (linear axes) in millimetres")]
    src = ["&ACCESS RVP", "&REL 1", *head, f"DEF {name}( )", "BAS(#INITMOV, 0)", "BAS(#VEL_PTP, 100)"]
    dat = ["&ACCESS RVP", "&REL 1", *head, f"DEFDAT {name} PUBLIC"]
    for i, (q, mark) in enumerate(zip(Q, _mark(kinds, poses))):
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


def write_rapid(Q: np.ndarray, kinds: list[str], poses: list[int], info: ProgramInfo, speed: str = "v1000",
                tool: str = "tool0") -> dict[str, str]:
    """ABB RAPID: a module with a ``CONST jointtarget`` per target and ``MoveAbsJ`` through them."""
    rev, ext = _split(info, "rapid")
    name = _names(info)
    lines = [f"MODULE {name}"]
    lines += [f"  ! {h}" for h in info.header_lines("robax in degrees, extax (linear axes) in millimetres, "
                                                     "9E9 = no axis")]
    for i, q in enumerate(Q):
        rob = ",".join(f"{math.degrees(q[j]):.6f}" for j in rev)
        eax = ",".join(f"{q[ext[k]] * 1e3:.6f}" if k < ext.size else "9E9" for k in range(6))
        lines.append(f"  CONST jointtarget jP{i + 1}:=[[{rob}],[{eax}]];")
    lines.append("  PROC main()")
    for i, mark in enumerate(_mark(kinds, poses)):
        lines.append(f"    ! step {i}: {mark}")
        lines.append(f"    MoveAbsJ jP{i + 1}, {speed}, fine, {tool};")
        if mark.startswith("MEASURE"):
            lines.append(f"    WaitTime {info.dwell_s:g};")
    lines += ["  ENDPROC", "ENDMODULE"]
    return {".mod": "\n".join(lines) + "\n"}


WRITERS = {"csv": write_csv, "urscript": write_urscript, "krl": write_krl, "rapid": write_rapid}


def write_program(fmt: str, Q: np.ndarray, kinds: list[str], poses: list[int], info: ProgramInfo) -> dict[str, str]:
    """The program texts of a format.

    Args:
        fmt: one of :data:`FORMATS`.
        Q: targets in execution order (k, n), rad / m.
        kinds: ``home`` / ``measure`` / ``via`` per target.
        poses: design index per target (-1 when not a measurement point).
        info: header fields.

    Returns:
        ``{suffix: text}``.

    Raises:
        InputError: unknown format, or a robot the format cannot hold.
    """
    if fmt not in WRITERS:
        raise InputError(f"--format: unknown format '{fmt}' (known: {', '.join(FORMATS)})")
    return WRITERS[fmt](np.atleast_2d(np.asarray(Q, float)), list(kinds), [int(p) for p in poses], info)


# ============================================================================ parsers
_NUM = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"


def _measure_marks(text: str, pattern: str) -> list[int]:
    return [int(m.group(1)) for m in re.finditer(pattern, text)]


def parse_program(fmt: str, texts: dict[str, str], revolute: np.ndarray) -> tuple[np.ndarray, list[int]]:
    """Read a written program back.

    Args:
        fmt: the format.
        texts: ``{suffix: text}`` as :func:`write_program` returns (or as read from the files).
        revolute: revolute mask of the robot's joints (model order).

    Returns:
        (targets (k, n) in rad / m in model order, design pose index of each MEASURE point in order).

    Raises:
        InputError: text that is not a program of the format.
    """
    revolute = np.asarray(revolute, bool)
    rev, ext = np.flatnonzero(revolute), np.flatnonzero(~revolute)
    n = revolute.size
    if fmt == "csv":
        rows = [r for r in texts[".csv"].splitlines() if r and not r.startswith("#")]
        head = rows[0].split(",")
        cols = [k for k, h in enumerate(head) if h.endswith("_rad") or h.endswith("_m")][-n:]
        data = [r.split(",") for r in rows[1:]]
        Q = np.array([[float(d[k]) for k in cols] for d in data])
        return Q, [int(d[2]) for d in data if d[1] == "measure"]
    if fmt == "urscript":
        t = texts[".script"]
        Q = np.array([[float(x) for x in m.group(1).split(",")] for m in re.finditer(r"movej\(\[([^\]]*)\]", t)])
        return Q, _measure_marks(t, r'textmsg\("MEASURE \d+ \(design pose (\d+)\)"\)')
    if fmt == "krl":
        pts = {}
        for m in re.finditer(r"DECL E6AXIS XP(\d+)=\{([^}]*)\}", texts[".dat"]):
            vals = dict((k, float(v)) for k, v in re.findall(rf"([AE]\d) ({_NUM})", m.group(2)))
            q = np.zeros(n)
            q[rev] = np.radians([vals[f"A{k + 1}"] for k in range(rev.size)])
            q[ext] = [vals[f"E{k + 1}"] * 1e-3 for k in range(ext.size)]
            pts[int(m.group(1))] = q
        order = [int(k) for k in re.findall(r"^PTP XP(\d+)", texts[".src"], re.M)]
        return np.array([pts[k] for k in order]), _measure_marks(texts[".src"],
                                                                 r";step \d+: MEASURE \d+ \(design pose (\d+)\)")
    if fmt == "rapid":
        t = texts[".mod"]
        pts = {}
        for m in re.finditer(r"CONST jointtarget jP(\d+):=\[\[([^\]]*)\],\[([^\]]*)\]\];", t):
            q = np.zeros(n)
            q[rev] = np.radians([float(x) for x in m.group(2).split(",")])
            q[ext] = [float(x) * 1e-3 for x in m.group(3).split(",")[:ext.size]]
            pts[int(m.group(1))] = q
        order = [int(k) for k in re.findall(r"MoveAbsJ jP(\d+),", t)]
        return np.array([pts[k] for k in order]), _measure_marks(t, r"! step \d+: MEASURE \d+ \(design pose (\d+)\)")
    raise InputError(f"unknown format '{fmt}' (known: {', '.join(FORMATS)})")
