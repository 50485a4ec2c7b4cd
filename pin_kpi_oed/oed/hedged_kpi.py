r"""A design under an *assumed* discrepancy that hedges against the assumption being wrong.

Without a fitted discrepancy ``kpi_gp`` assumes one (the robot class's default,
:mod:`~pin_kpi_oed.oed.discrepancy_defaults`): a kernel with its length scales and a level of δ against the white
noise. The design that is optimal for that assumption spends poses on kriging the discrepancy near the working
configurations; on a robot whose discrepancy is shorter, longer, smaller or absent, those poses identify the
parameters worse than the paper's noise-only KPI design would.

The hedged criterion takes the KPI under a *family* of priors P_1 … P_K and their geometric mean

.. math::  φ_H(Q) = \prod_k φ_k(Q)^{ω_k}, \qquad
           \log φ_H(Q) = \sum_k ω_k \log φ_k(Q) = \sum_k ω_k \log\frac{φ_k(Q)}{φ_k^*} + \mathrm{const},
           \qquad \sum_k ω_k = 1,

φ_k = tr C_s under P_k (:class:`~pin_kpi_oed.oed.discrepancy_kpi.DiscrepancyDesignCriterion`, m²). Minimising φ_H
minimises the weighted mean log-regret against each member's own optimum φ_k^*: a member's *relative* loss counts
whatever the size of its traces. The weights: ω = 0.7 for the noise-only member (the paper's KPI, optimal when the
discrepancy is absent or does not matter) and 0.3 shared by the others (:data:`NOISE_ONLY_WEIGHT`; 0.5 and 0.7 were
measured, 0.7 was never worse than the noise-only KPI beyond the noise of the comparison on 12 cases of simulated
robots, 0.5 once: docs/results.md). The family (:func:`prior_family`) around the assumed prior P_0:

* P_0 itself;
* its length scales (whole-configuration and one-joint) × 1/2 and × 2;
* its δ 3× larger against the white level (w / 9);
* the noise-only prior (k ≡ 0, white level w: the paper's KPI, σ² = w s² per axis).

The exact gradient is ∇φ_H = φ_H · Σ_k ω_k ∇φ_k / φ_k (each member's exact dφ_k/dQ), so IPOPT designs with it
as with ``kpi_gp``. Pool selection (:meth:`HedgedDesignCriterion.select`): every member's own selection
(:func:`~pin_kpi_oed.oed.discrepancy_pool.select_pool_gp`, greedy + exchange) is a candidate set; the one of least
φ_H is kept and improved by the one pool selector's exchange passes on φ_H (:class:`HedgedState`: a chosen pose
swapped for the pool candidate that lowers φ_H most, over a seeded subset of the pool when m times the candidates
exceeds :data:`EXCHANGE_EVALUATIONS`; every member's tr C_s of a swap from its
:class:`~pin_kpi_oed.oed.discrepancy_pool.GreedyState`, an exact downdate and rank-three update, instead of a kriging
solve per member and candidate).

A fitted discrepancy (``design --model``) is not hedged: it is a measurement, not an assumption.
"""

from __future__ import annotations

import copy
import dataclasses
import time
from collections.abc import Sequence
from typing import Any

import numpy as np

from pin_kpi_oed.errors import IdentifiabilityError, InputError
from pin_kpi_oed.discrepancy.prior import DiscrepancyPrior
from pin_kpi_oed.oed.discrepancy_kpi import DiscrepancyDesignCriterion
from pin_kpi_oed.oed.discrepancy_pool import GreedyState, after_given
from pin_kpi_oed.oed.pool_search import PoolState, exchange
from pin_kpi_oed.oed.kriging import kpi_gp_value_and_grad
from pin_kpi_oed.oed.design_objective import DesignObjective
from pin_kpi_oed.oed.selection_result import PoolSelection

__all__ = ["LENGTH_FACTORS", "LEVEL_FACTORS", "HEDGE_LINE", "prior_family", "HedgedDesignCriterion",
           "HedgedState"]

#: Factors on the assumed prior's length scales (whole-configuration and one-joint alike).
LENGTH_FACTORS = (0.5, 2.0)
#: Factors on the assumed prior's δ level against its white level (δ × f: w / f²).
LEVEL_FACTORS = (3.0,)
#: Weight of the noise-only member (the other members share the rest evenly).
NOISE_ONLY_WEIGHT = 0.7
#: The line ``design`` prints when it hedges (parameters named as the design settings name them).
HEDGE_LINE = ("kpi_gp: the discrepancy is an assumption (no model_file): the design hedges over 5 priors (weight "
              f"{1 - NOISE_ONLY_WEIGHT:g} on the assumed one, its length scales x{LENGTH_FACTORS[0]:g} and "
              f"x{LENGTH_FACTORS[1]:g} and its level x{LEVEL_FACTORS[0]:g}, {NOISE_ONLY_WEIGHT:g} on noise only; "
              "the weighted geometric mean of their tr C_s), so that a robot whose discrepancy differs is not "
              "designed worse than by the noise-only KPI (hedge False: the assumed prior alone); the sigma shown "
              "is the assumed prior's")
