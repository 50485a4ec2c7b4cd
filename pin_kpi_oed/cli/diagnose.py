"""CLI subcommand ``diagnose`` of ``pin-kpi-oed``: the sim-to-real gap diagnosis.

``register(subparsers)`` adds the subcommand; its handler :func:`run` returns the exit code
(0 when the report was produced). Errors are :class:`~pin_kpi_oed.errors.PinKpiOedError`
with one-line messages (``cli.py`` prints them and exits with code 2). The JSON report and
the figures are written atomically, after the whole diagnosis has been computed.

Examples::

    pin-kpi-oed diagnose --robot ur10 --train train.csv --validate test.csv --reflector 0.05,0.02,0.1 \\
        --json report.json --figures figs/
    pin-kpi-oed diagnose --robot ur10 --train all.csv --kfold 5 --sigma 1e-5 --json report.json
    pin-kpi-oed diagnose --robot ur10 --train C.csv --validate D.csv --register-rows 60 --seed 0 \\
        --reflector 0,0,0.109 --sigma 1e-4                 # another session: set-up re-registered first
"""

from __future__ import annotations

import argparse
import math
import os
from typing import Any

import numpy as np

from pin_kpi_oed.cli.flags import in_flags, in_flags_all
from pin_kpi_oed.cli.identify import add_discrepancy_arg, add_register_args
from pin_kpi_oed.cli.util import add_table_options, table_options
from pin_kpi_oed.cli.util import parse_floats
from pin_kpi_oed.errors import InputError
from pin_kpi_oed.cli.tool import add_cell_arg, command_tool
from pin_kpi_oed.model.robot import ROBOT_HELP, TOOL_HELP

__all__ = ["register", "run"]




