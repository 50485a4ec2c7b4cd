"""``pin-kpi-oed design``: heuristic and optimum measurement designs of a cell, as a table and JSON.

Example::

    pin-kpi-oed design --cell kr15 --criteria random,param,kpi --measurements 60 --seed 0 --json design.json

prints, per design: the criterion, tr(C_s) (mm²), the TCP σ = sqrt(tr(C_s)/t) (µm), the
improvement of tr(C_s) over the heuristic design (%), the smallest clearance (mm) and largest
incidence angle (°) found by the independent check, Ipopt iterations and solve time (s).
``--clearance-margin`` (default 0.02 m) and ``--incidence-margin`` (default 1°) tighten the cell the
optimiser designs in; the table's clearance and incidence are the true ones (independent check of
the cell as given; ``demo`` keeps the paper's zero margins). ``--no-collision`` drops the collision and line-of-sight
constraints (joint bounds and incidence
only) and reports the share of poses that collide.
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Sequence


import pin_kpi_oed.design.optimize  # noqa: F401  (registers the path and 6-D criteria --criteria is checked against)
from pin_kpi_oed.design.runner import DesignSettings, design_run
from pin_kpi_oed.design.design_writer import write_design
from pin_kpi_oed.design.scores import sigma_given
from pin_kpi_oed.design.margins import DEFAULT_CLEARANCE_MARGIN_M, DEFAULT_INCIDENCE_MARGIN_DEG
from pin_kpi_oed.cli.flags import in_flags
from pin_kpi_oed.errors import InputError
from pin_kpi_oed.oed.criteria import check_names, criterion_names
from pin_kpi_oed.validation.options import check_discrepancy_options
from pin_kpi_oed.validation.robot_checks import check_same_robot


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``design`` subcommand to the CLI's subparsers."""
    p = subparsers.add_parser("design", help="heuristic and optimum (IPOPT) measurement designs of a cell",
                              description=__doc__.splitlines()[0])
    p.add_argument("--cell", default="kr15", help="shipped cell (kr15, kr300, kr500, ur10) or a cell YAML file")
    p.add_argument("--criteria", default="random,param,kpi",
                   help="comma-separated: random (heuristic) and registered criteria: " + ", ".join(criterion_names()))
    p.add_argument("--measurements", type=int, default=None, help="number of measurement configurations "
                   "(default: the cell's)")
    p.add_argument("--n", dest="measurements", type=int, default=None, help="the same as --measurements")
    p.add_argument("--seed", type=int, default=0, help="seed of the heuristic design and of the starts")
    p.add_argument("--json", default=None, help="write the designs to this JSON file")
    p.add_argument("--no-collision", dest="no_collision", action="store_true",
                   help="optimise without collision/line-of-sight constraints (report the colliding share)")
    p.add_argument("--starts", type=int, default=None, help="Ipopt starts per criterion (default 2)")
    p.add_argument("--max-iter", dest="max_iter", type=int, default=None, help="Ipopt iteration limit (default 500)")
    p.add_argument("--quiet", action="store_true", help="print the table only")
    p.add_argument("--distances", choices=["coal", "closed-form"], default="coal",
                   help="capsule distances in the optimiser: Coal through a Pinocchio GeometryModel (default; one "
                        "computeDistances per pose) or the closed-form segment distances "
                        "(the test oracle; equal to 1e-15 m)")
    p.add_argument("--start", choices=["pool", "random"], default="pool",
                   help="first Ipopt start: pool selection (default) or the heuristic design")
    p.add_argument("--certificate", action="store_true",
                   help="bound tr(C_s) by the approximate-design relaxation over a feasible pool; report efficiencies")
    p.add_argument("--model", default=None, help="calibrated model file: design over its geometry + effects "
                   "(transmission_error, gear_harmonic, link_bending) instead of the nominal geometry")
    p.add_argument("--prior", choices=["model", "tolerances", "none"], default="model",
                   help="with --model: prior of the parameters (the file's covariance, manufacturing tolerances, none)")
    p.add_argument("--pool-size", dest="pool_size", type=int, default=None,
                   help="feasible candidates of the certificate's pool (default 5000; a camera cell's 600)")
    p.add_argument("--clearance-margin", dest="clearance_margin", type=float, default=DEFAULT_CLEARANCE_MARGIN_M,
                   help="clearance the optimiser keeps on top of the cell's (m, default "
                        f"{DEFAULT_CLEARANCE_MARGIN_M:g}; the check reports the true clearance)")
    p.add_argument("--incidence-margin", dest="incidence_margin", type=float, default=DEFAULT_INCIDENCE_MARGIN_DEG,
                   help="incidence angle the optimiser keeps below the cell's limit (deg, default "
                        f"{DEFAULT_INCIDENCE_MARGIN_DEG:g}; the check reports the true angle)")
    p.add_argument("--pool", default=None, help="select the poses from these candidates (CSV, joint columns in rad, "
                   "up to 100,000 rows) instead of optimising; the selection's bound is the certificate "
                   "(with --given: on top of the measured poses)")
    p.add_argument("--given", default=None, help="poses already measured (CSV, joint columns in rad): design "
                   "--measurements more on top of them (their information counts; they must pass the cell's check)")
    p.add_argument("--given-prior", dest="given_prior", default=None,
                   help="with --given: calibrated model file of an earlier calibration; its parameter covariance "
                        "is a prior on the robot parameters (set-up parameters get none)")
    p.add_argument("--target-sigma", dest="target_sigma", type=float, default=None,
                   help="with --given: how many more poses until the predicted TCP sigma <= this (m), "
                        "answered greedily over the --pool candidates (else --pool-size random feasible poses) "
                        "and verified by recomputing C_s")
    p.add_argument("--curve", default=None,
                   help="with the discrepancy (kpi_gp or --model with a discrepancy): write the poses-needed figure "
                        "(predicted TCP sigma at the working configurations vs number of poses, designed and random; "
                        "PNG); the curve also goes to --json")
    p.add_argument("--work-radius", dest="work_radius", type=float, default=None,
                   help="kpi_gp: take the KPI over the working region, the working configurations plus "
                        "--work-samples seeded configurations within this radius of them (rad, Euclidean over joints "
                        "1-5, within the joint bounds and collision-free); default 0.5 with kpi_gp (the discrepancy's "
                        "length scales are short: a few configurations do not represent where the robot works), "
                        "0 = the working configurations alone")
    p.add_argument("--no-hedge", dest="no_hedge", action="store_true",
                   help="kpi_gp without --model: design for the class's default discrepancy alone (default: hedge "
                        "over its length scales x0.5 and x2, its level x3 and noise only, so that a robot whose "
                        "discrepancy differs from the default is not designed worse than by the noise-only KPI)")
    p.add_argument("--robot-class", dest="robot_class", choices=["collaborative", "industrial", "generic"],
                   default=None, help="class of the default discrepancy without --model (default: from the robot's "
                                      "name: ur*, panda* collaborative; kr* industrial; else generic)")
    p.add_argument("--work-samples", dest="work_samples", type=int, default=None,
                   help="configurations drawn for the working region (default 100; the infeasible ones are dropped)")
    p.add_argument("--reregister", default=None, metavar="work|FILE",
                   help="with the discrepancy: the calibration will be used in another session, after the tracker "
                        "(set-up) is registered again on these configurations (CSV, joint columns in rad; 'work': the "
                        "working configurations and the working region's); kpi_gp and the honest sigma then score "
                        "the TCP error after that registration instead of the parameter uncertainty carried in the "
                        "old set-up")
    _iso_options(p)
    p.set_defaults(func=run)


