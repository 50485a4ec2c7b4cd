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
import dataclasses
import math
from collections.abc import Sequence

import numpy as np

from pin_kpi_oed.design.runner import DesignRun, DesignSettings, design_run, true_checks
from pin_kpi_oed.design.design_writer import write_design
from pin_kpi_oed.design.scores import discrepancy_scores, extended_scores, sigma_given
from pin_kpi_oed.identification.prediction_sigma import sigma_at
from pin_kpi_oed.design.margins import DEFAULT_CLEARANCE_MARGIN_M, DEFAULT_INCIDENCE_MARGIN_DEG, with_margins
from pin_kpi_oed.errors import IdentifiabilityError, InputError
from pin_kpi_oed.oed.criteria import check_names, criterion_names, get_criterion
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
    p.add_argument("--pool-size", dest="pool_size", type=int, default=5000,
                   help="feasible candidates of the certificate's pool (default 5000)")
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
    p.set_defaults(func=run)


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
    head = (f"{'criterion':<10}" + (f"{'ext tr(C_s) mm^2':>18}{'ext sigma um':>14}" if ext_by_id else "")
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
        lines.append(f"{r.criterion:<10}{ext}{r.trace_cs_m2 * 1e6:>{18 if ext_by_id else 14}.4e}"
                     f"{r.tcp_sigma_m * 1e6:>14.4f}{imp:>+{13 if ext_by_id else 12}.1f}"
                     f"{r.min_clearance_m * 1e3:>11.1f}{r.max_incidence_deg:>12.1f}{it:>7}"
                     f"{r.time_s:>8.2f}"
                     + (f"{100 * certificate.efficiency(r.trace_cs_m2):>10.1f}" if certificate else "")
                     + f"  {chk}")
    return "\n".join(lines)



def run(args: argparse.Namespace) -> int:
    """Handler of ``pin-kpi-oed design`` (returns the exit code).

    Raises:
        PinKpiOedError: bad cell, unknown criterion, infeasible cell, solver failure (one-line message).
    """
    from pin_kpi_oed.cell.cell import load_cell
    from pin_kpi_oed.design.path_profile import path_profiles, profile_lines
    from pin_kpi_oed.design.user_pool import check_candidates, design_from_pool, duplicates_line, pool_line, read_pool

    criteria = parse_criteria(getattr(args, "criteria", "random,param,kpi"))
    cell = load_cell(getattr(args, "cell", "kr15"))
    m, seed, collision, starts, max_iter, quiet = _run_knobs(args, cell)
    true_cell = cell
    margins = (float(getattr(args, "clearance_margin", 0.0) or 0.0),
               float(getattr(args, "incidence_margin", 0.0) or 0.0))
    cell = with_margins(cell, *margins)  # the optimiser's cell; `true_cell` for the reported clearances
    pool_file, given_file, target = _pool_given_target(args)
    problem = _make_problem(args, cell, given_file, collision, quiet, true_cell)
    gp_names = _gp_names(criteria)
    disc_on = problem.discrepancy is not None or bool(gp_names)
    if target is not None and not disc_on and not given_file:
        raise InputError(f"--target-sigma needs --given or a discrepancy: --model {getattr(args, 'model', None)} "
                         f"holds no discrepancy block (write it with identify --model-out)")
    if target is not None and not disc_on:  # before any work: "how many more" needs M⁻¹ of the measured poses
        problem.require_identified(f"--target-sigma: --given {given_file}")
    if not quiet:
        print_header(cell, problem, m, seed, collision, starts)
    _set_region(args, problem, criteria, seed, true_cell)
    _set_reregister(args, problem, disc_on)
    settings = DesignSettings(criteria=tuple(criteria), measurements=m, seed=seed, collision=collision,
                              n_starts=starts, max_iter=max_iter, start=getattr(args, "start", "pool") or "pool",
                              certificate=bool(getattr(args, "certificate", False)),
                              certificate_pool_size=getattr(args, "pool_size", 5000) or 5000,
                              clearance_margin_m=margins[0], incidence_margin_deg=margins[1])
    checked = None
    if pool_file:
        Qc, outside = read_pool(pool_file, cell.robot, "--pool")
        reasons: dict[str, int] = {}
        ok, Fp, _ = check_candidates(problem, Qc, reasons=reasons)
        print(pool_line(pool_file, len(Qc) + len(outside), outside, int(ok.sum()), reasons))
        checked = (Qc[ok], Fp)
        try:
            results, cert, n_ok = design_from_pool(problem, Qc, criteria, m, seed, checked=(ok, Fp))
        except IdentifiabilityError as exc:  # near-duplicate candidates: name their rows
            rows = np.setdiff1d(np.arange(1, len(Qc) + len(outside) + 1), outside)[ok]
            raise IdentifiabilityError(duplicates_line(pool_file, Qc[ok], rows) or f"--pool {pool_file}: {exc}") \
                from None
        run = DesignRun(cell=true_cell, problem=problem, results=results, m=m, seed=seed, collision=collision,
                        margins=margins, certificate=cert,
                        true_checks=true_checks(true_cell, results) if cell is not true_cell else None,
                        extended_scores=extended_scores(problem, results, true_cell.q_work),
                        discrepancy_scores=discrepancy_scores(problem, results) if disc_on else None,
                        path_profiles=path_profiles(problem, results, discrepancy=disc_on))
    else:
        run = design_run(true_cell, settings, problem, discrepancy=disc_on)
    run = dataclasses.replace(run, given_file=given_file, pool_file=pool_file, model_file=getattr(args, "model", None),
                              prior=getattr(args, "prior", None))
    results = list(run.results)
    print_results(results, criteria, run.certificate, m, pool_file, quiet, cell, true_cell, margins, run.true_checks,
                   given_file, run.extended_scores)
    print(*profile_lines(run.path_profiles), sep="\n", end="\n" if run.path_profiles else "")
    if run.discrepancy_scores is not None:  # opt-in: the paper's output is unchanged without
        gp_scores = list(run.discrepancy_scores)
        print(problem.discrepancy_prior().describe() + "\n" + _sigma_plan(problem, m))
        if given_file:
            print(f"measured poses alone ({len(problem.Q_given)}): predicted TCP sigma with the discrepancy "
                  f"{sigma_given(problem) * 1e6:.3f} um; the table adds each design's poses to them")
        print(discrepancy_table([r for r in results if r.criterion in criteria] or results,
                                [g for r, g in zip(results, gp_scores) if r.criterion in criteria] or gp_scores))
        _discrepancy_notes(problem, gp_names)
    curve = None
    if disc_on and (target is not None or getattr(args, "curve", None)):
        curve = _poses_needed(args, problem, cell, target, seed, m, checked, results)
    until = _poses_until(args, problem, cell, target, seed, checked) if target is not None and not disc_on else None
    if getattr(args, "json", None):
        write_design(args.json, dataclasses.replace(run, until=until, poses_needed=curve))
        if not quiet:
            print(f"wrote {args.json}")
    return 0


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
    return [c for c in criteria if c != "random" and getattr(get_criterion(c), "uses_discrepancy", False)]


def _set_region(args: argparse.Namespace, problem, criteria: list[str], seed: int, true_cell) -> None:
    """``--work-radius`` / ``--work-samples``: the working region of ``kpi_gp`` (default 0.5 rad and 100 samples
    with kpi_gp, none otherwise), drawn with the design's seed, within the joint bounds and collision-free in the
    untightened cell; prints it.

    The region is always sampled, also with ``--pool``: the pool is where one may measure, the region where the robot
    works (a pool's rows near W would cover the region only where the candidates happen to lie).

    Raises:
        InputError: a negative radius or number of samples.
    """
    from pin_kpi_oed.design.region import DEFAULT_WORK_RADIUS_RAD, DEFAULT_WORK_SAMPLES

    # the options that act only with the discrepancy, refused (not ignored) without it
    check_discrepancy_options(args, bool(_gp_names(criteria)), getattr(problem, "discrepancy", None) is not None)
    radius = getattr(args, "work_radius", None)
    samples = getattr(args, "work_samples", None)
    samples = DEFAULT_WORK_SAMPLES if samples is None else int(samples)
    if radius is None:
        radius = DEFAULT_WORK_RADIUS_RAD if "kpi_gp" in criteria else 0.0
    if radius < 0 or samples < 0:
        raise InputError(f"--work-radius ({radius:g}) and --work-samples ({samples}) must be >= 0")
    if radius == 0 or samples == 0:
        return
    problem.set_region(radius, samples, seed, cell=true_cell)
    print(problem.region.describe())


def _set_reregister(args: argparse.Namespace, problem, disc_on: bool) -> None:
    """``--reregister work|FILE``: score kpi_gp and the honest σ after the set-up is registered again on these
    configurations (:attr:`DesignProblem.Q_register`); prints one line.

    Raises:
        InputError: without a discrepancy, an unreadable file, or configurations that do not determine the set-up.
    """
    where = getattr(args, "reregister", None)
    if where is None:
        return
    if not disc_on:
        raise InputError("--reregister needs the discrepancy: a discrepancy-aware criterion such as kpi_gp, or --model "
                         "with a discrepancy")
    if where == "work":
        region = getattr(problem, "region", None)
        Q = region.configurations() if region is not None else problem.cell.q_work
    else:
        from pin_kpi_oed.design.user_pool import read_poses

        Q = read_poses(where, problem.cell.robot, "--reregister")
    problem.Q_register = np.atleast_2d(Q)
    try:
        problem.gp_criterion(region=False)                 # checks that they determine the set-up
    except InputError as err:
        raise InputError(f"--reregister {where}: {err}") from None
    print(f"used in another session: kpi_gp and the honest sigma score the TCP error after the tracker is registered "
          f"again on {len(problem.Q_register)} configuration(s) ({where})")


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


def _poses_until(args: argparse.Namespace, problem, cell, target: float, seed: int, checked=None):
    """``--target-sigma``: add poses from the user's feasible ``--pool`` candidates (``checked`` = (poses, their
    Jacobians)) or from a random feasible pool until the target is met; prints and returns the result."""
    from pin_kpi_oed.design.sequential import poses_until

    if checked is not None:
        until = poses_until(problem, float(target), checked[0], Fp=checked[1])
        print(until.summary() + f" (from the {len(checked[0])} feasible --pool candidates)")
        return until
    pool_q, _ = problem.random_design(getattr(args, "pool_size", 5000) or 5000,
                                      seed=np.random.SeedSequence([seed, 2]),
                                      max_tries=max(cell.max_random_tries,
                                                    200 * (getattr(args, "pool_size", 5000) or 5000)))
    until = poses_until(problem, float(target), pool_q)
    print(until.summary())
    return until


def _poses_needed(args: argparse.Namespace, problem, cell, target: float | None, seed: int, m: int, checked=None,
                  results: list | None = None):
    """The poses-needed curve with the discrepancy (and the answer to ``--target-sigma``) over the user's feasible
    ``--pool`` candidates or random feasible poses (at most 2,000, seeded) plus the feasible poses of the optimised
    designs in ``results``; prints the answer, writes ``--curve``."""
    from pin_kpi_oed.oed.discrepancy_kpi import poses_needed

    if checked is not None:
        Q_pool = checked[0]
        what = "feasible --pool candidates"
    else:
        size = min(getattr(args, "pool_size", 5000) or 5000, 2000)
        Q_pool, _ = problem.random_design(size, seed=np.random.SeedSequence([seed, 3]),
                                          max_tries=max(cell.max_random_tries, 200 * size))
        # the optimised designs' own poses join the random ones (as in the certificate's pool): the curve and its
        # plateau never claim less than a design of the table reaches
        extra = [np.asarray(r.q_meas, float) for r in (results or []) if r.criterion != "random" and r.feasible]
        if extra:
            Q_pool = np.vstack([Q_pool] + extra)
        what = "feasible candidates: random" + (" + the designs' poses" if extra else "")
    n_max = min(len(Q_pool), max(4 * m, 120))
    curve = poses_needed(problem.gp_criterion(region=False), Q_pool, n_max, target_sigma_m=target, seed=seed)
    print(curve.summary() + f" ({len(Q_pool)} {what}, {curve.time_s:.1f} s)")
    if getattr(args, "curve", None):
        from pin_kpi_oed.viz.poses_needed import plot_poses_needed

        src = problem.discrepancy_prior().source or "given"
        plot_poses_needed(curve.to_dict(), args.curve, title=f"{cell.name}: poses needed (σ with the discrepancy: "
                                                             f"{src if len(src) <= 70 else src[:67] + '...'})")
        print(f"wrote {args.curve}")
    return curve


def _make_problem(args: argparse.Namespace, cell, given_file, collision: bool, quiet: bool, true_cell=None):
    """The design problem of ``design``: plain, on top of ``--given`` poses (checked in the true cell, with the
    ``--given-prior``), or over an extended model (``--model``)."""
    from pin_kpi_oed.design.optimize import DesignProblem
    from pin_kpi_oed.design.sequential import SequentialProblem
    from pin_kpi_oed.design.user_pool import read_poses

    problem: DesignProblem
    if given_file:
        Qg = read_poses(given_file, cell.robot, "--given")
        _check_given(true_cell or cell, Qg, given_file)
        problem = seq = SequentialProblem(cell, Qg, collision=collision)
        if getattr(args, "given_prior", None):
            seq.set_prior(_given_prior(args.given_prior, seq))
            seq.prior_file = str(args.given_prior)
    else:
        problem = DesignProblem(cell, collision=collision,
                                distances={"closed-form": "numpy"}.get(getattr(args, "distances", None), "geometry"))
    problem.robot_class = getattr(args, "robot_class", None)
    problem.hedge = not getattr(args, "no_hedge", False)
    if getattr(args, "model", None):
        if given_file:  # a measurement campaign: the discrepancy re-fitted on the measured batch, geometric design
            from pin_kpi_oed.cli.tool import model_cell_tool
            from pin_kpi_oed.identification.model_file import load_model_file

            cm = load_model_file(args.model)
            model_cell_tool(cm, args.model, cell, args.cell)  # the model's robot, tool frame and TCP are the cell's
            _set_discrepancy(problem, cm, args.model)
            from pin_kpi_oed.identification.design_discrepancy import refit_discrepancy

            line = refit_discrepancy(problem, given_file)
            if not quiet:
                print(line)
            return problem
        from pin_kpi_oed.cli.tool import model_cell_tool
        from pin_kpi_oed.identification.model_file import load_model_file
        from pin_kpi_oed.oed.extended import ExtendedModel

        prior = getattr(args, "prior", "model") or "model"
        cm = load_model_file(args.model)
        model_cell_tool(cm, args.model, cell, args.cell)  # the model's robot, tool frame and TCP are the cell's
        _set_discrepancy(problem, cm, args.model)
        problem.extended = ExtendedModel.from_calibrated_model(cm, model=problem.model,
                                                               base=problem.base,
                                                               prior=None if prior == "none" else prior)
        if not quiet:
            print(f"extended model from {args.model}: {problem.extended.nb} geometric + {problem.extended.k} effect "
                  f"parameters, prior: {prior}")
    return problem


def _set_discrepancy(problem, cm, path: str) -> None:
    """The discrepancy of ``--model`` (its kernel, per-axis scale and white level; the data it was fitted on are not
    used: a new calibration re-fits the robot) as the problem's discrepancy.

    Raises:
        InputError: the model file's robot has other joints than the cell's.
    """
    from pin_kpi_oed.discrepancy.prior import DiscrepancyPrior

    if cm.discrepancy is None:
        return
    if list(cm.robot.joint_names) != list(problem.cell.robot.joint_names):
        raise InputError(f"--model {path}: its robot's joints {list(cm.robot.joint_names)} are not the cell's "
                         f"{list(problem.cell.robot.joint_names)}")
    problem.discrepancy = DiscrepancyPrior.from_discrepancy(
        cm.discrepancy, f"--model {path}, fitted on {cm.discrepancy.n_rows} rows ({cm.discrepancy.kind})")
    sig, far = sigma_at(cm, problem.cell.q_work)
    problem.model_sigma = {"sigma_m": sig.tolist(), "extrapolated": far.tolist(), "note": "as predict gives it"}
    print(f"--model {path}: predicted sigma now at the working configurations (as predict gives it): "
          + ", ".join(f"{s * 1e3:.4f} mm" + (" (outside the coverage)" if f else "") for s, f in zip(sig, far))
          + (f"; {int(far.sum())} of {len(far)} outside the calibration's joint-space coverage: its discrepancy was "
             "not learnt there (the sigma is widened by the parameters' extrapolation error, predict / compensate "
             "flag them); the design's poses near them measure it" if far.any() else ""))


def _sigma_plan(problem, m: int) -> str:
    """What the discrepancy fit of the designed poses (and any --given ones) will need, and how identify will obtain
    the σ at that size (:func:`~pin_kpi_oed.discrepancy.gp.sigma_plan`)."""
    from pin_kpi_oed.discrepancy.gp import sigma_plan

    Qg = getattr(problem, "Q_given", None)
    return sigma_plan(m + (0 if Qg is None else len(Qg)), int(problem.base.size))




def _discrepancy_notes(problem, gp_names: list[str]) -> None:
    """Print that no certificate exists for the discrepancy-aware criteria, and the lever arm when the TCP is away
    from the reflector."""
    from pin_kpi_oed.oed.discrepancy_criteria import no_certificate

    print(*(no_certificate(c) for c in gp_names), sep="\n", end="\n" if gp_names else "")
    if "kpi_gp" in gp_names and problem.discrepancy_assumed and problem.hedge:
        from pin_kpi_oed.oed.hedged_kpi import HEDGE_LINE

        print(HEDGE_LINE)
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


def _check_given(cell, Q, path: str) -> None:
    """The measured poses must pass the independent check of the (untightened) cell.

    Raises:
        InputError: naming the file and the first infeasible poses (pose numbers count data rows from 1).
    """
    from pin_kpi_oed.cell.feasibility import FeasibilityChecker

    rep = FeasibilityChecker(cell).check(Q)
    if not rep.all_feasible:
        bad = np.flatnonzero(~rep.feasible)
        why = "; ".join(v.replace(f"pose {i}:", f"row {i + 1}:", 1) for i, v in zip(bad, rep.violations(2)))
        raise InputError(f"--given {path}: {bad.size} of {len(Q)} measured poses are infeasible in cell "
                         f"{cell.name} ({why}); remove them or fix the cell")


def _given_prior(path: str, problem) -> np.ndarray:
    """Prior information over the identifiable parameters from a calibrated model file's parameter covariance."""
    from pin_kpi_oed.design.sequential import prior_information
    from pin_kpi_oed.identification.model_file import load_model_file

    try:
        cm = load_model_file(path)
    except InputError as exc:
        raise InputError(f"--given-prior: {exc}") from None
    check_same_robot(cm.robot, problem.cell.robot, f"--given-prior {path}")
    par = cm.parameters or {}
    if par.get("covariance") is None or not par.get("names"):
        raise InputError(f"--given-prior {path}: the model file holds no parameter covariance")
    return prior_information(problem, list(par["names"]), np.asarray(par["covariance"], float), f"--given-prior {path}")
