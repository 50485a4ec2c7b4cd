r"""The TCP's tr C_s of a design whose pose i measures nest k_i, as a function of the poses: the IPOPT design over
pose × nest optimises the poses under a fixed nest assignment with it (:mod:`pin_kpi_oed.design.nest_design`).

The value is :func:`~pin_kpi_oed.oed.nests.nest_trace`'s (identified set B: the structural one of the nests the
assignment measures; N the joint-placement parameters left held, at their tolerances Σ_N)::

    φ(Q) = tr(E_B C Eᵀ_B) + tr(G Σ_N Gᵀ),   C = (F_Bᵀ F_B + P)⁻¹,   A = C F_Bᵀ F_N,   G = E_B A − E_N

where row block i of F = [F_B F_N] is the weighted Jacobian of pose i at its nest (``model.at_nests(nest)``).
Its exact gradient with respect to F, with W = E_Bᵀ G Σ_N and X = C W Aᵀ::

    ∂φ/∂F_B = −2 F_B C E_Bᵀ E_B C + 2 (F_N Wᵀ C − F_B (X + Xᵀ)),   ∂φ/∂F_N = 2 F_B C W

chained with each row's dF/dq at its nest gives dφ/dQ.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from pin_kpi_oed.oed.design_objective import CriterionInfo, DesignObjective
from pin_kpi_oed.oed.nests import NestStructure

if TYPE_CHECKING:
    from pin_kpi_oed.model.tolerances import Tolerances
    from pin_kpi_oed.model.tracker import TrackerModel

__all__ = ["NestKpiInfo", "NestObjective"]


class NestKpiInfo(CriterionInfo):
    """What the nest-aware KPI says about itself (a positive trace in m²)."""

    name = "kpi_nests"
    label = "tr C_s at the TCP, each pose at its nest, held joint placements included"
    unit = "m^2"
    is_ratio = True
    needs_kpi = True


@dataclass
class NestObjective(DesignObjective):
    """φ(Q) = tr C_s at the working configurations of poses measured at fixed nests (module docstring).

    Attributes:
        model: the measurement model with its nests (``nests_m``) and TCP.
        nest: the nest of every pose, (m,) int.
        Q_work: working configurations (t, n) rad.
        tolerances: the held parameters' prior (default :class:`~pin_kpi_oed.model.tolerances.Tolerances`).
        seed: the structural analysis's excitation; structure: its cache (shared with
            :func:`~pin_kpi_oed.oed.nests.assign_nests` calls of the same seed), or None.

    Raises:
        IdentifiabilityError (on evaluation): the poses do not identify the parameters of their nests.
    """

    model: TrackerModel
    nest: np.ndarray
    Q_work: np.ndarray
    tolerances: Tolerances | None = None
    seed: int = 0
    structure: NestStructure | None = None
    crit: CriterionInfo = field(default_factory=NestKpiInfo, init=False, repr=False)

    def __post_init__(self) -> None:
        from pin_kpi_oed.model.tolerances import Tolerances, held_columns
        from pin_kpi_oed.oed.covariance import prior_of

        self.nest = np.asarray(self.nest, int)
        st = self.structure or NestStructure(self.model, self.seed)
        self.B = st.base(tuple(sorted(set(self.nest.tolist()))))
        self.N = held_columns(self.model, self.B)
        self.measured = self.model.at_nests(self.nest)
        p0 = np.zeros(self.model.n_params)
        E = self.model.kpi_jacobian(p0, np.atleast_2d(self.Q_work))
        self.E_B, self.E_N = E[:, self.B], E[:, self.N]
        self.sig_N = (self.tolerances or Tolerances()).sigma_vector(self.model)[self.N]
        self.prior = prior_of(self.model, self.B)
        self.names = [self.model.layout.names[i] for i in self.B]

    def _check(self, Q: np.ndarray) -> np.ndarray:
        Q = np.atleast_2d(np.asarray(Q, float))
        if len(Q) != len(self.nest):
            raise ValueError(f"{len(Q)} poses for {len(self.nest)} nests")
        return Q

    def _traces(self, Q: np.ndarray) -> tuple[float, float]:
        """(tr C_s, its held part tr(G Σ_N Gᵀ)) (m²)."""
        from pin_kpi_oed.oed.covariance import tcp_covariances

        F = self.measured.weighted_jacobian(np.zeros(self.model.n_params), self._check(Q))
        F = F.reshape(-1, self.model.n_params)
        _, C_s, C_h = tcp_covariances(F[:, self.B], F[:, self.N], self.E_B, self.E_N, self.sig_N, self.prior,
                                      self.names)
        return float(np.trace(C_s)), float(np.trace(C_h))

    def value(self, Q: np.ndarray) -> float:
        """φ(Q) (m²) for the poses Q, (m, n) rad, pose i at nest ``nest[i]``."""
        return self._traces(Q)[0]

    def held_m2(self, Q: np.ndarray) -> float:
        """The held part of φ(Q), tr(G Σ_N Gᵀ) (m²): mostly a floor no design lowers (parameters the tracker's pose
        absorbs whatever the poses)."""
        return self._traces(Q)[1]

    def value_and_grad(self, Q: np.ndarray) -> tuple[float, np.ndarray]:
        """φ(Q) (m²) and dφ/dQ, (m, n) m² per rad."""
        from pin_kpi_oed.oed.covariance import param_covariance

        Q = self._check(Q)
        F, dF = self.measured.weighted_jacobian_dq(np.zeros(self.model.n_params), Q)
        m, nh, npar, n = dF.shape
        FB, FN = F[:, :, self.B].reshape(-1, self.B.size), F[:, :, self.N].reshape(-1, self.N.size)
        C = param_covariance(FB, self.prior, self.names)
        A = C @ (FB.T @ FN)
        G = self.E_B @ A - self.E_N
        S = self.sig_N ** 2
        val = float(np.sum((self.E_B @ C) * self.E_B) + np.sum(G * G * S))
        W = self.E_B.T @ (G * S)
        X = C @ W @ A.T
        CEEC = C @ self.E_B.T @ self.E_B @ C
        dB = -2.0 * FB @ CEEC + 2.0 * (FN @ W.T @ C - FB @ (X + X.T))
        dN = 2.0 * FB @ C @ W
        grad = (np.einsum("mac,mack->mk", dB.reshape(m, nh, -1), dF[:, :, self.B, :])
                + np.einsum("mac,mack->mk", dN.reshape(m, nh, -1), dF[:, :, self.N, :]))
        return val, grad