#: Swaps tried per exchange pass: each of the m chosen poses is tried against every other candidate when the pool
#: allows, else against a seeded subset of max(10, this / m) of them (the pass costs about this many evaluations of
#: the K members).
EXCHANGE_EVALUATIONS = 4000


def _scaled_kernel(kernel: Any, factor: float) -> Any:
    """A copy of a :class:`~pin_kpi_oed.discrepancy.kernel.JointKernel` with every length scale × ``factor``."""
    k = copy.deepcopy(kernel)
    k.length_scale = np.asarray(kernel.length_scale, float) * factor
    k.joint_length_scale = np.asarray(kernel.joint_length_scale, float) * factor
    return k


def prior_family(prior: DiscrepancyPrior, length_factors: tuple = LENGTH_FACTORS,
                 level_factors: tuple = LEVEL_FACTORS, noise_only: bool = True) -> list[DiscrepancyPrior]:
    """The priors the hedged criterion averages over (see the module docstring), the assumed one first.

    Args:
        prior: the assumed prior P_0.
        length_factors: factors on its length scales.
        level_factors: factors on its δ against the white level.
        noise_only: add the noise-only prior (k ≡ 0, the same white level).

    Returns:
        [P_0, length variants, level variants, noise-only]; a white prior (no kernel) alone when P_0 is white.
    """
    fam = [prior]
    if prior.kernel is None:
        return fam
    for f in length_factors:
        fam.append(DiscrepancyPrior(_scaled_kernel(prior.kernel, float(f)), prior.scale_m, prior.noise,
                                    f"{prior.source}; length scales x{f:g}"))
    for f in level_factors:
        fam.append(DiscrepancyPrior(prior.kernel, prior.scale_m, prior.noise / float(f) ** 2,
                                    f"{prior.source}; delta x{f:g} against the white level"))
    if noise_only:
        fam.append(DiscrepancyPrior(None, prior.scale_m, prior.noise, "noise only (the paper's KPI)"))
    return fam


