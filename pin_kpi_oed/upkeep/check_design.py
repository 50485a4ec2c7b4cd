"""The designed check: a few poses chosen for verification, not identification.

The poses maximise the check's power against the weakest change of each parameter group of the robot that moves
the TCP by the tolerance τ (RMS over the working configurations), the set-up re-determined on the same poses:
:class:`~pin_kpi_oed.oed.check_power.CheckPower` (a criterion of the information matrix over the set-up and the
groups' columns) minimised over a pool of configurations that are feasible in the cell (collision, joint limits,
tracker line of sight and incidence: :func:`~pin_kpi_oed.cell.sampling.random_feasible`), by greedy forward
selection (a ridge on the first poses, until the set-up is determined) and an exchange pass, with the rank-3
information of every candidate computed once. The poses are whitened by the model's honest σ (the median over the
pool of :meth:`~pin_kpi_oed.calibrated.model_file.CalibratedModel.predict_with_sigma`).

The design is sized for the check's verdict, not only for its test: *the robot changed* needs the test T to reject
and the change to be shown above the tolerance (:func:`~pin_kpi_oed.upkeep.check.verdict_powers`). The design states
that power against the weakest change of :data:`SIZE_FACTOR` × τ of each group, and the fewest poses of the greedy
order that reach :data:`TARGET_POWER` (``poses_needed``; 0 when :data:`MAX_POSES` do not).
"""

from __future__ import annotations

import time
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field
from itertools import chain, islice

import numpy as np

from pin_kpi_oed.errors import IdentifiabilityError, InputError
from pin_kpi_oed.upkeep.check import check_criterion, check_null, check_powers, verdict_powers
from pin_kpi_oed.calibrated.model_file import CalibratedModel
from pin_kpi_oed.oed.check_power import CheckPower
from pin_kpi_oed.oed.selection_result import PoolSelection
from pin_kpi_oed.results import Result

__all__ = ["CheckDesign", "design_check", "check_pool", "select_check", "SIZE_FACTOR", "TARGET_POWER"]

#: The change (× the tolerance) the verdict's power is stated against, and the power the design is sized for.
SIZE_FACTOR = 1.5
TARGET_POWER = 0.95
#: The most poses the sizing tries.
MAX_POSES = 40


@dataclass(kw_only=True)
class CheckDesign(Result):
    """A designed check (SI units).

    Attributes:
        Q: the poses (m, n) rad; selection: the :class:`PoolSelection`.
        power: group -> power against its weakest change of size ``tolerance_m`` at level ``alpha``.
        power_random: the same for m seeded random poses of the same pool (the median over ``n_random`` draws).
        tolerance_m, alpha: what the power is stated for; sigma_m: the honest σ per axis the poses are whitened with.
        feasible_in: the cell the pool is feasible in, or "" (joint limits only).
        verdict_power: group -> probability that the verdict says *the robot changed* for the group's weakest change
            of :data:`SIZE_FACTOR` × ``tolerance_m`` at the TCP.
        poses_needed: the fewest poses of the greedy order whose weakest verdict power reaches :data:`TARGET_POWER`
            (0: not within :data:`MAX_POSES` or the pool).
    """

    Q: np.ndarray
    selection: PoolSelection = field(repr=False)
    power: dict
    power_random: dict
    tolerance_m: float
    alpha: float
    sigma_m: np.ndarray
    feasible_in: str = ""
    verdict_power: dict = field(default_factory=dict)
    poses_needed: int = 0

    def summary(self) -> str:
        """One line (mm)."""
        w = min(self.power, key=self.power.get)
        wr = min(self.power_random, key=self.power_random.get)
        where = f"feasible in {self.feasible_in}" if self.feasible_in else "within the joint limits (no cell given)"
        return (f"check design: {len(self.Q)} poses ({where}); power against a {self.tolerance_m * 1e3:.3g} mm change "
                f"at the TCP (alpha {self.alpha:g}): weakest {self.power[w]:.2f} ({w}); {len(self.Q)} random poses: "
                f"{self.power_random[wr]:.2f} ({wr})" + self.sizing_text())

    def sizing_text(self) -> str:
        """The verdict's power against a change of 1.5 × τ and the poses it needs."""
        if not self.verdict_power:
            return ""
        w = min(self.verdict_power, key=self.verdict_power.get)
        need = (f"{self.poses_needed} poses reach {TARGET_POWER:.2f}" if self.poses_needed
                else f"more than {MAX_POSES} poses would be needed for {TARGET_POWER:.2f}")
        return (f"; the verdict says 'the robot changed' for a {SIZE_FACTOR:g} x tolerance change with probability "
                f"{self.verdict_power[w]:.2f} (weakest: {w}); {need}")

    def to_dict(self) -> dict:
        """Plain JSON-able dict (SI units)."""
        return {**self.result_dict(), "q_check": np.asarray(self.Q).tolist(), "power": self.power,
                "power_random": self.power_random, "tolerance_m": self.tolerance_m, "alpha": self.alpha,
                "sigma_m": np.asarray(self.sigma_m).tolist(), "feasible_in": self.feasible_in,
                "verdict_power": self.verdict_power, "poses_needed": self.poses_needed,
                "selection": self.selection.to_dict()}


