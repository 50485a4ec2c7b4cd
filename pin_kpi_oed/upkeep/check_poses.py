r"""Poses to add to a check whose rows do not determine what the verdict needs.

Ten rows measured near C's working configurations of another session determine the tracker pose on the rows, but
not its lever arm at the working configurations; or a group named by the verdict is not determined by the rows.
Instead of refusing, the check names the poses to measure next: the measured rows are *given* (their whitened
information is the fixed rows ``F_given`` of a :class:`~pin_kpi_oed.oed.objective.DesignCriterion`, M₀ = F_gᵀF_g)
and poses of a pool are added greedily by the check criterion φ(M₀ + Σ Mᵢ)
(:class:`~pin_kpi_oed.oed.check_power.CheckPower`: the power against the weakest change of each group) until

* the set-up is determined at the working configurations W: the registration's own σ there,
  sqrt(tr(E_s (M_ss)⁻¹ E_sᵀ) / t) (E_s the KPI Jacobian's set-up columns, M_ss the set-up block of the whitened
  information), is at most ``factor`` × the model's honest σ at W (RMS 3-D);
* every group's change is determined (φ finite: each μ_g > 0).
"""

from __future__ import annotations

import numpy as np

from pin_kpi_oed.errors import IdentifiabilityError
from pin_kpi_oed.oed.check_power import CheckPower

__all__ = ["registration_sigma_m", "poses_to_add", "SETUP_FACTOR"]

#: The registration's σ at the working configurations may be at most this multiple of the honest σ there.
SETUP_FACTOR = 2.0


def registration_sigma_m(E_s: np.ndarray, M_ss: np.ndarray) -> float:
    """RMS 3-D σ (m) the registration alone leaves at the working configurations: sqrt(tr(E_s M_ss⁻¹ E_sᵀ) / t).

    Args:
        E_s: KPI Jacobian's set-up columns (3t, k) m per unit; M_ss: whitened information of the set-up (k, k).
    """
    C = E_s @ np.linalg.pinv(M_ss, hermitian=True) @ E_s.T
    return float(np.sqrt(max(np.trace(C), 0.0) / (E_s.shape[0] // 3)))


def _needs(crit: CheckPower, M: np.ndarray, E_s: np.ndarray, limit_m: float) -> bool:
    """Whether information M still leaves the set-up undetermined at W or a group undetermined."""
    s = crit.setup
    if registration_sigma_m(E_s, M[np.ix_(s, s)]) > limit_m:
        return True
    try:
        return not np.isfinite(crit.value_M(M))
    except IdentifiabilityError:
        return True


def poses_to_add(crit: CheckPower, wm, p: np.ndarray, F_given: np.ndarray, E_s: np.ndarray, honest_w_m: float,
                 Q_pool: np.ndarray, *, max_add: int = 20, factor: float = SETUP_FACTOR, seed: int = 0
                 ) -> tuple[np.ndarray, float]:
    """The fewest pool poses (greedy) that, with the measured rows, determine the set-up at the working
    configurations and every group (module docstring).

    Args:
        crit: the check criterion; wm, p: the station's measurement model (noise σ = the honest σ per axis) and its
            raw parameters.
        F_given: the measured rows' whitened Jacobian (3m, np).
        E_s: KPI Jacobian's set-up columns at the working configurations (3t, k); honest_w_m: the honest σ there
            (RMS 3-D, m).
        Q_pool: candidate configurations (N, n) rad (feasible ones: ``check design --given``).
        max_add: the most poses to add; factor: as :data:`SETUP_FACTOR`; seed: tie order.

    Returns:
        (poses (k, n) rad — empty when the measured rows suffice —, the registration's σ at W after them, m); k =
        ``max_add`` when the pool cannot reach the goal (the σ says how far it got).
    """
    from pin_kpi_oed.oed.objective import DesignCriterion

    given = DesignCriterion(wm, np.arange(wm.layout.n), crit, F_given=np.asarray(F_given, float), p=p)
    R = np.asarray(given.F_given, float)
    M = R.T @ R
    limit = factor * honest_w_m
    if not _needs(crit, M, E_s, limit):
        return np.zeros((0, Q_pool.shape[1])), registration_sigma_m(E_s, M[np.ix_(crit.setup, crit.setup)])
    Fp = wm.weighted_jacobian(p, Q_pool)[:, :3, :]
    Mi = np.einsum("nap,naq->npq", Fp, Fp)
    ridge = 1e-9 * max(float(np.max(np.diag(M))), 1e-300) * np.eye(M.shape[0])
    order = np.random.default_rng(seed).permutation(len(Q_pool))
    s = crit.setup
    chosen: list[int] = []
    for _ in range(max_add):
        vals, regs = np.full(len(order), np.inf), np.full(len(order), np.inf)
        for j, i in enumerate(order):
            if i not in chosen:
                regs[j] = registration_sigma_m(E_s, (M + Mi[i])[np.ix_(s, s)])
        # while no candidate determines the set-up at W, its σ there leads; then the check criterion (evaluated on
        # the candidates that determine it: no other's value is read)
        ok = regs <= limit
        for c in np.flatnonzero(ok).tolist():
            try:
                vals[c] = crit.value_M(M + Mi[order[c]] + ridge)
            except IdentifiabilityError:
                pass
        k = int(order[int(np.argmin(np.where(ok, vals, np.inf)))] if ok.any() else order[int(np.argmin(regs))])
        chosen.append(k)
        M = M + Mi[k]
        if not _needs(crit, M, E_s, limit):
            break
    return Q_pool[chosen], registration_sigma_m(E_s, M[np.ix_(s, s)])
