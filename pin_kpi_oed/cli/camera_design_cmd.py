"""``design --cell CAMERA_CELL``: the KPI design of a camera calibration (:mod:`pin_kpi_oed.design.camera_design`:
the pool selection with its certificate, IPOPT from it, the independent check by OpenCV and Coal), printed as the
tracker's design table and written to ``--json`` (:mod:`pin_kpi_oed.design.camera_design_file`).

The camera cell states its device and what the camera needs to see the board (``camera.view``); the options that
shape the tracker's design (criteria other than kpi, margins, starts, a model, a pool, measured poses, the
discrepancy) are refused with the option named. ``--n`` / ``--measurements`` (poses), ``--seed`` (the pool),
``--pool-size`` (feasible candidates, default :data:`CAMERA_POOL_SIZE`), ``--max-iter`` (IPOPT), ``--json`` and
``--quiet`` act as for the tracker; the certificate is always computed (``--certificate``, which asks the tracker's
design for it, is refused as saying nothing).
"""

from __future__ import annotations

import argparse
from typing import Any

import numpy as np

from pin_kpi_oed.design.margins import DEFAULT_CLEARANCE_MARGIN_M, DEFAULT_INCIDENCE_MARGIN_DEG
from pin_kpi_oed.errors import InfeasibleError, InputError

__all__ = ["run_camera_design", "CAMERA_POOL_SIZE", "DESIGN_TRACKER_ONLY"]

#: feasible candidates of a camera design's pool without ``--pool-size``
CAMERA_POOL_SIZE = 600
#: design options a camera cell refuses: dest -> its default (given when on the command line or not the default)
DESIGN_TRACKER_ONLY: dict[str, Any] = {
    "no_collision": False, "starts": None, "distances": "coal", "start": "pool", "model": None, "prior": "model",
    "clearance_margin": DEFAULT_CLEARANCE_MARGIN_M, "incidence_margin": DEFAULT_INCIDENCE_MARGIN_DEG, "pool": None,
    "given": None, "given_prior": None, "target_sigma": None, "curve": None, "work_radius": None, "no_hedge": False,
    "robot_class": None, "work_samples": None, "reregister": None}


def _refuse_tracker_options(args: argparse.Namespace, cell_name: str) -> None:
    """Raises InputError naming the first tracker-only option given (module docstring)."""
    argv = [str(a) for a in getattr(args, "argv", None) or []]
    crit = str(getattr(args, "criteria", "kpi") or "kpi")
    if crit not in ("kpi", "random,param,kpi"):
        raise InputError(f"design --criteria {crit}: a camera cell ({cell_name}) is designed for the KPI "
                         "criterion alone; leave --criteria out")
    if getattr(args, "certificate", False):
        raise InputError(f"design --certificate: a camera cell ({cell_name}) always computes its design's optimality "
                         "certificate (the efficiency column and the 'certificate:' line); leave it out")
    for dest, default in DESIGN_TRACKER_ONLY.items():
        opt = "--" + dest.replace("_", "-")
        on_line = any(a == opt or a.startswith(opt + "=") for a in argv)
        if on_line or getattr(args, dest, default) != default:
            raise InputError(f"design {opt}: a laser tracker's design option; a camera cell ({cell_name}) states "
                             "its camera, board and view limits (leave it out)")


def _held_line(held: Any, model: Any, t: int, trace_cs_m2: float) -> str:
    """What the held joint placements add to the TCP σ, and what removes it ("" when nothing is held)."""
    if not held.names or held.trace_m2 <= 0:
        return ""
    total = trace_cs_m2 + held.trace_m2
    top = [i for i in np.argsort(-held.contrib_m)[:2] if held.contrib_m[i] > 0.05 * np.sqrt(held.trace_m2 / t)]
    named = ", ".join(f"{held.names[i]} ({held.contrib_m[i] * 1e3:.3g} mm)" for i in top)
    mounted = model.target_groups[0]
    return (f"TCP sigma = sqrt((tr(C_s) + held) / t) at the {t} working configuration(s); held at nominal: "
            f"{held.trace_m2 * 1e6:.4g} mm^2 ({100 * held.trace_m2 / total:.0f} % of {total * 1e6:.4g} mm^2), mostly "
            f"{named}: the fitted {mounted} pose on the tool absorbs it, no image of the board determines it; the "
            f"TCP's position relative to the {mounted} (a tool calibration) removes it")


