"""The heuristic design: configurations uniform within the joint bounds, rejection-sampled until the constraint
model accepts them (the incidence row first: it alone rejects most samples)."""

from __future__ import annotations

import numpy as np

from pin_kpi_oed.cell.collision import CollisionModel
from pin_kpi_oed.cell.constraint_rows import INCID
from pin_kpi_oed.errors import InfeasibleError


def random_feasible(coll: CollisionModel, m: int, rng: np.random.Generator, max_tries: int,
                    batch: int = 2000) -> tuple[np.ndarray, int]:
    """Heuristic design: configurations uniform within the joint bounds, rejection-sampled until feasible.

    Args:
        coll: the constraint model (its rows decide feasibility).
        m: number of configurations wanted.
        rng: random generator.
        max_tries: sampling budget.
        batch: configurations drawn per batched evaluation.

    Returns:
        (Q (m, n) rad, number of samples drawn until the m-th feasible one).

    Raises:
        InfeasibleError: fewer than m feasible poses in ``max_tries`` samples (naming the most
            often violated constraint).
    """
    lo, hi = coll.robot.q_lower, coll.robot.q_upper
    found: list[np.ndarray] = []
    drawn = 0
    viol = np.zeros(coll.n_rows, int)
    inc_row = np.flatnonzero(coll.info.kind == INCID)
    while drawn < max_tries and len(found) < m:
        k = min(batch, max_tries - drawn)
        Q = rng.uniform(lo, hi, size=(k, coll.n))
        ok = np.ones(k, bool)
        if coll.with_incidence:  # cheap first stage: the incidence row alone rejects most samples (96 % on KR 15)
            ok = coll.model.incidence_cos(coll.p0, Q) - coll.cos_max >= 0
            viol[inc_row] += k - int(ok.sum())
        pre = np.flatnonzero(ok)
        g = coll.evaluate(Q[pre], with_grad=False)
        ok = np.zeros(k, bool)
        ok[pre] = np.all(g >= 0, axis=1) if g.shape[1] else True
        viol += np.sum(g < 0, axis=0)
        idx = np.flatnonzero(ok)
        need = m - len(found)
        if idx.size >= need:
            drawn += int(idx[need - 1]) + 1
            found.extend(Q[idx[:need]])
            break
        drawn += k
        found.extend(Q[idx])
    if len(found) < m:
        top = [coll.info.names[r] for r in np.argsort(-viol)[:3] if viol[r] > 0]
        raise InfeasibleError(f"{coll.cell.source or coll.cell.name}: no feasible random pose found "
                              f"({len(found)} of {m} needed) in {max_tries} tries; most often "
                              f"violated: {', '.join(top) or 'none'}; relax the cell (obstacles, incidence limit, "
                              f"joint bounds) or raise max_random_tries")
    return np.array(found[:m]), drawn
