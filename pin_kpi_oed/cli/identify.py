"""CLI subcommands ``identify`` and ``import-ipa`` of ``pin-kpi-oed`` (``simulate``: :mod:`pin_kpi_oed.cli.simulate`).

``register(subparsers)`` adds the three subcommands; each sets ``func`` to its handler
``run_*(args) -> int`` (0 on success). Errors are :class:`~pin_kpi_oed.errors.PinKpiOedError`
with one-line messages (``cli.py`` prints them and exits with code 2). Every output file is
written atomically, and only after everything it depends on has been computed and checked.

Examples::

    pin-kpi-oed simulate --robot kr15 --n 80 --n-test 200 --seed 1 --out train.csv --test-out test.csv \\
        --reflector 0.03,0.02,0.08 --noise 1e-5 --truth-json truth.json
    pin-kpi-oed identify --robot kr15 --data train.csv --validate test.csv --reflector 0.03,0.02,0.08 \\
        --json result.json --urdf-out calibrated.urdf --model-out model.json
    pin-kpi-oed identify --robot ur10 --data B.csv --data C.csv --data D.csv --reflector 0,0,0.109 --sigma 1e-4 \\
        --model-out bcd.json                                  # three stations, one robot
    pin-kpi-oed identify --robot ur10 --data C.csv --validate D.csv --register-rows 60 --seed 0 --reflector 0,0,0.109
    pin-kpi-oed identify --cell cell.yaml --data train.csv --model-out model.json   # tool frame, reflector, TCP
    pin-kpi-oed import-ipa ../shared/data/ipa_ur10/Series_C --position-only --split 0.5 --seed 0 \\
        --train c_train.csv --test c_test.csv
"""

from __future__ import annotations

import argparse
import math
import sys
from dataclasses import replace
from typing import Any

import numpy as np

from pin_kpi_oed.cli.util import add_table_options, table_options
from pin_kpi_oed.cli.util import parse_floats
from pin_kpi_oed.cli.flags import in_flags, in_flags_all
from pin_kpi_oed.errors import InputError
from pin_kpi_oed.cli.tool import add_cell_arg, command_tool
from pin_kpi_oed.model.robot import ROBOT_HELP, TOOL_HELP

__all__ = ["register", "run_identify", "run_import_ipa"]




def _positive(text: str, what: str) -> float:
    try:
        v = float(text)
    except ValueError:
        raise InputError(f"{what}: expected a number, got '{text}'") from None
    if not (math.isfinite(v) and v > 0):
        raise InputError(f"{what}: must be positive and finite, got {text}")
    return v


