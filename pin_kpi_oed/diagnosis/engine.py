"""The diagnosis engine: how the data are split (folds) and how a set of effects is fitted and scored held-out."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any
from collections.abc import Sequence

import numpy as np

from pin_kpi_oed.data.measurements import MeasurementSet
from pin_kpi_oed.diagnosis.diagnose_options import DiagnoseOptions
from pin_kpi_oed.effects.library import Effect
from pin_kpi_oed.errors import InputError
from pin_kpi_oed.model.tracker import TrackerModel

__all__ = ["Fit", "Scored", "Plan", "Engine", "plan_folds"]


@dataclass
class Fit:
    """One identification and what the diagnosis needs of it."""

    result: Any  # IdentificationResult
    chi2: float
    n_rows: int
    nx: int


@dataclass
class Scored:
    """A model (set of effects) fitted on the training side and scored on the held-out side."""

    effects: list
    full: Fit  # training-side statistics (train fit; all-data fit in K-fold)
    R: np.ndarray  # held-out residuals, measured − predicted (n, 3) m
    S: np.ndarray  # held-out σ (n, 3) m
    V: np.ndarray  # held-out weighted prediction variance (n, 3)

    @property
    def w2(self) -> np.ndarray:
        """Per-measurement weighted squared held-out residual Σ_axes (r/σ)²."""
        return np.sum((self.R / self.S) ** 2, axis=1)


@dataclass
class Plan:
    """How the data are split: folds (train, held-out) and the held-out rows' numbers in their file."""

    mode: str
    k: int
    folds: list  # [(train, test)]
    orders: list  # per fold: row indices of the held-out rows in ``heldout_source``
    fold_rows: list | None  # K-fold: per fold (train rows, test rows) of the training file
    heldout_source: MeasurementSet
    registration: MeasurementSet | None = None
    registration_info: dict = field(default_factory=dict)


