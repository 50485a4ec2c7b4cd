"""Trials of measurement designs: Monte-Carlo identification and real data.

**Monte-Carlo.** The KPI covariance C_s = E C_p Eᵀ (eq. 19) is a linearised
prediction. For a design q_meas we simulate many identification experiments:
a true robot p* drawn from the tolerances (on the identifiable parameters: the
others are held nominal by the convention and no tracker experiment can see
them), measurements h(p*, q_meas) + ε with ε from the tracker's noise model,
full nonlinear identification (:func:`pin_kpi_oed.identification.identify.identify`, from the
nominal model and a registered tracker pose), and the realised TCP error
ŝ − s* at the working configurations. The empirical covariance of these
errors is compared with C_s (ratio of traces; 1 means the linearisation holds).

**Real data.** On a measured data set (the IPA UR10), some measured poses are
the working configurations (held out, never used for identification); m
calibration poses are chosen from the rest by a criterion (pool selection,
:mod:`pin_kpi_oed.oed.pool`) or at random; the robot is identified from their
measurements only; the real position errors at the working poses are the
result. Repeated over seeded splits, reported as mean ± standard deviation.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from pin_kpi_oed.data.measurements import MeasurementSet
from pin_kpi_oed.errors import InputError
from pin_kpi_oed.identification.identify import identify, validate
from pin_kpi_oed.simulation.simulator import Tolerances, random_truth, simulate
from pin_kpi_oed.model.tracker import TrackerModel
from pin_kpi_oed.oed.covariance import covariances, design_covariances, prior_of
from pin_kpi_oed.oed.objective import information_criterion
from pin_kpi_oed.oed.identifiability import analyse
from pin_kpi_oed.oed.pool import select
from pin_kpi_oed.progress import progress
from pin_kpi_oed.results import Result


@dataclass(kw_only=True)
class MonteCarloResult(Result):
    """Predicted vs realised TCP covariance over simulated identification experiments.

    A :class:`~pin_kpi_oed.results.Result`: ``success`` when every identification converged
    (``status`` ``completed``, else ``failures``), ``nit`` = repetitions, ``time_s`` the wall time.

    Attributes:
        n_rep: repetitions; n_meas: measurements per experiment.
        predicted_cov_m2: C_s at the nominal model (3t × 3t, m²).
        empirical_cov_m2: covariance of the realised TCP errors (m²).
        trace_ratio: tr(empirical) / tr(predicted).
        bias_m: mean realised TCP error (3t,), m.
        errors_m: realised TCP errors per repetition, (n_rep, 3t) m.
        failures: repetitions whose identification did not converge.
    """

    n_rep: int
    n_meas: int
    predicted_cov_m2: np.ndarray
    empirical_cov_m2: np.ndarray
    trace_ratio: float
    bias_m: np.ndarray
    errors_m: np.ndarray = field(repr=False)
    failures: int = 0

    def to_dict(self) -> dict:
        """Plain JSON-able dict (SI units): the common result keys and the comparison."""
        return {**self.result_dict(), "n_rep": self.n_rep, "n_meas": self.n_meas,
                "predicted_trace_cs_m2": float(np.trace(
            self.predicted_cov_m2)), "empirical_trace_m2": float(np.trace(self.empirical_cov_m2)),
            "trace_ratio": self.trace_ratio, "bias_m": self.bias_m.tolist(), "failures": self.failures,
            "predicted_cov_m2": self.predicted_cov_m2.tolist(), "empirical_cov_m2": self.empirical_cov_m2.tolist()}

    def summary(self) -> str:
        """Readable summary (µm)."""
        tp, te = np.trace(self.predicted_cov_m2), np.trace(self.empirical_cov_m2)
        return (f"Monte-Carlo: {self.n_rep} identifications of {self.n_meas} measurements\n"
                f"  predicted TCP sigma sqrt(tr C_s) = {np.sqrt(tp) * 1e6:.3f} um\n"
                f"  realised  TCP sigma              = {np.sqrt(te) * 1e6:.3f} um\n"
                f"  trace ratio realised/predicted   = {self.trace_ratio:.3f}   "
                f"(|bias| = {np.linalg.norm(self.bias_m) * 1e6:.3f} um, failures {self.failures})")


def monte_carlo(model: TrackerModel, Q_meas: np.ndarray, Q_work: np.ndarray, n_rep: int = 200,
                tol: Tolerances | None = None, seed: int = 0, show_progress: bool = True) -> MonteCarloResult:
    """Simulate ``n_rep`` identification experiments of design ``Q_meas`` and compare with C_s.

    Args:
        model: nominal measurement model (robot, tracker pose, reflector, noise).
        Q_meas: measurement configurations (m, n) rad.
        Q_work: working configurations (t, n) rad (the KPI).
        n_rep: number of simulated experiments.
        tol: tolerances of the true geometric errors (default :class:`Tolerances`).
        seed: base seed; repetition k uses seeds derived from (seed, k).
        show_progress: progress bar on a terminal.

    Raises:
        InputError: n_rep < 10.
    """
    t0 = time.perf_counter()
    if n_rep < 10:
        raise InputError(f"n_rep must be at least 10 for a covariance estimate, got {n_rep}")
    Q_meas = model.robot.check_q(Q_meas, "q_meas")
    Q_work = model.robot.check_q(Q_work, "q_work")
    ident = analyse(model)
    b = ident.base
    p0 = np.zeros(model.n_params)
    _, C_s = design_covariances(model, b, Q_meas, model.kpi_jacobian(p0, Q_work)[:, b], p0, ident.base_names)
    errs, failures = [], 0
    seeds = np.random.SeedSequence(seed).spawn(n_rep)
    for k in progress(range(n_rep), desc="Monte-Carlo", disable=not show_progress):
        s_truth, s_noise = (int(x) for x in seeds[k].generate_state(2))
        p_true = random_truth(model, tol, seed=s_truth, only=b)
        data = simulate(model, Q_meas, p_true, seed=s_noise, record_sigma=False)
        res = identify(model, data, Q_work=Q_work, ident=ident, raise_on_failure=False, discrepancy="none",
                       on_poor_fit="ignore", loss="linear")
        if not res.converged:
            failures += 1
        s_hat = res.model.kpi(res.p, Q_work).ravel()
        errs.append(s_hat - model.kpi(p_true, Q_work).ravel())
    E = np.array(errs)
    C_emp = np.cov(E.T)
    ratio = float(np.trace(C_emp) / np.trace(C_s))
    return MonteCarloResult(n_rep=n_rep, n_meas=Q_meas.shape[0], predicted_cov_m2=C_s, empirical_cov_m2=C_emp,
                            trace_ratio=ratio, bias_m=E.mean(axis=0), errors_m=E, failures=failures,
                            success=failures == 0, status="completed" if failures == 0 else "failures",
                            message=f"trace ratio realised/predicted {ratio:.3f}; {failures} of {n_rep} "
                                    "identifications did not converge", nit=n_rep, time_s=time.perf_counter() - t0)


@dataclass(kw_only=True)
class RealDataValidation(Result):
    """Real position errors at held-out working poses for designs chosen by several criteria.

    A :class:`~pin_kpi_oed.results.Result` (``status`` ``completed``, ``nit`` = splits, ``time_s``).

    Attributes:
        methods: criterion names (``kpi``, ``D``, ``random``).
        mean_error_m: per method, the mean error at the working poses for each split, (n_split,) m.
        predicted_sigma_m: per method, the predicted RMS position std at the working poses
            sqrt(tr(K C_p Kᵀ)/n_work) of each split, from the noise model (m): what the design controls.
        n_meas, n_work, n_splits: sizes; seed: seed of the splits.
    """

    methods: list[str]
    mean_error_m: dict[str, np.ndarray]
    predicted_sigma_m: dict[str, np.ndarray]
    n_meas: int
    n_work: int
    n_splits: int
    seed: int

    def to_dict(self) -> dict:
        """Plain JSON-able dict (SI units)."""
        return {**self.result_dict(), "n_meas": self.n_meas, "n_work": self.n_work, "n_splits": self.n_splits,
                "seed": self.seed,
                "methods": {k: {"mean_error_m": float(v.mean()), "std_over_splits_m": float(v.std(ddof=1)),
                                "per_split_m": v.tolist(),
                                "predicted_sigma_m": float(self.predicted_sigma_m[k].mean())}
                            for k, v in self.mean_error_m.items()}}

    def summary(self) -> str:
        """Readable table (mm)."""
        lines = [f"real data: {self.n_splits} splits, {self.n_work} working poses held out, "
                 f"{self.n_meas} calibration poses per design (seed {self.seed})",
                 f"{'design':<10}{'mean error at working poses (mm)':>36}{'wins vs random':>16}"
                 f"{'predicted sigma (mm)':>22}"]
        rnd = self.mean_error_m.get("random")
        for k, v in self.mean_error_m.items():
            wins = "" if rnd is None or k == "random" else f"{int(np.sum(v < rnd))}/{v.size}"
            lines.append(f"{k:<10}{v.mean() * 1e3:>24.4f} +- {v.std(ddof=1) * 1e3:.4f}{wins:>16}"
                         f"{self.predicted_sigma_m[k].mean() * 1e3:>22.4f}")
        return "\n".join(lines)


def real_data_validation(model: TrackerModel, data: MeasurementSet, n_meas: int = 60, n_work: int = 30,
                         n_splits: int = 10, methods: tuple[str, ...] = ("kpi", "D", "random"), seed: int = 0,
                         show_progress: bool = True) -> RealDataValidation:
    """Choose calibration poses from measured data by each method and score them at held-out working poses.

    The KPI is the measured point (the reflector) at the working poses, so its sensitivity is the
    measurement Jacobian there. The design model uses the tracker pose and reflector fitted to the
    whole pool with the nominal robot (set-up only), which is available before any calibration, and
    the model's priors; the predicted σ is from C_s (:func:`~pin_kpi_oed.oed.covariance.covariances`, eq. 19).

    Args:
        model: nominal measurement model (robot, reflector guess, noise, priors).
        data: the measured poses (position only is used).
        n_meas: calibration poses per design; n_work: working poses held out per split.
        n_splits: number of seeded splits.
        methods: ``random`` and criteria with a pool-selection form (``kpi``, ``D``, ``param``, ...).
        seed: seed of the splits and of the random designs.
        show_progress: progress bar on a terminal.

    Raises:
        InputError: too few rows for the split, or a method that cannot select poses from a pool.
    """
    t0 = time.perf_counter()
    if len(data) < n_meas + n_work + 10:
        raise InputError(f"{data.source}: {len(data)} rows are too few for {n_work} working and {n_meas} "
                         "calibration poses")
    crits = {k: information_criterion(k) for k in methods if k != "random"}
    for k, c in crits.items():
        if not c.has_pool_form:
            raise InputError(f"method '{k}': the criterion has no pool-selection form (use kpi, param, D or random)")
    design_model = position_design_model(model, data)
    ident = analyse(design_model)
    b = ident.base
    p0 = np.zeros(design_model.n_params)
    Fp_all = design_model.weighted_jacobian(p0, data.q)[:, :, b]
    prior = prior_of(design_model, b)
    out: dict[str, list[float]] = {k: [] for k in methods}
    pred: dict[str, list[float]] = {k: [] for k in methods}
    rng = np.random.default_rng(seed)
    for _ in progress(range(n_splits), desc="splits", disable=not show_progress):
        perm = rng.permutation(len(data))
        work, pool = perm[:n_work], perm[n_work:]
        E_work = design_model.jacobian(p0, data.q[work])[:, :3, :][:, :, b].reshape(-1, b.size)
        for meth in methods:
            if meth == "random":
                chosen = rng.choice(pool, n_meas, replace=False)
            else:
                chosen = pool[select(Fp_all[pool], n_meas, crits[meth].pool_form(E_work, b.size)).indices]
            res = identify(model, data.subset(chosen), use_orientation=False, raise_on_failure=False,
                           discrepancy="none", on_poor_fit="ignore", loss="linear")
            out[meth].append(validate(res, data.subset(work))["mean_m"])
            _, C_s = covariances(Fp_all[chosen], E_work, prior)
            pred[meth].append(float(np.sqrt(np.trace(C_s) / n_work)))
    return RealDataValidation(methods=list(methods), mean_error_m={k: np.array(v) for k, v in out.items()},
                              predicted_sigma_m={k: np.array(v) for k, v in pred.items()}, n_meas=n_meas,
                              n_work=n_work, n_splits=n_splits, seed=seed, success=True, status="completed",
                              message=f"{n_splits} splits, methods {', '.join(methods)}", nit=n_splits,
                              time_s=time.perf_counter() - t0)


def position_design_model(model: TrackerModel, data: MeasurementSet) -> TrackerModel:
    """The position-only model of the design: set-up (tracker pose, reflector) fitted with the nominal robot,
    the noise and the priors (by parameter name) of ``model``."""
    setup = identify(model, data, setup_only=True, use_orientation=False, discrepancy="none", on_poor_fit="ignore")
    dm = TrackerModel(model.robot, tracker_T_base=_se3(setup.tracker_T_base), reflector_m=setup.reflector_m,
                      noise=model.noise)
    for i, name in enumerate(dm.layout.names):
        if name in model.layout.names:
            dm.layout.prior_sigma[i] = model.layout.prior_sigma[model.layout.index(name)]
    return dm


def _se3(T: np.ndarray):
    import pinocchio as pin

    T = np.asarray(T)
    return pin.SE3(T[:3, :3].copy(), T[:3, 3].copy())


# ---------------------------------------------------------------------- designs over the extended model, real data
#: Methods of :func:`extended_design_validation`: name -> (criterion, model the criterion is evaluated on).
EXTENDED_METHODS: dict[str, tuple[str | None, str]] = {
    "random": (None, ""), "D": ("D", "extended"), "param": ("param", "extended"),
    "kpi_geo": ("kpi", "geometric"), "kpi_ext": ("kpi", "extended"), "D_geo": ("D", "geometric"),
    "kpi_bias": ("kpi", "extended+bias"),
}


@dataclass(kw_only=True)
class ExtendedDesignValidation(Result):
    """Held-out real errors near working configurations of 60-pose designs, calibrated with the extended model.

    A :class:`~pin_kpi_oed.results.Result` (``status`` ``completed``, ``nit`` = splits, ``time_s``).

    Attributes:
        methods: design methods (keys of :data:`EXTENDED_METHODS`).
        error_m: per method, the mean 3-D error of the scored rows of each split, (n_splits,) m.
        n_scored: scored held-out rows per split; n_terms: selected effect groups per split.
        settings: the split, radius, prior and selection settings (plain numbers, SI).
    """

    methods: list[str]
    error_m: dict[str, np.ndarray]
    n_scored: np.ndarray
    n_terms: np.ndarray
    settings: dict

    def paired(self, a: str, b: str = "random") -> dict:
        """Paired comparison of method ``a`` against ``b`` over the splits: mean relative reduction,
        wins, Wilcoxon signed-rank and paired t-test p-values (two-sided)."""
        from scipy import stats

        x, y = self.error_m[a], self.error_m[b]
        red = 1.0 - x / y
        out = {"reduction_mean": float(red.mean()), "reduction_of_means": float(1.0 - x.mean() / y.mean()),
               "wins": int(np.sum(x < y)), "n": int(x.size)}
        if x.size >= 2 and np.any(x != y):
            out["p_wilcoxon"] = float(stats.wilcoxon(x, y).pvalue)
            out["p_ttest"] = float(stats.ttest_rel(x, y).pvalue)
        return out

    def to_dict(self) -> dict:
        """Plain JSON-able dict (SI units)."""
        return {**self.result_dict(), "settings": self.settings, "n_scored": self.n_scored.tolist(),
                "n_terms": self.n_terms.tolist(),
                "methods": {k: {"mean_error_m": float(v.mean()), "std_over_splits_m": float(v.std(ddof=1)),
                                "per_split_m": v.tolist(),
                                **({} if k == "random" else {"vs_random": self.paired(k)})}
                            for k, v in self.error_m.items()}}

    def summary(self) -> str:
        """Readable table (mm)."""
        s = self.settings
        lines = [f"{s['case']}: {self.nit} splits, {self.settings['n_meas']} poses per design, scored rows within "
                 f"{s['radius_rad']} rad (joints 1-5) of {s['n_work']} working configurations: "
                 f"{self.n_scored.mean():.0f} rows per split; {self.n_terms.mean():.1f} effect groups selected",
                 f"{'design':<10}{'held-out error (mm)':>24}{'vs random':>12}{'wins':>7}{'p Wilcoxon':>12}"
                 f"{'p t-test':>10}"]
        for k, v in self.error_m.items():
            if k == "random":
                lines.append(f"{k:<10}{v.mean() * 1e3:>14.4f} +- {v.std(ddof=1) * 1e3:.4f}")
                continue
            c = self.paired(k)
            lines.append(f"{k:<10}{v.mean() * 1e3:>14.4f} +- {v.std(ddof=1) * 1e3:.4f}"
                         f"{-100 * c['reduction_of_means']:>+11.1f}%{c['wins']:>5}/{c['n']}"
                         f"{c.get('p_wilcoxon', float('nan')):>12.2g}{c.get('p_ttest', float('nan')):>10.2g}")
        return "\n".join(lines)


def fit_extended(model: TrackerModel, data: MeasurementSet, base: np.ndarray, effects: list, p_ref: np.ndarray,
                  prior_rad: float, held: list | None = None) -> np.ndarray:
    """MAP fit of (p_B, θ): weighted residuals plus θ/σ_prior rows (rad); returns x (p_B, θ)."""
    from scipy.optimize import least_squares

    from pin_kpi_oed.identification.problem import ResidualModel

    prob = ResidualModel(model, data, base, effects=effects, p_ref=p_ref, held=held or ())
    nb, k = prob.nb, prob.k
    R = np.hstack([np.zeros((k, nb)), np.eye(k) / prior_rad])

    def fun(x):
        return np.concatenate([prob.residual(x), R @ x])

    def jac(x):
        return np.vstack([prob.jacobian(x), R])

    return least_squares(fun, prob.x0(), jac=jac, method="lm", x_scale="jac", max_nfev=200).x


def _errors(model: TrackerModel, data: MeasurementSet, base: np.ndarray, effects: list, p_ref: np.ndarray,
            x: np.ndarray) -> np.ndarray:
    """3-D prediction error of every row of ``data`` (m)."""
    from pin_kpi_oed.identification.problem import ResidualModel

    prob = ResidualModel(model, data, base, effects=effects, p_ref=p_ref)
    return np.linalg.norm(prob.evaluate(x)[0], axis=1)


def near_training(Q: np.ndarray, Q_work: np.ndarray, radius: float, joints: int) -> np.ndarray:
    """Rows of Q within ``radius`` (Euclidean, rad, first ``joints`` joints) of any working configuration."""
    d = np.linalg.norm(Q[:, None, :joints] - Q_work[None, :, :joints], axis=2)
    return np.flatnonzero(d.min(axis=1) <= radius)


def extended_design_validation(model: TrackerModel, data: MeasurementSet, target: MeasurementSet | None = None, *,
                               n_meas: int = 60, n_splits: int = 20, test_frac: float = 0.3, n_work: int = 5,
                               radius_rad: float = 0.5, joints: int = 5, max_terms: int = 15, max_order: int = 40,
                               prior_rad: float = 1e-4, n_register: int = 60,
                               methods: tuple[str, ...] = ("random", "D", "param", "kpi_geo", "kpi_ext"),
                               seed: int = 0, show_progress: bool = True) -> ExtendedDesignValidation:
    """Designs over the extended model on real data: choose, calibrate with the extended model, score near the work.

    Per seeded split: the rows of ``data`` are split into a training pool and a held-out part
    (``test_frac``); ``n_work`` held-out rows are the working configurations and the held-out
    rows within ``radius_rad`` of one of them (joint space, first ``joints`` joints) are scored.
    On the training pool the geometry is fitted and the transferable terms are selected
    (:func:`~pin_kpi_oed.diagnosis.selection.select_terms`, ``max_terms`` groups, orders 1 …
    ``max_order``); the extended model (:class:`~pin_kpi_oed.oed.extended.ExtendedModel`, prior σ
    ``prior_rad`` on every effect parameter) gives each candidate's F block. Each method chooses
    ``n_meas`` poses (random; D or A on C_p on the extended model; the KPI — the measured point at
    the working configurations — on the geometric or on the extended model); every set is calibrated
    with the extended model (geometry + set-up + the selected terms, MAP with the same prior) and
    scored. With ``target`` (another series, a directed pair) the working configurations and scored
    rows come from ``target``; its set-up is re-registered on ``n_register`` seeded rows (robot and
    terms held) that are not scored.

    Args:
        model: nominal measurement model (robot, reflector guess, noise; position only is used).
        data: the measured rows (the training source).
        target: another series for the directed-pair case, or None (within-session).
        n_meas: poses per design; n_splits: seeded splits; test_frac: held-out share.
        n_work: working configurations per split; radius_rad: scoring radius (rad); joints: joints used.
        max_terms, max_order: term selection; prior_rad: prior σ of the effect parameters (rad).
        n_register: rows of ``target`` used to re-register its set-up.
        methods: keys of :data:`EXTENDED_METHODS`.
        seed: seed of the splits, the working configurations, the random designs and the selection.
        show_progress: progress bar.

    Returns:
        The :class:`ExtendedDesignValidation`.

    Raises:
        InputError: unknown method, too few rows.
    """
    t0 = time.perf_counter()
    _check_extended(methods, data, n_meas)
    rng = np.random.default_rng(seed)
    err: dict[str, list[float]] = {k: [] for k in methods}
    n_scored, n_terms, bias = [], [], []
    for s in progress(range(n_splits), desc="splits", disable=not show_progress):
        perm = rng.permutation(len(data))
        n_test = int(round(test_frac * len(data))) if target is None else 0
        pool_rows = np.sort(perm[n_test:])
        pool = data.subset(pool_rows)
        fit = _fit_split(model, pool, seed + s, max_order, max_terms, prior_rad)
        n_terms.append(fit.n_terms)
        bias.append(fit.cv_rms_m)
        work, scored, reg = work_and_scored(data, target, perm, n_test, rng, n_work, n_register, radius_rad, joints)
        n_scored.append(len(scored))
        for meth, e in _score_methods(fit, pool, work, scored, reg, methods, rng, n_meas, seed + s, prior_rad):
            err[meth].append(e)
    settings = {"case": f"{data.source}" + (f" -> {target.source}" if target is not None else " (within)"),
                "n_meas": n_meas, "test_frac": test_frac, "n_work": n_work, "radius_rad": radius_rad,
                "joints": joints, "max_terms": max_terms, "max_order": max_order, "prior_rad": prior_rad,
                "n_register": n_register if target is not None else 0, "seed": seed,
                "selection_cv_rms_m": float(np.mean(bias))}
    return ExtendedDesignValidation(methods=list(methods), error_m={k: np.array(v) for k, v in err.items()},
                                    n_scored=np.array(n_scored), n_terms=np.array(n_terms), settings=settings,
                                    success=True, status="completed", nit=n_splits,
                                    message=f"{n_splits} splits, methods {', '.join(methods)}",
                                    time_s=time.perf_counter() - t0)


def _check_extended(methods: tuple[str, ...], data: MeasurementSet, n_meas: int) -> None:
    """Raise InputError for an unknown method or too few rows for ``n_meas``-pose designs."""
    for k in methods:
        if k not in EXTENDED_METHODS:
            raise InputError(f"method '{k}': unknown (known: {', '.join(EXTENDED_METHODS)})")
    if len(data) < 3 * n_meas:
        raise InputError(f"{data.source}: {len(data)} rows are too few for {n_meas}-pose designs")


def _score_methods(fit: _SplitFit, pool: MeasurementSet, work: np.ndarray, scored: MeasurementSet,
                   reg: MeasurementSet | None, methods: tuple[str, ...], rng: np.random.Generator, n_meas: int,
                   seed: int, prior_rad: float) -> list[tuple[str, float]]:
    """(method, mean position error (m)) on the scored rows of each method's design, calibrated with the extended
    model."""
    # KPI: the measured point at the working configurations, in the pool's tracker frame
    ext = fit.ext
    E_ext = ext.jacobian(work, weighted=False)[:, :3, :].reshape(-1, ext.nx)
    out = []
    for meth in methods:
        chosen = _choose(meth, fit, E_ext, rng, len(pool), n_meas, seed)
        x = fit_extended(fit.geo.model, pool.subset(np.sort(chosen)), fit.base, fit.effects, fit.p_ref, prior_rad)
        if reg is None:
            e = _errors(fit.geo.model, scored, fit.base, fit.effects, fit.p_ref, x)
        else:
            e = _register_and_score(fit.geo.model, fit.base, fit.effects, fit.p_ref, x, reg, scored)
        out.append((meth, float(e.mean())))
    return out


@dataclass
class _SplitFit:
    """One split's training-pool fit: geometry, selected terms and the extended model's pool Jacobians."""

    geo: Any              # IdentificationResult of the geometric fit on the pool
    n_terms: int          # selected transferable terms
    cv_rms_m: float       # the selection's held-out RMS (m), NaN without selection
    effects: list
    base: np.ndarray      # identifiable base parameters
    p_ref: np.ndarray     # reference parameters: nominal robot, the pool's set-up
    ext: Any              # ExtendedModel (prior sigma on every effect parameter)
    Fp: np.ndarray        # weighted pool Jacobians of the extended model
    Fp_bias: np.ndarray   # the same with the selection's bias added to the measurement variance


def _fit_split(model: TrackerModel, pool: MeasurementSet, seed: int, max_order: int, max_terms: int,
               prior_rad: float) -> _SplitFit:
    """Fit the geometry on the training pool, select the transferable terms, build the extended model."""
    from pin_kpi_oed.diagnosis.selection import select_terms
    from pin_kpi_oed.oed.extended import ExtendedModel

    geo = identify(model, pool, use_orientation=False, discrepancy="none", on_poor_fit="ignore")
    sel = select_terms(geo, pool, max_order=max_order, max_terms=max_terms, prior_rad=prior_rad, seed=seed,
                       refit=False, show_progress=False)
    effects = list(sel.effects)
    cv_rms = float(sel.cv_rms_m[-1]) if len(sel.cv_rms_m) else float("nan")
    base = np.asarray(geo.identifiability.base, int)
    p_ref = np.asarray(geo.p, float).copy()
    p_ref[:6 * model.robot.nq] = 0.0  # start from the nominal robot, the set-up of the pool
    ext = ExtendedModel(geo.model, p_ref, base, effects)
    ext.prior_info = np.diag(np.r_[np.zeros(ext.nb), np.full(ext.k, prior_rad ** -2)])
    Fp = ext.jacobian(pool.q)
    # bias-aware option: the selection's held-out RMS (per axis) added to the measurement variance
    b_axis = float(sel.cv_rms_m[-1]) / np.sqrt(3.0) if len(sel.cv_rms_m) else 0.0
    s_row = model.noise.sigma(pool.position_m)
    Fp_bias = Fp * (s_row / np.sqrt(s_row ** 2 + b_axis ** 2))[:, :, None]
    return _SplitFit(geo=geo, n_terms=len(sel.terms), cv_rms_m=cv_rms, effects=effects, base=base, p_ref=p_ref,
                     ext=ext, Fp=Fp, Fp_bias=Fp_bias)


def work_and_scored(data: MeasurementSet, target: MeasurementSet | None, perm: np.ndarray, n_test: int,
                     rng: np.random.Generator, n_work: int, n_register: int, radius_rad: float,
                     joints: int) -> tuple[np.ndarray, MeasurementSet, MeasurementSet | None]:
    """(working configurations (rad), scored rows, registration rows of ``target`` or None) of one split."""
    if target is None:
        test_rows = np.sort(perm[:n_test])
        tq = data.q[test_rows]
        work = tq[rng.choice(test_rows.size, n_work, replace=False)]
        return work, data.subset(test_rows[near_training(tq, work, radius_rad, joints)]), None
    tperm = rng.permutation(len(target))
    reg = target.subset(np.sort(tperm[:n_register]))
    rest = np.sort(tperm[n_register:])
    work = target.q[rest[rng.choice(rest.size, n_work, replace=False)]]
    return work, target.subset(rest[near_training(target.q[rest], work, radius_rad, joints)]), reg


def _choose(meth: str, fit: _SplitFit, E_ext: np.ndarray, rng: np.random.Generator, n_pool: int, n_meas: int,
            seed: int) -> np.ndarray:
    """Pool indices of the ``n_meas`` poses chosen by method ``meth`` (a key of :data:`EXTENDED_METHODS`)."""
    from pin_kpi_oed.oed.extended import select_pool

    ext = fit.ext
    crit, on = EXTENDED_METHODS[meth]
    if crit is None:
        return rng.choice(n_pool, n_meas, replace=False)
    K = information_criterion(crit).pool_form(E_ext[:, :ext.nb] if on == "geometric" else E_ext,
                                      ext.nb if on == "geometric" else ext.nx)
    if on == "geometric":
        return select(fit.Fp[:, :, :ext.nb], n_meas, K, seed=seed).indices
    return select_pool(fit.Fp_bias if on.endswith("bias") else fit.Fp, n_meas, K, ext.prior_info,
                       seed=seed).indices


def _register_and_score(model: TrackerModel, base: np.ndarray, effects: list, p_ref: np.ndarray, x: np.ndarray,
                        reg: MeasurementSet, scored: MeasurementSet) -> np.ndarray:
    """Re-register the set-up (tracker pose, reflector) on ``reg`` with robot and terms held; errors of ``scored``."""
    from pin_kpi_oed.identification.problem import ResidualModel

    prob = ResidualModel(model, reg, base, effects=effects, p_ref=p_ref)
    P, th = prob.unpack(x)
    L = model.layout
    setup = np.array([i for i in range(L.n) if L.names[i].split(".")[0] in L.setup_groups], int)
    held = list(zip(effects, th))
    from scipy.optimize import least_squares

    from pin_kpi_oed.identification.identify import register_points

    # Kabsch start of the tracker pose from the held robot's predictions, then the set-up by least squares
    pr = ResidualModel(model, reg, setup, p_ref=P, held=held)
    xs = least_squares(pr.residual, pr.x0(), jac=pr.jacobian, method="lm", max_nfev=200).x
    P2 = P.copy()
    P2[setup] = xs
    del register_points
    ps = ResidualModel(model, scored, setup, p_ref=P2, held=held)
    return np.linalg.norm(ps.evaluate(xs)[0], axis=1)