def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``diagnose`` subcommand."""
    d = subparsers.add_parser(
        "diagnose", help="sim-to-real gap diagnosis: noise or gap, where, which unmodelled effect, how far it shrinks",
        description="Fit the geometric model on training data, test held-out residuals against the noise (chi2), "
                    "summarise where they lie, try every unmodelled effect (joint_compliance, gear_harmonic, "
                    "backlash, thermal_expansion, joint_scale) alone and by forward selection, and report how far "
                    "each shrinks the held-out error. A tracker range-scale error cannot be seen in such data "
                    "(it equals a uniform scaling of the robot); the report says so.")
    d.add_argument("--robot", default=None, help=ROBOT_HELP + "; default: the robot of --cell or of the data's header")
    d.add_argument("--tool", default=None, help=TOOL_HELP)
    add_cell_arg(d)
    d.add_argument("--kinematics", default=None,
                   help="UR kinematics file (ur_description default_kinematics.yaml layout, e.g. from ur_calibration) "
                        "as the nominal model of a UR --robot")
    d.add_argument("--train", required=True, action="append",
                   help="training measurement CSV (joint columns, x, y, z in m, ...); repeat for several files "
                        "(each its own station unless it has a 'station' column)")
    g = d.add_mutually_exclusive_group(required=True)
    g.add_argument("--validate", default=None, help="held-out measurement CSV, disjoint from --train")
    g.add_argument("--kfold", type=int, default=None, help="K-fold cross-validation on --train alone (K >= 2)")
    add_register_args(d)
    d.add_argument("--reflector", default=None,
                   help="nominal reflector offset in the tool frame x,y,z (m); default: the reflector of --cell or of "
                        "the data's header, else estimated from --train")
    d.add_argument("--sigma", default=None,
                   help="tracker noise sigma per axis (m), 1 or 3 values; overrides the files' sigma columns "
                        "(needed when the files have none)")
    d.add_argument("--effects", default=None,
                   help="candidate effects, comma-separated, or none (geometry only: nothing to extrapolate in another "
                        "session's joint ranges) (default: joint_compliance, gear_harmonic, backlash, "
                        "thermal_expansion, joint_scale, transmission_error and link_bending: the last two's terms "
                        "are chosen by sparse selection on held-out error); also drift (linear in time/row order)")
    d.add_argument("--harmonics", type=int, default=40,
                   help="highest order (cycles per revolution) of the transmission_error candidate (default 40)")
    d.add_argument("--term-prior", type=float, default=None, metavar="RAD",
                   help="Gaussian prior sigma (rad) on every selected transmission_error / link_bending term, e.g. "
                        "1e-4: keeps terms fitted in one region of joint space from extrapolating (default none)")
    d.add_argument("--alpha", type=float, default=0.01, help="significance level of the tests (default 0.01)")
    d.add_argument("--t-ref", type=float, default=None,
                   help="reference temperature of thermal_expansion (degC; default the training mean)")
    d.add_argument("--seed", type=int, default=0, help="seed of the K-fold split and the registration rows (default 0)")
    d.add_argument("--json", default=None, help="write the report (JSON, SI units) here")
    d.add_argument("--figures", default=None, help="write PNG figures of the residuals into this folder")
    d.add_argument("--model-out", default=None,
                   help="write the model the diagnosis reports (geometry + the selected effects, fitted on all "
                        "training rows, with the discrepancy of --discrepancy) as a model file for register, predict, "
                        "compensate and design --model")
    add_discrepancy_arg(d)
    d.add_argument("--quiet", action="store_true", help="print only the one-line verdict")
    add_table_options(d)
    d.set_defaults(func=run)


def _checked_effects(args: argparse.Namespace) -> list[str] | None:
    """Check the output paths and numeric options; the ``--effects`` names (None: all candidates)."""
    from pathlib import Path

    from pin_kpi_oed.effects.library import ALL_EFFECT_NAMES

    if args.json:
        t = Path(args.json)
        parent = t.parent if str(t.parent) else Path(".")
        if not parent.is_dir():
            raise InputError(f"cannot write '{t}': directory '{parent}' does not exist")
        if t.is_dir():
            raise InputError(f"cannot write '{t}': it is a directory")
    if args.figures and Path(args.figures).exists() and not Path(args.figures).is_dir():
        raise InputError(f"--figures {args.figures}: exists and is not a folder")
    if args.harmonics < 1:
        raise InputError(f"--harmonics must be >= 1, got {args.harmonics}")
    if args.term_prior is not None and not (math.isfinite(args.term_prior) and 0 < args.term_prior < 0.1):
        raise InputError(f"--term-prior must be a positive angle in rad below 0.1 (e.g. 1e-4), got {args.term_prior}")
    if not (math.isfinite(args.alpha) and 0 < args.alpha < 1):
        raise InputError(f"--alpha must be in (0, 1), got {args.alpha}")
    from pin_kpi_oed.diagnosis.diagnose_options import DEFAULT_CANDIDATES

    effects = list(DEFAULT_CANDIDATES)
    if args.effects and args.effects.strip().lower() == "none":
        return []  # geometry only: what transfers to configurations the training did not measure
    if args.effects:
        effects = [e.strip() for e in args.effects.split(",") if e.strip()]
        unknown = [e for e in effects if e not in ALL_EFFECT_NAMES]
        if unknown:
            raise InputError(f"--effects: unknown effect(s) {', '.join(unknown)} "
                             f"(known: {', '.join(ALL_EFFECT_NAMES)}; "
                             "a tracker range-scale error is not among them: it cannot be observed)")
    return effects


def _noise(args: argparse.Namespace, train: Any, val: Any, reg: Any) -> tuple[Any, str]:
    """(noise model, weighting) from ``--sigma`` or, without it, the files' sigma columns."""
    from pin_kpi_oed.model.noise import NoiseModel

    if args.sigma is not None:
        s = parse_floats(args.sigma, (1, 3), "--sigma")
        if np.any(s <= 0) or np.median(s) > 0.1:
            raise InputError(f"--sigma {args.sigma}: must be positive, in m (e.g. 1e-5 for 10 µm)")
        return NoiseModel(sigma_xyz_m=tuple(s)), "noise"
    missing = [f for f, ms in ((", ".join(args.train), train), (args.validate, val), (args.register_data, reg))
               if ms is not None and ms.sigma_m is None]
    if missing:
        raise InputError(f"{missing[0]}: no sigma columns, so the noise is unknown: give --sigma S (m), the "
                         "tracker's standard deviation per axis (e.g. 1e-5)")
    return NoiseModel(), "data"