class Engine:
    """Fits and scores models on a fixed set of folds (with a set-up registration in transfer mode)."""

    def __init__(self, model: TrackerModel, plan: Plan, full_train: MeasurementSet, heldout_idx: list,
                 weights: str, identify_options: dict, exact_kfold: bool = False):
        self.model = model
        self.plan = plan
        self.folds = plan.folds
        self.full_train = full_train
        self.heldout_idx = heldout_idx  # per fold: rows of the test set kept for scoring
        self.weights = weights
        self.opts = dict(identify_options)
        self.split = plan.fold_rows is None
        self.fold_rows = plan.fold_rows
        self.exact_kfold = exact_kfold
        self.unconverged: set[str] = set()
        self.n_fits = 0

    def sigma(self, data: MeasurementSet) -> np.ndarray:
        """Per-axis σ of every row (n, 3) m: the data's sigma columns (weights auto/data) or the noise model."""
        use_data = data.sigma_m is not None and self.weights in ("auto", "data")
        return np.asarray(data.sigma_m, float) if use_data else self.model.noise.sigma(data.position_m)

    def fit(self, data: MeasurementSet, effects: Sequence[Effect]) -> Fit:
        """Identify the geometry and ``effects`` on ``data`` (position rows; non-convergence noted, not raised)."""
        from pin_kpi_oed.identification.identify import identify

        opts = {"raise_on_failure": False, **self.opts}
        res = identify(self.model, data, effects=list(effects), weights=self.weights, use_orientation=False,
                       **{"discrepancy": "none", "on_poor_fit": "ignore", "loss": "linear", "tcp_sigma": False,
                          **opts})  # the diagnosis reads no TCP σ of its fits
        self.n_fits += 1
        if not res.converged:
            self.unconverged.add(", ".join(e.name for e in effects) or "geometry")
        chi2 = float(np.sum(res.weighted_errors ** 2))
        return Fit(res, chi2, 3 * len(data), len(res.names))

    def heldout(self, fit: Fit, test: MeasurementSet) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Held-out residuals (measured − predicted), σ and weighted prediction variance of ``fit`` on ``test``.

        In transfer mode the fit's set-up is first re-registered on the registration rows
        (robot and effects held); the variance then counts the robot and effect parameters only.
        """
        from pin_kpi_oed.identification.problem import ResidualModel

        res = fit.result
        S = self.sigma(test)
        if self.plan.registration is not None:
            rm, x, keep = self._registered(res, test, S)
        else:
            rm, x, keep = ResidualModel(res.station_set, test, res.identifiability.base, res.effects, sigma=S,
                                        p_ref=res.P), res.values, np.arange(res.values.size)
        R = -rm.evaluate(x)[0]
        F = rm.jacobian_full(x)[:, :3, :]  # weighted
        C = res.covariance[np.ix_(keep, keep)]
        V = np.einsum("mai,ij,maj->ma", F, C, F)
        return R, S, np.clip(V, 0.0, None)

    def _registered(self, res: Any, test: MeasurementSet, S: np.ndarray) -> tuple[Any, np.ndarray, np.ndarray]:
        """Residual model of ``test`` at the set-up re-registered on the registration rows (robot held)."""
        from pin_kpi_oed.identification.problem import ResidualModel
        from pin_kpi_oed.upkeep.transfer import register_setup

        rr = register_setup(res.calibrated_model(), self.plan.registration, station="transfer", weights=self.weights)
        wm, p = rr.model.station_model("transfer")
        nb = len(res.identifiability.base)
        setup = set(res.model.layout.setup_groups)
        robot = [i for i, n in enumerate(res.names[:nb]) if n.split(".")[0].split("@")[0] not in setup]
        base = np.array([wm.layout.index(res.names[i]) for i in robot], int)
        rm = ResidualModel(wm, test, base, res.effects, sigma=S, p_ref=p)
        x = np.concatenate([p[base]] + [np.asarray(t, float) for t in res.theta])
        keep = np.r_[np.asarray(robot, int), np.arange(nb, res.values.size)]
        return rm, x, keep

    def _fold_linear(self, full: Fit) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
        """K-fold held-out residuals by one Gauss-Newton step from the all-data fit per fold.

        The fold's fit differs from the all-data fit by O(noise); one Gauss-Newton step on the
        fold's training rows from the all-data solution x̂ reaches it to second order:
        δ_f = −(J_Tᵀ J_T)⁺ J_Tᵀ f_T, held-out residual f_test + J_test δ_f (weighted).
        """
        from pin_kpi_oed.identification.problem import ResidualModel

        res = full.result
        data = self.full_train
        S = self.sigma(data)
        rm = ResidualModel(res.station_set, data, res.identifiability.base, res.effects, sigma=S, p_ref=res.P)
        J = rm.jacobian_full(res.values)[:, :3, :]
        fw = rm.weighted_rows(res.values)[:, :3]  # (model − measured) / σ
        out = []
        for tr, te in self.fold_rows:
            A = J[tr].reshape(-1, J.shape[2])
            n = np.linalg.norm(A, axis=0)
            n = np.where(n > 0, n, 1.0)
            U, s, Vt = np.linalg.svd(A / n, full_matrices=False)
            ok = s > 1e-10 * s[0]
            Ainv = (Vt[ok].T / s[ok]) @ U[:, ok].T  # scaled pseudo-inverse
            delta = -(Ainv @ fw[tr].ravel()) / n
            Jt = J[te]
            f_new = fw[te] + Jt @ delta
            Cs = (Vt[ok].T / s[ok] ** 2) @ Vt[ok]
            Jts = Jt / n
            V = np.einsum("mai,ij,maj->ma", Jts, Cs, Jts)
            out.append((-f_new * S[te], S[te], V))
        return out

    def score(self, effects: Sequence[Effect], full: Fit | None = None) -> Scored:
        """Fit ``effects`` with the geometry (or take ``full``) and score them on the held-out rows of every fold."""
        full = full or self.fit(self.full_train, effects)
        if self.split:
            parts = [self.heldout(full, self.folds[0][1])]
        elif not self.exact_kfold:
            parts = self._fold_linear(full)
        else:
            parts = [self.heldout(self.fit(train, effects), test) for train, test in self.folds]
        Rs, Ss, Vs = [], [], []
        for (R, S, V), keep in zip(parts, self.heldout_idx):
            Rs.append(R[keep])
            Ss.append(S[keep])
            Vs.append(V[keep])
        return Scored(list(effects), full, np.vstack(Rs), np.vstack(Ss), np.vstack(Vs))


def plan_folds(train: MeasurementSet, validate: MeasurementSet | None, opts: DiagnoseOptions, robot: Any = None
               ) -> Plan:
    """Step 2: the folds: train / validate, train / validate with a set-up registration, or K-fold (seeded; near-
    duplicate configurations of ``robot``'s joints share a fold, :func:`~pin_kpi_oed.diagnosis.selection.
    measurement_folds`; without ``robot`` the data's joint columns, every joint wrapped)."""
    if validate is not None and opts.register_rows is None and opts.register_data is None:
        return Plan("split", 1, [(train, validate)], [np.arange(len(validate))], None, validate)
    if validate is not None:
        from pin_kpi_oed.upkeep.transfer import registration_split

        if opts.register_data is not None:
            reg, reg_rows, scored = opts.register_data, np.arange(len(opts.register_data)), np.arange(len(validate))
        else:
            reg_rows, scored = registration_split(len(validate), opts.register_rows, opts.seed)
            reg = validate.subset(reg_rows)
        info = {"source": reg.source, "n": int(len(reg)), "rows": (reg_rows + 1).tolist(),
                "seed": int(opts.seed) if opts.register_data is None else None,
                "scored_source": validate.source, "scored_rows": (scored + 1).tolist()}
        return Plan("transfer", 1, [(train, validate.subset(scored))], [scored], None, validate, reg, info)
    kfold = opts.kfold
    if isinstance(kfold, bool) or not isinstance(kfold, (int, np.integer)) or kfold < 2:
        raise InputError(f"diagnose: parameter 'kfold' must be an integer >= 2, got {kfold!r}")
    if kfold > len(train) // 3:
        raise InputError(f"diagnose: {len(train)} measurements are too few for {kfold} folds "
                         f"(each fold needs at least 3 measurements)")
    from pin_kpi_oed.diagnosis.selection import measurement_folds
    from pin_kpi_oed.identification.problem import align_data

    Q = align_data(robot, train, need_position=False) if robot is not None else train.q
    fold = measurement_folds(Q, int(kfold), opts.seed, None if robot is None else robot.periodic_joints)
    kfold = int(fold.max()) + 1
    parts = [np.flatnonzero(fold == k) for k in range(kfold)]
    folds, orders, fold_rows = [], [], []
    for i, te in enumerate(parts):
        tr = np.sort(np.concatenate([f for j, f in enumerate(parts) if j != i]))
        te = np.sort(te)
        folds.append((train.subset(tr), train.subset(te)))
        orders.append(te)
        fold_rows.append((tr, te))
    return Plan("kfold", int(kfold), folds, orders, fold_rows, train)