@dataclasses.dataclass
class HedgedDesignCriterion(DesignObjective):
    """``kpi_gp`` under an assumed prior, hedged over :func:`prior_family`: the objective the configuration criterion
    ``kpi_gp`` builds when the discrepancy is an assumption (a :class:`~pin_kpi_oed.oed.objective.DesignObjective`:
    ``value``, ``value_and_grad``, ``select``).

    Attributes:
        members: one :class:`DiscrepancyDesignCriterion` per prior of the family (same model, base, working
            configurations, measured poses and parameter prior), the assumed one first.
        crit: the members' criterion (``kpi_gp``: φ_H > 0, m²).
    """

    members: list
    weights: np.ndarray | None = None
    crit: Any = dataclasses.field(default=None, repr=False)

    def __post_init__(self) -> None:
        if not self.members:
            raise InputError("hedged kpi_gp: no prior in the family")
        self.crit = self.members[0].crit
        K = len(self.members)
        if self.weights is None:
            noise = K > 1 and self.members[-1].discrepancy.kernel is None
            self.weights = (np.r_[np.full(K - 1, (1 - NOISE_ONLY_WEIGHT) / (K - 1)), NOISE_ONLY_WEIGHT] if noise
                            else np.full(K, 1.0 / K))
        self.weights = np.asarray(self.weights, float).reshape(-1)
        if self.weights.size != K or np.any(self.weights < 0) or not np.isclose(self.weights.sum(), 1.0):
            raise InputError(f"hedged kpi_gp: {self.weights.size} weights for {K} priors, or not summing to 1")

    @classmethod
    def around(cls, crit: DiscrepancyDesignCriterion, noise_weight: float = NOISE_ONLY_WEIGHT, **family: Any
               ) -> HedgedDesignCriterion:
        """The hedged criterion around ``crit``'s prior: ``noise_weight`` on the noise-only member, the rest shared
        evenly (``family``: keywords of :func:`prior_family`).

        Raises:
            InputError: ``noise_weight`` outside [0, 1).
        """
        if not 0.0 <= float(noise_weight) < 1.0:
            raise InputError(f"hedged kpi_gp: the noise-only weight must be in [0, 1), got {noise_weight}")
        members = [crit]
        for P in prior_family(crit.discrepancy, **family)[1:]:
            members.append(DiscrepancyDesignCriterion(crit.model, crit.base, P, crit.Q_work, Q_given=crit.Q_given,
                                                      prior_info=crit.prior_info, p=crit.p,
                                                      Q_register=crit.Q_register))
        K = len(members)
        if K > 1 and members[-1].discrepancy.kernel is None:
            return cls(members, np.r_[np.full(K - 1, (1.0 - noise_weight) / (K - 1)), noise_weight])
        return cls(members)

    @property
    def discrepancy(self) -> DiscrepancyPrior:
        """The assumed prior P_0 (what the design states and its σ uses)."""
        return self.members[0].discrepancy

    @property
    def Q_given(self) -> np.ndarray | None:
        """Poses measured before (shared by every member)."""
        return self.members[0].Q_given

    def member_values(self, Q: np.ndarray) -> np.ndarray:
        """tr C_s of every member (K,) m²."""
        return np.array([c.value(Q) for c in self.members], float)

    def value(self, Q: np.ndarray) -> float:
        """φ_H (m²): the weighted geometric mean of the members' tr C_s."""
        return float(np.exp(self.weights @ np.log(self.member_values(Q))))

    def value_and_grad(self, Q: np.ndarray) -> tuple[float, np.ndarray]:
        """φ_H (m²) and its exact gradient w.r.t. Q (m, n) (m² per rad)."""
        vals, grads = zip(*(c.value_and_grad(Q) for c in self.members))
        v = np.asarray(vals, float)
        phi = float(np.exp(self.weights @ np.log(v)))
        return phi, phi * sum(w * g / vk for w, g, vk in zip(self.weights, grads, v))

    def covariance(self, Q: np.ndarray) -> np.ndarray:
        """C_s under the assumed prior (3t, 3t) m² (the σ the design states)."""
        return self.members[0].covariance(Q)

    def pool_jacobians(self, Q_pool: np.ndarray) -> np.ndarray:
        """Base-frame Jacobians of candidate poses (N, 3, nb)."""
        return self.members[0].pool_jacobians(Q_pool)

    def set_registration(self, Q_register: np.ndarray) -> None:
        """Score every member after the set-up is registered again on ``Q_register``."""
        for c in self.members:
            c.set_registration(Q_register)

    def select(self, Q_pool: np.ndarray, m: int, seed: int = 0, J_pool: np.ndarray | None = None,
               exchange_passes: int = 1, **kw: Any) -> PoolSelection:
        """m of the candidate poses minimising φ_H: the best of the members' own selections, then exchange passes.

        Args:
            Q_pool: candidates (N, n) rad; m: poses to choose; J_pool: their Jacobians (default computed).
            exchange_passes: exchange passes on φ_H (0: the best member selection as it is).
            seed: seed of the candidate subsets of an exchange over a large pool (:data:`EXCHANGE_EVALUATIONS`).
            kw: passed to each member's :meth:`~DiscrepancyDesignCriterion.select` (e.g. ``time_budget_s``).

        Raises:
            InputError: m larger than the pool. IdentifiabilityError: no member's selection identifies the parameters.
        """
        t0 = time.perf_counter()
        Q_pool = np.atleast_2d(np.asarray(Q_pool, float))
        J_pool = self.pool_jacobians(Q_pool) if J_pool is None else J_pool
        best, best_v = None, np.inf
        caches = self._kernel_caches()
        score = self._pool_scorer(Q_pool, J_pool)
        for c, cache in zip(self.members, caches):
            try:
                idx = np.asarray(c.select(Q_pool, m, J_pool=J_pool, kcols=cache, **kw).indices, int)
                v = score(idx)
            except IdentifiabilityError:
                continue
            if v < best_v:
                best, best_v = idx, v
        if best is None:
            raise IdentifiabilityError(f"hedged kpi_gp: no selection of {m} of the {len(Q_pool)} candidates "
                                       "identifies the parameters under every prior of the family")
        path = [best_v]
        best, best_v, swaps = self._exchange(Q_pool, J_pool, best, best_v, exchange_passes, seed, path, score,
                                             caches)
        return PoolSelection(indices=best, value=float(best_v), path=np.array(path), nit=swaps,
                             time_s=time.perf_counter() - t0, success=True, status="selected",
                             message=f"best member selection + exchange ({swaps} swaps); no certificate")

    def _kernel_caches(self) -> list[dict | None]:
        """One cache of kernel columns per member, shared by the members of one kernel (the level variants)."""
        by_kernel: dict[int, dict] = {}
        return [None if c.discrepancy.kernel is None else by_kernel.setdefault(id(c.discrepancy.kernel), {})
                for c in self.members]

    def _pool_scorer(self, Q_pool: np.ndarray, J_pool: np.ndarray) -> Any:
        """φ_H of pool subsets, from scratch: ``score(idx) -> float`` (m²)."""
        def score(idx: np.ndarray) -> float:
            logs = []
            for c in self.members:
                d = c.discrepancy
                Ja, Qa, k0 = after_given(J_pool, Q_pool, 1, c.J_given, c.Q_given)
                rows = np.concatenate([np.arange(k0), k0 + np.asarray(idx, int)])
                v = kpi_gp_value_and_grad(Ja[rows], c.E, d.covariance(Qa[rows]), d.covariance(c.Q_work, Qa[rows]),
                                          c.tr_kww, d.scale_m, d.noise, c.prior_info, grad=False)[0] + c.tr_register
                logs.append(np.log(v))
            return float(np.exp(self.weights @ np.asarray(logs)))

        return score

    def _exchange(self, Q_pool: np.ndarray, J_pool: np.ndarray, idx: np.ndarray, val: float, passes: int,
                  seed: int, path: list, score: Any, caches: list) -> tuple[np.ndarray, float, int]:
        """Exchange passes on φ_H: the one pool selector's :func:`~pin_kpi_oed.oed.pool_search.exchange` on a
        :class:`HedgedState` (each chosen pose in turn swapped for the candidate of least φ_H among a seeded subset
        of the others; φ_H of a swap from the updates, of the final set from scratch). Appends φ_H after each pass
        to ``path``."""
        if passes <= 0:
            return idx, val, 0
        states = []
        for c, cache in zip(self.members, caches):
            Ja, Qa, k0 = after_given(J_pool, Q_pool, 1, c.J_given, c.Q_given)
            states.append(GreedyState(Ja, Qa, c.E, c.Q_work, c.discrepancy, c.prior_info, 0.0))
            if cache is not None:
                states[-1].kcols = cache
        fixed = list(range(k0))
        st: PoolState = HedgedState([s.build(fixed + list(k0 + idx)) for s in states], self.weights,
                                    np.array([c.tr_register for c in self.members]), k0, len(idx),
                                    np.random.default_rng(seed))
        excl = np.zeros(st.n_candidates, bool)
        excl[:k0] = True
        excl[k0 + idx] = True
        swaps = 0
        for _ in range(int(passes)):
            st, sel, val, n, _ = exchange(st, list(k0 + idx), excl, val, 1, rel_tol=1e-9, fixed=fixed)
            idx, swaps = np.array(sel, int) - k0, swaps + n
            path.append(val)
            if n == 0:
                break
        if swaps:
            val = score(idx)                                     # the value of the set from scratch
            path[-1] = val
        return idx, val, swaps


