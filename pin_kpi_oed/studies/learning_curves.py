r"""Learning curves on measured data: the held-out error near the work against the number of calibration poses.

For each seeded split of a measured data set (the protocol of
:func:`~pin_kpi_oed.studies.design_trials.extended_design_validation`: within one session a share of the rows is
held out, some held-out rows are the working configurations W and the held-out rows within a radius of them are
scored; across sessions S → T the whole of S is the pool and T's set-up is re-registered on seeded rows of T),
m poses are chosen from the training pool by each method, for every m of a grid:

* ``kpi_gp``: the discrepancy-aware KPI (:func:`~pin_kpi_oed.oed.discrepancy_pool.select_pool_gp`, greedy + one
  exchange pass), tr C_s at W under the prior discrepancy;
* ``kpi_gp_region``: the same criterion over the working *region*
  (:func:`~pin_kpi_oed.design.region.working_region`): W plus up to ``region_rows`` seeded pool rows
  within the scoring radius of W (known configurations of the region, never scored rows); the scores are taken
  over a region of 0.5 rad, which five points with a discrepancy of short length scales do not represent;
* ``kpi``: the paper's KPI (noise only), pool selection (:func:`~pin_kpi_oed.oed.pool.select`);
* ``D``: D-optimal pool selection;
* ``random``: the first m of one seeded permutation of the pool (nested sets).

Every chosen set is calibrated the same way (:func:`calibrate_fixed`): geometry and set-up by least squares
(:func:`~pin_kpi_oed.identification.identify.identify`), then the discrepancy's posterior mean conditioned on
the m residuals with the hyper-parameters (kernel, per-axis scale, white level) **fixed** to a prior model fitted
on other data (:class:`~pin_kpi_oed.discrepancy.prior.DiscrepancyPrior`, the same one the ``kpi_gp`` design
uses). The full pool is calibrated the same way (the reference accuracy). Per chosen set the result holds the
mean and RMS 3-D error of the scored rows (with and without the discrepancy's mean) and the predicted σ:
sqrt(tr C_s / t) at W (the design's own number, the poses-needed curve) and the predicted RMS 3-D error at the
scored rows, sqrt(tr C_s(scored) / n + Σ_a w s_a²) (universal kriging plus the white level). Across sessions the
criteria and the predictions are those after T's set-up is registered on its registration rows
(:mod:`pin_kpi_oed.oed.reregistration`: the registration configurations are known when the poses are chosen; their
measurements are not used), which is how the calibration is scored.
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from pin_kpi_oed.data.measurements import MeasurementSet
from pin_kpi_oed.errors import InputError
from pin_kpi_oed.model.tracker import TrackerModel
from pin_kpi_oed.oed.objective import information_criterion
from pin_kpi_oed.discrepancy.prior import DiscrepancyPrior
from pin_kpi_oed.oed.discrepancy_kpi import DiscrepancyDesignCriterion
from pin_kpi_oed.oed.identifiability import analyse
from pin_kpi_oed.oed.pool import select
from pin_kpi_oed.results import Result

__all__ = ["SIZES", "METHODS", "calibrate_fixed", "curve_split", "region_beyond", "LearningCurves",
           "learning_curves", "poses_within", "Split", "make_split", "score_split", "PoolDesigns",
           "poses_text"]

#: Numbers of calibration poses of the curves.
SIZES = (12, 20, 30, 60, 120)
#: Design methods.
METHODS = ("kpi_gp", "kpi_gp_region", "kpi", "D", "random")


def calibrate_fixed(model: TrackerModel, data: MeasurementSet, prior: DiscrepancyPrior):
    """Geometry + set-up by least squares, then the discrepancy's posterior mean on the residuals, hyper-parameters
    fixed to ``prior`` (nothing of the discrepancy is re-fitted but its conditioning on these rows).

    Returns:
        (the :class:`~pin_kpi_oed.calibrated.model_file.CalibratedModel` with the discrepancy (None for a white
        prior), the same without it).
    """
    from pin_kpi_oed.discrepancy.gp import Discrepancy
    from pin_kpi_oed.identification.discrepancy_fit import base_frame_residuals
    from pin_kpi_oed.identification.identify import identify
    from pin_kpi_oed.identification.problem import align_data

    res = identify(model, data, use_orientation=False, raise_on_failure=False, discrepancy="none",
                   on_poor_fit="ignore", loss="linear", tcp_sigma=False)  # the models carry no TCP σ of the fit
    plain = res.calibrated_model()
    if prior.kernel is None:
        return plain, plain
    rows, R = base_frame_residuals(res)
    Q = align_data(res.model.robot, data)[rows]
    d = Discrepancy("exact", list(res.model.robot.joint_names), prior.scale_m.copy(), np.zeros(3), prior.noise,
                    prior.kernel, Z=Q, y=R / prior.scale_m, n_rows=len(Q),
                    decision=f"hyper-parameters fixed ({prior.source or 'given'})")
    return dataclasses.replace(plain, discrepancy=d), plain


@dataclass
class Split:
    """One split: the pool, the working configurations, the scored rows and the registration rows (or None)."""

    pool: MeasurementSet
    work: np.ndarray
    scored: MeasurementSet
    reg: MeasurementSet | None


def make_split(data: MeasurementSet, target: MeasurementSet | None, rng: np.random.Generator, test_frac: float,
                n_work: int, radius_rad: float, joints: int, pool_size: int | None, n_register: int) -> Split:
    """The split of :func:`extended_design_validation` (same draws), the pool optionally subsampled to ``pool_size``."""
    from pin_kpi_oed.studies.design_trials import work_and_scored

    perm = rng.permutation(len(data))
    n_test = int(round(test_frac * len(data))) if target is None else 0
    pool_rows = np.sort(perm[n_test:])
    work, scored, reg = work_and_scored(data, target, perm, n_test, rng, n_work, n_register, radius_rad, joints)
    if pool_size is not None and pool_rows.size > pool_size:
        pool_rows = np.sort(rng.choice(pool_rows, pool_size, replace=False))
    if len(scored) == 0:
        raise InputError(f"{data.source}: no held-out row within {radius_rad} rad of the working configurations")
    return Split(data.subset(pool_rows), work, scored, reg)


def _random_order(seed: int, n: int) -> np.ndarray:
    """The seeded permutation of a pool of n rows whose first m are the random set of m poses (nested sets)."""
    return np.random.default_rng(seed).permutation(n)


def score_split(model: TrackerModel, rows: MeasurementSet, sp: Split, prior: DiscrepancyPrior) -> tuple[float, ...]:
    """(mean, RMS with the discrepancy's mean; mean without) 3-D error (m) of the scored rows after calibrating on
    ``rows`` (pairs: the target's set-up re-registered on the registration rows, robot and discrepancy held)."""
    out = []
    for cm in calibrate_fixed(model, rows, prior):
        station = None
        if sp.reg is not None:
            from pin_kpi_oed.upkeep.transfer import register_setup

            cm = register_setup(cm, sp.reg, station="target", use_orientation=False).model
            station = "target"
        e = np.linalg.norm(sp.scored.position_m - cm.predict(sp.scored.q, station=station), axis=1)
        out.append(e)
    e, e0 = out
    return float(e.mean()), float(np.sqrt(np.mean(e ** 2))), float(e0.mean())


class PoolDesigns:
    """One split's pool quantities, computed once for every m: the design model (nominal robot, the pool's
    set-up), the base-frame and weighted Jacobians of the pool, and the criteria at W and at the scored rows."""

    def __init__(self, model: TrackerModel, sp: Split, prior: DiscrepancyPrior, seed: int, radius_rad: float,
                 joints: int, region_rows: int) -> None:
        from pin_kpi_oed.design.region import working_region
        from pin_kpi_oed.studies.design_trials import position_design_model

        dm = position_design_model(model, sp.pool)
        b = analyse(dm).base
        p0 = np.zeros(dm.n_params)
        self.Q = sp.pool.q
        self.crit_w = DiscrepancyDesignCriterion(dm, b, prior, sp.work)
        self.crit_s = DiscrepancyDesignCriterion(dm, b, prior, sp.scored.q)
        # the KPI is the measured point (the reflector) at W and at the scored rows, what the scores measure
        self.crit_w.E = self.crit_w.pool_jacobians(sp.work)
        self.crit_s.E = self.crit_s.pool_jacobians(sp.scored.q)
        region = working_region(sp.work, radius_rad, region_rows, seed, pool=self.Q, joints=joints)
        self.crit_r = DiscrepancyDesignCriterion(dm, b, prior, region.configurations())
        self.crit_r.E = self.crit_r.pool_jacobians(self.crit_r.Q_work)
        if sp.reg is not None:  # another session: scored after T's set-up is registered on its rows
            for crit in (self.crit_w, self.crit_s, self.crit_r):
                crit.set_registration(sp.reg.q)
        self.Jp = self.crit_w.pool_jacobians(self.Q)
        self.Fp = dm.weighted_jacobian(p0, self.Q)[:, :, b]
        E = dm.jacobian(p0, sp.work)[:, :3, :][:, :, b].reshape(-1, b.size)
        self.K_kpi = information_criterion("kpi").pool_form(E, b.size)
        self.white_m2 = float(np.sum(prior.scale_m ** 2) * prior.noise)
        self.order = _random_order(seed, len(self.Q))
        self.seed = seed

    def choose(self, meth: str, m: int) -> np.ndarray:
        """Pool indices of the m poses of method ``meth``."""
        if meth == "random":
            return self.order[:m]
        if meth in ("kpi_gp", "kpi_gp_region"):
            crit = self.crit_w if meth == "kpi_gp" else self.crit_r
            return crit.select(self.Q, m, J_pool=self.Jp, exchange_passes=1).indices
        if meth in ("kpi", "D"):
            return select(self.Fp, m, self.K_kpi if meth == "kpi" else None, seed=self.seed).indices
        raise InputError(f"method '{meth}': unknown (known: {', '.join(METHODS)})")

    def predicted(self, idx: np.ndarray) -> tuple[float, float, float]:
        """(σ at W = sqrt(tr C_s / t), predicted RMS 3-D error at the scored rows, the same with the exact
        re-registered covariance) of the poses ``idx`` (m); the last two are equal within a session."""
        Q = self.Q[np.asarray(idx, int)]
        t, n = self.crit_w.Q_work.shape[0], self.crit_s.Q_work.shape[0]
        rms = float(np.sqrt(self.crit_s.value(Q) / n + self.white_m2))
        exact = rms if self.crit_s.reg is None else float(
            np.sqrt(np.trace(self.crit_s.reregistered_covariance(Q)) / n + self.white_m2))
        return float(np.sqrt(self.crit_w.value(Q) / t)), rms, exact


def curve_split(model: TrackerModel, data: MeasurementSet, prior: DiscrepancyPrior,
                target: MeasurementSet | None = None, *, seed: int = 0, sizes: tuple[int, ...] = SIZES,
                methods: tuple[str, ...] = METHODS, test_frac: float = 0.3, n_work: int = 5,
                radius_rad: float = 0.5, joints: int = 5, pool_size: int | None = None,
                n_register: int = 60, random_beyond: tuple[int, ...] = (240, 480, 960), region_rows: int = 100) -> dict:
    """One split of the learning curves (see the module docstring); plain JSON-able numbers (SI units).

    Args:
        model: nominal measurement model (robot, reflector guess, noise; position only is used).
        data: the measured rows (within-session) or the training source S (with ``target``).
        prior: the discrepancy whose hyper-parameters are fixed (fitted on data other than the scored rows).
        target: the other session T of a directed pair, or None.
        seed: seed of this split (rows, working configurations, random sets, selection starts).
        sizes: numbers of poses; methods: keys of :data:`METHODS`.
        test_frac, n_work, radius_rad, joints, n_register: the split (as ``extended_design_validation``).
        pool_size: subsample the training pool to this many rows (None: all).
        region_rows: most pool rows of the working region in ``kpi_gp_region``'s criterion.
        random_beyond: larger sizes scored for the random sets only (where random comes within reach of the full
            pool); sizes above the pool are skipped.

    Returns:
        ``{"seed", "n_pool", "n_scored", "sizes", "methods", "error_mean_m", "error_rms_m", "error_geo_mean_m",
        "pred_sigma_work_m", "pred_rms_scored_m", "pred_rms_scored_exact_m"`` (per method, one value per size;
        the last is the prediction with the exact re-registered covariance across sessions), ``"full"`` (the same
        numbers
        of the whole pool), ``"random_beyond"`` (``sizes`` and ``error_mean_m`` of the larger random sets),
        ``"select_time_s"`` (per method), ``"time_s"``}.

    Raises:
        InputError: an unknown method, a size larger than the pool, no scored row.
    """
    t0 = time.perf_counter()
    rng = np.random.default_rng(seed)
    sp = make_split(data, target, rng, test_frac, n_work, radius_rad, joints, pool_size, n_register)
    if max(sizes) > len(sp.pool):
        raise InputError(f"{data.source}: a pool of {len(sp.pool)} rows is too small for {max(sizes)} poses")
    des = PoolDesigns(model, sp, prior, seed, radius_rad, joints, region_rows)
    keys = ("error_mean_m", "error_rms_m", "error_geo_mean_m", "pred_sigma_work_m", "pred_rms_scored_m",
            "pred_rms_scored_exact_m")
    out: dict = {k: {meth: [] for meth in methods} for k in keys}
    sel_time = {meth: 0.0 for meth in methods}
    for m in sizes:
        for meth in methods:
            ts = time.perf_counter()
            idx = np.sort(des.choose(meth, m))
            sel_time[meth] += time.perf_counter() - ts
            vals = score_split(model, sp.pool.subset(idx), sp, prior) + des.predicted(idx)
            for k, v in zip(keys, vals):
                out[k][meth].append(v)
    full = score_split(model, sp.pool, sp, prior) + des.predicted(np.arange(len(sp.pool)))
    big = [m for m in random_beyond if m < len(sp.pool)]
    beyond = {"sizes": big, "error_mean_m": [score_split(model, sp.pool.subset(np.sort(des.order[:m])), sp, prior)[0]
                                             for m in big]}
    return {"seed": seed, "n_pool": len(sp.pool), "n_scored": len(sp.scored), "sizes": list(sizes),
            "methods": list(methods), **out, "full": dict(zip(keys, full)), "random_beyond": beyond,
            "select_time_s": sel_time,
            "time_s": time.perf_counter() - t0}


def region_beyond(model: TrackerModel, data: MeasurementSet, prior: DiscrepancyPrior,
                  target: MeasurementSet | None = None, *, seed: int = 0, sizes: tuple[int, ...] = (240, 480),
                  test_frac: float = 0.3, n_work: int = 5, radius_rad: float = 0.5, joints: int = 5,
                  pool_size: int | None = None, n_register: int = 60, region_rows: int = 100,
                  method: str = "kpi_gp_region") -> dict:
    """Larger sets of the region form (``kpi_gp_region``; ``method="random"``: of the nested random sets) on the
    split of :func:`curve_split` with the same arguments (the same draws): where the designs come within reach of
    the full pool. Sizes above the pool are skipped.

    Returns:
        ``{"sizes", "error_mean_m", "time_s"}`` (m).

    Raises:
        InputError: a method other than ``kpi_gp_region`` and ``random``.
    """
    if method not in ("kpi_gp_region", "random"):
        raise InputError(f"method '{method}': larger sets are drawn for kpi_gp_region and random only")
    t0 = time.perf_counter()
    rng = np.random.default_rng(seed)
    sp = make_split(data, target, rng, test_frac, n_work, radius_rad, joints, pool_size, n_register)
    big = [m for m in sizes if m < len(sp.pool)]
    if method == "random":  # the nested random sets of curve_split, without the criteria
        order = _random_order(seed, len(sp.pool))
        choose = lambda m: order[:m]  # noqa: E731
    else:
        des = PoolDesigns(model, sp, prior, seed, radius_rad, joints, region_rows)
        choose = lambda m: des.choose("kpi_gp_region", m)  # noqa: E731
    err = [score_split(model, sp.pool.subset(np.sort(choose(m))), sp, prior)[0] for m in big]
    return {"sizes": big, "error_mean_m": err, "time_s": time.perf_counter() - t0}


def poses_within(sizes: np.ndarray, curve: np.ndarray, ref: float, frac: float = 0.1) -> float:
    """Fewest poses at which ``curve`` comes within ``frac`` of ``ref`` (linear interpolation in log m between the
    sizes; inf when not reached within the largest size)."""
    sizes, curve = np.asarray(sizes, float), np.asarray(curve, float)
    goal = (1.0 + frac) * ref
    ok = np.flatnonzero(curve <= goal)
    if ok.size == 0:
        return float("inf")
    k = int(ok[0])
    if k == 0:
        return float(sizes[0])
    a, b = curve[k - 1], curve[k]
    f = (a - goal) / (a - b)
    return float(np.exp(np.log(sizes[k - 1]) + f * (np.log(sizes[k]) - np.log(sizes[k - 1]))))


@dataclass(kw_only=True)
class LearningCurves(Result):
    """Learning curves over seeded splits (``nit`` = splits).

    Attributes:
        case: a name of the case; prior: where the fixed hyper-parameters come from.
        sizes: numbers of poses; methods: design methods.
        splits: the per-split dicts of :func:`curve_split`.
    """

    case: str
    prior: str
    sizes: list
    methods: list
    splits: list = field(repr=False)

    def array(self, key: str, meth: str) -> np.ndarray:
        """(splits, sizes) values of ``key`` for method ``meth``."""
        return np.array([s[key][meth] for s in self.splits], float)

    def full(self, key: str) -> np.ndarray:
        """(splits,) values of ``key`` for the full pool."""
        return np.array([s["full"][key] for s in self.splits], float)

    def paired(self, meth: str, base: str = "random", key: str = "error_mean_m") -> list[dict]:
        """Per size: the median over the splits of the paired relative change of ``key`` (default the observed mean
        error; ``pred_rms_scored_m``: the predicted one) against ``base`` (robust to a failed set), the change of
        the means, wins and the Wilcoxon signed-rank p (two-sided)."""
        from scipy import stats

        x, y = self.array(key, meth), self.array(key, base)
        out = []
        for j in range(len(self.sizes)):
            a, b = x[:, j], y[:, j]
            p = float(stats.wilcoxon(a, b).pvalue) if a.size >= 2 and np.any(a != b) else float("nan")
            out.append({"change": float(np.median(a / b) - 1.0), "change_of_means": float(a.mean() / b.mean() - 1.0),
                        "wins": int(np.sum(a < b)), "n": int(a.size), "p_wilcoxon": p})
        return out

    def needed(self, key: str = "error_mean_m", frac: float = 0.1) -> dict:
        """Poses each method needs to come within ``frac`` of the full pool, on the median curve over the splits
        (robust to a failed set; observed: ``error_mean_m``; predicted: ``pred_sigma_work_m`` or
        ``pred_rms_scored_m``)."""
        ref = float(np.median(self.full(key)))
        out = {meth: poses_within(np.array(self.sizes), np.median(self.array(key, meth), 0), ref, frac)
               for meth in self.methods}
        for meth in ("random", "kpi_gp_region"):
            big = self.beyond(meth)
            if key == "error_mean_m" and meth in out and big is not None:
                out[meth] = poses_within(np.r_[self.sizes, big[0]], np.r_[np.median(self.array(key, meth), 0),
                                                                         np.median(big[1], 0)], ref, frac)
        return out

    def largest(self, meth: str) -> int:
        """The largest size tried for ``meth`` (the random sets and, when run, the region form's go further)."""
        big = self.beyond(meth) if meth in ("random", "kpi_gp_region") else None
        return int(big[0][-1]) if big is not None else int(self.sizes[-1])

    def equivalent(self, meth: str, base: str = "random", key: str = "error_mean_m") -> list[float]:
        """Per size m: the poses ``meth`` needs (log-m interpolation of its median curve of ``key`` over the splits)
        to reach what ``base`` reaches with m poses (inf beyond the largest size; ``sizes[0]`` when it is better
        already there)."""
        x = np.median(self.array(key, meth), 0)
        y = np.median(self.array(key, base), 0)
        return [poses_within(np.array(self.sizes), x, float(v), 0.0) for v in y]

    def beyond(self, meth: str = "random") -> tuple[np.ndarray, np.ndarray] | None:
        """(sizes, (splits, sizes) mean errors) of the larger sets of ``meth`` common to every split (``random``:
        ``random_beyond``; ``kpi_gp_region``: ``region_beyond``, of :func:`region_beyond`), or None."""
        key = "random_beyond" if meth == "random" else "region_beyond"
        sizes = [m for m in (self.splits[0].get(key) or {}).get("sizes", [])
                 if all(m in (s.get(key) or {}).get("sizes", []) for s in self.splits)]
        if not sizes:
            return None
        return np.array(sizes), np.array([[s[key]["error_mean_m"][s[key]["sizes"].index(m)] for m in sizes]
                                          for s in self.splits])

    def to_dict(self) -> dict:
        """Plain JSON-able dict (SI units): the per-size means and spreads, the paired tests, the poses needed."""
        keys = ("error_mean_m", "error_rms_m", "error_geo_mean_m", "pred_sigma_work_m", "pred_rms_scored_m")
        per: dict[str, dict[str, Any]] = {meth: {k: {"mean": self.array(k, meth).mean(0).tolist(),
                          "median": np.median(self.array(k, meth), 0).tolist(), "sd": self.array(k, meth).std(0, ddof=1)
                          .tolist() if len(self.splits) > 1 else None} for k in keys} for meth in self.methods}
        for meth in self.methods:
            if meth != "random" and "random" in self.methods:
                per[meth]["vs_random"] = self.paired(meth)
        big = self.beyond()
        for meth in self.methods:
            if meth != "random" and "random" in self.methods:
                per[meth]["poses_to_match_random"] = self.equivalent(meth)
                per[meth]["poses_to_match_random_predicted"] = self.equivalent(meth, key="pred_rms_scored_m")
        return {**self.result_dict(), "case": self.case, "prior": self.prior, "sizes": self.sizes,
                "n_splits": len(self.splits), "n_pool": float(np.mean([s["n_pool"] for s in self.splits])),
                "n_scored": float(np.mean([s["n_scored"] for s in self.splits])), "methods": per,
                "full": {k: float(self.full(k).mean()) for k in keys},
                "region_beyond": _beyond_dict(self.beyond("kpi_gp_region")),
                "random_beyond": None if big is None else {"sizes": big[0].tolist(),
                                                           "error_mean_m": big[1].mean(0).tolist(),
                                                           "error_median_m": np.median(big[1], 0).tolist()},
                "poses_within_10pct": {"observed": self.needed(), "predicted_work": self.needed("pred_sigma_work_m"),
                                       "predicted_scored": self.needed("pred_rms_scored_m")}}

    def summary(self) -> str:
        """Readable table (mm)."""
        n_sc = np.mean([s["n_scored"] for s in self.splits])
        lines = [f"{self.case}: {len(self.splits)} splits, {n_sc:.0f} scored rows per split; discrepancy "
                 f"hyper-parameters fixed from {self.prior}",
                 f"{'design':<8}{'m':>5}{'mean error (mm)':>20}{'median':>8}{'vs random':>11}{'wins':>7}{'p':>9}"
                 f"{'pred. sigma W':>15}{'pred. RMS':>11}{'obs. RMS':>10}"]
        for meth in self.methods:
            e, r = self.array("error_mean_m", meth), self.array("error_rms_m", meth)
            pw, ps = self.array("pred_sigma_work_m", meth), self.array("pred_rms_scored_m", meth)
            pr = self.paired(meth) if meth != "random" and "random" in self.methods else None
            for j, m in enumerate(self.sizes):
                sd = e[:, j].std(ddof=1) if len(e) > 1 else 0.0
                cmp = (f"{100 * pr[j]['change']:>+10.1f}%{pr[j]['wins']:>4}/{pr[j]['n']:<2}{pr[j]['p_wilcoxon']:>9.2g}"
                       if pr else f"{'':>11}{'':>7}{'':>9}")
                lines.append(f"{meth:<8}{m:>5}{e[:, j].mean() * 1e3:>12.4f} +- {sd * 1e3:.4f}"
                             f"{np.median(e[:, j]) * 1e3:>8.4f}{cmp}"
                             f"{pw[:, j].mean() * 1e3:>15.4f}{ps[:, j].mean() * 1e3:>11.4f}"
                             f"{r[:, j].mean() * 1e3:>10.4f}")
        f = {k: self.full(k).mean() * 1e3 for k in ("error_mean_m", "pred_sigma_work_m", "pred_rms_scored_m",
                                                      "error_rms_m")}
        lines.append(f"{'full':<8}{self.splits[0]['n_pool']:>5}{f['error_mean_m']:>12.4f}{'':>43}"
                     f"{f['pred_sigma_work_m']:>15.4f}{f['pred_rms_scored_m']:>11.4f}{f['error_rms_m']:>10.4f}")
        for meth in ("random", "kpi_gp_region"):
            big = self.beyond(meth)
            if big is not None:
                lines.append(f"{meth}, larger sets (median): " + ", ".join(
                    f"{m} poses {v * 1e3:.4f} mm" for m, v in zip(big[0], np.median(big[1], 0))))
        for key, word in (("error_mean_m", "observed"), ("pred_sigma_work_m", "predicted (sigma at W)")):
            need = self.needed(key)
            lines.append(f"poses to within 10 % of the full pool, {word}: "
                         + ", ".join(f"{k} {poses_text(v, self.largest(k))}" for k, v in need.items()))
        for meth in self.methods:
            if meth != "random" and "random" in self.methods:
                lines.append(f"{meth}: poses to match random's {', '.join(str(m) for m in self.sizes)}: "
                             + ", ".join(poses_text(v, self.sizes[-1], self.sizes[0]) for v in self.equivalent(meth)))
        return "\n".join(lines)


def _beyond_dict(big: tuple[np.ndarray, np.ndarray] | None) -> dict | None:
    """The larger sets of :meth:`LearningCurves.beyond` as a JSON-able dict (m), or None."""
    if big is None:
        return None
    return {"sizes": big[0].tolist(), "error_mean_m": big[1].mean(0).tolist(),
            "error_median_m": np.median(big[1], 0).tolist()}


def poses_text(v: float, largest: int, smallest: int = 0) -> str:
    """A number of poses: ``> largest`` when not reached, ``<= smallest`` when reached at the smallest size."""
    return f"> {largest}" if not np.isfinite(v) else (f"<= {smallest}" if v <= smallest else f"{v:.0f}")


def learning_curves(model: TrackerModel, data: MeasurementSet, prior: DiscrepancyPrior,
                    target: MeasurementSet | None = None, *, seeds: tuple[int, ...] = tuple(range(20)),
                    case: str = "", **kw) -> LearningCurves:
    """:func:`curve_split` over ``seeds`` (one split each), collected in :class:`LearningCurves`."""
    t0 = time.perf_counter()
    splits = [curve_split(model, data, prior, target, seed=s, **kw) for s in seeds]
    return LearningCurves(case=case or data.source, prior=prior.source, sizes=list(splits[0]["sizes"]),
                          methods=list(splits[0]["methods"]), splits=splits, success=True, status="completed",
                          nit=len(splits), message=f"{len(splits)} splits", time_s=time.perf_counter() - t0)