def _check_outputs(*paths: str | None) -> None:
    """Fail before anything is written if an output's folder is missing or the path is a folder; claim the outputs
    (a write finding one changed by another process meanwhile is refused)."""
    from pin_kpi_oed.data.atomic import check_writable, claim_output

    for p in paths:
        if p:
            check_writable(p)
            claim_output(p)


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``simulate``, ``identify`` and ``import-ipa`` subcommands."""
    from pin_kpi_oed.cli.simulate import register_simulate

    register_simulate(subparsers)
    _register_identify(subparsers)
    _register_import_ipa(subparsers)


def _register_identify(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``identify`` subcommand and its options."""
    i = subparsers.add_parser("identify", help="identify geometric parameters from measurements, validate, export URDF",
                              description="Weighted nonlinear least squares (Levenberg-Marquardt, analytic Jacobian) "
                                          "over the identifiable parameters; tracker pose guessed by point-set "
                                          "registration, one per station (file or 'station' column), the robot "
                                          "shared. With --validate: position errors on held-out data before "
                                          "(nominal robot + fitted tracker pose and reflector) and after calibration; "
                                          "with --register-rows/--register-data the set-up is first re-registered "
                                          "on some rows of another session and only the rest are scored.")
    i.add_argument("--robot", default=None, help=ROBOT_HELP + "; default: the robot of --cell or of the data's header")
    i.add_argument("--tool", default=None, help=TOOL_HELP)
    add_cell_arg(i)
    i.add_argument("--kinematics", default=None,
                   help="UR kinematics file (ur_description default_kinematics.yaml layout, e.g. from ur_calibration) "
                        "as the nominal model of a UR --robot")
    i.add_argument("--data", required=True, action="append",
                   help="measurement CSV (joint columns, x, y, z in m, ...); repeat for several files: each file is "
                        "its own station (tracker placement) unless it has a 'station' column")
    i.add_argument("--reflector-per-station", action="store_true",
                   help="every station has its own reflector offset (default: one reflector for all stations)")
    _add_validation_args(i, "held-out measurement CSV (nothing is re-fitted on it unless --register-rows/"
                            "--register-data re-register the set-up)")
    i.add_argument("--reflector", default=None,
                   help="nominal reflector offset in the tool frame x,y,z (m); default: the reflector of --cell or of "
                        "the data's header, else estimated from the data (set-up fit with the nominal geometry, "
                        "rounded to 1 mm)")
    i.add_argument("--effects", default=None,
                   help="effects identified with the geometry, comma-separated names of the effect library (e.g. "
                        "joint_compliance,gear_harmonic); stored in --model-out")
    i.add_argument("--json", default=None, help="write the result (parameters, covariance, tracker pose, ...) here")
    i.add_argument("--urdf-out", default=None, help="write the calibrated URDF here (geometry only)")
    i.add_argument("--urdf-frames", action="store_true", help="add the tracker (cell) frame and reflector/TCP of "
                   "every station to the calibrated URDF as fixed frames (tracker_<station>, reflector_<station>)")
    i.add_argument("--model-out", default=None,
                   help="write the calibrated model file here (geometry, effects, set-up per station, noise; "
                        "for pin-kpi-oed register / predict)")
    i.add_argument("--sigma", default=None,
                   help="tracker noise sigma (m), 1 or 3 values; overrides the file's sigma columns. Without it the "
                        "noise level is the data's sigma columns, else the noise of --cell (its 'noise' field, as "
                        "the Python identify with cell.tracker_model()), else unknown: the weights are uniform and "
                        "the covariance is scaled by the reduced chi2")
    i.add_argument("--sigma-rot", default=None,
                   help="orientation noise of 6-D data (rad; default: the noise of --cell, else 1e-4)")
    i.add_argument("--position-only", action="store_true", help="ignore rx, ry, rz columns")
    i.add_argument("--loss", default=None, choices=["auto", "linear", "soft_l1", "huber", "cauchy"],
                   help="loss: linear (Levenberg-Marquardt) or robust (outliers flagged); default auto: linear, "
                        "switched to soft_l1 when outliers far beyond the noise are found, or any outlier with the "
                        "noise level unknown (as the Python API's identify)")
    i.add_argument("--accept-poor-fit", action="store_true",
                   help="write the calibrated URDF/model and exit 0 even when the fit-quality gate finds the fit "
                        "implausible (the verdict stays in the summary and the JSON)")
    i.add_argument("--fix", default=None, help="parameters held at nominal, comma-separated names or globs "
                                               "(e.g. 'reflector.*' or 'tracker.*')")
    i.add_argument("--geometry-prior", dest="geometry_prior", default=None, metavar="TRANS_M,ROT_RAD",
                   help="a Gaussian prior on every joint placement around the nominal model, sigma of its translation "
                        "(m) and rotation (rad), e.g. 5e-3,1e-2 (ten times manufacturing tolerances): changes nothing "
                        "the data determine and keeps a fit of few poses from landing on another geometric solution")
    i.add_argument("--max-nfev", type=int, default=None, help="maximum number of residual evaluations")
    add_discrepancy_arg(i)
    i.add_argument("--quiet", action="store_true", help="print only the validation lines")
    add_table_options(i)
    i.set_defaults(func=run_identify)


def add_discrepancy_arg(p: argparse.ArgumentParser) -> None:
    """``--discrepancy auto|on|none`` (identify, diagnose)."""
    p.add_argument("--discrepancy", default="auto", choices=["auto", "on", "none"],
                   help="model discrepancy: a Gaussian process over the joint angles fitted to the residuals of the "
                        "parametric fit, so that every prediction carries an honest sigma. auto (default, as the "
                        "Python identify): fitted with at least 60 distinct poses when it lowers the 5-fold held-out "
                        "error (repeated poses in one fold), else the residual level as an independent error per row, "
                        "corrected for the fitted parameters and never below the stated noise; on: always the "
                        "Gaussian process; none: the paper's noise-only model. Every sigma adds the parameters' "
                        "covariance")