def check_pool(model: CalibratedModel, n: int, seed: int, cell=None) -> np.ndarray:
    """n seeded candidate configurations: feasible in ``cell`` when given, else uniform within the joint limits.

    Raises:
        InfeasibleError: the cell admits too few poses.
    """
    rng = np.random.default_rng(seed)
    rb = model.robot
    if cell is None:
        return rng.uniform(rb.q_lower, rb.q_upper, size=(n, rb.nq))
    from pin_kpi_oed.cell.collision import CollisionModel
    from pin_kpi_oed.cell.sampling import random_feasible

    return random_feasible(CollisionModel(cell), n, rng, cell.max_random_tries)[0]


def select_check(crit: CheckPower, Fp: np.ndarray, m: int, seed: int = 0, exchange: bool = True) -> PoolSelection:
    """m of the candidates (whitened Jacobians Fp (N, 3, np)) minimising the check criterion: greedy forward
    selection (a ridge of 1e-6 of the mean information until the set-up is determined), one exchange pass (unless
    ``exchange`` is False: the greedy order).

    Raises:
        InputError: m larger than the pool or below 3.
    """
    return _select(crit, Fp, m, seed, exchange)[0]


def _select(crit: CheckPower, Fp: np.ndarray, m: int, seed: int,
            exchange: bool) -> tuple[PoolSelection, Iterator[tuple[int, float, np.ndarray]]]:
    """:func:`select_check`'s selection and the whole greedy order it began with (its first m steps, then the
    rest, made as they are read: :func:`_greedy`'s steps)."""
    t0 = time.perf_counter()
    if not 3 <= m <= len(Fp):
        raise InputError(f"check design: {m} poses from a pool of {len(Fp)} candidates (3 to {len(Fp)})")
    Mi = np.einsum("nap,naq->npq", Fp, Fp)
    greedy = _greedy(crit, Mi, seed)
    steps = list(islice(greedy, m))
    return _exchanged(crit, Mi, steps, exchange, t0), chain(steps, greedy)


def _exchanged(crit: CheckPower, Mi: np.ndarray, steps: list[tuple[int, float, np.ndarray]], exchange: bool,
               t0: float) -> PoolSelection:
    """The selection of :func:`select_check` from its first greedy ``steps`` (:func:`_greedy`): one exchange pass
    over them unless ``exchange`` is False; ``t0``: when the selection began (``time.perf_counter``, s)."""
    N, m = len(Mi), len(steps)
    chosen = [i for i, _, _ in steps]
    path = [value for _, value, _ in steps]
    M = steps[-1][2]
    cur, swaps = _phi_one(crit, M), 0
    for pos in range(m if exchange else 0):
        base = M - Mi[chosen[pos]]
        vals = np.full(N, np.inf)
        free = np.setdiff1d(np.arange(N), chosen)
        vals[free] = phi_batch(crit, base, Mi, free)
        if vals.min() < cur:
            k = int(np.argmin(vals))
            chosen[pos], M, cur, swaps = k, base + Mi[k], float(vals[k]), swaps + 1
    return PoolSelection(indices=np.array(chosen), value=float(cur), path=np.array(path), nit=swaps,
                         time_s=time.perf_counter() - t0, success=bool(np.isfinite(cur)), status="selected",
                         message=f"greedy + one exchange pass ({swaps} swaps) on the check criterion; no certificate")


