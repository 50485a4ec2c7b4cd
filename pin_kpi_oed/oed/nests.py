r"""Which reflector nest each pose measures: the KPI decides (:mod:`pin_kpi_oed.model.nests`).

A row of a design is a pose *and* a nest. The criterion is the TCP's tr C_s at the working configurations with the
parameters held at nominal (:func:`~pin_kpi_oed.oed.covariance.tcp_covariances`)::

    tr C_s = tr(E_B C_p E_Bᵀ) + tr(G Σ_N Gᵀ),   C_p = (F_Bᵀ F_B + prior)⁻¹,   G = E_B A − E_N

where the identified set B is the structural one of the nests the design measures (each nest adds what moves the
nests apart: the last joint's rotation about its axis, with a nest on that axis its rotations across it) and
N the joint-placement parameters left held. Measuring a second nest moves parameters from N (a tolerance-sized,
design-independent term) to B (a term the poses shrink), which is why the choice is the KPI's and not a rule.

:func:`assign_nests` chooses the nest of every pose of a given design (the pool selection's or the IPOPT design's
poses) by coordinate descent on tr C_s: start with every pose at nest 0, then, pose by pose, move it to the nest
with the smallest tr C_s, until a pass changes nothing. Each step evaluates tr C_s from scratch (the structural
analysis per set of nests is cached), so the result is exact for the design returned. A single pose moved to a
new nest adds that nest's parameters with one row to determine them, so the descent also starts from every second
pose at nest k (each k), and the best of the starts and of nest 0 alone is returned. Its :class:`NestDesign` says
what one nest cannot remove and what the chosen nests buy.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from pin_kpi_oed.errors import IdentifiabilityError
from pin_kpi_oed.results import Result

if TYPE_CHECKING:
    from pin_kpi_oed.model.tolerances import Tolerances
    from pin_kpi_oed.oed.identifiability import Identifiability
    from pin_kpi_oed.model.tracker import TrackerModel

__all__ = ["NestTrace", "NestDesign", "NestStructure", "nest_trace", "assign_nests", "nests_identifiability"]


@dataclass
class NestTrace:
    """tr C_s of a design measuring its rows at given nests (SI units).

    Attributes:
        identified_m2: tr(E_B C_p E_Bᵀ) at the working configurations (m²): what more poses shrink.
        held_m2: tr(G Σ_N Gᵀ) (m²): what no measurement of these nests removes.
        held_names: the held joint-placement parameters; nests: the nests measured.
    """

    identified_m2: float
    held_m2: float
    held_names: list[str] = field(default_factory=list)
    nests: list[int] = field(default_factory=list)

    @property
    def total_m2(self) -> float:
        """tr C_s (m²)."""
        return self.identified_m2 + self.held_m2


class NestStructure:
    """The structural identified set per set of nests, on one seeded excitation (cached).

    Args:
        model: the measurement model with its nests; seed: the excitation's seed; n: its configurations.
    """

    def __init__(self, model: TrackerModel, seed: int, n: int = 60):
        self.model, self.Qx = model, model.robot.random_q(np.random.default_rng(seed), n)
        self.cache: dict[tuple[int, ...], np.ndarray] = {}

    def analysis(self, nests: tuple[int, ...]) -> Identifiability:
        """The identifiability analysis of a design measuring every one of the nests ``nests`` (not cached)."""
        from pin_kpi_oed.oed.identifiability import analyse

        mx = self.model.at_nests(np.repeat(nests, len(self.Qx)))
        return analyse(mx, Q=np.tile(self.Qx, (len(nests), 1)))

    def base(self, nests: tuple[int, ...]) -> np.ndarray:
        """Raw indices of the parameters a design measuring the nests ``nests`` (sorted, distinct) identifies."""
        if nests not in self.cache:
            self.cache[nests] = np.asarray(self.analysis(nests).base, int)
        return self.cache[nests]


def nests_identifiability(model: TrackerModel, seed: int = 0) -> Identifiability:
    """What a design measuring every nest of the model identifies (the structural analysis at all its nests): a
    cell's TCP need only be estimable with all its nests, nest 0 alone may leave part of it held.

    Args:
        model: the measurement model with its nests; seed: the excitation's seed.

    Returns:
        The :class:`~pin_kpi_oed.oed.identifiability.Identifiability` over all nests.
    """
    return NestStructure(model, seed).analysis(tuple(range(model.n_nests)))


def nest_trace(model: TrackerModel, Q: np.ndarray, nest: np.ndarray, Q_work: np.ndarray,
               tolerances: Tolerances | None = None, seed: int = 0, structure: NestStructure | None = None
               ) -> NestTrace:
    """tr C_s at the working configurations of a design measuring pose i at nest ``nest[i]`` (module docstring).

    Args:
        model: the measurement model with its nests (``nests_m``) and TCP; Q: the poses (m, n) rad;
        nest: each pose's nest (m,) int; Q_work: working configurations (t, n) rad;
        tolerances: the held parameters' prior (default :class:`~pin_kpi_oed.model.tolerances.Tolerances`);
        seed: the structural analysis's excitation; structure: a cache shared between calls.

    Returns:
        The :class:`NestTrace`.

    Raises:
        IdentifiabilityError: the poses do not identify the parameters of their nests.
    """
    from pin_kpi_oed.model.tolerances import Tolerances, held_columns
    from pin_kpi_oed.oed.covariance import prior_of, tcp_covariances

    nest = np.asarray(nest, int)
    used = tuple(sorted(set(nest.tolist())))
    B = (structure or NestStructure(model, seed)).base(used)
    N = held_columns(model, B)
    p0 = np.zeros(model.n_params)
    F = model.at_nests(nest).weighted_jacobian(p0, np.atleast_2d(Q)).reshape(-1, model.n_params)
    E = model.kpi_jacobian(p0, np.atleast_2d(Q_work))
    sig = (tolerances or Tolerances()).sigma_vector(model)
    _, C_s, C_h = tcp_covariances(F[:, B], F[:, N], E[:, B], E[:, N], sig[N], prior_of(model, B),
                                  [model.layout.names[i] for i in B])
    held = float(np.trace(C_h))
    return NestTrace(float(np.trace(C_s)) - held, held, [model.layout.names[i] for i in N], list(used))


@dataclass(kw_only=True)
class NestDesign(Result):
    """The nests a design measures and what they buy (:func:`assign_nests`).

    Attributes:
        nest: the nest of every pose, (m,) int.
        one: tr C_s with every pose at nest 0; chosen: with the chosen nests.
        t: the number of working configurations (the traces are sums over them).
    """

    nest: np.ndarray
    one: NestTrace
    chosen: NestTrace
    t: int = 1

    def line(self) -> str:
        """One line: what nest 0 alone cannot remove and what the chosen nests buy (mm², %)."""
        one, ch = self.one, self.chosen
        head = (f"with nest 0 alone tr(C_s) = {one.total_m2 * 1e6:.4g} mm^2 at {self.t} working configurations, "
                f"{one.held_m2 * 1e6:.4g} mm^2 ({100 * one.held_m2 / max(one.total_m2, 1e-300):.0f} %) of it from "
                "parameters no measurement of that nest determines")
        counts = np.bincount(self.nest, minlength=max(ch.nests) + 1 if ch.nests else 1)
        if ch.nests == [0]:
            return head + "; no other nest lowers it (every pose measures nest 0)"
        at = ", ".join(f"nest {k} at {int(c)}" for k, c in enumerate(counts) if c)
        gain = 1.0 - ch.total_m2 / one.total_m2
        return (head + f"; the design measures {at} of {len(self.nest)} poses: tr(C_s) = {ch.total_m2 * 1e6:.4g} "
                f"mm^2 ({ch.held_m2 * 1e6:.4g} mm^2 held), {100 * gain:.0f} % less")


def assign_nests(model: TrackerModel, Q: np.ndarray, Q_work: np.ndarray, tolerances: Tolerances | None = None,
                 seed: int = 0, max_passes: int = 4, min_gain: float = 0.01, start: np.ndarray | None = None
                 ) -> NestDesign:
    """Each pose's nest by coordinate descent on tr C_s (module docstring).

    Args:
        model: the measurement model with its nests and TCP; Q: the design's poses (m, n) rad;
        Q_work: working configurations (t, n) rad; tolerances: the held parameters' prior;
        seed: the structural analysis's excitation; max_passes: passes over the poses at most;
        min_gain: the share of tr C_s other nests must remove to be measured (moving the reflector costs time);
        start: a further start of the descent, (m,) int (e.g. the nests the poses were designed for), or None.

    Returns:
        The :class:`NestDesign` (``success``; ``nit`` the passes made).

    Raises:
        IdentifiabilityError: the poses at nest 0 do not identify its parameters.
    """
    import time

    t0 = time.perf_counter()
    Q = np.atleast_2d(np.asarray(Q, float))
    st = NestStructure(model, seed)
    one = nest_trace(model, Q, np.zeros(len(Q), int), Q_work, tolerances, seed, st)
    best_nest, best, passes, nfev = np.zeros(len(Q), int), one, 0, 1
    starts = []
    for k in range(1, model.n_nests):  # a start measuring nest k at every second pose
        s0 = np.zeros(len(Q), int)
        s0[1::2] = k
        starts.append(s0)
    if start is not None:
        starts.append(np.asarray(start, int).copy())
    for s0 in starts:
        try:
            nest, tr, p, f = _descend(model, Q, s0, Q_work, tolerances, seed, st, max_passes)
        except IdentifiabilityError:
            continue
        passes, nfev = passes + p, nfev + f
        if tr.total_m2 < best.total_m2 and tr.total_m2 < (1.0 - min_gain) * one.total_m2:
            best_nest, best = nest, tr
    nest = best_nest
    t = len(np.atleast_2d(Q_work))
    return NestDesign(nest=nest, one=one, chosen=best, t=t, success=True, status="converged", nit=passes,
                      nfev=nfev, time_s=time.perf_counter() - t0,
                      message=f"nests chosen for {len(Q)} poses by tr(C_s) in {passes} passes")


def _descend(model: TrackerModel, Q: np.ndarray, nest: np.ndarray, Q_work: np.ndarray,
             tolerances: Tolerances | None, seed: int, st: NestStructure, max_passes: int
             ) -> tuple[np.ndarray, NestTrace, int, int]:
    """Coordinate descent from ``nest``: (nests, their trace, passes, evaluations)."""
    best = nest_trace(model, Q, nest, Q_work, tolerances, seed, st)
    passes, nfev = 0, 1
    while passes < max_passes:
        passes += 1
        changed = False
        for i in range(len(Q)):
            for k in range(model.n_nests):
                if k == nest[i]:
                    continue
                trial = nest.copy()
                trial[i] = k
                try:
                    tr = nest_trace(model, Q, trial, Q_work, tolerances, seed, st)
                except IdentifiabilityError:  # a nest set the poses do not identify is no candidate
                    continue
                nfev += 1
                if tr.total_m2 < best.total_m2 * (1 - 1e-9):
                    nest, best, changed = trial, tr, True
        if not changed:
            break
    return nest, best, passes, nfev