def _iso_options(p: argparse.ArgumentParser) -> None:
    """The ISO 9283 cube test's options of ``design``."""
    p.add_argument("--iso9283", default=None, metavar="PROGRAM",
                   help="instead of a design: plan the ISO 9283 cube test around the working configurations (the "
                        "largest cube that fits, P1..P5 on its diagonal plane, 30 cycles, every pose and move "
                        "checked) and write it as a robot program (format from the suffix: .csv, .script, .src, .mod)")
    p.add_argument("--iso-side", dest="iso_side", type=float, default=None, metavar="M", help="with --iso9283: the "
                   "cube's side in m (default: the largest that fits; refused, naming it, when the given one does not)")


def parse_criteria(text: str) -> list[str]:
    """Split and validate the ``--criteria`` list.

    Raises:
        InputError: empty list or unknown name.
    """
    names = [c.strip() for c in str(text).split(",") if c.strip()]
    if not names:
        raise InputError("--criteria: give at least one of random, " + ", ".join(criterion_names()))
    try:
        return check_names(names)
    except InputError as exc:
        raise InputError(f"--criteria: {exc}") from None


def table(results: list, reference=None, certificate=None, extended: list | None = None,
          extended_reference: dict | None = None) -> str:
    """The design table (one row per :class:`~pin_kpi_oed.design.optimize.DesignResult`; efficiency with a certificate).

    Args:
        results: the designs; reference: the design the "vs random" column compares with (default the first).
        certificate: the optimality certificate or None.
        extended: per design (same order as ``results``) the extended-model scores of :func:`extended_scores`
            (``--model``): the table then shows the extended-model tr(C_s) (with the prior) and TCP σ first,
            labels the geometric ones "geo" and compares the extended tr(C_s) with the reference's.
        extended_reference: the reference design's extended scores when it is not among ``results``.
    """
    ref = reference or results[0]
    ext_by_id = {id(r): e for r, e in zip(results, extended)} if extended is not None else None
    head = (f"{'criterion':<12}" + (f"{'ext tr(C_s) mm^2':>18}{'ext sigma um':>14}" if ext_by_id else "")
            + f"{'geo tr(C_s) mm^2' if ext_by_id else 'tr(C_s) mm^2':>{18 if ext_by_id else 14}}"
            f"{'geo sigma um' if ext_by_id else 'TCP sigma um':>14}"
            f"{'ext vs rnd %' if ext_by_id else 'vs random %':>{13 if ext_by_id else 12}}{'min clr mm':>11}"
            f"{'max inc deg':>12}{'iters':>7}{'time s':>8}" + (f"{'effic. %':>10}" if certificate else "")
            + "  check")
    lines = [head, "-" * len(head)]
    for r in results:
        # signed change of tr(C_s) against the random (the paper's heuristic) design: negative = more precise
        imp = 0.0 - r.improvement_over(ref) + 0.0 if math.isfinite(r.trace_cs_m2) else float("nan")
        if ext_by_id:  # the extended tr(C_s) against the reference's (the criterion the designs optimised)
            e_r, e_ref = ext_by_id.get(id(r)), ext_by_id.get(id(ref), extended_reference)
            imp = (100.0 * (e_r["trace_cs_m2"] / e_ref["trace_cs_m2"] - 1.0) + 0.0 if e_r and e_ref
                   else float("nan"))
        it = f"{r.nit:d}" if r.criterion != "random" else "-"
        chk = "ok" if r.feasible else f"{100 * r.share_colliding:.0f}% coll."
        if not r.feasible and r.share_colliding == 0:
            chk = f"{100 * r.share_infeasible:.0f}% infeas."
        ext = ""
        if ext_by_id:
            e = ext_by_id.get(id(r), {"trace_cs_m2": float("nan"), "tcp_sigma_m": float("nan")})
            ext = f"{e['trace_cs_m2'] * 1e6:>18.4e}{e['tcp_sigma_m'] * 1e6:>14.4f}"
        lines.append(f"{r.criterion:<12}{ext}{r.trace_cs_m2 * 1e6:>{18 if ext_by_id else 14}.4e}"
                     f"{r.tcp_sigma_m * 1e6:>14.4f}{imp:>+{13 if ext_by_id else 12}.1f}"
                     f"{r.min_clearance_m * 1e3:>11.1f}{r.max_incidence_deg:>12.1f}{it:>7}"
                     f"{r.time_s:>8.2f}"
                     + (f"{100 * certificate.efficiency(r.trace_cs_m2):>10.1f}" if certificate else "")
                     + f"  {chk}")
    return "\n".join(lines)