def _greedy(crit: CheckPower, Mi: np.ndarray, seed: int) -> Iterator[tuple[int, float, np.ndarray]]:
    """The greedy forward order of :func:`select_check`, one pose at a time (a pose's choice does not depend on how
    many follow, so a caller may stop at any length): the candidates in a seeded random order, a ridge of 1e-6 of the
    mean information until the set-up is determined.

    Args:
        crit: the check criterion; Mi: (N, np, np) rank-3 information of each candidate; seed: the order's seed.

    Yields:
        (the pose chosen, φ with it (log units), the information of the poses chosen so far (np, np)).
    """
    ridge = 1e-6 * np.mean(np.einsum("npp->np", Mi), axis=0).max() * np.eye(Mi.shape[1])
    order = np.random.default_rng(seed).permutation(len(Mi))
    chosen: list[int] = []
    M = np.zeros_like(ridge)
    while len(chosen) < len(Mi):
        cand = np.array([i for i in order if i not in chosen])
        vals = phi_batch(crit, M, Mi, cand, ridge)
        j = int(np.argmin(vals))
        chosen.append(int(cand[j]))
        M = M + Mi[cand[j]]
        yield int(cand[j]), float(vals[j]), M


def phi_batch(crit: CheckPower, base: np.ndarray, Mi: np.ndarray, idx: np.ndarray, ridge: np.ndarray | None = None,
              chunk: int = 256) -> np.ndarray:
    """The criterion φ(base + Mi[i] (+ ridge)) of each candidate i in ``idx`` (inf where the poses do not determine
    the set-up or a group): :meth:`CheckPower.value_M` evaluated on a stack of information matrices at once, the
    same algebra (Cholesky of the set-up block, its solve, each group's Schur complement and smallest eigenvalue,
    the smooth maximum) as the one-matrix form, in chunks of ``chunk`` candidates.

    Args:
        crit: the check criterion; base: (np, np) information of the poses already chosen.
        Mi: (N, np, np) rank-3 information of each candidate; idx: (B,) the candidates evaluated.
        ridge: (np, np) added to each sum, or None; chunk: candidates stacked at once.

    Returns:
        (B,) φ per candidate (log units).
    """
    out = np.empty(len(idx))
    for a in range(0, len(idx), chunk):
        Ms = base + Mi[idx[a:a + chunk]]
        out[a:a + chunk] = _phi_stack(crit, Ms if ridge is None else Ms + ridge)
    return out


def _phi_stack(crit: CheckPower, Ms: np.ndarray) -> np.ndarray:
    """φ of each matrix of the stack Ms (B, np, np); inf where :meth:`CheckPower.value_M` raises."""
    every = (slice(None),)
    try:
        Lss = np.linalg.cholesky(Ms[every + crit.ix_ss])
    except np.linalg.LinAlgError:           # one of them does not determine the set-up: one at a time
        return np.array([_phi_one(crit, M) for M in Ms])
    X_all = np.linalg.solve(Lss, Ms[every + crit.ix_s_all])
    mu = np.empty((len(Ms), len(crit.groups)))
    for j, (g, (pos, gg)) in enumerate(zip(crit.groups, crit.ix_groups)):
        X = X_all[:, :, pos]
        H = g.C.T @ (Ms[every + gg] - np.swapaxes(X, 1, 2) @ X) @ g.C
        mu[:, j] = np.linalg.eigh(0.5 * (H + np.swapaxes(H, 1, 2)))[0][:, 0]
    bad = np.any(mu <= 0, axis=1)
    lw = -crit.kappa * np.log(np.where(bad[:, None], 1.0, mu))
    top = lw.max(axis=1)
    val = (top + np.log(np.exp(lw - top[:, None]).sum(axis=1))) / crit.kappa
    return np.where(bad, np.inf, val)


def _phi_one(crit: CheckPower, M: np.ndarray) -> float:
    """φ(M), inf where the poses do not determine the set-up or a group."""
    try:
        return crit.value_M(M)
    except IdentifiabilityError:
        return np.inf