def _table(design: Any, held_sel: Any, held: Any, t: int) -> str:
    """The design table: the pool selection and the design returned (tr C_s, held, TCP σ, iterations, efficiency,
    check)."""
    head = (f"{'design':<12}{'tr(C_s) mm^2':>14}{'held mm^2':>12}{'TCP sigma um':>14}{'iters':>7}{'time s':>8}"
            f"{'effic. %':>10}  check")
    cert, chk = design.certificate, design.check
    rows = [("selection", design.selection_trace_cs_m2, held_sel.trace_m2, "-", None),
            (f"kpi ({design.source})", design.trace_cs_m2, held.trace_m2, str(design.nit), chk)]
    eff_ok = design.stated_efficiency is not None
    lines = [head, "-" * len(head)]
    for name, tr, h, it, c in rows:
        ok = "-" if c is None else ("ok" if c.ok.all() else f"{int((~c.ok).sum())} of {len(c.ok)} do not see")
        secs = f"{design.time_s:.2f}" if c is not None else "-"
        eff = f"{100 * cert.efficiency(tr):.1f}" if (c is None or eff_ok) else "off pool"
        lines.append(f"{name:<12}{tr * 1e6:>14.4e}{h * 1e6:>12.4e}{np.sqrt((tr + h) / t) * 1e6:>14.2f}{it:>7}"
                     f"{secs:>8}{eff:>10}  {ok}")
    return "\n".join(lines)


def run_camera_design(args: argparse.Namespace, cell: Any) -> int:
    """``design --cell CAMERA_CELL`` (module docstring); returns the exit code.

    Args:
        args: the parsed ``design`` options; cell: the camera cell.

    Returns:
        0.

    Raises:
        InputError: a tracker's design option, too few poses, no working configuration.
        InfeasibleError: too few candidates see the board, or a designed pose fails the independent check (no file
            written).
    """
    from pin_kpi_oed.cell.camera_view import cell_view_limits
    from pin_kpi_oed.data.atomic import atomic_write_json
    from pin_kpi_oed.design.camera_design import CameraDesignProblem, design_camera
    from pin_kpi_oed.design.camera_design_file import camera_design_document
    from pin_kpi_oed.design.ipopt import ipopt_options
    from pin_kpi_oed.oed.held import design_held

    _refuse_tracker_options(args, cell.source or cell.name)
    m = int(getattr(args, "measurements", None) or cell.measurements)
    seed = int(getattr(args, "seed", 0) or 0)
    pool_size = int(getattr(args, "pool_size", None) or CAMERA_POOL_SIZE)
    max_iter = int(getattr(args, "max_iter", None) or 500)
    quiet = bool(getattr(args, "quiet", False))
    limits = cell_view_limits(cell)
    model = cell.measurement_model()
    problem = CameraDesignProblem(cell, model, limits, cell.q_work)
    t = cell.q_work.shape[0]
    if not quiet:
        print(cell.summary().split(", incidence")[0] + "".join(f"\nnote: {n}" for n in cell.robot.notes))
        print(f"camera {model.mode}: {m} images of the board ({model.board.n} corners, {model.sigma_px:g} px), seed "
              f"{seed}; {problem.base.size} identifiable parameters; view: margin {limits.margin_px:g} px, angle <= "
              f"{limits.max_angle_deg:.1f} deg, depth {limits.near_m:g}..{limits.far_m:g} m, rays clear of the "
              f"cell; pool {pool_size} feasible candidates, IPOPT <= {max_iter} iterations")
    design = design_camera(problem, m, seed=seed, pool_size=pool_size, ipopt=True,
                           ipopt_options=ipopt_options(max_iter=max_iter))
    held = design_held(model, problem.base, design.Q, cell.q_work)
    held_sel = design_held(model, problem.base, design.Q_selection, cell.q_work)
    print(_table(design, held_sel, held, t))
    line = _held_line(held, model, t, design.trace_cs_m2)
    if line:
        print(line)
    cert, chk = design.certificate, design.check
    print(f"certificate: every {m}-pose design from the {cert.pool_size} feasible candidates has tr(C_s) >= "
          f"{cert.lower_bound_trace_cs_m2 * 1e6:.4e} mm^2 (equivalence theorem: mean of the {m} largest d / phi = "
          f"{cert.approx.max_d_ratio:.4f}); tr(C_s) in the {model.frame_group} frame, identified parameters only"
          + ("" if design.stated_efficiency is not None else
             f"; IPOPT's design leaves the pool and is {design.efficiency:.2f}x below this bound of the pool's "
             "designs, which it does not bound: no efficiency is stated for it (the pool misses the best poses; a "
             "larger --pool-size tightens the bound)"))
    note = design.ipopt_note()
    if note:
        print(note)
    if not quiet:
        ray = chk.ray_clearance_m[np.isfinite(chk.ray_clearance_m)]
        print(f"independent check (OpenCV projection, Coal ray distances): {int(chk.ok.sum())} of {m} poses see the "
              f"board; corners inside >= {int(chk.corners_inside.min())} of {chk.n_corners}, depth "
              f"{chk.depth_m.min():.3f}..{chk.depth_m.max():.3f} m, viewing angle <= {chk.angle_deg.max():.1f} deg"
              + (f", ray clearance >= {ray.min() * 1e3:.1f} mm" if ray.size else ""))
    if not design.success:
        bad = np.flatnonzero(~chk.ok)
        raise InfeasibleError(f"design --cell {cell.source or cell.name}: pose(s) {', '.join(map(str, bad[:5]))} "
                              "fail the independent check (see above); no design written")
    if getattr(args, "json", None):
        atomic_write_json(args.json, camera_design_document(cell, problem, design, held, seed))
        if not quiet:
            print(f"wrote {args.json}")
    return 0