def run(args: argparse.Namespace) -> int:
    """Handler of ``pin-kpi-oed design`` (returns the exit code): the options become
    :class:`~pin_kpi_oed.design.runner.DesignSettings`, the library declares the problem
    (:func:`~pin_kpi_oed.design.declare.design_problem`) and runs it (:func:`~pin_kpi_oed.design.runner.design_run`);
    this prints the run and writes its file.

    Raises:
        PinKpiOedError: bad cell, unknown criterion, infeasible cell, solver failure (one-line message).
    """
    from pin_kpi_oed.cell.cell import load_cell
    from pin_kpi_oed.design.declare import design_problem
    from pin_kpi_oed.design.path_profile import profile_lines

    if getattr(args, "iso9283", None):
        from pin_kpi_oed.cli.iso9283 import run_iso9283

        return run_iso9283(args)
    criteria = parse_criteria(getattr(args, "criteria", "random,param,kpi"))
    cell = load_cell(getattr(args, "cell", "kr15"))
    if cell.camera is not None:  # the camera's design (pin_kpi_oed.cli.camera_design_cmd)
        from pin_kpi_oed.cli.camera_design_cmd import run_camera_design

        return run_camera_design(args, cell)
    settings, quiet = _settings(args, cell, criteria)
    problem = design_problem(cell, settings)
    disc_on = problem.discrepancy is not None or bool(_gp_names(criteria))
    if settings.target_sigma_m is not None and not disc_on and not settings.given_file:
        raise InputError(f"--target-sigma needs --given or a discrepancy: --model {getattr(args, 'model', None)} "
                         f"holds no discrepancy block (write it with identify --model-out)")
    if not quiet:
        if problem.extended is not None:
            print(f"extended model from {settings.model_file}: {problem.extended.nb} geometric + "
                  f"{problem.extended.k} effect parameters, prior: {settings.model_prior}")
        print_header(cell, problem, settings.measurements, settings.seed, settings.collision,
                     settings.n_starts)  # the cell as given: the margins' line after the table names the tightening
    _print_declared(problem, settings.reregister)
    run = design_run(cell, settings, problem, discrepancy=disc_on, say=_say)
    results, m = list(run.results), run.m
    print_results(results, criteria, run.certificate, m, settings.pool_file, quiet, problem.cell, cell, run.margins,
                  run.true_checks, settings.given_file, run.extended_scores)
    print(*profile_lines(run.path_profiles), sep="\n", end="\n" if run.path_profiles else "")
    print(*(f"nests of {r.criterion}: " + (nd.line() if nd is not None else "its poses do not identify the "
                                            "parameters of nest 0; every pose measures nest 0")
            for r, nd in zip(results, run.nests or ())), sep="\n", end="\n" if run.nests else "")
    if run.discrepancy_scores is not None:  # opt-in: the paper's output is unchanged without
        _print_discrepancy(run, criteria)
    print(*(in_flags(line) for line in run.answers), sep="\n", end="\n" if run.answers else "")
    if getattr(args, "curve", None) and run.poses_needed is not None:
        from pin_kpi_oed.viz.poses_needed import plot_poses_needed

        src = problem.discrepancy_prior().source or "given"
        plot_poses_needed(run.poses_needed.to_dict(), args.curve,
                          title=f"{cell.name}: poses needed (σ with the discrepancy: "
                                f"{src if len(src) <= 70 else src[:67] + '...'})")
        print(f"wrote {args.curve}")
    if getattr(args, "json", None):
        write_design(args.json, run)
        if not quiet:
            print(f"wrote {args.json}")
    return 0


