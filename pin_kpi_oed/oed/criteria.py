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

**One class per criterion.** Each criterion is a subclass of :class:`Criterion` carrying its
``name``, ``label``, ``unit``, whether it ``is_ratio`` (a positive quantity the design solver scales
by its start value; the others are logarithms, shifted instead), whether it ``needs_kpi`` (the
sensitivity E), its value and exact gradient dφ/dF (:meth:`Criterion.value_and_grad_F`) and its
pool-selection form (:meth:`Criterion.pool_form`). The registry :data:`CRITERIA` maps names to
instances; every user (the IPOPT design, the pool start, ``evaluate``, the CLI, the validation)
looks criteria up there. **Adding a criterion** = writing one subclass and calling
:func:`register` on it (from this file or from outside the package)::

    class WorstTcpVariance(Criterion):
        name, label, unit, is_ratio, needs_kpi = "cs_max", "largest eigenvalue of C_s", "m^2", True, True
        def value_and_grad_F(self, F, E=None, prior_sigma=None): ...

    register(WorstTcpVariance())

Gradients: dφ/dF is closed form (e.g. −2 F M⁻¹EᵀE M⁻¹ for tr C_s, and
dμ_i = u_iᵀ dF v_i for singular-value criteria), chained with dF/dq from
:meth:`TrackerModel.weighted_jacobian_dq` by :class:`DesignCriterion`.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import ClassVar

import numpy as np

from pin_kpi_oed.errors import IdentifiabilityError, InputError
from pin_kpi_oed.model.tracker import TrackerModel
from pin_kpi_oed.oed.covariance import information, prior_of

__all__ = ["Criterion", "CovarianceCriterion", "SingularValueCriterion", "DiscrepancyForm", "CRITERIA", "register",
           "unregister", "get_criterion", "check_names", "DesignCriterion", "evaluate_all"]


