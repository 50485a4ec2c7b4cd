r"""Fitting the discrepancy: hyper-parameters by maximum marginal likelihood on a seeded subset
(:mod:`pin_kpi_oed.discrepancy.marginal`), the exact or inducing-point posterior, the K-fold check by block inversion
and the automatic decision (:func:`fit_discrepancy`; the model it returns:
:class:`~pin_kpi_oed.discrepancy.gp.Discrepancy`).
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np
from scipy import linalg as sla

from pin_kpi_oed.discrepancy.cholesky import jitter_cholesky
from pin_kpi_oed.discrepancy.coverage import JointCoverage
from pin_kpi_oed.discrepancy.gp import JITTER, Discrepancy, DiscrepancyOptions, grouped_folds, kfold_rows, white_level
from pin_kpi_oed.discrepancy.kernel import JointKernel
from pin_kpi_oed.errors import InputError

if TYPE_CHECKING:
    from pin_kpi_oed.discrepancy.marginal import StartRace

__all__ = ["fit_discrepancy"]


def _hyper_fit(Q: np.ndarray, Y: np.ndarray, opts: DiscrepancyOptions, joint_amplitude: float,
               min_noise: float = 1e-5, linear: np.ndarray | None = None,
               joint_span: np.ndarray | None = None, race: StartRace | None = None) -> tuple[JointKernel, float]:
    """Maximum marginal likelihood of the kernel and the white level on a seeded subset (normalised Y),
    from a start whose additive (one-joint) amplitudes are ``joint_amplitude``; the white level at least
    ``min_noise`` (the data's stated noise in normalised units)
    (:func:`~pin_kpi_oed.discrepancy.marginal.maximise_marginal_likelihood`). Length scales start at 1 rad (whole
    configuration) and 0.5 rad (one joint), a ``linear`` joint's at the same share of its travel ``joint_span``
    (m) / 2π (:meth:`JointKernel.for_joints`); the search raced against the fit's earlier starts in ``race``
    (:class:`~pin_kpi_oed.discrepancy.marginal.StartRace`, which records it), None: not raced."""
    from pin_kpi_oed.discrepancy.marginal import maximise_marginal_likelihood

    d = Q.shape[1]
    rng = np.random.default_rng(opts.seed)
    sub = rng.permutation(len(Q))[:opts.n_fit]
    k0 = JointKernel.for_joints(0.7, np.ones(d), np.full(d, joint_amplitude), np.full(d, 0.5), linear, joint_span)
    kernel, noise, _ = maximise_marginal_likelihood(Q[sub], Y[sub], k0, max(0.3, 1.5 * min_noise),
                                                    (min_noise, max(10.0, 4.0 * min_noise)), opts.max_iter,
                                                    opts.restarts, opts.seed, race)
    return kernel, noise


def _posterior(kernel: JointKernel, noise: float, Q: np.ndarray, Y: np.ndarray, opts: DiscrepancyOptions,
               rng: np.random.Generator, chunk: int = 2000) -> dict:
    """Exact (n ≤ max_exact) or DTC posterior pieces for :class:`Discrepancy`."""
    n = len(Q)
    if n <= opts.max_exact:
        return {"kind": "exact", "Z": Q.copy(), "y": Y.copy()}
    Z = Q[np.sort(rng.permutation(n)[:opts.n_inducing])]
    m = len(Z)
    # the lower triangle alone: the Cholesky factor reads nothing else
    Lz = jitter_cholesky(kernel.lower(Z), (1e-8, 1e-6, 1e-4, 1e-2), "the inducing configurations' kernel matrix")
    # A = K_ZZ + w⁻¹ K_ZQ K_QZ = L_z B L_zᵀ with B = I + w⁻¹ V Vᵀ, V = L_z⁻¹ K_ZQ (eigenvalues of B ≥ 1)
    B = np.eye(m)
    c = np.zeros((m, 3))
    for a in range(0, n, chunk):
        V = sla.solve_triangular(Lz, kernel(Z, Q[a:a + chunk]), lower=True, check_finite=False)
        B += V @ V.T / noise
        c += V @ Y[a:a + chunk] / noise
    cB = sla.cho_factor(B, lower=True, check_finite=False)
    alpha = sla.solve_triangular(Lz, sla.cho_solve(cB, c, check_finite=False), lower=True, trans="T",
                                 check_finite=False)
    inner = np.eye(m) - sla.cho_solve(cB, np.eye(m), check_finite=False)           # I − B⁻¹
    Li = sla.solve_triangular(Lz, np.eye(m), lower=True, check_finite=False)       # L_z⁻¹
    Minv = Li.T @ inner @ Li                                                      # K_ZZ⁻¹ − A⁻¹
    return {"kind": "inducing", "Z": Z, "alpha": alpha, "Minv": 0.5 * (Minv + Minv.T)}


def _inverse_blocks(S: np.ndarray, Y: np.ndarray, fold: np.ndarray, n_folds: int, keep: dict | None = None
                   ) -> tuple[np.ndarray, list[np.ndarray]]:
    """(Σ⁻¹Y, the diagonal blocks (Σ⁻¹)_II of the folds) of a symmetric positive-definite Σ from its Cholesky factor
    Σ = LLᵀ (LAPACK potrf; S's lower triangle is all that is read): (Σ⁻¹)_II = (L⁻¹)_{:,I}ᵀ (L⁻¹)_{:,I} from the
    columns of L⁻¹ (trtri) of fold I, the rows from its first one down (L⁻¹ is lower triangular), about half the work
    of the whole inverse (potri); the lower factor is stored in ``keep["chol"]`` when ``keep`` is given.

    Raises:
        numpy.linalg.LinAlgError: Σ not positive definite.
    """
    Lc, info = sla.lapack.dpotrf(S, lower=1, clean=1, overwrite_a=0)
    if info != 0:
        raise np.linalg.LinAlgError("the discrepancy covariance is not positive definite")
    if keep is not None:
        keep["chol"] = Lc
    alpha = sla.cho_solve((Lc, True), Y, check_finite=False)
    Li, info = sla.lapack.dtrtri(Lc, lower=1, overwrite_c=0)
    if info != 0:
        raise np.linalg.LinAlgError("the discrepancy covariance could not be inverted")
    blocks = []
    for k in range(n_folds):
        cols = np.flatnonzero(fold == k)
        C = Li[cols[0]:, cols]
        blocks.append(C.T @ C)
    return alpha, blocks


def kfold_split(kernel: JointKernel, noise: float, Q: np.ndarray, Y: np.ndarray, scale: np.ndarray,
           opts: DiscrepancyOptions, names: list, keep: dict | None = None,
           periodic: np.ndarray | None = None) -> dict:
    """K-fold held-out check with the hyper-parameters fixed: mean 3-D error (m) without and with δ,
    and the standardised errors z of the held-out rows (their RMS and excess kurtosis E z⁴ / (E z²)² − 3, pooled over
    the axes: a check's test of few rows needs the tails, :mod:`pin_kpi_oed.upkeep.check`).

    Up to ``max_exact`` rows the folds come from one Cholesky factor of Σ = K + wI (block inversion: the
    held-out residuals of fold I are (Σ⁻¹)_II⁻¹ (Σ⁻¹y)_I with covariance (Σ⁻¹)_II⁻¹, exactly what refitting
    the posterior without fold I gives; only the folds' diagonal blocks of Σ⁻¹ are formed, :func:`_inverse_blocks`);
    above it each fold's DTC posterior is built. Σ is the exact posterior's
    (jitter included), and its Cholesky factor is stored in ``keep["chol"]`` for the posterior when ``keep`` is given.
    """
    fold, _ = grouped_folds(Q, opts.folds, opts.seed + 1, periodic)
    n_folds = int(fold.max()) + 1
    e0, e1, z2, inside = [], [], [], []
    exact = len(Q) <= opts.max_exact
    if exact:
        S = kernel.lower(Q)  # the lower triangle alone: the Cholesky factor reads nothing else
        S[np.diag_indices_from(S)] += noise + JITTER
        alpha, blocks = _inverse_blocks(S, Y, fold, n_folds, keep)
    for k in range(n_folds):
        tr, te = fold != k, fold == k
        if exact:
            c = sla.cho_factor(blocks[k], lower=True, check_finite=False)
            r = sla.cho_solve(c, alpha[te], check_finite=False)                  # y_I − μ_I (normalised)
            var = np.diag(sla.cho_solve(c, np.eye(int(te.sum())), check_finite=False))
        else:
            post = _posterior(kernel, noise, Q[tr], Y[tr], opts, np.random.default_rng(opts.seed + 2 + k))
            dk = Discrepancy(post["kind"], names, scale, np.zeros(3), noise, kernel, post["Z"], post.get("y"),
                             post.get("alpha"), post.get("Minv"))
            mu, v = dk.predict_normalised(Q[te])
            r, var = Y[te] - mu, v + noise
        e0.append(np.linalg.norm(Y[te] * scale, axis=1))
        e1.append(np.linalg.norm(r * scale, axis=1))
        zz = r ** 2 / var[:, None]
        z2.append(zz)
        inside.append(zz.sum(1) <= 7.8147)
    a0, a1, zz2 = np.concatenate(e0), np.concatenate(e1), np.vstack(z2)
    return {"folds": n_folds, "grouped": True, "mean_without_m": float(a0.mean()), "mean_with_m": float(a1.mean()),
            "rms_without_m": float(np.sqrt(np.mean(a0 ** 2))), "rms_with_m": float(np.sqrt(np.mean(a1 ** 2))),
            "z_rms": float(np.sqrt(zz2.mean())), "z_kurtosis": float(np.mean(zz2 ** 2) / zz2.mean() ** 2 - 3.0),
            "inside_95": float(np.concatenate(inside).mean())}


def fit_discrepancy(Q: np.ndarray, R: np.ndarray, joint_names: Sequence[str],
                    options: DiscrepancyOptions | None = None, *, n_params: int = 0,
                    noise_floor_m: np.ndarray | None = None, periodic: np.ndarray | None = None,
                    linear: np.ndarray | None = None, joint_span: np.ndarray | None = None,
                    jacobian: np.ndarray | None = None, joint_jacobian: np.ndarray | None = None
                    ) -> Discrepancy | None:
    """Fit δ to the residuals of a parametric fit.

    Args:
        Q: training configurations (n, d) rad. R: residuals measured − predicted in the robot base frame (n, 3) m.
        joint_names: the robot's joints (columns of Q).
        options: :class:`DiscrepancyOptions` (mode ``none`` returns None).
        n_params: parameters the parametric fit estimated from these rows (the white level's 3m − p correction,
            :func:`white_level`).
        noise_floor_m: the data's stated noise per axis (m): no white level (of the white kind or the Gaussian
            process's) below it. None: no floor (the noise level is unknown).
        jacobian, joint_jacobian: the fit's Jacobians w.r.t. its parameters (n, 3, P) and the joint angles (n, 3, d),
            base frame: below a Gaussian process, joint-angle errors beside the white level (:func:`_joint_angle`; not
            on a robot with a linear joint).
        periodic: (d,) bool, joints compared mod 2π (``Robot.periodic_joints``); None: every joint.
        linear: (d,) bool, the linear (prismatic) joints, on the line in the kernel (``~Robot.is_revolute``); None:
            none. joint_span: (d,) the joints' travel (upper − lower limit, m for a linear joint): a linear joint's
            starting length scales and bounds follow it; None: the training values' own spread.

    Returns:
        The :class:`Discrepancy` (``decision`` says what was decided and why), or None for mode ``none``.

    Raises:
        InputError: too few rows for mode ``on``, non-finite residuals.
    """
    t0 = time.perf_counter()
    opts = options or DiscrepancyOptions()
    if opts.mode == "none":
        return None
    Q, R, names = np.atleast_2d(np.asarray(Q, float)), np.asarray(R, float).reshape(-1, 3), list(joint_names)
    if not np.all(np.isfinite(R)) or not np.all(np.isfinite(Q)):
        raise InputError("discrepancy: non-finite residuals or joint values")
    n = len(Q)
    coverage = JointCoverage.from_training(Q, opts.seed, periodic)
    white = _white(R, names, n_params, noise_floor_m, coverage)
    # distinct poses (near-duplicates counted once) on a seeded subset: enough to tell whether there are min_rows
    few = np.sort(np.random.default_rng(opts.seed + 3).permutation(n)[:max(2000, 4 * opts.min_rows)])
    _, n_poses = grouped_folds(Q[few], opts.folds, opts.seed + 1, periodic)
    if n_poses < opts.min_rows:
        if opts.mode == "on":
            raise InputError(f"discrepancy: {n_poses} distinct poses are too few for the Gaussian process (at least "
                             f"{opts.min_rows}); measure more poses or use discrepancy='auto' or 'none'")
        if linear is None or not np.any(linear):              # the joint-angle kernel is one of angles
            _joint_angle(white, Q, R, jacobian, joint_jacobian, noise_floor_m, periodic)
        white.decision = (f"discrepancy: white: {n_poses} distinct poses, fewer than the {opts.min_rows} a Gaussian "
                          f"process needs; {white.decision}")
        white.time_s = time.perf_counter() - t0
        return white
    mean, scale = R.mean(axis=0), np.maximum(R.std(axis=0), 1e-12)
    min_noise = 1e-5 if noise_floor_m is None else max(1e-5, float(np.max((np.asarray(noise_floor_m) / scale) ** 2)))
    Y = (R - mean) / scale
    cv_rows = kfold_rows(n, opts)
    span = np.ptp(Q, axis=0) if joint_span is None else np.asarray(joint_span, float)
    kernel, noise, cv, chol = _best_start(Q, Y, scale, opts, names, min_noise, cv_rows, coverage.periodic,
                                          (linear, span))
    gain = 1.0 - cv["mean_with_m"] / cv["mean_without_m"]
    cv["gain"] = float(gain)
    words = (f"{cv['folds']}-fold held-out mean (near-duplicate poses in one fold) {cv['mean_without_m'] * 1e3:.4f} "
             f"-> {cv['mean_with_m'] * 1e3:.4f} mm ({gain * 100:+.1f} %), standardised RMS {cv['z_rms']:.2f}"
             + (f", on a seeded subset of {len(cv_rows)} of the {n} rows" if len(cv_rows) < n else ""))
    if opts.mode == "auto" and gain < opts.min_gain:
        white.cv.update(cv)
        white.decision = (f"discrepancy: white: the Gaussian process does not lower the held-out error enough "
                          f"({words}; needs {opts.min_gain * 100:.0f} %); {white.decision}")
        white.time_s = time.perf_counter() - t0
        return white
    post = _posterior(kernel, noise, Q, Y, opts, np.random.default_rng(opts.seed + 100))
    scale = _dof_rescale(post, scale, n, n_params, cv)
    out = Discrepancy(post["kind"], names, scale, mean, noise, kernel, post["Z"], post.get("y"), post.get("alpha"),
                      post.get("Minv"), coverage, n, cv)
    if post["kind"] == "exact" and chol is not None:
        out.set_factor(chol)
    out.decision = (f"discrepancy: Gaussian process fitted ({post['kind']}, {n} rows): {words}")
    out.time_s = time.perf_counter() - t0
    return out


def _best_start(Q: np.ndarray, Y: np.ndarray, scale: np.ndarray, opts: DiscrepancyOptions, names: list,
                min_noise: float, cv_rows: np.ndarray, periodic: np.ndarray | None, joints: tuple) -> tuple:
    """The hyper-parameters from each of ``opts.starts`` (:func:`_hyper_fit`; ``joints`` = (linear mask, travel)),
    the one of least K-fold held-out mean error (:func:`kfold_split` on ``cv_rows``): (kernel, white level, the
    check, the Cholesky factor of all rows or None).

    The starts' searches are raced on their log marginal likelihood (same rows, :class:`StartRace`): a start that
    trails the best by more than ``StartRace.nats`` at its iteration ``StartRace.at`` is stopped there, and only the
    starts that finish within that margin of the best are checked (the K-fold check inverts the covariance of all
    rows, the largest cost on a few thousand rows); with ``opts.restarts`` every start that finished is checked."""
    from pin_kpi_oed.discrepancy import marginal

    race = marginal.StartRace(marginal.RACE_AT, marginal.RACE_NATS)
    linear, span = joints
    fits = [_hyper_fit(Q, Y, opts, float(a0), min_noise, linear, span, race=race) for a0 in opts.starts]
    assert fits, "DiscrepancyOptions.starts is empty"
    raced = race.contenders() if len(race.finals) == len(fits) else [True] * len(fits)
    best = None
    for (kernel, noise), contender in zip(fits, raced):
        if not contender:
            continue
        keep: dict = {}  # the factor of all rows (reused by an exact posterior): only when the check uses them all
        cv = kfold_split(kernel, noise, Q[cv_rows], Y[cv_rows], scale, opts, names,
                         keep if len(cv_rows) == len(Q) else None, periodic)
        if best is None or cv["mean_with_m"] < best[2]["mean_with_m"]:
            best = (kernel, noise, cv, keep.get("chol"))
    assert best is not None, "no start finished the race"
    return best


def _dof_rescale(post: dict, scale: np.ndarray, n: int, n_params: int, cv: dict) -> np.ndarray:
    """The residuals are those of a fit of p parameters: their level is sqrt((3n − p) / 3n) of the error at a new
    pose. S grows by the inverse (every variance by 3n / (3n − p)); y and alpha shrink alike, so the posterior mean
    is unchanged. Returns the new S (``cv["dof_factor"]`` records the factor)."""
    dof = float(np.sqrt(3.0 * n / max(3 * n - int(n_params), 1)))
    for key in ("y", "alpha"):
        if post.get(key) is not None:
            post[key] = post[key] / dof
    cv["dof_factor"] = dof
    return scale * dof


def _joint_angle(white: Discrepancy, Q: np.ndarray, R: np.ndarray, F: np.ndarray | None, Jq: np.ndarray | None,
                 floor_m: np.ndarray | None, periodic: np.ndarray | None) -> None:
    """Give the white discrepancy the joint-angle errors its residuals show, when the restricted likelihood supports
    them and they predict left-out poses not clearly worse (:mod:`pin_kpi_oed.discrepancy.joint_angle`): its white
    level becomes that fit's σ_n and its decision says so."""
    if F is None or Jq is None:
        return
    from pin_kpi_oed.discrepancy.joint_angle import fit_joint_angle
    groups, _ = grouped_folds(Q, len(Q), 0, periodic)
    got = fit_joint_angle(Q, R, Jq, F, floor_m, float(white.cv.get("small_sample_factor", 1.0)),
                          white.noise_var_m2, groups)
    if got is None:
        white.decision += "; joint-angle errors predict left-out poses no better than the white level"
        return
    term, stat = got
    white.joint_term = term
    white.scale_m = np.full(3, np.sqrt(term.noise_var_m2))
    white.noise = 1.0
    white.cv.update({"joint_angle_tau_rad": float(np.sqrt(term.tau2)),
                     "joint_angle_length_scale_rad": float(term.length_scale_rad), "joint_angle_loo_gain": float(stat)})
    white.decision = (f"joint-angle errors of {np.sqrt(term.tau2) * 1e6:.1f} urad per joint, length scale "
                      f"{term.length_scale_rad:g} rad (restricted maximum likelihood on the residuals, its test "
                      f"against a white level alone passed; leave-one-pose-out log predictive density {stat:+.1f} "
                      f"against the white level's, not worse by two standard errors) and a "
                      f"white level of {np.sqrt(term.noise_var_m2) * 1e3:.4f} mm per axis, each widened "
                      f"x{white.cv.get('small_sample_factor', 1.0):.3f} for its small-sample uncertainty; every sigma "
                      f"adds the parameter covariance under them, takes back what the fit absorbed and is never "
                      f"below the white level's alone")


def _white(R: np.ndarray, names: list, n_params: int, floor_m: np.ndarray | None,
           coverage: JointCoverage) -> Discrepancy:
    """The white discrepancy of residuals R (:func:`white_level`), its decision's second half."""
    level, k, widen = white_level(R, n_params, floor_m)
    raw = np.sqrt(np.mean(R ** 2, axis=0))
    floored = floor_m is not None and bool(np.any(level <= np.asarray(floor_m, float) * (1 + 1e-12)))
    out = Discrepancy("white", names, level, np.zeros(3), 1.0, coverage=coverage, n_rows=len(R),
                      cv={"dof": k, "n_params": int(n_params), "small_sample_factor": widen})
    out.decision = (f"white level {np.sqrt(np.sum(level ** 2)) * 1e3:.4f} mm (3-D) from the residual RMS "
                    f"{np.sqrt(np.sum(raw ** 2)) * 1e3:.4f} mm: corrected for the {int(n_params)} fitted parameters "
                    f"(3m - p = {k}), widened x{widen:.3f} for its small-sample uncertainty"
                    + (", at least the data's stated noise" if floored else "")
                    + "; every sigma adds the parameter covariance")
    return out
