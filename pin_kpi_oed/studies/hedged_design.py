r"""Does the hedged ``kpi_gp`` design hold when the assumed discrepancy is wrong? Simulated robots and measured series.

The design assumes a discrepancy it has not measured (the robot class's default, or one fitted on another robot or
series). Per case, m poses are chosen from a pool by

* ``kpi_gp``: the discrepancy-aware KPI under the assumed prior alone
  (:func:`~pin_kpi_oed.oed.discrepancy_pool.select_pool_gp`, greedy + one exchange pass);
* ``kpi_gp_hedged``: the same criterion hedged over a family of priors around the assumed one
  (:class:`~pin_kpi_oed.oed.hedged_kpi.HedgedDesignCriterion`, what ``design`` uses without a fitted discrepancy);
* ``kpi``: the paper's noise-only KPI (:func:`~pin_kpi_oed.oed.pool.select`);
* ``random``: the first m of a seeded permutation of the pool;

and every chosen set is calibrated the same way (:func:`~pin_kpi_oed.studies.learning_curves.calibrate_fixed`:
geometry and set-up by least squares, then the discrepancy's posterior mean with the assumed prior's
hyper-parameters). The score is the RMS 3-D TCP error at the working configurations, with the discrepancy's mean
(``error_m``) and of the geometry alone (``error_geo_m``).

* :func:`simulated_case`: a simulated robot whose discrepancy is *not* the assumed one: random geometric errors
  (0.5 mm / 1 mrad on the identifiable parameters) plus δ(q) drawn from a Gaussian process with its own level and
  length scales (:data:`TRUTH_KINDS`: none, short, long, small, large), or a gear harmonic the model never names,
  added to every measured reflector position and to the TCP (the TCP is scored at the reflector: what a reflector
  measurement can see). The working configurations are known, their TCP is the simulated truth.
* :func:`measured_case`: a measured series (real data): seeded working configurations (rows of the series, never
  in the pool) and a pool of other rows; the score is |measured − predicted| at the working configurations.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Sequence
from typing import Any

import numpy as np

from pin_kpi_oed.errors import IdentifiabilityError, InputError

__all__ = ["TRUTH_KINDS", "METHODS", "choose_sets", "gp_discrepancy_sample", "simulated_case", "measured_case"]

#: Design methods compared.
METHODS = ("kpi_gp", "kpi_gp_hedged", "kpi", "random")
#: Kinds of simulated robot: δ per axis (m, GP prior σ) and length scale (rad) of a squared-exponential kernel over
#: the joint angles: ``none`` (geometry only), ``short`` (0.1 mm, 0.3 rad), ``long`` (0.3 mm, 3 rad), ``small``
#: (0.02 mm, 1 rad), ``large`` (1 mm, 1 rad); ``harmonic``: a gear harmonic of 0.3 mrad per component (orders 2 and 3
#: of three joints, :func:`~pin_kpi_oed.studies.kpi_withheld.withheld_truth`; length None).
TRUTH_KINDS: dict[str, tuple[float, float | None]] = {
    "none": (0.0, 1.0),
    "short": (1e-4, 0.3),
    "long": (3e-4, 3.0),
    "small": (2e-5, 1.0),
    "large": (1e-3, 1.0),
    "harmonic": (3e-4, None),
}


def gp_discrepancy_sample(Q: np.ndarray, sigma_m: float, length_rad: float, seed: int) -> np.ndarray:
    """δ(Q) (m, 3) m: one seeded draw of a zero-mean Gaussian process per axis with k(q, q') = σ² exp(−|q ⊖ q'|² /
    (2ℓ²)) over the wrapped joint angles (chordal distance 2 sin(Δ/2) per joint)."""
    Q = np.atleast_2d(np.asarray(Q, float))
    if sigma_m == 0.0:
        return np.zeros((len(Q), 3))
    D = np.sum((2.0 * np.sin(0.5 * (Q[:, None, :] - Q[None, :, :]))) ** 2, axis=2)
    K = sigma_m ** 2 * np.exp(-0.5 * D / length_rad ** 2) + 1e-12 * sigma_m ** 2 * np.eye(len(Q))
    w, V = np.linalg.eigh(K)
    L = V * np.sqrt(np.clip(w, 0.0, None))
    return L @ np.random.default_rng([seed, 11]).standard_normal((len(Q), 3))


def choose_sets(model: Any, assumed: Any, Q_pool: np.ndarray, W: np.ndarray, m: int, seed: int,
                exchange_passes: int = 1, noise_weight: float | None = None) -> dict[str, np.ndarray]:
    """Pool indices of every method of :data:`METHODS` for m poses (they depend on the pool and W, not the robot).

    Args:
        model: the nominal measurement model; assumed: the :class:`DiscrepancyPrior` the design assumes.
        Q_pool: candidates (N, n) rad; W: working configurations (t, n) rad; m: poses; seed: the random set's seed.
        exchange_passes: exchange passes of the hedged selection.
        noise_weight: the hedged criterion's weight on noise only (default: the package's,
            :data:`~pin_kpi_oed.oed.hedged_kpi.NOISE_ONLY_WEIGHT`).
    """
    from pin_kpi_oed.oed.objective import information_criterion
    from pin_kpi_oed.oed.discrepancy_kpi import DiscrepancyDesignCriterion
    from pin_kpi_oed.oed.hedged_kpi import HedgedDesignCriterion
    from pin_kpi_oed.oed.identifiability import analyse
    from pin_kpi_oed.oed.pool import select

    base = analyse(model).base
    p0 = np.zeros(model.n_params)
    crit = DiscrepancyDesignCriterion(model, base, assumed, W, p=p0)
    Jp = crit.pool_jacobians(Q_pool)
    out = {"kpi_gp": np.asarray(crit.select(Q_pool, m, J_pool=Jp, exchange_passes=1).indices, int)}
    hedged = HedgedDesignCriterion.around(crit) if noise_weight is None else \
        HedgedDesignCriterion.around(crit, noise_weight=noise_weight)
    out["kpi_gp_hedged"] = np.asarray(hedged.select(Q_pool, m, J_pool=Jp, exchange_passes=exchange_passes,
                                                    seed=seed).indices, int)
    E = model.kpi_jacobian(p0, W)[:, base]
    Fp = model.weighted_jacobian(p0, Q_pool)[:, :, base]
    out["kpi"] = np.asarray(select(Fp, m, information_criterion("kpi").pool_form(E, base.size), seed=0).indices, int)
    out["random"] = np.random.default_rng([seed, 7]).permutation(len(Q_pool))[:m]
    return out


def _score(model: Any, rows: Any, assumed: Any, W: np.ndarray, truth_W: np.ndarray) -> tuple[float, float]:
    """RMS 3-D TCP error at W of the calibration of ``rows`` (with the discrepancy's mean, geometry alone)."""
    from pin_kpi_oed.studies.kpi_withheld import predicted_tcp
    from pin_kpi_oed.studies.learning_curves import calibrate_fixed

    cm, plain = calibrate_fixed(model, rows, assumed)
    e = np.linalg.norm(predicted_tcp(cm, W) - truth_W, axis=1)
    e0 = np.linalg.norm(predicted_tcp(plain, W) - truth_W, axis=1)
    return float(np.sqrt(np.mean(e ** 2))), float(np.sqrt(np.mean(e0 ** 2)))


def simulated_case(model: Any, Q_pool: np.ndarray, W: np.ndarray, kind: str, seed: int, sets: dict,
                   assumed: Any, noise_m: float = 2e-5) -> dict:
    """One simulated robot of ``kind`` (:data:`TRUTH_KINDS`) measured on the pool; each method's sets scored.

    Args:
        model: the nominal measurement model (its TCP is set to the reflector); Q_pool, W: pool and working
            configurations (rad); kind: a key of :data:`TRUTH_KINDS`; seed: the robot and its noise.
        sets: ``{m: {method: pool indices}}`` (:func:`choose_sets`); assumed: the prior the calibration uses.
        noise_m: tracker noise per axis (m).

    Returns:
        ``{"kind", "seed", "error_m": {method: {m: e}}, "error_geo_m": ...}`` (m).

    Raises:
        InputError: an unknown kind.
    """
    from pin_kpi_oed.simulation.simulator import Tolerances, random_truth, simulate
    from pin_kpi_oed.model.noise import NoiseModel
    from pin_kpi_oed.oed.identifiability import analyse
    from pin_kpi_oed.studies.kpi_withheld import true_tcp, withheld_truth

    if kind not in TRUTH_KINDS:
        raise InputError(f"simulated robot kind '{kind}': unknown (known: {', '.join(TRUTH_KINDS)})")
    model = dataclasses.replace(model, noise=NoiseModel(sigma_xyz_m=(noise_m,) * 3),
                                tcp_m=np.asarray(model.reflector_m, float).copy())
    level, length = TRUTH_KINDS[kind]
    if length is None:
        p_true, effects = withheld_truth(model, level, seed)
        delta = np.zeros((len(Q_pool) + len(W), 3))
    else:
        p_true = random_truth(model, Tolerances(5e-4, 1e-3), seed=seed, only=analyse(model).base)
        effects = []
        delta = gp_discrepancy_sample(np.vstack([Q_pool, W]), level, length, seed)
    R = model.tracker_pose(p_true).rotation
    data = simulate(model, Q_pool, p_true, effects=effects, seed=seed + 1)
    data = dataclasses.replace(data, position_m=data.position_m + delta[:len(Q_pool)] @ R.T)
    truth_W = true_tcp(model, p_true, effects, W) + delta[len(Q_pool):] @ R.T
    out: dict = {"kind": kind, "seed": int(seed), "error_m": {}, "error_geo_m": {}}
    for m, by in sets.items():
        for meth, idx in by.items():
            e, e0 = _score(model, data.subset(np.asarray(idx, int)), assumed, W, truth_W)
            out["error_m"].setdefault(meth, {})[int(m)] = e
            out["error_geo_m"].setdefault(meth, {})[int(m)] = e0
    return out


def measured_case(model: Any, data: Any, assumed: Any, seed: int, sizes: Sequence[int] = (12, 20),
                  pool_size: int = 200, n_work: int = 8, exchange_passes: int = 1,
                  noise_weight: float | None = None) -> dict:
    """One seeded split of a measured series: ``n_work`` rows are the working configurations (scored by their
    measured positions), a pool of ``pool_size`` other rows; every method's sets of each size calibrated and scored.

    Args:
        model: the nominal measurement model (robot, reflector; the tracker pose is registered by the fit).
        data: the series (joint columns, positions); assumed: the prior the design and the calibration assume.
        seed: the split and the random sets; sizes: numbers of poses; pool_size, n_work: rows of each part.
        exchange_passes, noise_weight: of the hedged selection (:func:`choose_sets`).

    Returns:
        ``{"seed", "error_m": {method: {m: e}}, "error_geo_m": ..., "time_s"}`` (m).

    Raises:
        InputError: too few rows for the split.
    """
    from pin_kpi_oed.identification.problem import align_data
    from pin_kpi_oed.studies.learning_curves import calibrate_fixed

    t0 = time.perf_counter()
    if len(data) < pool_size + n_work:
        raise InputError(f"{data.source or 'data'}: {len(data)} rows, the split needs {pool_size + n_work}")
    perm = np.random.default_rng([seed, 3]).permutation(len(data))
    work, pool = perm[:n_work], perm[n_work:n_work + pool_size]
    Q = align_data(model.robot, data)
    Yw = data.position_m[work]
    out: dict = {"seed": int(seed), "error_m": {}, "error_geo_m": {}}
    for m in sizes:
        try:
            sets = choose_sets(model, assumed, Q[pool], Q[work], int(m), seed, exchange_passes, noise_weight)
        except IdentifiabilityError:
            continue
        for meth, idx in sets.items():
            cm, plain = calibrate_fixed(model, data.subset(pool[idx]), assumed)
            for key, mm in (("error_m", cm), ("error_geo_m", plain)):
                Y = mm.predict(Q[work], None, station=mm.station())
                out[key].setdefault(meth, {})[int(m)] = float(np.sqrt(np.mean(np.sum((Y - Yw) ** 2, axis=1))))
    out["time_s"] = time.perf_counter() - t0
    return out
