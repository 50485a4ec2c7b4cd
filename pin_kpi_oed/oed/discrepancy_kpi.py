r"""The KPI criterion under model discrepancy (``kpi_gp``) as a function of the measurement configurations.

The measurement of pose q in the robot base frame is y = J(q) θ + δ(q) + ε with the discrepancy δ (kernel k over
joint angles, per-axis scale S, white level w); the calibrated TCP's error covariance at the working configurations
is the universal-kriging C_s of :mod:`pin_kpi_oed.oed.kriging` (with k ≡ 0 the paper's C_s). The value is tr C_s
(m², base frame).

:class:`DiscrepancyDesignCriterion` is its :class:`~pin_kpi_oed.oed.objective.DesignObjective`: the value, the exact
dφ/dQ through J(Q), K_QQ and K_WQ, the re-registered form (:mod:`pin_kpi_oed.oed.reregistration`), the pool
selection (:func:`~pin_kpi_oed.oed.discrepancy_pool.select_pool_gp`: greedy additions by exact rank-one (kernel) and
rank-three (information) updates, then exchange passes; no equivalence-theorem certificate exists for this
criterion: the kernel couples the poses). :func:`poses_needed` predicts σ against the number of poses.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from pin_kpi_oed.discrepancy.prior import DiscrepancyPrior
from pin_kpi_oed.errors import IdentifiabilityError, InputError
from pin_kpi_oed.oed.covariance import prior_of
from pin_kpi_oed.oed.criteria import KpiDiscrepancy
from pin_kpi_oed.oed.discrepancy_pool import select_pool_gp
from pin_kpi_oed.oed.kriging import kpi_gp_covariance, kpi_gp_value_and_grad, pad_rows
from pin_kpi_oed.oed.design_objective import DesignObjective
from pin_kpi_oed.oed.selection_result import PoolSelection
from pin_kpi_oed.results import Result

__all__ = ["base_frame_jacobian", "chain_q", "DiscrepancyDesignCriterion", "PosesNeeded", "poses_needed"]


# --------------------------------------------------------------------------- the criterion of configurations
def base_frame_jacobian(model, p, Q, base, with_dq):
    """Reflector Jacobian in the robot base frame over the base parameters: J (m, 3, nb) and ∂J/∂q (m, 3, nb, n)."""
    R = model.tracker_pose(p).rotation
    if with_dq:
        _, J, dJ, _ = model.jacobian_dq(p, Q)
        J = np.einsum("ba,mbp->map", R, J[:, :3, base])
        dJ = np.einsum("ba,mbpk->mapk", R, dJ[:, :3][:, :, base])
        return J, dJ
    return model.base_jacobian(p, Q, base), None


def chain_q(g: dict, dJ: np.ndarray, disc: DiscrepancyPrior, Q: np.ndarray, Qa: np.ndarray, k: int) -> np.ndarray:
    """dφ/dQ of the moving poses Q = Qa[k:] from ∂φ/∂J and ∂φ/∂G (K_QQ through both its arguments), (m, n)."""
    grad = np.einsum("iac,iack->ik", g["J"][k:], dJ)
    Gs = g["G"] + g["G"].T
    return grad + np.einsum("ij,ijk->ik", Gs[k:], disc.grad_x(Q, Qa))


@dataclass
class DiscrepancyDesignCriterion(DesignObjective):
    """``kpi_gp`` as a function of the measurement configurations Q (a
    :class:`~pin_kpi_oed.oed.objective.DesignObjective`: the objective of the configuration criterion
    :class:`~pin_kpi_oed.oed.criteria.KpiDiscrepancy`).

    Attributes:
        model: the measurement model (3-D tracker; linearised at ``p``).
        base: indices of the identifiable parameters.
        discrepancy: the :class:`DiscrepancyPrior`.
        Q_work: working configurations (t, n) rad.
        Q_given: poses measured before (k, n) rad (their rows count; only Q moves), or None.
        prior_info: Σ₀⁻¹ (nb, nb) or None (default: the layout's prior, :func:`prior_of`).
        p: linearisation point (raw parameters); default nominal.
        Q_register: configurations where the set-up will be registered again before the calibration is used (another
            session), or None (used in the set-up it was measured in); see :meth:`set_registration`.

    Raises:
        InputError: a 6-D probe model (the discrepancy covers positions only).
    """

    model: Any
    base: np.ndarray
    discrepancy: DiscrepancyPrior
    Q_work: np.ndarray
    Q_given: np.ndarray | None = None
    prior_info: np.ndarray | None = None
    p: np.ndarray | None = None
    Q_register: np.ndarray | None = None
    crit: Any = field(default=None, repr=False)
    #: The :class:`~pin_kpi_oed.oed.reregistration.Reregistration` when the set-up is registered again, else None.
    reg: Any = field(default=None, repr=False)

    def __post_init__(self) -> None:
        if getattr(self.model, "nh", 3) != 3:
            raise InputError("kpi_gp: the discrepancy covers reflector positions only; a 6-D probe model is not "
                             "supported")
        if self.p is None:
            self.p = np.zeros(self.model.n_params)
        self.crit = KpiDiscrepancy()
        self.Q_work = np.atleast_2d(np.asarray(self.Q_work, float))
        R = self.model.tracker_pose(self.p).rotation
        t = self.Q_work.shape[0]
        E = self.model.kpi_jacobian(self.p, self.Q_work).reshape(t, 3, -1)[:, :, self.base]
        self.E = np.einsum("ba,tbp->tap", R, E)
        if self.prior_info is None:
            ps = prior_of(self.model, self.base)
            self.prior_info = None if ps is None else np.diag(1.0 / np.asarray(ps, float) ** 2)
        d = self.discrepancy
        self.tr_kww = float(np.trace(d.covariance(self.Q_work)))
        self.Kww = d.covariance(self.Q_work)
        if self.Q_given is not None and len(self.Q_given):
            self.Q_given = np.atleast_2d(np.asarray(self.Q_given, float))
            self.J_given = base_frame_jacobian(self.model, self.p, self.Q_given, self.base, False)[0]
        else:
            self.Q_given, self.J_given = None, None
        if self.Q_register is not None:
            self.set_registration(self.Q_register)

    def set_registration(self, Q_register: np.ndarray) -> None:
        """Score the TCP error after the set-up is registered again on ``Q_register`` (another session): E becomes
        the re-registered KPI Jacobian Ẽ and the registration's own covariance is added to C_s
        (:mod:`pin_kpi_oed.oed.reregistration`). Set :attr:`E` before the first call; a later call (other
        configurations) starts again from that un-registered E.

        Raises:
            InputError: configurations that do not determine the set-up.
        """
        from pin_kpi_oed.oed.reregistration import reregistration

        Q_register = np.atleast_2d(np.asarray(Q_register, float))
        setup = self.model.layout.is_setup()[self.base]
        E = self.E if self.reg is None else self.reg.E_before
        d = self.discrepancy
        self.reg = reregistration(E, self.pool_jacobians(Q_register), setup, d.scale_m, d.noise, Q_register)
        self.E = self.reg.E
        self.Q_register = Q_register

    @property
    def tr_register(self) -> float:
        """tr C_reg (m²): the registration's own error at the working configurations (0 without re-registration)."""
        return 0.0 if self.reg is None else self.reg.trace_m2

    def _all(self, Q: np.ndarray, J: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
        if J is None:  # no new poses: the measured ones alone
            return self.Q_given, self.J_given
        if self.Q_given is None:
            return Q, J
        return np.vstack([self.Q_given, Q]), np.concatenate([self.J_given, J])

    def cross_covariance(self, Qa: np.ndarray) -> np.ndarray:
        """K_WQ of the KPI rows (len(E), len(Qa)): the kernel between the working configurations and the poses Qa,
        zero for KPI rows beyond the working configurations (they carry no discrepancy, :func:`pad_rows`)."""
        return pad_rows(self.discrepancy.covariance(self.Q_work, Qa), self.E.shape[0])

    def covariance(self, Q: np.ndarray) -> np.ndarray:
        """C_s (3t, 3t) m² of the measured poses (``Q_given`` + Q), base frame."""
        Qa, Ja = self._all(np.atleast_2d(Q),
                           base_frame_jacobian(self.model, self.p, np.atleast_2d(Q), self.base, False)[0])
        d = self.discrepancy
        r = self.E.shape[0]
        Kww = pad_rows(pad_rows(self.Kww, r).T, r)
        C = kpi_gp_covariance(Ja, self.E, d.covariance(Qa), self.cross_covariance(Qa), Kww, d.scale_m, d.noise,
                              self.prior_info)
        return C if self.reg is None else C + self.reg.cov_m2

    def reregistered_covariance(self, Q: np.ndarray) -> np.ndarray:
        """C_s (3t, 3t) m² of the measured poses (``Q_given`` + Q), base frame, after re-registration in the exact
        form: the kriging error at R in the registration
        (:func:`~pin_kpi_oed.oed.reregistration.reregistered_covariance`);
        :meth:`covariance` without re-registration."""
        from pin_kpi_oed.oed.reregistration import reregistered_covariance

        Q = np.atleast_2d(Q)
        if self.reg is None:
            return self.covariance(Q)
        Qa, Ja = self._all(Q, base_frame_jacobian(self.model, self.p, Q, self.base, False)[0] if len(Q) else None)
        d, WR = self.discrepancy, np.vstack([self.Q_work, self.Q_register])
        E2 = np.concatenate([self.reg.E_before, self.pool_jacobians(self.Q_register)])
        C_WR = kpi_gp_covariance(Ja, E2, d.covariance(Qa), d.covariance(WR, Qa), d.covariance(WR), d.scale_m, d.noise,
                                 self.prior_info)
        return reregistered_covariance(self.reg, C_WR)

    def value(self, Q: np.ndarray) -> float:
        """tr C_s (m²)."""
        Q = np.atleast_2d(Q)
        if len(Q) == 0 and self.Q_given is None:
            raise IdentifiabilityError("no poses: the parameters are not identified")
        Qa, Ja = self._all(Q, base_frame_jacobian(self.model, self.p, Q, self.base, False)[0] if len(Q) else None)
        d = self.discrepancy
        return kpi_gp_value_and_grad(Ja, self.E, d.covariance(Qa), self.cross_covariance(Qa), self.tr_kww,
                                     d.scale_m, d.noise, self.prior_info, grad=False)[0] + self.tr_register

    def value_and_grad(self, Q: np.ndarray) -> tuple[float, np.ndarray]:
        """tr C_s (m²) and its exact gradient w.r.t. Q (m, n) (m² per rad)."""
        Q = np.atleast_2d(np.asarray(Q, float))
        J, dJ = base_frame_jacobian(self.model, self.p, Q, self.base, True)
        Qa, Ja = self._all(Q, J)
        k = 0 if self.Q_given is None else len(self.Q_given)
        d = self.discrepancy
        val, g = kpi_gp_value_and_grad(Ja, self.E, d.covariance(Qa), self.cross_covariance(Qa), self.tr_kww,
                                       d.scale_m, d.noise, self.prior_info)
        grad = chain_q(g, dJ, d, Q, Qa, k)
        grad += np.einsum("ti,itk->ik", g["Kwq"][:len(self.Q_work), k:], d.grad_x(Q, self.Q_work))
        return val + self.tr_register, grad

    def pool_jacobians(self, Q_pool: np.ndarray) -> np.ndarray:
        """Base-frame Jacobians of candidate poses (N, 3, nb)."""
        return base_frame_jacobian(self.model, self.p, np.atleast_2d(Q_pool), self.base, False)[0]

    def select(self, Q_pool: np.ndarray, m: int, seed: int = 0, J_pool: np.ndarray | None = None, **kw: Any
               ) -> PoolSelection:
        """m of the candidate poses by :func:`select_pool_gp` (on top of ``Q_given``)."""
        J_pool = self.pool_jacobians(Q_pool) if J_pool is None else J_pool
        sel = select_pool_gp(J_pool, np.atleast_2d(Q_pool), self.E, self.Q_work, self.discrepancy, m,
                             self.prior_info, Q_given=self.Q_given, J_given=self.J_given, **kw)
        if self.reg is not None:
            sel.value += self.tr_register
            sel.path = sel.path + self.tr_register
        return sel


# --------------------------------------------------------------------------- how many poses
@dataclass
class PosesNeeded(Result):
    """Predicted TCP σ at the working configurations (discrepancy included) against the number of poses (a
    :class:`~pin_kpi_oed.results.Result`: ``success`` when the target is reached or none was asked for, ``status``
    ``reached`` / ``not reached`` / ``curve``).

    Attributes:
        n: numbers of new poses (on top of the measured ones, if any).
        sigma_designed_m: σ = sqrt(tr C_s / t) of the greedy kpi_gp design of each size from the pool (m;
            the sizes are nested: the first n poses of one greedy sequence), recomputed from scratch.
        sigma_random_m: mean σ of ``n_random`` seeded random subsets of the pool of each size (m).
        sigma_random_sd_m: their standard deviation (m).
        sigma_now_m: σ of the measured poses alone (m), or None without measured poses.
        order: the greedy sequence (pool indices).
        pool_size: candidates; seed: seed of the random subsets.
        target_sigma_m: the target (m) or None; n_for_target: fewest designed poses reaching it (None: not reached
            within ``n.max()``; 0: the measured poses already reach it); plateau_m: σ with the most designed poses tried
            (what the discrepancy allows
            with this pool and budget).
    """

    n: np.ndarray
    sigma_designed_m: np.ndarray
    sigma_random_m: np.ndarray
    sigma_random_sd_m: np.ndarray
    sigma_now_m: float | None
    order: np.ndarray
    pool_size: int
    seed: int
    target_sigma_m: float | None = None
    n_for_target: int | None = None
    plateau_m: float = float("nan")

    def to_dict(self) -> dict:
        """Plain JSON-able dict (SI units)."""
        return {**self.result_dict(), "n": self.n.tolist(), "sigma_designed_m": self.sigma_designed_m.tolist(),
                "sigma_random_m": self.sigma_random_m.tolist(), "sigma_random_sd_m": self.sigma_random_sd_m.tolist(),
                "sigma_now_m": self.sigma_now_m, "pool_size": self.pool_size, "seed": self.seed,
                "target_sigma_m": self.target_sigma_m, "n_for_target": self.n_for_target,
                "plateau_m": self.plateau_m, "time_s": self.time_s,
                "note": "predicted TCP sigma at the working configurations with the discrepancy (universal kriging); "
                        "designed = greedy kpi_gp sequence from the pool "
                        "(nested; the IPOPT design of one size is usually better)"
                        ", random = mean of seeded random subsets"}

    def summary(self) -> str:
        """The answer in words (µm), with the honest plateau when the target is out of reach."""
        top = int(self.n.max())
        if self.target_sigma_m is None:
            return (f"poses needed (discrepancy included): {top} designed poses reach {self.plateau_m * 1e6:.1f} um "
                    f"at the working configurations (random: {self.sigma_random_m[-1] * 1e6:.1f} um)")
        tgt = self.target_sigma_m * 1e6
        if self.n_for_target == 0:
            return (f"target_sigma_m {tgt:.3g} um (discrepancy included): the measured poses already reach it "
                    f"(predicted {self.sigma_now_m * 1e6:.1f} um); no more poses are needed")
        if self.n_for_target is not None:
            return (f"target_sigma_m {tgt:.3g} um (discrepancy included): {self.n_for_target} designed pose(s) "
                    f"reach it (verified by recomputing C_s); random poses of this pool: "
                    + (f"{int(self.n[np.argmax(self.sigma_random_m <= self.target_sigma_m)])}"
                       if np.any(self.sigma_random_m <= self.target_sigma_m) else f"more than {top}"))
        half = int(np.argmin(np.abs(self.n - top / 2)))
        gain = 100.0 * (1.0 - self.plateau_m / self.sigma_designed_m[half])
        return (f"target_sigma_m {tgt:.3g} um is below what the discrepancy allows within {top} poses: {top} designed "
                f"poses reach only {self.plateau_m * 1e6:.1f} um, {self.plateau_m * 1e6 - tgt:.1f} um "
                f"({self.plateau_m / self.target_sigma_m:.2f}x) above the target, "
                f"and going from {int(self.n[half])} to "
                f"{top} poses lowered sigma by only {gain:.0f} %; a better model (effects) or a smaller working "
                f"region helps more than poses")


def poses_needed(crit: DiscrepancyDesignCriterion, Q_pool: np.ndarray, n_max: int, n_points: int = 12,
                 target_sigma_m: float | None = None, n_random: int = 5, seed: int = 0) -> PosesNeeded:
    """The poses-needed curve: predicted σ at the working configurations (discrepancy included) vs number of poses,
    for the greedy kpi_gp sequence and for random subsets of a feasible pool; the fewest designed poses that reach
    ``target_sigma_m``.

    Args:
        crit: the discrepancy-aware criterion (with the measured poses, if any).
        Q_pool: feasible candidate poses (N, n) rad.
        n_max: most new poses (≤ N).
        n_points: sizes of the curve (geometric grid from the smallest identifying size to ``n_max``).
        target_sigma_m: target σ (m) or None.
        n_random: random subsets per size; seed: their seed.

    Raises:
        InputError: a non-positive target, fewer candidates than ``n_max``.
    """
    t0 = time.perf_counter()
    if target_sigma_m is not None and not (target_sigma_m > 0):
        raise InputError(f"target_sigma_m: must be > 0 m, got {target_sigma_m}")
    N = len(Q_pool)
    n_max = min(int(n_max), N)
    t = crit.Q_work.shape[0]
    Jp = crit.pool_jacobians(Q_pool)
    sel = crit.select(Q_pool, n_max, J_pool=Jp, exchange_passes=0)
    order = sel.indices
    nb = crit.E.shape[2]
    given = crit.Q_given is not None
    n_min = 1 if given else max(1, int(np.ceil(nb / 3)))
    grid = np.unique(np.round(np.geomspace(n_min, n_max, n_points)).astype(int))

    def sigma(idx: np.ndarray) -> float:
        try:
            return float(np.sqrt(crit.value(Q_pool[idx]) / t))
        except IdentifiabilityError:
            return float("inf")
    des = np.array([sigma(order[:k]) for k in grid])
    rng = np.random.default_rng(seed)
    rs = np.array([[sigma(rng.choice(N, k, replace=False)) for _ in range(n_random)] for k in grid])
    rs = np.where(np.isfinite(rs), rs, np.nan)
    now = None
    if given:
        try:
            now = float(np.sqrt(crit.value(np.zeros((0, Q_pool.shape[1]))) / t))
        except IdentifiabilityError:
            now = float("inf")
    out = PosesNeeded(n=grid, sigma_designed_m=des, sigma_random_m=np.nanmean(rs, axis=1),
                      sigma_random_sd_m=np.nanstd(rs, axis=1), sigma_now_m=now, order=order, pool_size=N, seed=seed,
                      target_sigma_m=target_sigma_m, plateau_m=float(des[-1]))
    if target_sigma_m is not None and now is not None and now <= target_sigma_m:
        out.n_for_target = 0                                   # the measured poses already reach it
    elif target_sigma_m is not None:
        path = np.sqrt(np.maximum(sel.path, 0) / t)
        hit = np.flatnonzero(path <= target_sigma_m)
        if hit.size:
            k = int(hit[0]) + 1
            while k <= n_max and sigma(order[:k]) > target_sigma_m * (1 + 1e-9):  # verify from scratch
                k += 1
            out.n_for_target = k if k <= n_max else None
    out.time_s = time.perf_counter() - t0
    out.success = target_sigma_m is None or out.n_for_target is not None
    out.status = "curve" if target_sigma_m is None else ("reached" if out.n_for_target is not None else "not reached")
    out.message = out.summary()
    return out
