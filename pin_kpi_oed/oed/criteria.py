"""Design criteria φ as objects: value, exact gradient, unit, label, pool-selection form (paper eqs. 8–10, 19, 24a).

All criteria are written *to be minimised*. With F the weighted Jacobian over
the identifiable parameters (eq. 24d), M = FᵀF + P its information matrix,
C_p = M⁻¹, E the KPI sensitivity at the working configurations (eq. 24e) and
μ₁ ≥ … ≥ μ_r the singular values of F:

==========  =====================================  ==================================
name        φ                                      meaning
==========  =====================================  ==================================
``kpi``     tr(C_s) = tr(E C_p Eᵀ)  (m²)           A on C_s: the paper's KPI criterion (eqs. 19, 24a)
``param``   tr(C_p)                                A on C_p: the paper's state of the art
``D``       −log det M                             D-optimality (eq. 10, Daney)
``E``       λ_max(C_p) = 1/λ_min(M)                E-optimality
``cond``    μ₁/μ_r                                 condition number (eq. 9)
``O1``      −log((μ₁⋯μ_r)^{1/r}/√m)                Borm–Menq O1 (eq. 8), maximised
``O2``      −log(μ_r/μ₁)                           inverse condition number
``O3``      −log μ_r                               minimum singular value
``O4``      −log(μ_r²/μ₁)                          noise amplification index (Nahvi)
``O5``      log Σ 1/μ_i                            Sun–Hollerbach O5 = 1/Σ(1/μ_i)
==========  =====================================  ==================================

**Two kinds of criteria, one class each.**

* A :class:`Criterion` is a function of the information matrix (in the spirit of cvxpy's atoms): φ(M₀) and
  Γ = ∂φ/∂M₀ (:meth:`Criterion.value_and_grad_M`, M₀ the information of the measurements, the prior Σ₀⁻¹ given
  apart), the same on the weighted Jacobian F (:meth:`Criterion.value_and_grad_F`, dφ/dF = 2FΓ unless a subclass
  has a better form) and its pool form (:meth:`Criterion.pool_form`). It combines with every *information model*
  (:mod:`pin_kpi_oed.oed.objective`): noise only, with measured poses, extended with a prior, generalised least
  squares under the model discrepancy (its ``<name>_gp`` form, :class:`DiscrepancyForm`, made on demand for every
  criterion of the parameter information).
* A :class:`ConfigurationCriterion` is a function of the configurations that no information matrix carries (the
  universal-kriging ``kpi_gp``: the discrepancy kernel couples the poses); it builds its own
  :class:`~pin_kpi_oed.oed.objective.DesignObjective` on a design problem (:meth:`ConfigurationCriterion.objective`).

Both carry ``name``, ``label``, ``unit``, whether they are a ratio (``is_ratio``: a positive quantity the design
solver scales by its start value; the others are logarithms, shifted instead) and whether they need the KPI
sensitivity E (``needs_kpi``). The registry :data:`CRITERIA` maps names to instances; the IPOPT design, the pool
selection, ``evaluate``, the CLI and the validation look criteria up there (:func:`get_criterion`). **Adding a
criterion** = writing one subclass and calling :func:`register` on it (from this file or from outside the
package; ``tests/test_criteria.py`` does both kinds)::

    class WorstTcpVariance(Criterion):
        name, label, unit, is_ratio, needs_kpi = "cs_max", "largest eigenvalue of C_s", "m^2", True, True
        def value_and_grad_M(self, M0, E=None, prior_info=None, rows=0): ...   # φ, ∂φ/∂M₀

    register(WorstTcpVariance())

Gradients: Γ is closed form (−M⁻¹EᵀE M⁻¹ for tr C_s, −M⁻¹ for −log det M, Σ_i (∂φ/∂μ_i)/(2μ_i) v_i v_iᵀ for the
singular values μ_i = sqrt(λ_i(M₀))), chained with dF/dq (:meth:`TrackerModel.weighted_jacobian_dq`) by the
information model.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Iterable
from typing import Any, ClassVar

import numpy as np

from pin_kpi_oed.errors import IdentifiabilityError, InputError
from pin_kpi_oed.oed.covariance import check_pivots, information, singular_error
from pin_kpi_oed.oed.design_objective import CriterionInfo, DesignObjective


__all__ = ["CriterionInfo", "Criterion", "CovarianceCriterion", "SampleMeanTrace", "SingularValueCriterion",
           "ConfigurationCriterion", "DiscrepancyForm", "CRITERIA", "register", "unregister", "get_criterion",
           "check_names", "criterion_names", "evaluate_all"]


class Criterion(CriterionInfo, ABC):
    """A design criterion of the information matrix, to be minimised (the abstract base of the first kind).

    Subclasses set the :class:`CriterionInfo` attributes and implement :meth:`value_and_grad_M`; they may give a
    better-conditioned form on F (:meth:`value_and_grad_F`, e.g. singular values from F's SVD) and a pool form
    (:meth:`pool_form`, with ``has_pool_form = True``).

    Attributes:
        has_pool_form: :meth:`pool_form` is this criterion's own pool-selection form (A- or D-type); otherwise a pool
            selection for it falls back to D-optimality.
    """

    has_pool_form: ClassVar[bool] = False

    @abstractmethod
    def value_and_grad_M(self, M0: np.ndarray, E: np.ndarray | None = None, prior_info: np.ndarray | None = None,
                         rows: int = 0) -> tuple[float, np.ndarray]:
        """φ and Γ = ∂φ/∂M₀ (symmetric) of the information M₀ of the measurements.

        Args:
            M0: information of the measurements over the identifiable parameters, (nb, nb) (FᵀF; the GLS M₀ under
                the discrepancy), in 1/(parameter unit)².
            E: KPI sensitivity over the same parameters, (n_s, nb), m per parameter unit.
            prior_info: prior information Σ₀⁻¹ (nb, nb), or None; M = M₀ + Σ₀⁻¹ for the covariance criteria.
            rows: number of (whitened) measurement rows behind M₀ (Borm–Menq O1 counts them).

        Returns:
            (φ in :attr:`unit`, Γ with the shape of M₀).

        Raises:
            IdentifiabilityError: the design does not identify the parameters.
            InputError: E missing for a criterion that needs it.
        """

    def value_and_grad_F(self, F: np.ndarray, E: np.ndarray | None = None,
                         prior_sigma: np.ndarray | None = None) -> tuple[float, np.ndarray]:
        """Value φ and exact gradient dφ/dF = 2FΓ of the weighted Jacobian F.

        Args:
            F: weighted Jacobian over the identifiable parameters, (rows, nb).
            E: KPI sensitivity over the same parameters, (n_s, nb), m per parameter unit.
            prior_sigma: prior standard deviations (MAP), (nb,), or None.

        Returns:
            (φ in :attr:`unit`, dφ/dF with the shape of F).

        Raises:
            IdentifiabilityError: the design does not identify the parameters.
            InputError: E missing for a criterion that needs it.
        """
        P = None if prior_sigma is None else np.diag(1.0 / np.asarray(prior_sigma, float) ** 2)
        val, Gam = self.value_and_grad_M(F.T @ F, E, P, F.shape[0])
        return float(val), 2.0 * F @ Gam

    def value(self, F: np.ndarray, E: np.ndarray | None = None, prior_sigma: np.ndarray | None = None) -> float:
        """φ(F) (see :meth:`value_and_grad_F`)."""
        return self.value_and_grad_F(F, E, prior_sigma)[0]

    def pool_form(self, E: np.ndarray | None, nb: int) -> np.ndarray | None:
        """The criterion's form for pool selection (:mod:`pin_kpi_oed.oed.pool`).

        Args:
            E: KPI sensitivity over the identifiable parameters, (n_s, nb), or None.
            nb: number of identifiable parameters.

        Returns:
            K of the A-type form φ(w) = tr(K M(w)⁻¹ Kᵀ), or None for the D-type form −log det M(w)
            (the default, also the fallback of criteria without a pool form).
        """
        return None

    def need_E(self, E: np.ndarray | None) -> np.ndarray:
        """E, or an InputError naming the criterion when it is missing."""
        if E is None:
            raise InputError(f"the {self.name} criterion needs the working configurations (KPI sensitivity E)")
        return E


# ---------------------------------------------------------------------- covariance-based criteria
class CovarianceCriterion(Criterion):
    """A criterion of the parameter covariance C_p = (M₀ + Σ₀⁻¹)⁻¹ (eq. 19), through one Cholesky factor.

    Subclasses implement :meth:`from_covariance`.
    """

    def value_and_grad_M(self, M0: np.ndarray, E: np.ndarray | None = None, prior_info: np.ndarray | None = None,
                         rows: int = 0) -> tuple[float, np.ndarray]:
        M = M0 if prior_info is None else M0 + prior_info
        val, Gam = self._covariance_form(M, E)
        return val, 0.5 * (Gam + Gam.T)

    def value_and_grad_F(self, F: np.ndarray, E: np.ndarray | None = None,
                         prior_sigma: np.ndarray | None = None) -> tuple[float, np.ndarray]:
        val, Gam = self._covariance_form(information(F, prior_sigma), E)
        return val, 2.0 * F @ Gam

    def _covariance_form(self, M: np.ndarray, E: np.ndarray | None) -> tuple[float, np.ndarray]:
        try:
            L = np.linalg.cholesky(M)
        except np.linalg.LinAlgError:
            raise singular_error(M) from None
        check_pivots(M, np.diag(L))  # a near-singular M: refused, not a covariance with negative eigenvalues
        Linv = np.linalg.solve(L, np.eye(M.shape[0]))
        val, Gam = self.from_covariance(E, M, L, Linv.T @ Linv)
        return float(val), Gam

    @abstractmethod
    def from_covariance(self, E: np.ndarray | None, M: np.ndarray, L: np.ndarray, C: np.ndarray
                        ) -> tuple[float, np.ndarray]:
        """φ and Γ = ∂φ/∂M from the information M, its Cholesky factor L and C = M⁻¹."""


class KpiTrace(CovarianceCriterion):
    """A on C_s: φ = tr(C_s) = tr(E C_p Eᵀ), the TCP covariance at the working configurations (eqs. 19, 24a, 24c).

    Γ = −C_p Eᵀ E C_p.
    """

    name, label, unit = "kpi", "A on C_s: tr of the TCP covariance (m^2) - the paper's KPI criterion", "m^2"
    is_ratio, needs_kpi, has_pool_form = True, True, True

    def from_covariance(self, E, M, L, C):
        E = self.need_E(E)
        CE = C @ E.T
        return float(np.sum(E * CE.T)), -(CE @ CE.T)

    def pool_form(self, E, nb):
        return self.need_E(E)


class SampleMeanTrace(KpiTrace):
    """tr(E C_p Eᵀ) / S over a sensitivity E stacked from S samples of :attr:`rows_per_sample` rows each: the mean
    KPI per sample (m²) of a criterion whose E only it builds (paths, 6-D poses). Γ = −C_p Eᵀ E C_p / S; pool form
    K = E/√S."""

    rows_per_sample = 3

    def from_covariance(self, E, M, L, C):
        val, Gam = super().from_covariance(E, M, L, C)
        S = self.need_E(E).shape[0] // self.rows_per_sample
        return val / S, Gam / S

    def pool_form(self, E, nb):
        E = self.need_E(E)
        return E / np.sqrt(E.shape[0] // self.rows_per_sample)


class ParamTrace(CovarianceCriterion):
    """A on C_p: φ = tr(C_p), the paper's state of the art (A-optimality on the parameters).

    Mixed units (m² and rad²). Γ = −C_p².
    """

    name, label, unit = "param", "A on C_p: tr of the parameter covariance - the paper's state of the art", \
        "m^2 + rad^2 (mixed)"
    is_ratio, has_pool_form = True, True

    def from_covariance(self, E, M, L, C):
        return float(np.trace(C)), -(C @ C)

    def pool_form(self, E, nb):
        return np.eye(nb)


class DOptimality(CovarianceCriterion):
    """D-optimality: φ = −log det M (eq. 10, Daney). Γ = −C_p."""

    name, label, unit = "D", "D-optimality: -log det(F^T F)", "log"
    has_pool_form = True

    def from_covariance(self, E, M, L, C):
        return float(-2.0 * np.sum(np.log(np.diag(L)))), -C

    def pool_form(self, E, nb):
        return None


class EOptimality(CovarianceCriterion):
    """E-optimality: φ = λ_max(C_p) = 1/λ_min(M). Γ = −λ_max² v vᵀ, v the eigenvector of λ_max of C_p.

    Taken from C_p itself (positive definite from the checked Cholesky factor), not as 1/λ_min of M, whose smallest
    eigenvalue an ill-conditioned M can give negative."""

    name, label, unit = "E", "E-optimality: largest eigenvalue of C_p", "m^2 or rad^2"
    is_ratio = True

    def from_covariance(self, E, M, L, C):
        w, V = np.linalg.eigh(0.5 * (C + C.T))
        lam, v = float(w[-1]), V[:, -1]
        return lam, -(lam ** 2) * np.outer(v, v)


# ---------------------------------------------------------------------- singular-value criteria
class SingularValueCriterion(Criterion):
    """A criterion of the singular values μ₁ ≥ … ≥ μ_r of F (observability indices, eqs. 8–9).

    The prior is not used (the indices are defined on F). Subclasses implement
    :meth:`from_singular_values`; the gradient is dφ/dF = Σ_i (∂φ/∂μ_i) u_i v_iᵀ.
    """

    def value_and_grad_F(self, F: np.ndarray, E: np.ndarray | None = None,
                         prior_sigma: np.ndarray | None = None) -> tuple[float, np.ndarray]:
        U, mu, Vt = np.linalg.svd(F, full_matrices=False)
        if mu[-1] <= 1e-12 * mu[0]:
            raise IdentifiabilityError("rank-deficient Jacobian: the design does not identify the parameters")
        val, dmu = self.from_singular_values(mu, F.shape[0])
        return float(val), (U * dmu) @ Vt

    def value_and_grad_M(self, M0: np.ndarray, E: np.ndarray | None = None, prior_info: np.ndarray | None = None,
                         rows: int = 0) -> tuple[float, np.ndarray]:
        """μ_i = sqrt(λ_i(M₀)) (the singular values of any F with FᵀF = M₀, e.g. the whitened Jacobian) and
        Γ = Σ_i (∂φ/∂μ_i)/(2μ_i) v_i v_iᵀ; the prior is not used."""
        lam, Vec = np.linalg.eigh(M0)
        lam, Vec = lam[::-1], Vec[:, ::-1]
        if lam[-1] <= 1e-24 * lam[0]:
            raise IdentifiabilityError("rank-deficient (whitened) Jacobian: the design does not identify the "
                                       "parameters")
        mu = np.sqrt(lam)
        val, dmu = self.from_singular_values(mu, rows)
        return float(val), (Vec * (dmu / (2.0 * mu))) @ Vec.T

    @abstractmethod
    def from_singular_values(self, mu: np.ndarray, rows: int) -> tuple[float, np.ndarray]:
        """φ and ∂φ/∂μ from the singular values (descending) and the number of rows of F."""


class ConditionNumber(SingularValueCriterion):
    """Condition number μ₁/μ_r of F (eq. 9)."""

    name, label, unit, is_ratio = "cond", "condition number of F", "1", True

    def from_singular_values(self, mu, rows):
        dmu = np.zeros(mu.size)
        dmu[0], dmu[-1] = 1.0 / mu[-1], -mu[0] / mu[-1] ** 2
        return mu[0] / mu[-1], dmu


class O1(SingularValueCriterion):
    """Borm–Menq O1 = (μ₁⋯μ_r)^{1/r}/√m (eq. 8), maximised: φ = −log O1."""

    name, label, unit = "O1", "observability index O1 (Borm-Menq), as -log", "log"

    def from_singular_values(self, mu, rows):
        r = mu.size
        return -(np.sum(np.log(mu)) / r - 0.5 * np.log(rows)), -1.0 / (r * mu)


class O2(SingularValueCriterion):
    """O2 = μ_r/μ₁ (inverse condition number, eq. 9), maximised: φ = −log O2."""

    name, label, unit = "O2", "observability index O2 (inverse condition number), as -log", "log"

    def from_singular_values(self, mu, rows):
        dmu = np.zeros(mu.size)
        dmu[0], dmu[-1] = 1.0 / mu[0], -1.0 / mu[-1]
        return -(np.log(mu[-1]) - np.log(mu[0])), dmu


class O3(SingularValueCriterion):
    """O3 = μ_r (minimum singular value), maximised: φ = −log O3."""

    name, label, unit = "O3", "observability index O3 (minimum singular value), as -log", "log"

    def from_singular_values(self, mu, rows):
        dmu = np.zeros(mu.size)
        dmu[-1] = -1.0 / mu[-1]
        return -np.log(mu[-1]), dmu


class O4(SingularValueCriterion):
    """O4 = μ_r²/μ₁ (noise amplification index, Nahvi), maximised: φ = −log O4."""

    name, label, unit = "O4", "observability index O4 (noise amplification, Nahvi), as -log", "log"

    def from_singular_values(self, mu, rows):
        dmu = np.zeros(mu.size)
        dmu[0], dmu[-1] = 1.0 / mu[0], -2.0 / mu[-1]
        return -(2 * np.log(mu[-1]) - np.log(mu[0])), dmu


class O5(SingularValueCriterion):
    """O5 = 1/Σ(1/μ_i) (Sun–Hollerbach), maximised: φ = log Σ 1/μ_i."""

    name, label, unit = "O5", "observability index O5 (Sun-Hollerbach), as -log", "log"

    def from_singular_values(self, mu, rows):
        s = np.sum(1.0 / mu)
        return np.log(s), -1.0 / (mu ** 2 * s)


# ---------------------------------------------------------------------- criteria of the configurations
class ConfigurationCriterion(CriterionInfo, ABC):
    """A design criterion of the configurations that no information matrix carries (the abstract base of the second
    kind): it builds its own objective φ(Q) on a design problem.

    Subclasses set the :class:`CriterionInfo` attributes and implement :meth:`objective`.

    Attributes:
        uses_discrepancy: the objective is built on the problem's model discrepancy (the kriging ``kpi_gp``, the
            ``<name>_gp`` forms: the design then reports the σ with the discrepancy); False for a criterion of the
            configurations on the noise-only information (the path and 6-D KPIs).
    """

    uses_discrepancy: ClassVar[bool] = True

    @abstractmethod
    def objective(self, problem: Any) -> DesignObjective:
        """φ(Q) of this criterion on ``problem`` (a :class:`~pin_kpi_oed.design.optimize.DesignProblem`): a
        :class:`~pin_kpi_oed.oed.objective.DesignObjective` with its value, exact gradient and pool selection."""


class KpiDiscrepancy(ConfigurationCriterion):
    """A on the universal-kriging C_s: tr of the TCP error covariance with the model discrepancy (m²).

    The discrepancy kernel couples the poses: :class:`~pin_kpi_oed.oed.discrepancy_kpi.DiscrepancyDesignCriterion`
    on the problem's geometry, discrepancy, working region, measured poses and re-registration
    (:meth:`DesignProblem.gp_criterion <pin_kpi_oed.design.optimize.DesignProblem.gp_criterion>`). Pool selection:
    greedy + exchange (:func:`~pin_kpi_oed.oed.discrepancy_pool.select_pool_gp`; no certificate exists).
    """

    name, label, unit = "kpi_gp", "A on C_s with the model discrepancy (universal kriging, m^2)", "m^2"
    is_ratio, needs_kpi = True, True

    def objective(self, problem: Any) -> DesignObjective:
        return _gp_objective(problem, self.name)


def _gp_objective(problem: Any, name: str) -> DesignObjective:
    """The discrepancy-aware objective ``name`` of a design problem (its discrepancy, region, measured poses; hedged
    when the discrepancy is an assumption: ``DesignProblem.gp_objective``)."""
    if not hasattr(problem, "gp_objective"):
        raise InputError(f"criterion {name}: needs a design problem with its discrepancy (design, not evaluate)")
    return problem.gp_objective(name)


class DiscrepancyForm(ConfigurationCriterion):
    """The discrepancy-aware form ``<name>_gp`` of a criterion of the parameter information (D, A, E, the indices,
    and every such criterion registered later): made on demand by :func:`get_criterion`, never registered.

    The same φ on the GLS information M = Σ_a s_a⁻² J_aᵀ (K_QQ + wI)⁻¹ J_a + Σ₀⁻¹ (the indices: on the whitened
    Jacobian): :class:`~pin_kpi_oed.oed.discrepancy_criteria.GlsDesignCriterion` on the problem's discrepancy. Pool
    selection: greedy + exchange (no certificate exists).
    """

    SUFFIX = "_gp"

    def __init__(self, base: Criterion) -> None:
        if not self.applies(base):
            raise InputError(f"criterion {base.name}: no discrepancy-aware form (not a function of the parameter "
                             f"information alone)")
        self.base = base
        self.name = f"{base.name}{self.SUFFIX}"
        self.label = f"{base.label}, with the model discrepancy (GLS information)"
        self.unit, self.is_ratio, self.needs_kpi = base.unit, base.is_ratio, False

    @staticmethod
    def applies(crit: Any) -> bool:
        """Whether ``crit`` is a criterion of the parameter information alone (not of E: ``kpi``'s discrepancy-aware
        form is the kriging ``kpi_gp``)."""
        return isinstance(crit, Criterion) and not crit.needs_kpi

    def objective(self, problem: Any) -> DesignObjective:
        return _gp_objective(problem, self.name)


# ---------------------------------------------------------------------- registry
#: The registry: criterion name -> instance, in registration order (the order of ``evaluate``'s output).
CRITERIA: dict[str, Criterion | ConfigurationCriterion] = {}
_FORMS: dict[str, DiscrepancyForm] = {}


def register(criterion: Any, replace: bool = False) -> Criterion | ConfigurationCriterion:
    """Add a criterion to :data:`CRITERIA` (usable by the design, the pool start, ``evaluate`` and the CLI).

    Args:
        criterion: an instance (or a class, instantiated without arguments).
        replace: allow replacing a registered criterion of the same name.

    Returns:
        The registered instance.

    Raises:
        InputError: no name, a name clashing with ``random`` (the heuristic design) or an existing
            criterion (unless ``replace``).
    """
    crit = criterion() if isinstance(criterion, type) else criterion
    if not isinstance(crit, (Criterion, ConfigurationCriterion)) or not crit.name:
        raise InputError(f"{criterion!r}: a criterion is a Criterion or ConfigurationCriterion subclass with a "
                         f"non-empty name")
    if crit.name == "random" or (crit.name in CRITERIA and not replace):
        raise InputError(f"criterion name '{crit.name}' is already taken")
    CRITERIA[crit.name] = crit
    _FORMS.clear()
    return crit


def unregister(name: str) -> None:
    """Remove a criterion from :data:`CRITERIA` (no error if absent)."""
    CRITERIA.pop(name, None)
    _FORMS.clear()


def criterion_names() -> list[str]:
    """Every criterion name: the registered ones, then the discrepancy-aware forms ``<name>_gp`` of those of the
    parameter information (the order of the CLI's help)."""
    forms = [f"{n}{DiscrepancyForm.SUFFIX}" for n, c in CRITERIA.items() if DiscrepancyForm.applies(c)]
    return list(CRITERIA) + [f for f in forms if f not in CRITERIA]


def get_criterion(criterion: Any) -> Criterion | ConfigurationCriterion:
    """The criterion object of a name (an instance is returned as is); ``<name>_gp`` of a registered criterion of
    the parameter information is its :class:`DiscrepancyForm`.

    Raises:
        InputError: unknown name, listing the known ones.
    """
    if isinstance(criterion, (Criterion, ConfigurationCriterion)):
        return criterion
    if isinstance(criterion, str) and criterion in CRITERIA:
        return CRITERIA[criterion]
    if isinstance(criterion, str) and criterion.endswith(DiscrepancyForm.SUFFIX):
        base = CRITERIA.get(criterion[:-len(DiscrepancyForm.SUFFIX)])
        if DiscrepancyForm.applies(base):
            if criterion not in _FORMS:
                _FORMS[criterion] = DiscrepancyForm(base)  # type: ignore[arg-type]
            return _FORMS[criterion]
    raise InputError(f"unknown criterion '{criterion}' (known: random, {', '.join(criterion_names())})")


def check_names(names: Iterable[str]) -> list[str]:
    """Validate design names: ``random`` (the heuristic design) or registered criteria.

    Raises:
        InputError: the first unknown name, listing the known ones.
    """
    names = list(names)
    for n in names:
        if n != "random":
            get_criterion(n)
    return names


for _cls in (KpiTrace, ParamTrace, DOptimality, EOptimality, ConditionNumber, O1, O2, O3, O4, O5, KpiDiscrepancy):
    register(_cls)


def evaluate_all(model: Any, base: np.ndarray, Q: np.ndarray, E: np.ndarray | None,
                 context: Any = None, not_scored: dict[str, str] | None = None,
                 singular: dict[str, str] | None = None) -> dict[str, float]:
    """Every registered criterion for one design (NaN where undefined, e.g. kpi without E; inf if singular, the
    refusal's reason in ``singular`` when given: a singular value is no number to print): those
    of the information matrix on the noise-only information, those of the configurations on ``context`` (a
    :class:`~pin_kpi_oed.oed.objective.DesignContext` or a design problem) when given and they can be built on it
    (``kpi_gp`` needs a design problem's discrepancy, ``kpi_path`` a cell's working paths: left out otherwise, each
    with the reason in ``not_scored`` when given)."""
    from pin_kpi_oed.oed.covariance import prior_of

    F = model.weighted_jacobian(np.zeros(model.n_params), Q)[:, :, base].reshape(-1, base.size)
    prior = prior_of(model, base)
    out = {}
    for name, crit in CRITERIA.items():
        if not isinstance(crit, Criterion):
            if context is not None:
                try:
                    obj = crit.objective(context)
                except InputError as exc:
                    if not_scored is not None:
                        not_scored[name] = str(exc)
                    continue
                try:
                    out[name] = obj.value(Q)
                except IdentifiabilityError as exc:
                    out[name] = float("inf")
                    if singular is not None:
                        singular[name] = str(exc)
            continue
        if crit.needs_kpi and E is None:
            out[name] = float("nan")
            continue
        try:
            out[name] = crit.value(F, E, prior)
        except IdentifiabilityError as exc:
            out[name] = float("inf")
            if singular is not None:
                singular[name] = str(exc)
    return out
