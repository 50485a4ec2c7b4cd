"""The design problem a run's settings declare (:func:`design_problem`): the cell tightened by the margins, the
measured poses (checked in the untightened cell) and their prior, the model file's extended model and discrepancy, the
working region and the re-registration, built into one frozen
:class:`~pin_kpi_oed.design.problem_options.ProblemOptions`. ``design`` and the Python API declare a problem through
it; errors name the settings' parameters (``Q_given``, ``Q_register``, ``model_file``, ...). Units SI (rad, m).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from pin_kpi_oed.errors import InputError

__all__ = ["design_problem", "model_discrepancy", "check_given", "register_configurations", "uses_discrepancy"]


def uses_discrepancy(criteria: Any) -> list[str]:
    """The discrepancy-aware criteria (``kpi_gp``, ``D_gp``, …) among registered names (``random`` ignored)."""
    from pin_kpi_oed.oed.criteria import get_criterion

    return [c for c in criteria if c != "random" and getattr(get_criterion(c), "uses_discrepancy", False)]


def check_given(cell: Any, Q: np.ndarray, path: str) -> None:
    """The measured poses must pass the independent check of the (untightened) cell.

    Raises:
        InputError: naming the file and the first infeasible poses (pose numbers count data rows from 1).
    """
    from pin_kpi_oed.cell.feasibility import FeasibilityChecker

    rep = FeasibilityChecker(cell).check(Q)
    if not rep.all_feasible:
        bad = np.flatnonzero(~rep.feasible)
        why = "; ".join(v.replace(f"pose {i}:", f"row {i + 1}:", 1) for i, v in zip(bad, rep.violations(2)))
        raise InputError(f"Q_given {path}: {bad.size} of {len(Q)} measured poses are infeasible in cell "
                         f"{cell.name} ({why}); remove them or fix the cell")


def model_discrepancy(cell: Any, cm: Any, path: str | None) -> Any:
    """The discrepancy of a calibrated model file (its kernel, per-axis scale and white level; the data it was fitted
    on are not used: a new calibration re-fits the robot) as a design's
    :class:`~pin_kpi_oed.discrepancy.prior.DiscrepancyPrior`, or None when the file holds none.

    Raises:
        InputError: the model file's robot has other joints than the cell's (named ``model_file``).
    """
    from pin_kpi_oed.discrepancy.prior import DiscrepancyPrior

    if cm.discrepancy is None:
        return None
    if list(cm.robot.joint_names) != list(cell.robot.joint_names):
        raise InputError(f"model_file {path}: its robot's joints {list(cm.robot.joint_names)} are not the cell's "
                         f"{list(cell.robot.joint_names)}")
    prior = DiscrepancyPrior.from_discrepancy(
        cm.discrepancy, f"model_file {path}, fitted on {cm.discrepancy.n_rows} rows ({cm.discrepancy.kind})")
    return prior


def register_configurations(where: str | None, cell: Any, region: Any) -> np.ndarray | None:
    """The configurations of a re-registration before use in another session: ``"work"`` = the working
    configurations and the working region's, else a CSV of joint columns (rad); None for None.

    Raises:
        InputError: an unreadable file (named ``Q_register``).
    """
    if where is None:
        return None
    if where == "work":
        return region.configurations() if region is not None else cell.q_work
    from pin_kpi_oed.design.user_pool import read_poses

    return read_poses(where, cell.robot, "Q_register")


def design_problem(cell: Any, settings: Any) -> Any:
    """The :class:`~pin_kpi_oed.design.optimize.DesignProblem` a run's settings declare.

    Args:
        cell: the cell as given (untightened: the measured poses are checked and the working region drawn in it).
        settings: the run's :class:`~pin_kpi_oed.design.runner.DesignSettings` (margins, collision, distances,
            ``given_file`` + ``given_prior``, ``model`` + ``model_prior`` / ``discrepancy``, ``robot_class``,
            ``hedge``, ``work_radius_rad`` / ``work_samples``, ``reregister``).

    Returns:
        The problem on the cell tightened by the margins.

    Raises:
        InputError: infeasible or unreadable measured poses, a model of another robot, a re-registration without the
            discrepancy or that does not determine the set-up.
    """
    from pin_kpi_oed.design.margins import with_margins
    from pin_kpi_oed.design.optimize import DesignProblem
    from pin_kpi_oed.design.problem_options import ProblemOptions
    from pin_kpi_oed.design.region import default_region
    from pin_kpi_oed.design.user_pool import read_poses

    s = settings
    tight = with_margins(cell, s.clearance_margin_m, s.incidence_margin_deg)
    Q_given = None
    if s.given_file:
        Q_given = read_poses(s.given_file, cell.robot, "Q_given")
        check_given(cell, Q_given, s.given_file)
    discrepancy, extended = s.discrepancy, None
    if s.model is not None:
        if discrepancy is None:
            discrepancy = model_discrepancy(cell, s.model, s.model_file)
        if Q_given is None:  # with measured poses: a geometric design with the model's (re-fitted) discrepancy
            from pin_kpi_oed.oed.extended import ExtendedModel

            extended = ExtendedModel.from_calibrated_model(s.model, model=tight.tracker_model(),
                                                           prior=None if s.model_prior == "none" else s.model_prior)
    region = default_region(cell, s.criteria, s.work_radius_rad, s.work_samples, s.seed)
    if s.reregister is not None and discrepancy is None and not uses_discrepancy(s.criteria):
        raise InputError("Q_register needs the discrepancy: a discrepancy-aware criterion such as kpi_gp, or "
                         "model_file with a discrepancy")
    Q_register = register_configurations(s.reregister, cell, region)
    options = ProblemOptions(collision=s.collision, distances=s.distances, Q_given=Q_given, given_prior=s.given_prior,
                             extended=extended, discrepancy=discrepancy, robot_class=s.robot_class, hedge=s.hedge,
                             region=region, Q_register=Q_register)
    problem = DesignProblem(tight, options)
    if Q_register is not None:
        try:
            problem.gp_criterion(region=False)                 # checks that they determine the set-up
        except InputError as err:
            raise InputError(f"Q_register {s.reregister}: {err}") from None
    return problem