def _say(line: str) -> None:
    """Print a line of the library, its parameters named by the options that set them."""
    print(in_flags(line))


def _print_discrepancy(run, criteria: list[str]) -> None:
    """The discrepancy section: the prior, the σ plan, the measured poses' σ, the honest table and the notes."""
    problem, results, gp_scores = run.problem, list(run.results), list(run.discrepancy_scores)
    print(in_flags(problem.discrepancy_prior().describe()) + "\n" + _sigma_plan(problem, run.m))
    if run.given_file:
        print(f"measured poses alone ({len(problem.Q_given)}): predicted TCP sigma with the discrepancy "
              f"{sigma_given(problem) * 1e6:.3f} um; the table adds each design's poses to them")
    print(discrepancy_table([r for r in results if r.criterion in criteria] or results,
                            [g for r, g in zip(results, gp_scores) if r.criterion in criteria] or gp_scores))
    _discrepancy_notes(problem, _gp_names(criteria))


def _settings(args: argparse.Namespace, cell, criteria: list[str]) -> tuple[DesignSettings, bool]:
    """The options as the run's settings (and ``--quiet``): the combinations checked, ``--given-prior`` and
    ``--model`` read, the model's discrepancy re-fitted on the ``--given`` batch."""
    m, seed, collision, starts, max_iter, quiet = _run_knobs(args, cell)
    pool_file, given_file, target = _pool_given_target(args)
    given_prior = _given_prior(args.given_prior, cell) if getattr(args, "given_prior", None) else None
    cm = discrepancy = model_sigma = None
    if getattr(args, "model", None):
        from pin_kpi_oed.cli.tool import model_cell_tool
        from pin_kpi_oed.identification.design_discrepancy import model_design_inputs
        from pin_kpi_oed.calibrated.model_file import load_model_file

        cm = load_model_file(args.model)
        model_cell_tool(cm, args.model, cell, args.cell)  # the model's robot, tool frame and TCP are the cell's
        inputs = model_design_inputs(cm, cell, args.model, given_file)
        discrepancy, model_sigma = inputs.discrepancy, inputs.model_sigma
        for line in (inputs.sigma_line, None if quiet else inputs.refit_line):
            if line:
                print(in_flags(line))
    # the options that act only with the discrepancy, refused (not ignored) without it
    check_discrepancy_options(args, bool(_gp_names(criteria)), discrepancy is not None or (
        cm is not None and cm.discrepancy is not None))
    margins = (float(getattr(args, "clearance_margin", 0.0) or 0.0),
               float(getattr(args, "incidence_margin", 0.0) or 0.0))
    return DesignSettings(
        criteria=tuple(criteria), measurements=m, seed=seed, collision=collision, n_starts=starts, max_iter=max_iter,
        start=getattr(args, "start", "pool") or "pool", certificate=bool(getattr(args, "certificate", False)),
        certificate_pool_size=getattr(args, "pool_size", 5000) or 5000, clearance_margin_m=margins[0],
        incidence_margin_deg=margins[1],
        distances={"closed-form": "numpy"}.get(getattr(args, "distances", None), "geometry"),
        pool_file=pool_file, given_file=given_file, given_prior=given_prior, model=cm,
        model_file=getattr(args, "model", None), model_prior=getattr(args, "prior", "model") or "model",
        discrepancy=discrepancy, robot_class=getattr(args, "robot_class", None),
        hedge=not getattr(args, "no_hedge", False), work_radius_rad=getattr(args, "work_radius", None),
        work_samples=getattr(args, "work_samples", None), reregister=getattr(args, "reregister", None),
        target_sigma_m=target, poses_needed=bool(getattr(args, "curve", None)), model_sigma_at_work=model_sigma), quiet