def design_check(model: CalibratedModel, *, m: int = 10, tolerance_m: float = 1e-4, alpha: float = 0.05,
                 cell=None, pool_size: int = 400, seed: int = 0, station: str | None = None,
                 q_work: np.ndarray | None = None, n_random: int = 20, size: bool = True) -> CheckDesign:
    """Design a check of ``m`` poses (module docstring).

    Args:
        model: the calibrated model; station: the station whose set-up the check re-registers (default station).
        m: number of check poses (≥ 3; 10 recommended).
        tolerance_m: the RMS TCP change at the working configurations the check must detect (m).
        alpha: the check's false-alarm rate.
        cell: the work cell (a :class:`~pin_kpi_oed.cell.cell_model.Cell`) the poses must be feasible in, or None.
        pool_size: candidate configurations; seed: their seed and the selection's.
        q_work: working configurations (t, n) rad; default the model's, else the cell's.
        n_random: random designs of m pool poses the power is compared with.
        size: also find the poses the verdict needs (``poses_needed``; False: 0, not computed).

    Raises:
        InputError: no working configurations, m out of range, a tolerance ≤ 0.
        InfeasibleError: the cell admits fewer than ``pool_size`` poses.
    """
    t0 = time.perf_counter()
    if not (np.isfinite(tolerance_m) and tolerance_m > 0):
        raise InputError(f"check design: the tolerance must be > 0 m, got {tolerance_m}")
    qw = q_work if q_work is not None else model.q_work
    if qw is None and cell is not None:
        qw = cell.q_work
    if qw is None:
        raise InputError("check design: no working configurations (the model file has none; give a cell (parameter "
                         "'cell') with working configurations)")
    Q_pool = check_pool(model, pool_size, seed, cell)
    sigma = np.median(model.predict_with_sigma(Q_pool, station=station)[1], axis=0)
    crit, wm, p = check_criterion(model, np.atleast_2d(qw), sigma, station, seed=seed)
    Fp = wm.weighted_jacobian(p, Q_pool)[:, :3, :]
    sel, greedy = _select(crit, Fp, m, seed, True)     # the selection's greedy poses begin the sizing's order
    null = check_null(model)
    power = check_powers(crit, Fp[sel.indices].reshape(-1, Fp.shape[2]), tolerance_m, alpha, null)
    rng = np.random.default_rng(seed + 1)
    rand = [check_powers(crit, Fp[rng.choice(len(Q_pool), m, replace=False)].reshape(-1, Fp.shape[2]),
                         tolerance_m, alpha, null) for _ in range(n_random)]
    power_random = {k: float(np.median([r[k] for r in rand])) for k in power}
    vp = verdict_powers(crit, Fp[sel.indices].reshape(-1, Fp.shape[2]), tolerance_m, alpha, null, SIZE_FACTOR)
    return CheckDesign(Q=Q_pool[sel.indices], selection=sel, power=power, power_random=power_random,
                       tolerance_m=tolerance_m, alpha=alpha, sigma_m=sigma, verdict_power=vp,
                       poses_needed=_poses_needed(crit, Fp, tolerance_m, alpha, null, greedy)
                       if size else 0,
                       feasible_in=getattr(cell, "name", "") if cell is not None else "", success=sel.success,
                       status="designed", message=sel.message, time_s=time.perf_counter() - t0)


def _poses_needed(crit: CheckPower, Fp: np.ndarray, tolerance_m: float, alpha: float, null,
                  greedy: Iterable[tuple[int, float, np.ndarray]]) -> int:
    """The fewest poses of the greedy order (no exchange; ``greedy``: its steps, :func:`_greedy`) whose weakest
    verdict power reaches :data:`TARGET_POWER` (0 when :data:`MAX_POSES` or the pool do not); the order is grown only
    as far as the answer."""
    n = min(MAX_POSES, len(Fp))
    if n < 3:
        return 0
    order: list[int] = []
    for i, _, _ in islice(greedy, n):
        order.append(i)
        if len(order) < 3:
            continue
        F = Fp[order].reshape(-1, Fp.shape[2])
        try:
            if min(verdict_powers(crit, F, tolerance_m, alpha, null, SIZE_FACTOR).values()) >= TARGET_POWER:
                return len(order)
        except IdentifiabilityError:
            continue
    return 0
