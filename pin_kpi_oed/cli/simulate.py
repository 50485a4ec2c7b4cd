"""CLI subcommand ``simulate`` of ``pin-kpi-oed``: tracker measurements of a simulated true robot.

The nominal set-up comes from one source of truth: ``--cell`` (or the cell of ``--design``) gives the robot, its
tool frame, the tracker pose, the reflector, the TCP and the noise; ``--robot`` with ``--tool``, ``--tracker``,
``--reflector`` builds one without a cell. The true robot is drawn from tolerances (``--seed``) with the unmodelled
``--effects``, or reused from ``--truth FILE`` when that file exists (else it is saved there), so one simulated
robot can be measured again at other poses or in another session. Poses: ``--poses CSV`` (given joint values), the
design's (``--design``), or random ones feasible in the cell; held-out poses (``--n-test``) are random and, with a
cell, feasible in it. Every CSV written starts with the tool header (:mod:`pin_kpi_oed.data.tool_header`).

Examples::

    pin-kpi-oed simulate --robot kr15 --n 80 --n-test 200 --seed 1 --out train.csv --test-out test.csv \\
        --reflector 0.03,0.02,0.08 --noise 1e-5 --truth truth.json
    pin-kpi-oed simulate --design design.json --effects gear_harmonic=5e-5 --n-test 40 --out train.csv \\
        --test-out test.csv --truth truth.json
    pin-kpi-oed simulate --truth truth.json --poses targets_q.csv --seed 7 --out again.csv
"""

from __future__ import annotations

import argparse
import os
import re
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin

from pin_kpi_oed.cli.tool import CELL_HELP
from pin_kpi_oed.cli.util import parse_floats
from pin_kpi_oed.errors import InputError
from pin_kpi_oed.model.robot import ROBOT_HELP, TOOL_HELP

__all__ = ["register_simulate", "run_simulate"]

#: random training measurements without --design or --poses
DEFAULT_N = 80

#: Fallbacks of the options that describe the set-up without a cell.
_DEFAULT_REFLECTOR = "0.03,0.02,0.08"
_DEFAULT_NOISE = "1e-5"
#: Options that describe the true robot; refused together with an existing --truth.
_TRUTH_OPTIONS = ("tracker", "reflector", "tol_translation", "tol_rotation", "tol_reflector", "effects")