def _run_knobs(args: argparse.Namespace, cell) -> tuple[int, int, bool, int, int, bool]:
    """(measurements, seed, collision avoidance, starts, max Ipopt iterations, quiet), checked."""
    m = getattr(args, "measurements", None) or cell.measurements
    if m < 1:
        raise InputError(f"--measurements: must be >= 1, got {m}")
    seed = int(getattr(args, "seed", 0) or 0)
    collision = not getattr(args, "no_collision", False)
    starts = getattr(args, "starts", None) or 2
    max_iter = getattr(args, "max_iter", None) or 500
    quiet = bool(getattr(args, "quiet", False))
    if starts < 1 or max_iter < 1:
        raise InputError("--starts and --max-iter must be >= 1")
    return m, seed, collision, starts, max_iter, quiet


def _pool_given_target(args: argparse.Namespace) -> tuple[str | None, str | None, float | None]:
    """(``--pool``, ``--given``, ``--target-sigma`` in m), checked for combinations that make no sense."""
    pool_file, given_file = getattr(args, "pool", None), getattr(args, "given", None)
    target = getattr(args, "target_sigma", None)
    if getattr(args, "given_prior", None) and not given_file:
        raise InputError("--given-prior needs --given (the poses already measured)")
    crits = str(getattr(args, "criteria", "") or "")
    disc = getattr(args, "model", None) or bool(_gp_names([c.strip() for c in crits.split(",")]))
    if target is not None and not given_file and not disc:
        raise InputError("--target-sigma needs --given (the poses already measured) or the discrepancy "
                         "(--criteria with a discrepancy-aware criterion "
                         "such as kpi_gp, or --model with a discrepancy)")
    if getattr(args, "curve", None) and not disc:
        raise InputError("--curve needs the discrepancy (--criteria with a discrepancy-aware criterion such as kpi_gp, "
                         "or --model with a discrepancy)")
    if target is not None and not (target > 0):
        raise InputError(f"--target-sigma: must be > 0 m, got {target}")
    if getattr(args, "no_hedge", False) and ("kpi_gp" not in [c.strip() for c in crits.split(",")]
                                             or getattr(args, "model", None)):
        raise InputError("--no-hedge applies to kpi_gp without --model (the assumed class default); "
                         f"--criteria {crits or '(default)'}" + (" with --model: a fitted discrepancy is never hedged"
                                                                  if getattr(args, "model", None) else ""))
    return pool_file, given_file, target


