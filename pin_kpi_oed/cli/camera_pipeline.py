"""The camera through the command line: what ``simulate`` and ``identify`` do with a camera cell or a camera
measurement file (one row per detected corner, :mod:`pin_kpi_oed.data.corner_measurements`).

``simulate --cell CAMERA_CELL`` writes the corners of a true robot that is not the model
(:mod:`pin_kpi_oed.simulation.camera_sim`: every joint placement, the hand-eye transform and the board off nominal,
the intrinsics the cell's ``intrinsics_sigma`` names off nominal by N(0, σ²), ``--effects`` the model lacks) at
seeded configurations around the cell's working ones that see the whole board;
``identify CORNERS.csv --cell CAMERA_CELL --model-out MODEL.json`` fits the robot on the reprojection error
(:mod:`pin_kpi_oed.identification.camera_identify`) and writes the calibrated model, which ``predict --at tcp``,
``compensate`` and ``report`` read like any other. The tracker's options that describe a tracker (``--reflector``,
``--tracker``, ``--noise``, ``--pose6d``, ...) are refused with the option named. A camera's model has no
Gaussian-process discrepancy: ``--discrepancy auto`` (the default) and ``none`` print that decision and the residual
level every TCP σ carries (the parameters' covariance scaled by the fit's reduced χ² when above 1), ``--discrepancy
on`` is refused with the reason.
"""

from __future__ import annotations

import argparse
from typing import Any

import numpy as np

from pin_kpi_oed.errors import InputError

__all__ = ["simulate_camera", "identify_camera_cli", "is_camera_data", "TRACKER_ONLY", "CHI2_POOR"]

#: options of simulate / identify that describe a laser tracker (a camera cell states its own device)
TRACKER_ONLY = ("reflector", "tracker", "noise", "pose6d", "design", "poses", "tol_reflector")


def _refuse_tracker_options(args: argparse.Namespace, command: str, allowed: tuple[str, ...] = ()) -> None:
    for name in (n for n in TRACKER_ONLY if n not in allowed):
        v = getattr(args, name, None)
        if v not in (None, False, [], ""):
            opt = "--" + name.replace("_", "-")
            raise InputError(f"{command} {opt}: a laser tracker's option; the camera cell states its camera, board "
                             "and pixel noise (leave it out)")