def _estimated_reflector(args: argparse.Namespace, robot: Any, noise: Any, weights: str, train: Any,
                         reflector: np.ndarray) -> np.ndarray:
    """Nominal reflector offset (m) estimated from ``--train`` (a reflector assumed at 0,0,0 hides
    parameters and fakes a gap)."""
    from pin_kpi_oed.identification.identify import IdentifyOptions
    from pin_kpi_oed.identification.reflector_start import estimate_reflector
    from pin_kpi_oed.model.tracker import TrackerModel

    reflector = estimate_reflector(TrackerModel(robot, noise=noise, reflector_m=reflector), train,
                                   IdentifyOptions(weights=weights, scale_covariance=False))
    if not args.quiet:
        print(f"nominal reflector offset estimated from --train: {np.round(reflector * 1e3, 1).tolist()} mm "
              f"(give --reflector x,y,z in m to set it)")
    return reflector


def _write_and_print(args: argparse.Namespace, rep: Any) -> None:
    """Write the figures and the JSON report, print the summary (or the one-line verdict with --quiet)."""
    from pin_kpi_oed.data.atomic import atomic_write_json
    from pin_kpi_oed.viz.diagnosis_plots import diagnosis_figures

    if args.figures:
        rep.figures = diagnosis_figures(rep, args.figures)
    if args.json:
        out = rep.to_dict()
        out["notes"], out["mismatch"] = in_flags_all(out["notes"]), in_flags_all(out["mismatch"])  # options' words
        out["train"] = list(args.train)
        out["validate"] = args.validate
        atomic_write_json(args.json, out)
    if args.quiet:
        print(f"gap_detected={rep.gap_detected} dominant_effect={rep.dominant_effect} "
              f"heldout_rms_before={rep.heldout_before['rms_m'] * 1e3:.4f}mm "
              f"after={rep.heldout_after['rms_m'] * 1e3:.4f}mm")
    else:
        print(in_flags(rep.summary()))
        if args.json:
            print(f"wrote {args.json}")


