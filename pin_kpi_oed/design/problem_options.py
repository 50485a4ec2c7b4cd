"""What a design problem is declared with: :class:`ProblemOptions` (frozen), passed to
:class:`~pin_kpi_oed.design.optimize.DesignProblem` at construction; nothing is set on a problem afterwards.

A problem is the cell's model, identifiable set, KPI sensitivity and constraints, plus these declarations:

* the constraints' formulation: collision avoidance, pruning, the aggregation of the distance rows, the distances;
* poses already measured, Q_given, whose information F_gᵀF_g counts in every criterion and score, and an earlier
  calibration's prior on the robot parameters, Σ₀⁻¹ (:class:`ParameterPrior`, the covariance of a model file:
  :func:`prior_information` marginalises it to the identifiable robot parameters and inverts it there);
* an extended model (:class:`~pin_kpi_oed.oed.extended.ExtendedModel`: geometry + effects with a prior) the criteria
  of the information matrix are taken on;
* the discrepancy (:class:`~pin_kpi_oed.discrepancy.prior.DiscrepancyPrior`) of the discrepancy-aware criteria and
  of the honest σ (None: the robot class's default, :func:`~pin_kpi_oed.oed.discrepancy_defaults.class_discrepancy`,
  an assumption that ``kpi_gp`` hedges over unless ``hedge`` is False);
* the working region (:func:`~pin_kpi_oed.design.region.region_in_cell`) ``kpi_gp`` takes its KPI over, and the
  configurations Q_register where the set-up is registered again before the calibration is used in another session.

Units SI: rad, m; information in 1/m², 1/rad².
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from pin_kpi_oed.errors import InputError

__all__ = ["ProblemOptions", "ParameterPrior", "prior_information"]


@dataclass(frozen=True)
class ParameterPrior:
    """An earlier calibration's parameter covariance, the prior of a design on top of measured poses.

    Attributes:
        names: parameter names of the covariance (e.g. ``joint_a2.tx``).
        covariance: (k, k) in m², rad² (as the model file stores it).
        source: where it came from (the model file), for messages and the design file.
    """

    names: tuple[str, ...]
    covariance: np.ndarray = field(repr=False)
    source: str = "given_prior"

    @classmethod
    def from_model_file(cls, cm: Any, source: str) -> ParameterPrior:
        """The parameter covariance of a calibrated model (:class:`~pin_kpi_oed.calibrated.model_file.
        CalibratedModel`) read from ``source``.

        Raises:
            InputError: the model file holds no parameter covariance (named ``given_prior``).
        """
        par = cm.parameters or {}
        if par.get("covariance") is None or not par.get("names"):
            raise InputError(f"given_prior {source}: the model file holds no parameter covariance")
        return cls(tuple(par["names"]), np.asarray(par["covariance"], float), source)


@dataclass(frozen=True, eq=False)
class ProblemOptions:
    """The declaration of a :class:`~pin_kpi_oed.design.optimize.DesignProblem` (frozen).

    Attributes:
        collision: impose the collision and line-of-sight constraints (False: joint bounds and incidence only, the
            paper's "without collision avoidance"; the heuristic design is always collision-free).
        prune: drop constraint rows that can never be active.
        aggregate: per-configuration aggregation of the distance rows: ``"ks"`` (smooth, conservative, exact
            gradient), ``"min"`` or ``"none"`` (every row; the naive formulation).
        ks_length_m: KS smoothing length (m).
        distances: ``"geometry"`` (Coal through a Pinocchio GeometryModel) or ``"numpy"`` (the closed-form segment
            distances, the test oracle).
        Q_given: poses already measured (k, n) rad, or None; their information counts in every criterion.
        given_prior: with Q_given, an earlier calibration's prior on the robot parameters: a
            :class:`ParameterPrior` (resolved by :func:`prior_information`) or the information Σ₀⁻¹ (nb, nb) over the
            identifiable parameters.
        extended: an :class:`~pin_kpi_oed.oed.extended.ExtendedModel`: the criteria of the information matrix are
            taken on geometry + its effects with its prior (``design --model``).
        discrepancy: the :class:`~pin_kpi_oed.discrepancy.prior.DiscrepancyPrior` of the discrepancy-aware criteria
            and the honest σ; None: the default of the robot's class (an assumption).
        robot_class: the class of that default (a key of
            :data:`~pin_kpi_oed.oed.discrepancy_defaults.ROBOT_CLASSES`; None: from the robot's name).
        hedge: hedge ``kpi_gp`` over a family of priors around an assumed discrepancy (False: the assumed one alone).
        region: the :class:`~pin_kpi_oed.design.region.WorkingRegion` ``kpi_gp`` takes its KPI over (None: the
            working configurations alone).
        Q_register: configurations (r, n) rad where the set-up is registered again before the calibration is used
            in another session: ``kpi_gp`` and the honest σ score the TCP error after that registration; None: used
            in the set-up it is measured in.

    Raises:
        InputError: a prior without measured poses, an unknown aggregation or distances.
    """

    collision: bool = True
    prune: bool = True
    aggregate: str = "ks"
    ks_length_m: float = 2e-3
    distances: str = "geometry"
    Q_given: np.ndarray | None = field(default=None, repr=False)
    given_prior: ParameterPrior | np.ndarray | None = field(default=None, repr=False)
    extended: Any = field(default=None, repr=False)
    discrepancy: Any = None
    robot_class: str | None = None
    hedge: bool = True
    region: Any = field(default=None, repr=False)
    Q_register: np.ndarray | None = field(default=None, repr=False)

    def __post_init__(self) -> None:
        if self.given_prior is not None and self.Q_given is None:
            raise InputError("given_prior needs Q_given (the poses already measured)")
        if self.aggregate not in ("ks", "min", "none"):
            raise InputError(f"aggregate: 'ks', 'min' or 'none', got {self.aggregate!r}")
        if self.distances not in ("geometry", "numpy"):
            raise InputError(f"distances: 'geometry' or 'numpy', got {self.distances!r}")
        if self.Q_given is not None:
            object.__setattr__(self, "Q_given", np.atleast_2d(np.asarray(self.Q_given, float)))
        if self.Q_register is not None:
            object.__setattr__(self, "Q_register", np.atleast_2d(np.asarray(self.Q_register, float)))


def prior_information(problem: Any, names: list[str] | tuple[str, ...], covariance: np.ndarray,
                      source: str = "prior") -> np.ndarray:
    """Prior information Σ₀⁻¹ over the problem's identifiable parameters from an earlier calibration.

    The covariance of the parameters (matched by name, e.g. ``joint_a2.tx``) is marginalised to the
    identifiable robot parameters it contains and inverted there (pseudo-inverse); set-up parameters
    (tracker, reflector) get no prior: a new measurement set-up is placed anew.

    Args:
        problem: the design problem (its ``model.layout`` and identifiable set ``base``).
        names: parameter names of the covariance.
        covariance: (k, k) in m², rad² (as the model file stores it).
        source: the file, for messages.

    Returns:
        (nb, nb) information (1/m², 1/rad²), zero where no prior.

    Raises:
        InputError: a covariance that does not match its names, or no identifiable robot parameter in it.
    """
    cov = np.asarray(covariance, float)
    if cov.ndim != 2 or cov.shape != (len(names), len(names)) or not np.all(np.isfinite(cov)):
        raise InputError(f"{source}: parameter covariance is {cov.shape} (finite values needed) for {len(names)} names")
    layout = problem.model.layout
    setup = set(layout.setup_groups)
    here = {layout.names[i]: k for k, i in enumerate(problem.base) if layout.names[i].split(".")[0] not in setup}
    pairs = [(here[n], j) for j, n in enumerate(names) if n in here]
    if not pairs:
        raise InputError(f"{source}: its covariance names none of the identifiable robot parameters "
                         f"({', '.join(list(here)[:3])}, ...)")
    ii, jj = np.array(pairs).T
    P = np.zeros((problem.base.size, problem.base.size))
    P[np.ix_(ii, ii)] = np.linalg.pinv(cov[np.ix_(jj, jj)], rcond=1e-12, hermitian=True)
    return 0.5 * (P + P.T)
