"""Validation of measurement designs: Monte-Carlo identification and real data.

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

import numpy as np

from pin_kpi_oed.data.measurements import MeasurementSet
from pin_kpi_oed.errors import InputError
from pin_kpi_oed.identification.identify import identify, validate
from pin_kpi_oed.identification.simulate import Tolerances, random_truth, simulate
from pin_kpi_oed.model.tracker import TrackerModel
from pin_kpi_oed.oed.covariance import covariances, design_covariances, prior_of
from pin_kpi_oed.oed.criteria import get_criterion
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
        return {**self.result_dict(), "n_rep": self.n_rep, "n_meas": self.n_meas, "predicted_trace_cs_m2": float(np.trace(
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
        res = identify(model, data, Q_work=Q_work, ident=ident, raise_on_failure=False)
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
    crits = {k: get_criterion(k) for k in methods if k != "random"}
    for k, c in crits.items():
        if not c.has_pool_form:
            raise InputError(f"method '{k}': the criterion has no pool-selection form (use kpi, param, D or random)")
    design_model = _design_model(model, data)
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
            res = identify(model, data.subset(chosen), use_orientation=False, raise_on_failure=False)
            out[meth].append(validate(res, data.subset(work))["mean_m"])
            _, C_s = covariances(Fp_all[chosen], E_work, prior)
            pred[meth].append(float(np.sqrt(np.trace(C_s) / n_work)))
    return RealDataValidation(methods=list(methods), mean_error_m={k: np.array(v) for k, v in out.items()},
                              predicted_sigma_m={k: np.array(v) for k, v in pred.items()}, n_meas=n_meas,
                              n_work=n_work, n_splits=n_splits, seed=seed, success=True, status="completed",
                              message=f"{n_splits} splits, methods {', '.join(methods)}", nit=n_splits,
                              time_s=time.perf_counter() - t0)


def _design_model(model: TrackerModel, data: MeasurementSet) -> TrackerModel:
    """The position-only model of the design: set-up (tracker pose, reflector) fitted with the nominal robot,
    the noise and the priors (by parameter name) of ``model``."""
    setup = identify(model, data, setup_only=True, use_orientation=False)
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