def simulate_camera(args: argparse.Namespace, cell: Any, Q_design: np.ndarray | None = None,
                    what: str = "") -> int:
    """``simulate --cell CAMERA_CELL`` or ``simulate --design CAMERA_DESIGN.json``: the corner CSV (and
    ``--test-out``) of a true robot (module docstring).

    Args:
        args: the parsed ``simulate`` options; cell: the camera cell.
        Q_design: the design's poses (m, n) rad, measured instead of ``--n`` seeded views (``--n-test`` held-out
            views are seeded as without a design); what: the poses, for the printed line.

    Returns:
        0.

    Raises:
        InputError: a tracker's option, a bad tolerance or effect, no configuration seeing the board.
    """
    from pin_kpi_oed.cli.util import parse_floats
    from pin_kpi_oed.data.atomic import atomic_write_json
    from pin_kpi_oed.data.corner_measurements import CornerSet, write_corners
    from pin_kpi_oed.effects.spec import effect_spec
    from pin_kpi_oed.simulation.camera_sim import (CameraTolerances, camera_truth, lost_corners_text,
                                                   simulate_detections)

    _refuse_tracker_options(args, "simulate", ("design",) if Q_design is not None else ())
    model = cell.measurement_model()
    tol = CameraTolerances(
        joint_translation_m=float(parse_floats(args.tol_translation or "5e-4", 1, "--tol-translation")[0]),
        joint_rotation_rad=float(parse_floats(args.tol_rotation or "1e-3", 1, "--tol-rotation")[0]),
        intrinsics=_true_intrinsics_sigma(cell.camera.intrinsics_sigma))
    effects = []
    if args.effects:
        from pin_kpi_oed.effects.library import parse_effects_spec
        from pin_kpi_oed.validation.units import check_effect_sizes

        effects = parse_effects_spec(args.effects, model.robot, np.random.default_rng(args.seed + 3))
        check_effect_sizes(effects)
        if any(e.joint_offset(th, cell.q_work[:1], None)[0] is None for e, th in effects):
            raise InputError("--effects: a camera simulation takes joint-angle effects only")
    p_true = camera_truth(model, tol, seed=args.seed)
    if Q_design is None:
        Q_all = model.views(args.n + args.n_test, seed=args.seed + 1, around=cell.q_work)
        what = what or f"seeded poses around the working configurations of cell {cell.name}"
    else:
        args.n = len(Q_design)
        Q_test = model.views(args.n_test, seed=args.seed + 1, around=cell.q_work) if args.n_test else Q_design[:0]
        Q_all = np.vstack([np.asarray(Q_design, float), Q_test])
    uv, lost = simulate_detections(model, Q_all, p_true, effects, seed=args.seed + 2)
    names = list(model.robot.joint_names)
    labels = [f"pose_{i:04d}" for i in range(len(Q_all))]
    write_corners(CornerSet.from_arrays(labels[:args.n], Q_all[:args.n], uv[:args.n], names), args.out)
    if args.n_test:
        write_corners(CornerSet.from_arrays(labels[args.n:], Q_all[args.n:], uv[args.n:], names), args.test_out)
    truth = {"device": "camera", "cell": cell.source, "seed": args.seed,
             "raw_parameters": dict(zip(model.layout.names, p_true.tolist())),
             "effects": [{**effect_spec(e), "theta": np.asarray(th, float).tolist()} for e, th in effects]}
    for path in [p for p in (args.truth, args.truth_json) if p]:
        atomic_write_json(path, truth)
    seen = int(np.isfinite(uv[:args.n, ::2]).sum())
    print(f"simulated {args.n} images of the board ({model.board.n} corners each, {seen} detected) at {what} "
          f"-> {args.out}"
          + (f", {args.n_test} held-out -> {args.test_out}" if args.n_test else "")
          + f" (camera {model.mode}, pixel noise {model.sigma_px:g} px, seed {args.seed}"
          + (f", effects: {', '.join(e.name for e, _ in effects)}" if effects else "") + ")"
          + lost_corners_text({k: int(v[:args.n].sum()) for k, v in lost.items()}, Q_design is not None))
    return 0


def _true_intrinsics_sigma(sigma: dict | None) -> tuple[float, ...]:
    """σ of the simulated truth's intrinsic offsets in the model's order: the cell's prior σ for the intrinsics it
    estimates, 0 for the others (an empty tuple: the intrinsics are known)."""
    from pin_kpi_oed.model.camera import INTRINSIC_NAMES

    return tuple(float(sigma.get(n, 0.0)) for n in INTRINSIC_NAMES) if sigma else ()


#: options of identify a camera fit has no use for (tracker stations, reflector, effects, orientation rows)
_IDENTIFY_TRACKER_ONLY = ("reflector", "reflector_per_station", "effects", "sigma", "sigma_rot", "position_only",
                          "fix", "geometry_prior", "urdf_out", "urdf_frames", "register_rows", "register_data")
#: a reduced χ² above this says the pixel noise or the model is wrong (refused without --accept-poor-fit)
CHI2_POOR = 4.0
#: why a camera's model has no Gaussian-process discrepancy (``identify --discrepancy``)
NO_DISCREPANCY = ("the discrepancy is a Gaussian process on a tracker's TCP position residuals; a camera measures "
                  "board corners' pixels, whose residuals are not the TCP's")


