"""Per-configuration aggregation (KS, min) of the capsule-constraint rows the optimiser sees."""

from __future__ import annotations

from typing import Any

import numpy as np

from pin_kpi_oed.cell.collision import INCID, CollisionModel
from pin_kpi_oed.errors import InputError

__all__ = ["AggregatedConstraints"]


class AggregatedConstraints:
    """Per-configuration aggregation of the distance rows of a :class:`CollisionModel`.

    Each configuration keeps two rows: the Kreisselmeier–Steinhauser aggregate of all its
    distance rows (capsule pairs, half-spaces, beam) and the incidence row::

        c(q) = d_min − ℓ · log Σ_p exp(−(d_p − d_min)/ℓ),      ∂c/∂q = Σ_p w_p ∂d_p/∂q,
        w_p = exp(−(d_p − d_min)/ℓ) / Σ_k exp(−(d_k − d_min)/ℓ)  (softmax weights).

    c is smooth and its gradient is exact (the softmax-weighted exact distance gradients);
    ``min_p d_p − ℓ ln N ≤ c ≤ min_p d_p``, so ``c ≥ 0`` implies every ``d_p ≥ 0``: the aggregate is
    conservative (by less than ℓ when one pair is more than ~5ℓ closer than the others) and never
    admits a collision. ``mode="min"`` uses min_p d_p itself (exact value, gradient of the closest
    pair, not differentiable where two pairs tie). ``mode="none"`` keeps every row.

    Args:
        coll: the full constraint model.
        mode: ``"ks"``, ``"min"`` or ``"none"``.
        length_m: KS smoothing length ℓ (m).
        backend: distances of the capsule pairs: ``"numpy"`` (closed form, default) or ``"geometry"``
            (Coal through one ``pin.computeDistances`` per configuration, :class:`GeometryDistances`;
            witness points read only within 40ℓ of the closest pair for ``ks`` — the softmax weight of
            the others is below e⁻⁴⁰ — and for the closest pair only for ``min``).
    """

    def __init__(self, coll: CollisionModel, mode: str = "ks", length_m: float = 2e-3, backend: str = "numpy"):
        if mode not in ("ks", "min", "none"):
            raise InputError(f"unknown constraint aggregation '{mode}' (ks, min, none)")
        if backend not in ("numpy", "geometry"):
            raise InputError(f"unknown distance backend '{backend}' (numpy, geometry)")
        self.coll, self.mode, self.length, self.backend = coll, mode, float(length_m), backend
        self.n, self.robot, self.cell = coll.n, coll.robot, coll.cell
        kind = coll.info.kind
        self.dist = np.flatnonzero(kind != INCID)
        self.inc = np.flatnonzero(kind == INCID)
        if mode == "none":
            self.n_rows, self.units = coll.n_rows, list(coll.info.units)
            self.jac_rows, self.jac_cols = coll.jac_rows, coll.jac_cols
            self.names = list(coll.info.names)
            return
        deps: list[set[int]] = [set(), set()]
        for r in self.dist:
            deps[0].update(int(j) for j in coll.info.deps[r])
        for r in self.inc:
            deps[1].update(int(j) for j in coll.info.deps[r])
        rows, cols, units, names = [], [], [], []
        k = 0
        for part, idx, unit, name in ((0, self.dist, "m", f"{mode}(clearances)"), (1, self.inc, "cos", "incidence")):
            if idx.size == 0:
                continue
            d = sorted(deps[part])
            rows += [k] * len(d)
            cols += d
            units.append(unit)
            names.append(name)
            k += 1
        self.n_rows, self.units, self.names = k, units, names
        self.jac_rows, self.jac_cols = np.array(rows, int), np.array(cols, int)

    def evaluate(self, Q: np.ndarray, with_grad: bool = True) -> np.ndarray | tuple[np.ndarray, np.ndarray]:
        """Aggregated rows (m, n_rows) and, with ``with_grad``, their gradients (m, n_rows, n)."""
        out: Any  # the rows, or (rows, gradients) with with_grad
        if self.backend == "numpy":
            out = self.coll.evaluate(Q, with_grad=with_grad)
        else:
            band = {"ks": 40.0 * self.length, "min": 0.0, "none": None}[self.mode]
            out = self.coll.evaluate(Q, with_grad=with_grad, backend="geometry", band=band)
        if self.mode == "none":
            return out
        g, G = out if with_grad else (out, None)
        m = g.shape[0]
        vals, grads = [], []
        if self.dist.size:
            gd = g[:, self.dist]
            k = np.argmin(gd, axis=1)
            dmin = gd[np.arange(m), k]
            if self.mode == "min":
                vals.append(dmin)
                if with_grad:
                    grads.append(G[np.arange(m), self.dist[k]])
            else:
                e = np.exp(-(gd - dmin[:, None]) / self.length)
                s = e.sum(axis=1)
                vals.append(dmin - self.length * np.log(s))
                if with_grad:
                    grads.append(np.einsum("mr,mrn->mn", e / s[:, None], G[:, self.dist]))
        if self.inc.size:
            vals.append(g[:, self.inc[0]])
            if with_grad:
                grads.append(G[:, self.inc[0]])
        ga = np.stack(vals, axis=1) if vals else np.zeros((m, 0))
        if not with_grad:
            return ga
        return ga, (np.stack(grads, axis=1) if grads else np.zeros((m, 0, self.n)))