def _gp_names(criteria: list[str]) -> list[str]:
    """The discrepancy-aware criteria (``kpi_gp``, ``D_gp``, …) among registered names (others ignored)."""
    from pin_kpi_oed.design.declare import uses_discrepancy

    return uses_discrepancy(criteria)


def _print_declared(problem, reregister: str | None) -> None:
    """Print the working region and the re-registration the problem is declared with."""
    if problem.region is not None:
        print(problem.region.describe())
    if problem.Q_register is not None:
        print(f"used in another session: kpi_gp and the honest sigma score the TCP error after the tracker is "
              f"registered again on {len(problem.Q_register)} configuration(s) ({reregister})")


def print_header(cell, problem, m: int, seed: int, collision: bool, starts: int) -> None:
    """Print the cell summary and the size of the design problem."""
    rows = problem.coll.info.count()
    print(cell.summary())
    print(f"{m} measurements, seed {seed}, {'with' if collision else 'WITHOUT'} collision avoidance; "
          f"{problem.base.size} identifiable parameters; constraint rows per configuration: "
          + ", ".join(f"{k} {v}" for k, v in rows.items() if v)
          + f" (aggregated to {problem.cons.n_rows} for Ipopt); {starts} start(s) per criterion")


def print_results(results: list, criteria: list, cert, m: int, pool_file: str | None, quiet: bool, cell,
                   true_cell, margins: tuple[float, float], true_checks, given_file: str | None = None,
                   ext_scores: Sequence[dict] | None = None) -> None:
    """Print the result table, the certificate, the random design's acceptance and the infeasible designs."""
    shown = [r for r in results if r.criterion in criteria] or results
    ext_of = {id(r): e for r, e in zip(results, ext_scores)} if ext_scores is not None else None
    print(table(shown, results[0], cert, [ext_of[id(r)] for r in shown] if ext_of else None,
                ext_of[id(results[0])] if ext_of else None))
    held = next((r for r in shown if getattr(r, "held_trace_m2", 0.0) > 0), None)
    if held is not None:
        print(f"TCP sigma = sqrt((tr(C_s) + held) / t), held the same for every design: {held.held_line}")
    if ext_of:
        print("ext = extended model (geometry + the model file's effects, with the prior: the criterion the designs "
              "optimised); geo = identifiable geometry + set-up only, no prior (the plain design's tr(C_s))")
    if cert is not None:
        print(f"certificate: every {m}-pose design from the {cert.pool_size} feasible candidates "
              f"({'the user pool' if pool_file else 'random pool + the designs poses'})"
              f"{' on top of the measured poses' if given_file else ''} has tr(C_s) >= "
              f"{cert.lower_bound_trace_cs_m2 * 1e6:.4e} mm^2 "
              + (f"(equivalence theorem: mean of the {m} largest d / phi = {cert.approx.max_d_ratio:.4f})"
                 if not given_file else f"(equivalence theorem with the measured poses' information as a fixed "
                                        f"part: 1 + gap = {cert.approx.max_d_ratio:.4f})"))
    if not quiet and not pool_file:
        rnd = results[0]
        print(f"random design: {rnd.samples} uniform random poses drawn for {m} feasible ones "
              f"({100.0 * m / max(rnd.samples or 1, 1):.2f} % accepted); tr(C_s) in the tracker frame, "
              f"sigma = {cell.noise.sigma_xyz_m[0] * 1e6:g} um per axis; check = independent dense check")
    if not quiet:
        for r in results:
            if not r.feasible:
                print(f"  {r.criterion}: {', '.join(r.check.get('violations', [])[:3])}")
        if true_checks is not None:
            print(f"margins: clearance {margins[0] * 1e3:g} mm, incidence {margins[1]:g} deg "
                  f"enforced by the optimiser; "
                  f"min clr / max inc above are the TRUE values (cell clearance {true_cell.clearance_m * 1e3:g} mm, "
                  f"incidence limit {true_cell.incidence_max_deg:g} deg)")