def register_simulate(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``simulate`` subcommand and its options."""
    s = subparsers.add_parser("simulate", help="simulate tracker measurements of a robot with random geometric errors",
                              description="Simulate laser-tracker measurements (CSV, SI units) of a 'true' robot: "
                                          "random geometric errors from tolerances, tracker pose, reflector, noise, "
                                          "unmodelled effects. The set-up comes from --cell or --design (robot, tool "
                                          "frame, tracker, reflector, TCP, noise) or from --robot and its options; "
                                          "--truth saves the true robot or, when the file exists, measures it again.")
    s.add_argument("--robot", default=None, help=f"{ROBOT_HELP}; not with --design")
    s.add_argument("--kinematics", default=None, help="UR kinematics file (ur_description layout) of a UR --robot")
    s.add_argument("--cell", default=None, help=CELL_HELP + "; random and held-out poses are feasible in it")
    s.add_argument("--design", default=None,
                   help="design JSON (pin-kpi-oed design --json): measure its poses (--criterion) in its cell (robot, "
                        "tool frame, tracker pose, reflector, TCP), instead of random poses")
    s.add_argument("--criterion", default=None,
                   help="which design of --design to measure (default: the file's q_meas design, the one export "
                        "and evaluate take: the kpi design, else the file's last)")
    s.add_argument("--poses", default=None,
                   help="CSV with the robot's joint columns (rad / m): measure these poses (other columns ignored)")
    s.add_argument("--tool", default=None, help=TOOL_HELP)
    s.add_argument("--n", type=int, default=None,
                   help="number of random training measurements (default 80; refused with --design or --poses, "
                        "whose poses set the number)")
    s.add_argument("--n-test", type=int, default=0,
                   help="number of held-out measurements at random poses, feasible in the cell when there is one "
                        "(default 0)")
    s.add_argument("--out", required=True, help="training CSV file")
    s.add_argument("--test-out", default=None, help="held-out CSV file (with --n-test)")
    s.add_argument("--truth", default=None, metavar="FILE",
                   help="the true robot (geometric errors, effects, set-up): reused when FILE exists (measure the "
                        "same robot again, e.g. at --poses or with another --seed for the noise), else saved there")
    s.add_argument("--truth-json", default=None, help="also write the true robot here (the same document as --truth)")
    s.add_argument("--seed", type=int, default=0, help="seed of every random draw (default 0)")
    s.add_argument("--reflector", default=None,
                   help=f"reflector offset in the tool frame, x,y,z (m); default: the cell's, else "
                        f"{_DEFAULT_REFLECTOR}")
    s.add_argument("--tracker", default=None,
                   help="pose of the robot base in the tracker frame x,y,z[,roll,pitch,yaw] (m, rad); "
                        "default: the cell's, else a tracker reach + 1.5 m away")
    s.add_argument("--noise", default=None,
                   help=f"tracker noise sigma (m), 1 or 3 values (default: the cell's, else {_DEFAULT_NOISE})")
    s.add_argument("--tol-translation", default=None, help="sigma of the joint-placement translation errors (m; "
                                                           "default 5e-4)")
    s.add_argument("--tol-rotation", default=None, help="sigma of the joint-placement rotation errors (rad; "
                                                        "default 1e-3)")
    s.add_argument("--tol-reflector", default=None, help="sigma of the reflector offset error (m; default 0)")
    s.add_argument("--pose6d", action="store_true", help="also simulate 6-DoF probe orientations (rx, ry, rz)")
    s.add_argument("--sigma-rot", default="1e-4", help="orientation noise of --pose6d (rad)")
    s.add_argument("--effects", default=None,
                   help="unmodelled effects of the 'real' robot, e.g. joint_compliance=2e-6,gear_harmonic=5e-5 "
                        "(name=SIZE: random +-SIZE per parameter; name=v1:v2:... exact values; see "
                        "pin_kpi_oed.effects.library.parse_effects_spec). A tracker range-scale error is not offered: "
                        "it equals a uniform scaling of the robot and no data can reveal it")
    s.add_argument("--temperature", default="20,25",
                   help="temperature column: uniform between T0,T1 (degC), read by thermal_expansion")
    s.set_defaults(func=run_simulate)


def _positive(text: str, what: str) -> float:
    v = float(parse_floats(text, 1, what)[0])
    if not v > 0:
        raise InputError(f"{what}: must be positive and finite, got {text}")
    return v


def _check_args(args: argparse.Namespace) -> bool:
    """Option checks before any work; returns whether ``--truth`` names an existing file (reuse)."""
    from pin_kpi_oed.data.atomic import check_writable, claim_output

    if args.n is not None and (args.design or args.poses):
        raise InputError(f"--n {args.n}: not with {'--design' if args.design else '--poses'} (its poses are measured, "
                         "as many as it has): leave --n out")
    args.n = DEFAULT_N if args.n is None else args.n
    if args.n < 1 or args.n_test < 0:
        raise InputError(f"--n must be >= 1 and --n-test >= 0, got {args.n} and {args.n_test}")
    if args.n_test and not args.test_out:
        raise InputError("--n-test needs --test-out FILE")
    reuse = bool(args.truth) and Path(args.truth).exists()
    outs = [args.out, args.test_out, args.truth_json] + ([] if reuse else [args.truth])
    given = [os.path.abspath(p) for p in outs if p]
    if len(set(given)) < len(given):
        raise InputError("simulate: --out, --test-out, --truth and --truth-json must be different files")
    for out in outs:  # before any work: the folders exist, the outputs are claimed
        if out:
            check_writable(out)
            claim_output(out)
    if args.design and (args.robot or args.cell):
        raise InputError("simulate: give --robot ROBOT / --cell CELL or --design DESIGN.json (its poses and cell), "
                         "not both")
    if args.robot is None and args.design is None and args.cell is None and not reuse:
        raise InputError("simulate: give --robot ROBOT, --cell CELL, --design DESIGN.json or an existing --truth FILE")
    if args.criterion and not args.design:
        raise InputError("--criterion: only with --design")
    if args.poses and args.design:
        raise InputError("--poses: not with --design (it measures the design's poses)")
    if reuse:
        clash = [o for o in _TRUTH_OPTIONS if getattr(args, o) is not None] + (["pose6d"] if args.pose6d else [])
        if clash:
            opt = "--" + clash[0].replace("_", "-")
            raise InputError(f"{opt}: the true robot comes from --truth {args.truth}; leave {opt} out (or name "
                             "another --truth file to draw a new robot)")
    return reuse


def _setup(args: argparse.Namespace, reuse: bool, cell: Any = None) -> tuple[Any, Any, np.ndarray, list, Any, Any]:
    """(nominal model, cell or None, p*, [(effect, θ*)], tolerances or None, design entry or None); ``cell``: the
    ``--cell`` already read."""
    from pin_kpi_oed.cli.tool import canonical_robot, cell_tool_spec
    from pin_kpi_oed.data.tool_header import ToolSpec, resolve_tool
    from pin_kpi_oed.simulation.simulator import Tolerances, load_truth, random_truth

    design = _design_poses(args.design, args.criterion) if args.design else None
    cell = cell if cell is not None else (design[0].cell if design else None)
    truth = load_truth(args.truth) if reuse else None
    specs = [ToolSpec(robot=args.robot, source=f"--robot {args.robot}") if args.robot else None,
             ToolSpec(tool_frame=args.tool, source=f"--tool {args.tool}") if args.tool else None,
             ToolSpec(reflector_m=parse_floats(args.reflector, 3, "--reflector"),
                      source=f"--reflector {args.reflector}") if args.reflector else None,
             cell_tool_spec(cell, f"--cell {args.cell}" if args.cell else f"--design {args.design}") if cell else None,
             ToolSpec(robot=truth[0].robot.urdf_path, tool_frame=truth[0].robot.tool_frame,
                      reflector_m=truth[0].reflector_m, source=f"--truth {args.truth}") if truth else None]
    resolve_tool([canonical_robot(s) for s in specs], skip=("q_work",))
    noise = _noise(args, cell, truth)
    if truth is not None:
        model, p, effects = truth
        model.noise = noise
        return model, cell, p, effects, None, design
    model = _nominal_model(args, cell, noise)
    tol = Tolerances(joint_translation_m=float(parse_floats(args.tol_translation or "5e-4", 1, "--tol-translation")[0]),
                     joint_rotation_rad=float(parse_floats(args.tol_rotation or "1e-3", 1, "--tol-rotation")[0]),
                     reflector_m=float(parse_floats(args.tol_reflector or "0", 1, "--tol-reflector")[0]))
    effects = []
    if args.effects:
        from pin_kpi_oed.effects.library import parse_effects_spec
        from pin_kpi_oed.validation.units import check_effect_sizes

        effects = parse_effects_spec(args.effects, model.robot, np.random.default_rng(args.seed + 3))
        given = {m.group(1): m.group(2) for m in re.finditer(r"(\w+)(?:\[[^\]]*\])?\s*=\s*([^,\s]+)",
                                                              args.effects)}
        check_effect_sizes(effects, given=given)  # the size as written, in degrees or µrad, refused naming the unit
    return model, cell, random_truth(model, tol, seed=args.seed), effects, tol, design


def _noise(args: argparse.Namespace, cell: Any, truth: Any) -> Any:
    """``--noise`` / ``--sigma-rot``, else the cell's or the truth's noise, else the default."""
    from pin_kpi_oed.model.noise import NoiseModel

    sigma_rot = _positive(args.sigma_rot, "--sigma-rot")
    if args.noise is None and (truth is not None or cell is not None):
        base = truth[0].noise if truth is not None else cell.noise
        return NoiseModel(sigma_xyz_m=tuple(base.sigma_xyz_m), range_a_m=base.range_a_m, range_b=base.range_b,
                          sigma_rot_rad=sigma_rot)
    return NoiseModel(sigma_xyz_m=tuple(parse_floats(args.noise or _DEFAULT_NOISE, (1, 3), "--noise")),
                      sigma_rot_rad=sigma_rot)


def _nominal_model(args: argparse.Namespace, cell: Any, noise: Any) -> Any:
    """The nominal set-up: the cell's (tracker, reflector, TCP), else ``--robot`` with its options."""
    from pin_kpi_oed.simulation.simulator import default_tracker_pose
    from pin_kpi_oed.model.robot import load_robot
    from pin_kpi_oed.model.tracker import TrackerModel

    if cell is not None:
        if args.tracker:
            raise InputError(f"--tracker: the cell places the tracker ({args.cell or args.design}); leave --tracker "
                             "out")
        return TrackerModel(cell.robot, tracker_T_base=cell.tracker_T_base, reflector_m=cell.reflector_m.copy(),
                            tcp_m=cell.tcp_m.copy(), noise=noise, pose6d=args.pose6d, nests_m=cell.nests_m)
    robot = load_robot(args.robot, args.tool, kinematics=args.kinematics)
    if args.tracker:
        v = parse_floats(args.tracker, (3, 6), "--tracker")
        T = pin.SE3(pin.rpy.rpyToMatrix(v[3:] if v.size == 6 else np.zeros(3)), v[:3])
    else:
        T = default_tracker_pose(robot)
    reflector = parse_floats(args.reflector or _DEFAULT_REFLECTOR, 3, "--reflector")
    return TrackerModel(robot, tracker_T_base=T, reflector_m=reflector, noise=noise, pose6d=args.pose6d)


def _poses(args: argparse.Namespace, model: Any, cell: Any, design: Any) -> tuple[np.ndarray, np.ndarray, str]:
    """(training poses, held-out poses, what the training poses are)."""
    from pin_kpi_oed.simulation.simulator import feasible_poses

    robot = model.robot
    rng = np.random.default_rng(args.seed + 1)
    if args.poses:
        from pin_kpi_oed.data.measurements import read_measurements

        ms = read_measurements(args.poses, joint_names=robot.joint_names, require_position=False,
                               joint_units=list(robot.joint_units))
        if ms.tool is not None and ms.tool.robot is not None:
            _same_robot(ms.tool.robot, robot, args)
        Q, what = robot.check_q(ms.q, args.poses), f"the poses of {args.poses}"
    elif design:
        Q, what = design[1], f"the poses of design '{design[2]}' of {args.design}"
    elif cell is not None:
        Q, what = feasible_poses(cell, args.n, args.seed + 1), f"random poses feasible in cell {cell.name}"
    else:
        Q, what = robot.random_q(rng, args.n), "random poses"
    if cell is not None and args.n_test:
        return Q, feasible_poses(cell, args.n_test, args.seed + 5), what
    return Q, robot.random_q(rng, args.n_test), what


def _same_robot(header_robot: str, robot: Any, args: argparse.Namespace) -> None:
    """Refuse ``--poses`` whose tool header names another robot than the simulated one (their joint values are not
    this robot's poses, even when the joint names agree).

    Raises:
        InputError: both robots named.
    """
    from pin_kpi_oed.cli.tool import canonical_robot
    from pin_kpi_oed.data.tool_header import ToolSpec
    from pin_kpi_oed.model.robot import portable_spec

    mine = canonical_robot(ToolSpec(robot=portable_spec(robot)))
    theirs = canonical_robot(ToolSpec(robot=header_robot))
    if mine is not None and theirs is not None and mine.robot != theirs.robot:
        simulated = f"the true robot of --truth {args.truth}" if args.truth else "the simulated robot"
        raise InputError(f"--poses {args.poses}: its header says robot '{header_robot}', but {simulated} is "
                         f"'{robot.name}'; give poses of '{robot.name}' (or simulate '{header_robot}')")


def run_simulate(args: argparse.Namespace) -> int:
    """Handler of ``pin-kpi-oed simulate``."""
    from pin_kpi_oed.data.atomic import atomic_write_json
    from pin_kpi_oed.data.measurements import write_measurements
    from pin_kpi_oed.data.tool_header import ToolSpec
    from pin_kpi_oed.simulation.simulator import simulate, truth_to_dict
    from pin_kpi_oed.model.robot import portable_spec

    reuse = _check_args(args)
    cell = None
    if args.design:
        from pin_kpi_oed.design.camera_design_file import is_camera_design, load_camera_design

        if is_camera_design(args.design):  # a camera's design: its cell's camera images at the design's poses
            from pin_kpi_oed.cli.camera_pipeline import simulate_camera

            if reuse:
                raise InputError(f"--truth {args.truth}: a camera cell draws its true robot anew; name a new file")
            cd = load_camera_design(args.design, args.criterion)
            return simulate_camera(args, cd.cell, cd.Q, f"the {len(cd.Q)} poses of design {cd.criterion} of "
                                                       f"{args.design}")
    if args.cell:
        from pin_kpi_oed.cell.cell import load_cell

        cell = load_cell(args.cell)
        if cell.camera is not None:
            from pin_kpi_oed.cli.camera_pipeline import simulate_camera

            if reuse:
                raise InputError(f"--truth {args.truth}: a camera cell draws its true robot anew; name a new file")
            return simulate_camera(args, cell)
    model, cell, truth_p, effects, tol, design = _setup(args, reuse, cell)
    Q, Q_test, what = _poses(args, model, cell, design)
    robot = model.robot
    Q_all = np.vstack([Q, Q_test])
    t0, t1 = parse_floats(args.temperature, 2, "--temperature")
    aux = {"temperature_c": np.random.default_rng(args.seed + 4).uniform(t0, t1, len(Q_all))}
    nest = None if design is None or design[3] is None else np.concatenate([design[3], np.zeros(len(Q_test), int)])
    ms = simulate(model, Q_all, truth_p, effects=effects, aux=aux, seed=args.seed + 2, nest=nest)
    ms.tool = ToolSpec(robot=portable_spec(robot), tool_frame=robot.tool_frame, reflector_m=model.reflector_m,
                       tcp_m=model.tcp_m if (cell is not None or np.any(model.tcp_m != 0)) else None,
                       q_work=cell.q_work if cell is not None and np.size(cell.q_work) else None,
                       nests_m=model.nests_m if model.n_nests > 1 else None)
    doc = None if reuse and not args.truth_json else truth_to_dict(model, truth_p, tol, args.seed, effects)
    write_measurements(ms.subset(slice(0, len(Q))), args.out)
    if args.n_test:
        write_measurements(ms.subset(slice(len(Q), None)), args.test_out)
    for path in ([args.truth] if args.truth and not reuse else []) + ([args.truth_json] if args.truth_json else []):
        atomic_write_json(path, doc)
    print(f"simulated {len(Q)} measurements at {what} -> {args.out}"
          + (f", {args.n_test} held-out" + (" (feasible in the cell)" if cell is not None else "")
             + f" -> {args.test_out}" if args.n_test else "")
          + f" (robot {robot.name}, tool frame {robot.tool_frame}, noise sigma "
            f"{np.array(model.noise.sigma_xyz_m) * 1e6} µm, seed {args.seed}"
          + (f", effects: {', '.join(e.name for e, _ in effects)}" if effects else "")
          + (f"; true robot of {args.truth}" if reuse else (f"; true robot saved to {args.truth}" if args.truth
                                                              else "")) + ")")
    return 0


def _design_poses(path: str, criterion: str | None) -> tuple[Any, np.ndarray, str, np.ndarray | None]:
    """(design file, poses, criterion, each pose's reflector nest or None) of ``simulate --design``: the named
    design, else the file's default one (:attr:`~pin_kpi_oed.design.design_file.DesignFile.default_criterion`, as
    ``export`` and ``evaluate``); the nests are the design's ``nest`` (a cell listing several nests)."""
    from pin_kpi_oed.design.design_file import load_design

    df = load_design(path)
    if not df.designs:
        raise InputError(f"--design {path}: holds no design")
    entry = df.design(criterion or df.default_criterion)
    Q, nest = np.asarray(entry.q_meas, float), entry.info.get("nest")
    if nest is not None:
        from pin_kpi_oed.model.nests import check_row_nest

        k = 1 if df.cell.nests_m is None else len(df.cell.nests_m)
        nest = check_row_nest(nest, k, f"--design {path}: designs.{entry.criterion}.nest")
        if len(nest) != len(Q):
            raise InputError(f"--design {path}: designs.{entry.criterion}.nest has {len(nest)} entries for "
                             f"{len(Q)} poses")
    return df, Q, entry.criterion, nest