def _discrepancy_line(args: argparse.Namespace, chi2_reduced: float, joint_used: bool = False) -> str:
    """The printed decision of ``--discrepancy auto`` / ``none`` for a camera: no Gaussian process; every TCP σ
    (:func:`~pin_kpi_oed.calibrated.tcp_sigma.tcp_sigma`) scales the parameters' covariance by the fit's reduced χ²
    when above 1 (the residual level, never below the stated pixel noise), or, when the images showed joint-angle
    errors (``joint_used``: :mod:`~pin_kpi_oed.identification.camera_joint_noise`), carries them and the
    parameters' covariance under them."""
    if joint_used:
        level = ("every TCP sigma carries the images' joint-angle errors J_q diag(s^2) J_q^T and the parameters' "
                 "covariance under them")
    elif chi2_reduced > 1:
        level = (f"the parameters' covariance scaled by the fit's reduced chi2 {chi2_reduced:.2f} in every TCP sigma "
                 "(the residual level)")
    else:
        level = f"the fit's reduced chi2 {chi2_reduced:.2f} <= 1: the stated pixel noise kept"
    return f"discrepancy ({getattr(args, 'discrepancy', 'auto')}): none for a camera ({NO_DISCREPANCY}); {level}"


def is_camera_data(paths: list[str]) -> bool:
    """Whether the first measurement file is a camera's: its column header (the first line that is neither blank
    nor a ``#`` comment) has pose, corner, u_px, v_px. A file that cannot be read is left to the tracker's reader,
    which names what is wrong with it."""
    from pin_kpi_oed.data.corner_measurements import is_corner_file

    try:
        with open(paths[0], encoding="utf-8-sig") as f:
            for line in f:
                if line.strip() and not line.lstrip().startswith("#"):
                    return is_corner_file([c.strip().strip('"') for c in line.split(",")])
    except (OSError, UnicodeDecodeError, IndexError):
        return False
    return False


