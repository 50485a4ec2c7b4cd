"""The cell's own consistency, checked when its constraint model is built: the robot's fixed capsules clear of the
obstacles and half-spaces, the tracker outside every obstacle, every working configuration collision-free (its line
of sight to the tracker is not required: the hidden ones are named in the cell's summary). Each failure is one
message naming the capsules, grouped by cause, with the ``skip_pairs`` entry that fixes capsules overlapping by
construction."""

from __future__ import annotations

import numpy as np

from pin_kpi_oed.cell.cell_model import Cell
from pin_kpi_oed.cell.constraint_rows import INCID, PAIR
from pin_kpi_oed.cell.segments import point_segment_distance, segment_closest
from pin_kpi_oed.errors import InputError
from pin_kpi_oed.cell.segment_model import SegmentModel



def skip_hint(pairs: list[tuple[str, str]]) -> str:
    """The advice for capsules that overlap by construction: the cell file's ``skip_pairs`` entry to add."""
    listed = ", ".join(f"[{a}, {b}]" for a, b in pairs)
    return (f"if they overlap by construction (enclosing capsules of adjacent links, a robot on its pedestal or "
            f"floor), list them under skip_pairs in the cell file: skip_pairs: [{listed}]")


def _clearance_parts(cell: Cell, actual_m: float) -> str:
    """Where a required clearance comes from (the cell file's ``clearance_m``, ``design --clearance-margin``) and the
    margin that admits a pose ``actual_m`` (m) clear."""
    margin = float(getattr(cell, "clearance_margin_m", 0.0))
    if margin <= 0:
        return " (clearance_m of the cell file)"
    fit = max(0.0, np.floor((actual_m - (cell.clearance_m - margin)) * 1e3 - 1e-6) / 1e3)  # strictly within
    return (f" (clearance_m {(cell.clearance_m - margin) * 1e3:g} mm of the cell file + clearance_margin_m "
            f"{margin * 1e3:g} mm; clearance_margin_m {fit:g} admits it)")


def check_static(coll: SegmentModel) -> None:
    """Fixed robot capsules vs obstacles/half-spaces, and the tracker outside every obstacle."""
    nr, cell = coll.n_robot, coll.cell
    T = coll.tracker
    where = "[" + ", ".join(f"{x:.3f}" for x in cell.W_T_tracker.translation) + "]"
    env_caps = cell.environment_capsule_names  # environment objects: checked as their solids below
    for o in range(nr, nr + coll.n_obst):
        if coll.seg_names[o] in env_caps:
            continue
        d = point_segment_distance(T, coll.A_loc[o], coll.B_loc[o]) - coll.radius[o] - cell.beam_radius_m
        if d < 0 and not coll.beam_skipped(o):
            raise InputError(f"{cell.source or cell.name}: the tracker at {where} m (cell frame) is inside "
                             f"obstacle '{coll.seg_names[o]}' "
                             f"({d * 1e3:.0f} mm clearance); move the tracker or the obstacle")
    _tracker_in_environment(coll, where)
    for hsp, (nv, off) in zip(cell.half_spaces, coll.halfspaces):
        if T @ nv - off - cell.beam_radius_m < 0:
            raise InputError(f"{cell.source or cell.name}: the tracker is outside the free side of "
                             f"half-space '{hsp.name}'; move the tracker")
    problems, pairs = [], []
    for a in range(nr):
        if coll.seg_joint[a] != 0:
            continue
        for o in range(nr, nr + coll.n_obst):
            if coll.skipped(a, o):
                continue
            _, _, w1, w2 = segment_closest(coll.A_loc[a], coll.B_loc[a], coll.A_loc[o], coll.B_loc[o])
            d = np.linalg.norm(w2 - w1) - coll.radius[a] - coll.radius[o]
            if d < cell.clearance_m:
                problems.append(f"fixed robot capsule '{coll.seg_names[a]}' collides with obstacle "
                                f"'{coll.seg_names[o]}' ({d * 1e3:.0f} mm)")
                pairs.append((coll.seg_names[a], coll.seg_names[o]))
        for hsp, (nv, off) in zip(cell.half_spaces, coll.halfspaces):
            if coll.skipped_half(a, hsp.name):
                continue
            d = min(coll.A_loc[a] @ nv, coll.B_loc[a] @ nv) - off - coll.radius[a]
            if d < cell.clearance_m:
                problems.append(f"fixed robot capsule '{coll.seg_names[a]}' crosses half-space '{hsp.name}' "
                                f"({d * 1e3:.0f} mm; move the robot base)")
                pairs.append((coll.seg_names[a], hsp.name))
    if problems:
        raise InputError(f"{cell.source or cell.name}: " + "; ".join(problems) + "; " + skip_hint(pairs)
                         + ", otherwise move the obstacle or the robot base")