class Criterion:
    """Base class of a design criterion φ(F), to be minimised.

    Subclasses set the class attributes and implement :meth:`value_and_grad_F`; optionally
    :meth:`pool_form` (with ``has_pool_form = True``) when the criterion can select poses from a pool.

    Attributes:
        name: registry key, as typed on the command line (``--criteria``).
        label: one readable line (what it measures, where it comes from).
        unit: unit of the value (``m^2``, ``1`` for dimensionless, ``log`` for logarithmic indices).
        is_ratio: the value is a positive quantity (the design solver divides by its start value);
            otherwise it is a logarithm (the solver subtracts its start value).
        needs_kpi: the value needs the KPI sensitivity E (working configurations).
        has_pool_form: :meth:`pool_form` is this criterion's own pool-selection form (A- or D-type);
            otherwise a pool selection for it falls back to D-optimality.
    """

    name: ClassVar[str] = ""
    label: ClassVar[str] = ""
    unit: ClassVar[str] = ""
    is_ratio: ClassVar[bool] = False
    needs_kpi: ClassVar[bool] = False
    has_pool_form: ClassVar[bool] = False
    #: a function of the configurations, not of F alone (``kpi_gp``): evaluated through the design problem
    needs_configurations: ClassVar[bool] = False

    def value_and_grad_F(self, F: np.ndarray, E: np.ndarray | None = None,
                         prior_sigma: np.ndarray | None = None) -> tuple[float, np.ndarray]:
        """Value φ and exact gradient dφ/dF.

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
        raise NotImplementedError

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

    def _need_E(self, E: np.ndarray | None) -> np.ndarray:
        if E is None:
            raise InputError(f"the {self.name} criterion needs the working configurations (KPI sensitivity E)")
        return E

    def __repr__(self) -> str:
        return f"<criterion {self.name}: {self.label} [{self.unit}]>"


# ---------------------------------------------------------------------- covariance-based criteria
class CovarianceCriterion(Criterion):
    """A criterion of the parameter covariance C_p = (FᵀF + P)⁻¹ (eq. 19), through one Cholesky factor.

    Subclasses implement :meth:`from_covariance`.
    """

    def value_and_grad_F(self, F: np.ndarray, E: np.ndarray | None = None,
                         prior_sigma: np.ndarray | None = None) -> tuple[float, np.ndarray]:
        M = information(F, prior_sigma)
        try:
            L = np.linalg.cholesky(M)
        except np.linalg.LinAlgError:
            raise IdentifiabilityError("singular information matrix: the design does not identify the "
                                       "parameters; use more or more varied configurations") from None
        Linv = np.linalg.solve(L, np.eye(M.shape[0]))
        return self.from_covariance(F, E, M, L, Linv.T @ Linv)

    def from_covariance(self, F: np.ndarray, E: np.ndarray | None, M: np.ndarray, L: np.ndarray, C: np.ndarray
                        ) -> tuple[float, np.ndarray]:
        """φ and dφ/dF from the information M, its Cholesky factor L and C = M⁻¹."""
        raise NotImplementedError


class KpiTrace(CovarianceCriterion):
    """A on C_s: φ = tr(C_s) = tr(E C_p Eᵀ), the TCP covariance at the working configurations (eqs. 19, 24a, 24c).

    dφ/dF = −2 F C_p Eᵀ E C_p.
    """

    name, label, unit = "kpi", "A on C_s: tr of the TCP covariance (m^2) - the paper's KPI criterion", "m^2"
    is_ratio, needs_kpi, has_pool_form = True, True, True

    def from_covariance(self, F, E, M, L, C):
        E = self._need_E(E)
        CE = C @ E.T
        return float(np.sum(E * CE.T)), -2.0 * F @ (CE @ CE.T)

    def pool_form(self, E, nb):
        return self._need_E(E)


class ParamTrace(CovarianceCriterion):
    """A on C_p: φ = tr(C_p), the paper's state of the art (A-optimality on the parameters).

    Mixed units (m² and rad²). dφ/dF = −2 F C_p².
    """

    name, label, unit = "param", "A on C_p: tr of the parameter covariance - the paper's state of the art", \
        "m^2 + rad^2 (mixed)"
    is_ratio, has_pool_form = True, True

    def from_covariance(self, F, E, M, L, C):
        return float(np.trace(C)), -2.0 * F @ (C @ C)

    def pool_form(self, E, nb):
        return np.eye(nb)


class DOptimality(CovarianceCriterion):
    """D-optimality: φ = −log det M (eq. 10, Daney). dφ/dF = −2 F C_p."""

    name, label, unit = "D", "D-optimality: -log det(F^T F)", "log"
    has_pool_form = True

    def from_covariance(self, F, E, M, L, C):
        return float(-2.0 * np.sum(np.log(np.diag(L)))), -2.0 * F @ C

    def pool_form(self, E, nb):
        return None


class EOptimality(CovarianceCriterion):
    """E-optimality: φ = λ_max(C_p) = 1/λ_min(M). dφ/dF = −(2/λ_min²) (F v) vᵀ, v the eigenvector of λ_min."""

    name, label, unit = "E", "E-optimality: largest eigenvalue of C_p", "m^2 or rad^2"
    is_ratio = True

    def from_covariance(self, F, E, M, L, C):
        w, V = np.linalg.eigh(M)
        v = V[:, 0]
        return float(1.0 / w[0]), -(2.0 / w[0] ** 2) * np.outer(F @ v, v)


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

    def from_singular_values(self, mu: np.ndarray, rows: int) -> tuple[float, np.ndarray]:
        """φ and ∂φ/∂μ from the singular values (descending) and the number of rows of F."""
        raise NotImplementedError


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


# ---------------------------------------------------------------------- a criterion of the configurations
class KpiDiscrepancy(Criterion):
    """A on the universal-kriging C_s: tr of the TCP error covariance with the model discrepancy (m²).

    A function of the configurations (the discrepancy kernel couples the poses), not of F alone: the design
    evaluates it through :class:`~pin_kpi_oed.oed.discrepancy_kpi.DiscrepancyDesignCriterion`
    (``DesignProblem.criterion('kpi_gp')``); :meth:`value_and_grad_F` refuses. Pool selection:
    :func:`~pin_kpi_oed.oed.discrepancy_kpi.select_pool_gp` (its own exchange; no certificate exists).
    """

    name, label, unit = "kpi_gp", "A on C_s with the model discrepancy (universal kriging, m^2)", "m^2"
    is_ratio, needs_kpi, has_pool_form = True, True, False
    needs_configurations = True

    def value_and_grad_F(self, F, E=None, prior_sigma=None):
        raise InputError("the kpi_gp criterion needs the configurations (the discrepancy kernel couples the "
                         "poses): evaluate it through the design problem (DesignProblem.criterion('kpi_gp'))")


class DiscrepancyForm(Criterion):
    """The discrepancy-aware form ``<name>_gp`` of a noise-only criterion of the parameters (D, A, E, the indices).

    The same φ on the GLS information M = Σ_a s_a⁻² J_aᵀ (K_QQ + wI)⁻¹ J_a + Σ₀⁻¹ (the indices: on the whitened
    Jacobian), a function of the configurations: evaluated through
    :class:`~pin_kpi_oed.oed.discrepancy_criteria.GlsDesignCriterion` (``DesignProblem.criterion('D_gp')``);
    :meth:`value_and_grad_F` refuses. Pool selection: its own greedy + exchange (no certificate exists).
    """

    has_pool_form = False
    needs_configurations = True

    def __init__(self, base: Criterion) -> None:
        if not self.applies(base):
            raise InputError(f"criterion {base.name}: no discrepancy-aware form (not a function of the parameter "
                             f"information)")
        self.base = base
        self.name = f"{base.name}_gp"  # type: ignore[misc]
        self.label = f"{base.label}, with the model discrepancy (GLS information)"  # type: ignore[misc]
        self.unit, self.is_ratio = base.unit, base.is_ratio  # type: ignore[misc]

    @staticmethod
    def applies(crit: Criterion) -> bool:
        """Whether ``crit`` is a function of the parameter information (has a discrepancy-aware form)."""
        return isinstance(crit, SingularValueCriterion) or (isinstance(crit, CovarianceCriterion)
                                                             and not crit.needs_kpi)

    def value_and_grad_F(self, F, E=None, prior_sigma=None):
        raise InputError(f"the {self.name} criterion needs the configurations (the discrepancy kernel couples the "
                         f"poses): evaluate it through the design problem (DesignProblem.criterion('{self.name}'))")


# ---------------------------------------------------------------------- registry
#: The registry: criterion name -> instance, in registration order (the order of ``evaluate``'s output).
CRITERIA: dict[str, Criterion] = {}


def register(criterion: Criterion | type[Criterion], replace: bool = False) -> Criterion:
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
    if not isinstance(crit, Criterion) or not crit.name:
        raise InputError(f"{criterion!r}: a criterion is a Criterion subclass with a non-empty name")
    if crit.name == "random" or (crit.name in CRITERIA and not replace):
        raise InputError(f"criterion name '{crit.name}' is already taken")
    CRITERIA[crit.name] = crit
    return crit


def unregister(name: str) -> None:
    """Remove a criterion from :data:`CRITERIA` (no error if absent)."""
    CRITERIA.pop(name, None)


def get_criterion(criterion: str | Criterion) -> Criterion:
    """The criterion object of a name (an instance is returned as is).

    Raises:
        InputError: unknown name, listing the known ones.
    """
    if isinstance(criterion, Criterion):
        return criterion
    try:
        return CRITERIA[criterion]
    except (KeyError, TypeError):
        raise InputError(f"unknown criterion '{criterion}' (known: random, {', '.join(CRITERIA)})") from None


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
for _c in list(CRITERIA.values()):
    if DiscrepancyForm.applies(_c):
        register(DiscrepancyForm(_c))


# ---------------------------------------------------------------------- criteria of configurations
@dataclass
class DesignCriterion:
    """A criterion as a function of the measurement configurations Q (chains dφ/dF with dF/dQ).

    Attributes:
        model: the measurement model (evaluated at the linearisation point ``p``).
        base: indices of the identifiable parameters.
        criterion: a registered name or a :class:`Criterion` instance.
        E: KPI sensitivity over the base parameters, (3t, nb), or None.
        p: linearisation point (raw parameters); default nominal.

    Raises:
        InputError: unknown criterion name.
    """

    model: TrackerModel
    base: np.ndarray
    criterion: str | Criterion = "kpi"
    E: np.ndarray | None = None
    p: np.ndarray | None = None
    crit: Criterion = field(init=False, repr=False)

    def __post_init__(self) -> None:
        if self.p is None:
            self.p = np.zeros(self.model.n_params)
        self.crit = get_criterion(self.criterion)
        self.prior = prior_of(self.model, self.base)

    @property
    def name(self) -> str:
        """The criterion's name."""
        return self.crit.name

    @property
    def is_ratio(self) -> bool:
        """Whether the criterion is a positive quantity (see :attr:`Criterion.is_ratio`)."""
        return self.crit.is_ratio

    def value(self, Q: np.ndarray) -> float:
        """φ(Q) for configurations Q, (m, n) rad."""
        F = self.model.weighted_jacobian(self.p, Q)[:, :, self.base].reshape(-1, self.base.size)
        return self.crit.value(F, self.E, self.prior)

    def value_and_grad(self, Q: np.ndarray) -> tuple[float, np.ndarray]:
        """φ(Q) and dφ/dQ, (m, n) (per rad)."""
        F, dF = self.model.weighted_jacobian_dq(self.p, Q)
        Fb = F[:, :, self.base]
        m, nh, nb = Fb.shape
        val, G = self.crit.value_and_grad_F(Fb.reshape(-1, nb), self.E, self.prior)
        grad = np.einsum("mac,mack->mk", G.reshape(m, nh, nb), dF[:, :, self.base, :])
        return val, grad


def evaluate_all(model: TrackerModel, base: np.ndarray, Q: np.ndarray, E: np.ndarray | None) -> dict[str, float]:
    """Every registered criterion for one design (NaN where undefined, e.g. kpi without E; inf if singular)."""
    F = model.weighted_jacobian(np.zeros(model.n_params), Q)[:, :, base].reshape(-1, base.size)
    prior = prior_of(model, base)
    out = {}
    for name, crit in CRITERIA.items():
        if getattr(crit, "needs_configurations", False):
            continue  # a function of the configurations (kpi_gp): scored by the design problem
        if crit.needs_kpi and E is None:
            out[name] = float("nan")
            continue
        try:
            out[name] = crit.value(F, E, prior)
        except IdentifiabilityError:
            out[name] = float("inf")
    return out