def _sigma_plan(problem, m: int) -> str:
    """What the discrepancy fit of the designed poses (and any --given ones) will need, and how identify will obtain
    the σ at that size (:func:`~pin_kpi_oed.discrepancy.gp.sigma_plan`)."""
    from pin_kpi_oed.discrepancy.gp import sigma_plan

    Qg = problem.Q_given
    return sigma_plan(m + (0 if Qg is None else len(Qg)), int(problem.base.size))




def _discrepancy_notes(problem, gp_names: list[str]) -> None:
    """Print that no certificate exists for the discrepancy-aware criteria, and the lever arm when the TCP is away
    from the reflector."""
    from pin_kpi_oed.oed.discrepancy_criteria import no_certificate

    print(*(no_certificate(c) for c in gp_names), sep="\n", end="\n" if gp_names else "")
    if "kpi_gp" in gp_names and problem.discrepancy_assumed and problem.hedge:
        from pin_kpi_oed.oed.hedged_kpi import HEDGE_LINE

        print(in_flags(HEDGE_LINE).replace("(hedge False:", "(--no-hedge:"))
    from pin_kpi_oed.discrepancy.lever_arm import LEVER_ARM_NOTE_M, lever_arm_line, lever_arm_m

    d = lever_arm_m(problem.model.tcp_m, problem.model.reflector_m)
    if d >= LEVER_ARM_NOTE_M:
        print(lever_arm_line(d))


def discrepancy_table(results: list, scores: list[dict]) -> str:
    """The predicted TCP σ at the working configurations: the paper's (tracker noise only) beside the honest one
    (discrepancy included), and the honest one over the working region when the scores hold it, µm."""
    region = any("tcp_sigma_region_m" in sc for sc in scores)
    head = (f"{'criterion':<10}{'paper sigma um':>16}{'with discrepancy sigma um':>27}"
            + (f"{'over the region um':>20}" if region else ""))
    lines = [head, "-" * len(head)]
    for r, sc in zip(results, scores):
        lines.append(f"{r.criterion:<10}{r.tcp_sigma_m * 1e6:>16.3f}{sc['tcp_sigma_m'] * 1e6:>27.3f}"
                     + (f"{sc.get('tcp_sigma_region_m', float('nan')) * 1e6:>20.3f}" if region else ""))
    return "\n".join(lines)


def _given_prior(path: str, cell):
    """``--given-prior``: the parameter covariance of a calibrated model file, the prior of the robot parameters."""
    from pin_kpi_oed.design.problem_options import ParameterPrior
    from pin_kpi_oed.calibrated.model_file import load_model_file

    try:
        cm = load_model_file(path)
    except InputError as exc:
        raise InputError(f"--given-prior: {exc}") from None
    check_same_robot(cm.robot, cell.robot, f"--given-prior {path}")
    return ParameterPrior.from_model_file(cm, path)