def run(args: argparse.Namespace) -> int:
    """Handler of ``pin-kpi-oed diagnose``; returns 0 when the report was produced."""
    from pin_kpi_oed.cli.identify import read_data_files, read_validation
    from pin_kpi_oed.diagnosis.diagnose import diagnose
    from pin_kpi_oed.model.tracker import TrackerModel

    effects = _checked_effects(args)
    if args.model_out:
        from pin_kpi_oed.data.atomic import check_writable

        check_writable(args.model_out)
        if any(os.path.abspath(args.model_out) == os.path.abspath(f) for f in args.train + [args.validate or ""]):
            raise InputError(f"--model-out {args.model_out}: is an input of this command; name another file")
    ct = command_tool(args, args.train, other_paths=[p for p in (args.validate, args.register_data) if p],
                      reflector_option=args.reflector)
    robot = ct.robot
    if not args.quiet:
        print(ct.line())
    reach = robot.reach()
    train = read_data_files(args.train, robot, "--train", opts=table_options(args, robot))
    train.tool = ct.tool  # the agreed tool travels into --model-out
    val, reg = read_validation(args, robot)
    reflector = parse_floats(args.reflector, (3,), "--reflector") if args.reflector is not None else (
        ct.tool.reflector_m if ct.tool.reflector_m is not None else np.zeros(3))
    if np.linalg.norm(reflector) > reach:
        raise InputError(f"--reflector {args.reflector}: {np.linalg.norm(reflector):.4g} m from the tool frame, more "
                         f"than the robot's reach ({reach:.3g} m): give it in m")
    noise, weights = _noise(args, train, val, reg)
    if args.reflector is None and ct.tool.reflector_m is None:
        reflector = _estimated_reflector(args, robot, noise, weights, train, reflector)
    model = TrackerModel(robot, reflector_m=reflector, noise=noise,
                         tcp_m=ct.tool.tcp_m if ct.tool.tcp_m is not None else np.zeros(3))
    rep = diagnose(model, train, val, kfold=args.kfold, effects=effects, weights=weights, alpha=args.alpha,
                   seed=args.seed, t_ref_c=args.t_ref, register_rows=args.register_rows, register_data=reg,
                   harmonics=args.harmonics, transfer_prior_rad=args.term_prior,
                   show_progress=False if args.quiet else None)
    cm = _diagnosed_model(args, rep, train)
    model_dict = None if cm is None else cm.to_dict()
    if model_dict is not None:
        from pin_kpi_oed.cli.provenance import stamp_model

        stamp_model(model_dict, args, robot, train=args.train, validate=args.validate, reflector_nominal_m=reflector,
                    extra={"step": "diagnose", "diagnosis": {"status": rep.status, "message": rep.message,
                                                            "summary": in_flags(rep.summary())}})
    if cm is not None and val is not None and rep.transfer:
        rep.transfer["model_sigma"] = _model_sigma(args, rep, cm, val, reg)
    _write_and_print(args, rep)
    if model_dict is not None:
        from pin_kpi_oed.data.atomic import atomic_write_json

        atomic_write_json(args.model_out, model_dict)
        disc = rep.model_fit.discrepancy.decision if rep.model_fit.discrepancy else "no discrepancy"
        print(f"wrote {args.model_out} (geometry" + "".join(f" + {e}" for e in rep.selected_effects) + f"; {disc})")
        if rep.selected_effects and not args.quiet:
            print(f"note: {', '.join(rep.selected_effects)} {'is' if len(rep.selected_effects) == 1 else 'are'} "
                  "fitted on the joint ranges of these rows; a session in other ranges is refused by register with "
                  "that cause: there a geometry-only model (--effects none) or a prior on the terms (--term-prior "
                  "1e-4) transfers")
    return 0


def _diagnosed_model(args: argparse.Namespace, rep: Any, train: Any) -> Any:
    """The model file content of ``--model-out``: the report's full-data fit with its discrepancy."""
    from pin_kpi_oed.identification.discrepancy_fit import discrepancy_options, result_discrepancy

    if not args.model_out:
        return None
    fit = rep.model_fit
    if not args.quiet and args.discrepancy != "none":
        print(f"fitting the model discrepancy ({args.discrepancy}) of the reported model on {len(train)} rows ...",
              flush=True)
    fit.discrepancy = result_discrepancy(fit, train, discrepancy_options(args.discrepancy, args.seed))
    return fit.calibrated_model()


def _model_sigma(args: argparse.Namespace, rep: Any, cm: Any, val: Any, reg: Any) -> dict:
    """The written model scored on the validation rows with its σ (the σ ``predict`` writes): re-registered as the
    diagnosis did in transfer mode (same rows, same seed), as is otherwise."""
    from pin_kpi_oed.identification.identify import validate
    from pin_kpi_oed.upkeep.transfer import validate_transfer

    if args.register_rows is not None or reg is not None:
        st = validate_transfer(cm, val, register_rows=None if reg is not None else args.register_rows,
                               register_data=reg, seed=args.seed)
    else:
        st = validate(cm, val)
    label = "geometry" + "".join(f" + {e}" for e in rep.selected_effects) + (
        " + discrepancy" if cm.discrepancy is not None and cm.discrepancy.kind != "white" else
        " + white discrepancy" if cm.discrepancy is not None else "")
    return {"model": label, "n": int(st["n"]), "mean_m": float(st["mean_m"]), "rms_m": float(st["rms_m"]),
            "sigma_mean_m": float(st["sigma_mean_m"]), "z_rms": float(st["z_rms"]),
            "inside_95": float(st["inside_95"]), "extrapolation_share": float(st["extrapolation_share"]),
            "sigma_scale": float(st.get("sigma_scale", 1.0))}