class HedgedState(PoolState):
    """The :class:`~pin_kpi_oed.oed.pool_search.PoolState` of the hedged criterion: every member's
    :class:`~pin_kpi_oed.oed.discrepancy_pool.GreedyState` over the same candidates (measured poses first); φ_H of a
    swap from the members' exact downdates and rank-three updates, over a seeded subset of the candidates when m
    times the candidates exceeds :data:`EXCHANGE_EVALUATIONS` (φ_H ``inf`` elsewhere)."""

    def __init__(self, states: list, weights: np.ndarray, tr_register: np.ndarray, k0: int, m: int,
                 rng: np.random.Generator) -> None:
        self.states, self.weights, self.tr_register = states, weights, tr_register
        self.k0, self.m, self.rng = k0, m, rng
        self.removed: int | None = None
        self.chosen = list(states[0].chosen)

    @property
    def n_candidates(self) -> int:
        return self.states[0].n_candidates

    def values(self, exclude: np.ndarray) -> np.ndarray:
        out = np.full(self.n_candidates, np.inf)
        if self.removed is None:  # additions are not part of the hedged search (it starts from a member's set)
            return out
        rest = np.flatnonzero(~exclude)
        rest = rest[rest != self.removed]
        k = max(10, EXCHANGE_EVALUATIONS // self.m)
        if len(rest) > k:
            rest = self.rng.choice(rest, k, replace=False)
        logs = np.zeros(len(rest))
        with np.errstate(invalid="ignore", divide="ignore"):
            for w, st, tr in zip(self.weights, self.states, self.tr_register):
                logs += w * np.log(st.values_without(self.removed, rest) + tr)
        out[rest] = np.where(np.isfinite(logs), np.exp(logs), np.inf)
        return out

    def without(self, i: int) -> HedgedState:
        st = copy.copy(self)
        st.removed = int(i)
        st.chosen = [c for c in self.chosen if c != i]
        return st

    def add(self, i: int) -> None:
        if self.removed is not None:
            self.states = [s.without(self.removed) for s in self.states]
            self.removed = None
        for s in self.states:
            s.add(int(i))
        self.chosen.append(int(i))

    def rebuild(self, chosen: Sequence[int]) -> HedgedState:
        st = copy.copy(self)
        st.states = [s.build(list(chosen)) for s in self.states]
        return st