def _register_import_ipa(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``import-ipa`` subcommand and its options."""
    p = subparsers.add_parser("import-ipa", help="convert IPA UR10 laser-tracker files to the measurement CSV format",
                              description="Import an IPA UR10 series (';', decimal commas, mm, degrees) into the SI "
                                          "measurement CSV format, optionally split at random into train/test.")
    p.add_argument("src", help="IPA series folder (e.g. Series_C) or its measurements_*.csv")
    p.add_argument("--out", default=None, help="CSV of all measurements")
    p.add_argument("--split", type=float, default=None,
                   help="share of the training part, e.g. 0.5, or (a whole number >= 1) its number of rows, e.g. 60: "
                        "the same seeded rows as --register-rows 60 --seed S of identify/diagnose")
    p.add_argument("--seed", type=int, default=0, help="seed of the random split (default 0)")
    p.add_argument("--train", default=None, help="training CSV (with --split)")
    p.add_argument("--test", default=None, help="held-out CSV (with --split)")
    p.add_argument("--position-only", action="store_true", help="drop the orientation (rx, ry, rz)")
    p.add_argument("--keep-sigma", action="store_true",
                   help="keep the std columns as sigma (they are the scatter of the tracker's averaged reading, "
                        "not its accuracy: by default they are dropped and the fit weights uniformly)")
    p.set_defaults(func=run_import_ipa)


def add_register_args(p: argparse.ArgumentParser) -> None:
    """``--register-rows`` / ``--register-data`` (transfer validation; shared by identify and diagnose)."""
    g = p.add_mutually_exclusive_group()
    g.add_argument("--register-rows", type=int, default=None,
                   help="--validate is from another session: re-fit the set-up (tracker pose, reflector; robot held) "
                        "on N seeded random rows of it (--seed) and score only the others")
    g.add_argument("--register-data", default=None,
                   help="--validate is from another session: re-fit the set-up on this CSV's rows (robot held) and "
                        "score every row of --validate")


def _add_validation_args(p: argparse.ArgumentParser, validate_help: str) -> None:
    """``--validate``, ``--register-rows``, ``--register-data``, ``--seed``."""
    p.add_argument("--validate", default=None, help=validate_help)
    add_register_args(p)
    p.add_argument("--seed", type=int, default=0, help="seed of every random choice (default 0)")


def read_data_files(paths: list[str], robot: Any, what: str = "--data", opts: dict | None = None) -> Any:
    """Read one or several measurement CSVs; several are joined, each its own station unless it has a
    'station' column (:func:`pin_kpi_oed.data.measurements.concat_measurements`)."""
    from pin_kpi_oed.data.measurements import concat_measurements, read_measurements

    reach = robot.reach()
    sets = [read_measurements(p, joint_names=robot.joint_names, reach_m=reach, **(opts or {})) for p in paths]
    return sets[0] if len(sets) == 1 else concat_measurements(sets)


def read_validation(args: argparse.Namespace, robot: Any) -> tuple[Any, Any]:
    """(validation set or None, registration set or None) of ``--validate`` / ``--register-*``.

    Raises:
        InputError: --register-rows/--register-data without --validate.
    """
    from pin_kpi_oed.data.measurements import read_measurements

    if (args.register_rows is not None or args.register_data) and not args.validate:
        raise InputError("--register-rows/--register-data re-register the set-up on rows of another session: they "
                         "need --validate FILE")
    reach, kw = robot.reach(), table_options(args, robot)
    test = (read_measurements(args.validate, joint_names=robot.joint_names, reach_m=reach, **kw)
            if args.validate else None)
    reg = read_measurements(args.register_data, joint_names=robot.joint_names, reach_m=reach, **kw) \
        if args.register_data else None
    return test, reg


def _effects(spec: str | None, robot: Any, train: Any) -> list:
    if not spec:
        return []
    from pin_kpi_oed.effects.library import EFFECT_NAMES, candidate_effects

    names = [e.strip() for e in spec.split(",") if e.strip()]
    unknown = [e for e in names if e not in EFFECT_NAMES]
    if unknown:
        raise InputError(f"--effects: unknown effect(s) {', '.join(unknown)} (known: {', '.join(EFFECT_NAMES)})")
    t_ref = float(np.mean(train.temperature_c)) if train.temperature_c is not None else 20.0
    return candidate_effects(robot, names, t_ref_c=t_ref)


def _validation(model: Any, train: Any, opts: Any, result: Any, test: Any, reg: Any,
                args: argparse.Namespace) -> tuple[dict, list[str]]:
    """Held-out errors before (nominal robot + fitted set-up) and after calibration, on the validation file."""
    from pin_kpi_oed.identification.identify import format_validation, identify, validate
    from pin_kpi_oed.upkeep.transfer import validate_transfer

    before = identify(model, train, opts, setup_only=True, discrepancy="none", on_poor_fit="ignore")
    if args.register_rows is None and reg is None:
        vb, va = validate(before, test), validate(result, test)
        head = []
        out = {}
    else:
        kw = dict(register_rows=args.register_rows, register_data=reg, seed=args.seed)
        vb = validate_transfer(before.calibrated_model(), test, **kw)
        va = validate_transfer(result.calibrated_model(), test, **kw)
        r = va["registration"]
        how = (f"{r['n']} seeded random rows (seed {args.seed}) of {args.validate}" if reg is None
               else f"the {r['n']} rows of {args.register_data}")
        head = [f"transfer to {args.validate}: set-up (tracker pose, reflector) re-registered on {how} with the robot "
                f"held; scored on the other {va['n']} rows (row numbers in the JSON: validation.registration.rows)"]
        head += va["registration"]["notes"]
        out = {"registration": r, "scored_rows": va["scored_rows"]}
    from pin_kpi_oed.calibrated.coverage import coverage_summary

    out["coverage"] = coverage_summary(model.robot, train, test)
    out.update({"before": vb, "after": va, "before_means": "nominal robot + fitted tracker pose and reflector",
                "after_means": "calibration (geometry" + (" + effects)" if result.effects else ")")})
    lines = head + [format_validation(vb, "before (nominal geometry + fitted tracker pose and reflector)"),
                    format_validation(va, "after  (calibration)                                        ")]
    return out, lines


def _noise_and_weights(args: argparse.Namespace, train: Any, cell: Any = None) -> tuple[Any, str, bool, str]:
    """(noise model, weighting, scale covariance by reduced chi2, where the noise level comes from).

    The noise level, in this order: ``--sigma``, the data's sigma columns, the noise of ``--cell`` (when the cell
    file states one), else unknown (uniform weights, the covariance scaled by the reduced chi2). ``--sigma-rot``
    (default: the cell's, else 1e-4 rad) is the orientation noise of 6-D data.
    """
    from pin_kpi_oed.model.noise import NoiseModel

    cell_noise = cell.noise if cell is not None and getattr(cell, "noise_stated", False) else None
    default_rot = cell_noise.sigma_rot_rad if cell_noise is not None else 1e-4
    sigma_rot = default_rot if args.sigma_rot is None else _positive(args.sigma_rot, "--sigma-rot")
    if args.sigma is not None:
        noise = NoiseModel(sigma_xyz_m=tuple(parse_floats(args.sigma, (1, 3), "--sigma")), sigma_rot_rad=sigma_rot)
        return noise, "noise", False, "--sigma"
    if cell_noise is not None:
        noise = NoiseModel(sigma_xyz_m=tuple(cell_noise.sigma_xyz_m), range_a_m=cell_noise.range_a_m,
                           range_b=cell_noise.range_b, sigma_rot_rad=sigma_rot)
        if train.sigma_m is not None:
            return noise, "auto", False, "the data's sigma columns"
        return noise, "noise", False, f"the noise of --cell {args.cell}"
    noise = NoiseModel(sigma_xyz_m=(1e-5,) * 3, sigma_rot_rad=sigma_rot)
    if train.sigma_m is not None:
        return noise, "auto", False, "the data's sigma columns"
    why = " (the cell file states no noise)" if cell is not None else ""
    return noise, "auto", True, f"unknown{why}: uniform weights, the covariance scaled by the reduced chi2"


def _nominal_reflector(args: argparse.Namespace, robot: Any, noise: Any, train: Any,
                       opts: Any, tool: Any = None) -> tuple[np.ndarray, bool]:
    """(nominal reflector offset in the tool frame (m), whether it was estimated from the data): ``--reflector``,
    else the reflector of the cell / the data's header (``tool``), else estimated."""
    from pin_kpi_oed.identification.reflector_start import estimate_reflector
    from pin_kpi_oed.model.tracker import TrackerModel

    reach = robot.reach()
    if args.reflector is None and tool is not None and tool.reflector_m is not None:
        return tool.reflector_m.copy(), False
    estimated = args.reflector is None
    if estimated:
        reflector = estimate_reflector(TrackerModel(robot, noise=noise, reflector_m=np.zeros(3)), train, opts)
        if not args.quiet:
            print(f"nominal reflector offset estimated from the data: {np.round(reflector * 1e3, 1).tolist()} mm "
                  f"in {robot.tool_frame} (give --reflector x,y,z in m to set it)")
    else:
        reflector = parse_floats(args.reflector, 3, "--reflector")
        if np.linalg.norm(reflector) > reach:
            raise InputError(f"--reflector {args.reflector}: {np.linalg.norm(reflector):.4g} m from the tool frame, "
                             f"more than the robot's reach ({reach:.3g} m): give it in m")
    return reflector, estimated


def _fit(model: Any, train: Any, opts: Any, effects: list) -> tuple[Any, Any]:
    """(result, options with the loss used): the library's fit (``--loss`` default auto: the robust loss when
    :func:`~pin_kpi_oed.identification.quality.robust_loss_reason` says so; the summary prints the decision)."""
    from pin_kpi_oed.identification.identify import identify

    result = identify(model, train, opts, effects=effects)
    return result, replace(opts, loss=result.loss)


def _restate_tcp_sigma(result: Any, train: Any, q_work: Any) -> None:
    """The TCP σ the summary prints, with the discrepancy just fitted: the model file's own (what ``predict --at
    tcp``, ``check`` and ``report`` state), at the tool's working configurations, else the training poses."""
    from pin_kpi_oed.identification.identify import restate_tcp_sigma

    restate_tcp_sigma(result, train, train.q if q_work is None else q_work)


def _discrepancy(args: argparse.Namespace, result: Any, train: Any) -> Any:
    """The discrepancy of the final fit (``--discrepancy``), its decision printed on one line."""
    from pin_kpi_oed.identification.discrepancy_fit import discrepancy_options, result_discrepancy

    if args.discrepancy != "none" and not args.quiet:
        print(f"fitting the model discrepancy ({args.discrepancy}) on {len(train)} rows ...", flush=True)
    disc = result_discrepancy(result, train, discrepancy_options(args.discrepancy, args.seed))
    if disc is not None and args.quiet:
        print(disc.decision)
    return disc


def _checked_urdf(args: argparse.Namespace, robot: Any, result: Any) -> tuple[str, float]:
    """(calibrated URDF text, its max FK position error (m)); raises SolverError if it does not reproduce the fit."""
    from pin_kpi_oed.errors import SolverError
    from pin_kpi_oed.calibrated.urdf_export import (calibrated_urdf_text, check_urdf_fk, model_frames,
                                                   result_urdf_comment)
    from pathlib import Path

    placements = result.model.joint_placements(result.p)
    out_dir = Path(args.urdf_out).parent
    urdf_text = calibrated_urdf_text(robot, placements, comment=result_urdf_comment(result, ", ".join(args.data)),
                                     out_dir=out_dir if str(out_dir) else ".",
                                     frames=model_frames(result.calibrated_model()) if args.urdf_frames else ())
    dp, dr = check_urdf_fk(urdf_text, robot, placements)
    if dp > 1e-9 or dr > 1e-9:
        raise SolverError(f"the calibrated URDF reproduces the identified FK only to {dp:.3g} m; nothing written")
    return urdf_text, dp


def _report_and_write(args: argparse.Namespace, result: Any, out: dict, lines: list[str], quality: Any,
                      urdf_text: str | None, model_dict: dict | None, refuse: bool) -> int:
    """Print the summary and validation lines, write the outputs; exit code (2 when a poor fit is refused)."""
    from pin_kpi_oed.data.atomic import atomic_write_json, atomic_write_text

    if not args.quiet:
        print(result.summary())
    for ln in lines:
        print(ln)
    if args.json:
        atomic_write_json(args.json, out)
    if urdf_text is not None:
        atomic_write_text(args.urdf_out, urdf_text)
    if model_dict is not None:
        atomic_write_json(args.model_out, model_dict)
    written = [f for f in (args.json, urdf_text is not None and args.urdf_out, model_dict is not None
                           and args.model_out) if f]
    if written and not args.quiet:
        print("wrote " + ", ".join(written))
    if refuse:
        kept = [f for f in (args.urdf_out, args.model_out) if f]
        print(f"pin-kpi-oed identify: error: {in_flags(quality.line())}"
              + (f"; {', '.join(kept)} not written" if kept else "") + " (--accept-poor-fit to use it anyway)",
              file=sys.stderr)
        return 2
    return 0


def _geometry_prior(text: str | None) -> tuple[float, float] | None:
    """``--geometry-prior TRANS_M,ROT_RAD``, checked before any work (None when not given).

    Raises:
        InputError: not two positive finite numbers, naming the option.
    """
    if text is None:
        return None
    t, r = parse_floats(text, 2, "--geometry-prior")
    if not (t > 0 and r > 0):
        raise InputError(f"--geometry-prior: both sigmas must be > 0 (translation m, rotation rad), got '{text}'")
    return float(t), float(r)


def run_identify(args: argparse.Namespace) -> int:
    """Handler of ``pin-kpi-oed identify``."""
    from pin_kpi_oed.identification.identify import IdentifyOptions
    from pin_kpi_oed.identification.quality import assess_fit
    from pin_kpi_oed.model.tracker import TrackerModel
    from pin_kpi_oed.cli.camera_pipeline import identify_camera_cli, is_camera_data

    if is_camera_data(args.data):
        return identify_camera_cli(args)
    _check_outputs(args.json, args.urdf_out, args.model_out)
    geometry_prior = _geometry_prior(getattr(args, "geometry_prior", None))
    ct = command_tool(args, args.data, other_paths=[p for p in (args.validate, args.register_data) if p],
                      reflector_option=args.reflector, per_station_reflector=args.reflector_per_station)
    robot = ct.robot
    if not args.quiet:
        print(ct.line())
    train = read_data_files(args.data, robot, opts=table_options(args, robot))
    train.tool = ct.tool  # the agreed tool travels into the model file
    test, reg = read_validation(args, robot)
    noise, weights, scale, noise_source = _noise_and_weights(args, train, ct.cell)
    if not args.quiet:
        print(f"noise level: {noise_source}")
    effects = _effects(args.effects, robot, train)
    opts = IdentifyOptions(weights=weights, scale_covariance=scale, use_orientation=not args.position_only,
                           loss=args.loss or "auto", max_nfev=args.max_nfev, Q_work=ct.tool.q_work,
                           reflector_per_station=args.reflector_per_station,
                           # the command runs the discrepancy (seeded by --seed), the TCP σ with it and the gate (with
                           # the validation rows and --accept-poor-fit) itself, on the final fit
                           discrepancy="none", on_poor_fit="ignore", tcp_sigma=False)
    reflector, estimated = _nominal_reflector(args, robot, noise, train, opts, ct.tool)
    tcp = ct.tool.tcp_m if ct.tool.tcp_m is not None else np.zeros(3)
    # the nests the cell or the data's tool header lists (agreed by command_tool), moved with the nominal reflector
    nests = None if ct.tool.nests_m is None else ct.tool.nests_m - ct.tool.nests_m[0] + reflector
    model = TrackerModel(robot, reflector_m=reflector, tcp_m=tcp, noise=noise, nests_m=nests)
    if ct.cell is not None:  # only the start of the registration: the same model as cell.tracker_model()
        model.tracker_T_base = ct.cell.tracker_T_base
    if args.fix:
        model.layout.fix(args.fix)
    if geometry_prior is not None:
        model.layout.set_joint_prior(*geometry_prior)
    result, opts = _fit(model, train, opts, effects)
    result.discrepancy = _discrepancy(args, result, train)
    _restate_tcp_sigma(result, train, ct.tool.q_work)
    out = {"result": result.to_dict(), "data": list(args.data), "validate": args.validate,
           "reflector_nominal_m": reflector.tolist(),
           "reflector_nominal_source": "estimated" if estimated else ("given" if args.reflector else "cell/header"),
           "noise_source": noise_source,
           "tool": {"tool_frame": robot.tool_frame, **ct.tool.to_dict(), "source": ct.tool.source}}
    lines: list[str] = []
    if test is not None:
        out["validation"], lines = _validation(model, train, opts, result, test, reg, args)
    quality = assess_fit(result, out.get("validation"), nominal_reflector_m=reflector, reflector_estimated=estimated)
    out["fit_quality"] = in_flags_all(quality.to_dict())
    lines.append(in_flags(quality.line()))
    refuse = quality.poor and not args.accept_poor_fit
    # everything is computed and checked before the first file is written
    urdf_text = None
    if args.urdf_out and not refuse:
        urdf_text, out["urdf_check_max_error_m"] = _checked_urdf(args, robot, result)
    model_dict = result.calibrated_model().to_dict() if args.model_out and not refuse else None
    if model_dict is not None:
        from pin_kpi_oed.cli.provenance import stamp_model

        stamp_model(model_dict, args, robot, train=args.data, validate=args.validate, options=opts,
                    reflector_nominal_m=reflector, quality=quality)
    return _report_and_write(args, result, out, lines, quality, urdf_text, model_dict, refuse)


def run_import_ipa(args: argparse.Namespace) -> int:
    """Handler of ``pin-kpi-oed import-ipa``."""
    from pin_kpi_oed.data.measurements import MeasurementSet, write_measurements
    from pin_kpi_oed.data.ipa import import_ipa

    if args.out is None and args.split is None:
        raise InputError("import-ipa: give --out FILE and/or --split FRACTION --train FILE --test FILE")
    if args.split is not None and not (args.train and args.test):
        raise InputError("import-ipa: --split needs both --train FILE and --test FILE")
    if args.split is None and (args.train or args.test):
        raise InputError("import-ipa: --train/--test need --split FRACTION (e.g. 0.5)")
    _check_outputs(args.out, args.train, args.test)
    ms = import_ipa(args.src)
    ms = MeasurementSet(joint_names=ms.joint_names, q=ms.q, position_m=ms.position_m,
                        rotvec_rad=None if args.position_only else ms.rotvec_rad,
                        sigma_m=ms.sigma_m if args.keep_sigma else None, temperature_c=ms.temperature_c,
                        payload_kg=ms.payload_kg, time_s=ms.time_s, source=ms.source, extra=ms.extra)
    jobs = []
    if args.out:
        jobs.append((ms, args.out))
    if args.split is not None:
        frac = args.split
        if frac >= 1:
            if frac != int(frac) or int(frac) >= len(ms):
                raise InputError(f"import-ipa: --split {args.split:g}: a number of rows must be a whole number below "
                                 f"the {len(ms)} measurements (or give a share in (0, 1))")
            frac = int(frac) / len(ms)
        tr, te = ms.split(frac, seed=args.seed)
        jobs += [(tr, args.train), (te, args.test)]
    for obj, path in jobs:
        write_measurements(obj, path)
    msg = f"imported {len(ms)} measurements from {ms.source}"
    if args.out:
        msg += f" -> {args.out}"
    if args.split is not None:
        msg += (f"; split with seed {args.seed}: {len(tr)} -> {args.train}, "
                f"{len(te)} -> {args.test}")
    print(msg)
    return 0