def identify_camera_cli(args: argparse.Namespace) -> int:
    """``identify --data CORNERS.csv --cell CAMERA_CELL``: the camera fit, its TCP σ, the model file (module
    docstring); ``--validate`` a held-out corner file's reprojection RMS.

    Raises:
        InputError: no camera cell, several data files, a tracker's option, ``--discrepancy on``, a bad file; a poor
            fit (reduced χ² above :data:`CHI2_POOR`) without ``--accept-poor-fit``.
    """
    from pin_kpi_oed.calibrated.tcp_sigma import tcp_sigma
    from pin_kpi_oed.cell.cell import load_cell
    from pin_kpi_oed.data.atomic import atomic_write_json
    from pin_kpi_oed.data.corner_measurements import read_corners
    from pin_kpi_oed.identification.camera_identify import identify_camera
    from pin_kpi_oed.validation.paths import check_outputs

    for name in _IDENTIFY_TRACKER_ONLY:
        if getattr(args, name, None) not in (None, False, [], ""):
            raise InputError(f"identify --{name.replace('_', '-')}: not for camera measurements (a tracker's "
                             "option); leave it out")
    if len(args.data) != 1:
        raise InputError(f"identify: camera measurements come in one file (one camera set-up), got {len(args.data)}")
    if getattr(args, "discrepancy", "auto") == "on":
        raise InputError(f"identify --discrepancy on: not for camera measurements ({NO_DISCREPANCY}); leave it "
                         "out (auto) or give none")
    if not args.cell:
        raise InputError(f"identify --data {args.data[0]}: camera measurements need --cell with the camera and its "
                         "board (intrinsics, mount, board size)")
    check_outputs([("--json", args.json), ("--model-out", args.model_out)],
                  [("--data", args.data[0]), ("--cell", args.cell), ("--validate", args.validate)])
    cell = load_cell(args.cell)
    if cell.camera is None:
        raise InputError(f"--cell {args.cell}: has no camera, but {args.data[0]} holds camera measurements")
    model = cell.camera.model(cell.robot, cell.W_T_base, cell.tcp_m)
    loss = "linear" if args.loss in (None, "auto") else args.loss
    res = identify_camera(model, read_corners(args.data[0]), source=args.data[0], seed=args.seed, loss=loss,
                          device=cell.camera.to_dict())
    cm = res.calibrated_model(cell.q_work if len(cell.q_work) else None, f"cell {cell.source or cell.name}")
    _stamp(cm, args, len(read_corners(args.validate)) if args.validate else 0)
    lines = [res.summary(), _discrepancy_line(args, res.fit.chi2_reduced, res.joint is not None and res.joint.used)]
    if len(cell.q_work):
        ts = tcp_sigma(cm, cell.q_work)
        lines.append(f"predicted TCP std at the {len(cell.q_work)} working configuration(s) (in the "
                     f"{model.frame_group} frame): RMS {ts.rms_m * 1e3:.4f} mm, of which held at nominal "
                     f"{np.sqrt(np.mean(ts.held_sigma_m ** 2)) * 1e3:.4f} mm")
        if ts.held_names and ts.held_share > 0.1:
            mounted = model.target_groups[0]
            top = np.argsort(-ts.held_contrib_m)[:2]
            held = ", ".join(f"{ts.held_names[i]} ({ts.held_contrib_m[i] * 1e3:.3g} mm)" for i in top)
            lines.append(f"mostly {held} held at its tolerance: the fitted {mounted} pose on the tool absorbs it, no "
                         f"image of the board determines it; the TCP's position relative to the {mounted} (a tool "
                         "calibration) removes it")
    out = {"device": "camera", "fit": res.fit.to_dict(), "identified": res.stored_names(), "data": args.data[0]}
    if args.validate:
        rms = _heldout_rms(res, args.validate)
        out["validation_rms_px"] = rms
        lines.append(f"held-out {args.validate}: reprojection RMS {rms:.3f} px (training {res.fit.rms_px:.3f} px)")
    poor = res.fit.chi2_reduced > CHI2_POOR
    if poor:
        lines.append(f"poor fit: reduced chi2 {res.fit.chi2_reduced:.2f} > {CHI2_POOR:g} (the pixel noise "
                     f"sigma_px {model.sigma_px:g} px is too small, or the model misses an effect)")
    for line in lines if not args.quiet else [x for x in lines if x.startswith(("held-out", "poor fit"))]:
        print(line)
    if poor and not args.accept_poor_fit:
        raise InputError("identify: poor fit, no model written (see above); --accept-poor-fit writes it anyway")
    if args.json:
        atomic_write_json(args.json, out)
    if args.model_out:
        cm.save(args.model_out)
        if not args.quiet:
            print(f"wrote {args.model_out}")
    return 0


def _stamp(cm: Any, args: argparse.Namespace, n_validate: int) -> None:
    """The provenance of this run in the model's last history step: the command line, the corner files (path, rows,
    SHA-256; what ``report`` checks its training file against), the software versions."""
    from pin_kpi_oed.data.provenance import command_line, file_record, software_versions

    step = cm.history[-1]
    step["command"] = command_line(getattr(args, "argv", None) or [])
    step["train_files"] = [file_record(args.data[0], int(cm.fit["n_rows"]) // 2)]
    step["validate_files"] = [file_record(args.validate, n_validate)] if args.validate else []
    step["software"] = software_versions()


def _heldout_rms(res: Any, path: str) -> float:
    """The reprojection RMS (px) of a held-out corner file with the fitted model."""
    from pin_kpi_oed.data.corner_measurements import read_corners

    cs = read_corners(path)
    _, Q, uv = cs.arrays(res.model.board.n, path)
    Q = Q[:, [cs.joint_names.index(n) for n in res.model.robot.joint_names]]
    r = res.model.predict(res.fit.p, res.model.robot.check_q(Q, path)) - uv
    return float(np.sqrt(np.nanmean(r ** 2)))