def _tracker_in_environment(coll: SegmentModel, where: str) -> None:
    """The tracker outside every environment solid (Coal's exact distance; the fitted capsules enclose more)."""
    from pin_kpi_oed.cell.environment import ball_distance

    cell = coll.cell
    for e in cell.environment:
        if e.name in cell.beam_skip:
            continue
        for s in e.solids:
            d = ball_distance(s, cell.W_T_tracker.translation, cell.beam_radius_m)
            if d < 0:
                raise InputError(f"{cell.source or cell.name}: the tracker at {where} m (cell frame) is inside "
                                 f"obstacle '{s.name}' ({d * 1e3:.0f} mm clearance); move the tracker or the "
                                 "obstacle")

def check_working(coll: SegmentModel) -> None:
    """Every working configuration must be collision-free (and clear by the required clearance); it need not be in
    the tracker's line of sight: it is where the robot works, not where it is measured (a TCP inside a car body is
    the common case). The hidden ones are kept in ``cell.hidden_work`` (index -> what blocks the beam), which the
    cell's summary names.

    Raises:
        InputError: one line, the problems grouped by cause (each configuration once per cause, the first few
            named) and each cause's fix named once.
    """
    cell = coll.cell
    saved = (coll.pairs, coll.half, coll.with_incidence, coll.info, coll.jac_rows, coll.jac_cols)
    coll.set_rows(coll.rows_all)
    try:
        g = coll.evaluate(cell.q_work, with_grad=False)
    finally:
        coll.pairs, coll.half, coll.with_incidence, coll.info, coll.jac_rows, coll.jac_cols = saved
    names = coll.rows_all["rows"].names
    kinds = coll.rows_all["rows"].kind
    hidden: dict[int, str] = {}
    groups: dict[str, dict[int, list[str]]] = {}
    pairs: list[tuple[str, str]] = []
    for i in range(g.shape[0]):
        for r in np.flatnonzero(g[i] < 0):
            nm = names[r]
            if kinds[r] == INCID:
                continue  # the reflector need not face the tracker while working
            if nm.startswith("beam"):
                hidden.setdefault(i, nm.removeprefix("beam|").removeprefix("beam@"))
                continue  # nor be seen by it
            if g[i, r] + cell.clearance_m >= 0:  # clear, but inside the required clearance (margins included)
                cause = (f"closer than the required clearance of {cell.clearance_m * 1e3:g} mm"
                         + _clearance_parts(cell, float(g[i, r]) + cell.clearance_m))
            else:
                cause = "in collision"
                if kinds[r] == PAIR:
                    pair = tuple(nm.removeprefix("robot:").split("|", 1))
                    pairs += [pair] if pair not in pairs else []
            groups.setdefault(cause, {}).setdefault(i, []).append(f"{nm}, {g[i, r] * 1e3:.1f} mm")
    cell.hidden_work = hidden
    if groups:
        parts = []
        for cause, per_conf in groups.items():
            shown = [f"{i} ({'; '.join(items[:6])}" + (f"; and {len(items) - 6} more)" if len(items) > 6 else ")")
                     for i, items in list(per_conf.items())[:8]]
            more = f" and {len(per_conf) - 8} more configuration(s)" if len(per_conf) > 8 else ""
            parts.append(f"working configuration(s) {cause}: {', '.join(shown)}{more}")
        raise InputError(f"{cell.source or cell.name}: " + "; ".join(parts)
                         + (f"; {skip_hint(pairs)}" if pairs else "")
                         + "; working configurations must be collision-free (their line of sight is not required)")
