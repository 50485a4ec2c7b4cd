"""``pin-kpi-oed design --iso9283 PROGRAM``: the ISO 9283 cube test of a cell as a robot program.

Example::

    pin-kpi-oed design --cell ur10 --iso9283 iso_ur10.script

plans the test cube around the working configurations (:func:`~pin_kpi_oed.design.iso9283.plan_iso_cube`:
the largest that fits, or the side ``--iso-side`` gives in m, its test plane and P1..P5), checks every pose
(independent check) and every move of the cycle P1, P5, P4, P3, P2, P1 densely (≤ 1° joint steps, Coal), and
writes the 30 cycles with the program export (format from the file's suffix: .csv, .script, .src, .mod). Nothing
is written when a pose or a move collides.
"""

from __future__ import annotations

import argparse
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from pin_kpi_oed.errors import InfeasibleError, InputError

__all__ = ["run_iso9283", "format_of", "cycle_moves"]


def cycle_moves(cell: Any) -> Callable[[np.ndarray], str]:
    """The check of a test cycle's moves P1, P5, P4, P3, P2, P1 in ``cell`` (dense, Coal): poses (5, n) rad / m ->
    "" when every move is clear, else the first that collides."""
    from pin_kpi_oed.design.iso9283 import CYCLE_ORDER
    from pin_kpi_oed.program.transitions import TransitionChecker

    tc = TransitionChecker(cell)
    loop = list(CYCLE_ORDER) + [CYCLE_ORDER[0]]

    def check(q: np.ndarray) -> str:
        for a, b in zip(loop[:-1], loop[1:]):
            mv = tc.check(q[a], q[b])
            if not mv.clear:
                return (f"the move P{a + 1} -> P{b + 1} collides ({mv.min_clearance_m * 1e3:.1f} mm at "
                        f"{mv.worst_fraction:.0%} of it)")
        return ""
    return check


def format_of(out: str) -> str:
    """The program format of an output file by its suffix.

    Raises:
        InputError: a suffix no format writes.
    """
    from pin_kpi_oed.program.export import FORMATS
    from pin_kpi_oed.program.formats.registry import get_format

    suffix = Path(out).suffix.lower()
    for name in FORMATS:
        if get_format(name).suffix == suffix:
            return name
    known = ", ".join(f"{get_format(n).suffix} ({n})" for n in FORMATS)
    raise InputError(f"--iso9283 {out}: unknown program suffix '{suffix}'; give one of {known}")


def run_iso9283(args: argparse.Namespace) -> int:
    """Plan, check and write the ISO 9283 cube test (returns the exit code).

    Raises:
        PinKpiOedError: bad cell or output, a cube that does not fit, a move of the cycle that collides.
    """
    from pin_kpi_oed.cell.cell import load_cell
    from pin_kpi_oed.cell.feasibility import FeasibilityChecker
    from pin_kpi_oed.data.atomic import atomic_write_text
    from pin_kpi_oed.design.iso9283 import CYCLE_ORDER, N_CYCLES, plan_iso_cube
    from pin_kpi_oed.program.export import ProgramInfo, program_files, write_program
    from pin_kpi_oed.program.timing import joint_speeds, move_time
    from pin_kpi_oed.program.transitions import TransitionChecker

    out = str(args.iso9283)
    fmt = format_of(out)
    files = program_files(fmt, out)
    cell = load_cell(getattr(args, "cell", "kr15"))
    test = plan_iso_cube(cell, side_m=getattr(args, "iso_side", None), moves=cycle_moves(cell))
    rep = FeasibilityChecker(cell).check(test.q)
    if not rep.feasible.all():
        raise InfeasibleError(f"--iso9283: pose P{int(np.argmin(rep.feasible)) + 1} fails the independent check")
    tc = TransitionChecker(cell)
    loop = list(CYCLE_ORDER) + [CYCLE_ORDER[0]]
    for a, b in zip(loop[:-1], loop[1:]):
        mv = tc.check(test.q[a], test.q[b])
        if not mv.clear:
            raise InfeasibleError(f"--iso9283: the move P{a + 1} -> P{b + 1} collides ({mv.min_clearance_m * 1e3:.1f} "
                                  f"mm at {mv.worst_fraction:.0%} of it); nothing written")
    Q, idx = test.cycle_poses()
    speeds = joint_speeds(cell.robot)
    cycle_s = float(sum(move_time(test.q[a], test.q[b], speeds) for a, b in zip(loop[:-1], loop[1:]))) * N_CYCLES
    robot = cell.robot
    texts = write_program(fmt, Q, ["measure"] * len(idx), idx,
                          ProgramInfo(cell=cell.name, design=f"ISO 9283 cube, side {test.side_m:.3f} m, {N_CYCLES} "
                                      f"cycles P1 P5 P4 P3 P2", robot=robot.name,
                                      joint_names=list(robot.joint_names),
                                      revolute=np.asarray(robot.is_revolute, bool), cycle_time_s=cycle_s,
                                      name=files[next(iter(files))].stem, speeds=speeds))
    at_mean = "" if test.side_at_mean_m is None else f" (on that mean: {test.side_at_mean_m * 1e3:.0f} mm)"
    print(f"ISO 9283 cube in {cell.name}: side {test.side_m * 1e3:.0f} mm, centre "
          f"({', '.join(f'{v:.3f}' for v in test.centre_m)}) m (cell frame), {test.shift_m * 1e3:.0f} mm from the "
          f"working configurations' mean TCP{at_mean}; {len({r.tobytes() for r in test.rotations})} tool "
          f"orientation(s)")
    for i, (p, c) in enumerate(zip(test.positions_m, rep.clearance_m)):
        print(f"  P{i + 1}: ({', '.join(f'{v:.4f}' for v in p)}) m, clearance {c * 1e3:.1f} mm, "
              f"incidence {rep.incidence_deg[i]:.1f} deg")
    print(f"{N_CYCLES} cycles, {len(idx)} poses, moves checked densely; predicted motion time {cycle_s:.1f} s")
    for suffix in sorted(texts, key=lambda s: s != ".dat"):
        atomic_write_text(files[suffix], texts[suffix])
    print("wrote " + ", ".join(str(files[s]) for s in texts))
    return 0
