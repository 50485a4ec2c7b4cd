r"""Simulation with a withheld effect: does the discrepancy-aware KPI design give a smaller TRUE TCP error at the
working configurations than the plain KPI design?

One case (:func:`withheld_case`) of a cell's robot: the truth is random geometric errors (tolerances) plus a gear
harmonic the model never names (orders 2 and 3 of some joints, amplitude ``a`` rad per component, random phases),
measured by a tracker with σ per axis. A fixed pool of feasible candidate poses is measured once (every design's
data are rows of the same noisy measurements: the comparison is paired). Per number of poses m:

* ``kpi_gp``: the discrepancy-aware KPI (:func:`~pin_kpi_oed.oed.discrepancy_pool.select_pool_gp`, greedy + one
  exchange pass) with the discrepancy's hyper-parameters fitted on a separate *pilot* set of the same robot
  (``identify(..., discrepancy="auto")``, a user's default, on random feasible poses that are not in the pool: a
  white discrepancy when the process does not pay on the pilot, and the criterion is then the noise-only KPI);
* ``kpi_gp_default``: the same criterion with the generic default discrepancy (nothing measured before; the UR10's
  class default of :mod:`~pin_kpi_oed.oed.discrepancy_defaults` differs by its scale only, which multiplies every
  tr C_s by the same factor and leaves the selection unchanged);
* ``kpi``: the paper's KPI (noise only), pool selection (:func:`~pin_kpi_oed.oed.pool.select`);
* ``random``: the first m of a seeded permutation of the pool.

Every chosen set is calibrated the same way (:func:`~pin_kpi_oed.studies.learning_curves.calibrate_fixed`):
geometry and set-up by least squares, then the discrepancy's posterior mean conditioned on the m residuals with
the pilot's hyper-parameters. The score is the true TCP error at the working configurations: the calibrated
model's TCP (geometry + the discrepancy's mean, tracker frame) against the simulated robot's (true geometry with
the harmonic), RMS of the 3-D errors over the working configurations.
"""

from __future__ import annotations

import dataclasses
import time
from typing import Any
from collections.abc import Sequence

import numpy as np

from pin_kpi_oed.errors import IdentifiabilityError, InputError

__all__ = ["HARMONIC_JOINTS", "HARMONIC_ORDERS", "DESIGNS", "working_region", "withheld_truth", "predicted_tcp",
           "true_tcp", "withheld_case", "paired_summary"]

#: Joints and orders of the withheld gear harmonic.
HARMONIC_JOINTS = ("shoulder_lift_joint", "elbow_joint", "wrist_1_joint")
HARMONIC_ORDERS = (2, 3)
#: Design methods of a case.
DESIGNS = ("kpi_gp", "kpi_gp_default", "kpi", "random")


def working_region(q_work: np.ndarray, per_point: int, radius_rad: float, seed: int) -> np.ndarray:
    """The working configurations plus ``per_point`` seeded perturbations of each (uniform ±``radius_rad`` on every
    joint): the configurations where the TCP accuracy is scored and designed for, (t, n) rad."""
    W = np.atleast_2d(np.asarray(q_work, float))
    rng = np.random.default_rng(seed)
    extra = [w + rng.uniform(-radius_rad, radius_rad, (per_point, W.shape[1])) for w in W] if per_point else []
    return np.vstack([W] + extra)


def withheld_truth(model: Any, amplitude_rad: float, seed: int, joints: Sequence[str] = HARMONIC_JOINTS,
                   orders: Sequence[int] = HARMONIC_ORDERS) -> tuple[np.ndarray, list]:
    """(true raw parameters, [(gear harmonic, θ)]) of one simulated robot: geometric errors (0.5 mm / 1 mrad per
    identifiable joint-placement and set-up component) and a gear harmonic of amplitude ``amplitude_rad`` per (joint,
    order) component with
    seeded random phases (the same phases for every amplitude of a seed)."""
    from pin_kpi_oed.effects.library import GearHarmonic
    from pin_kpi_oed.simulation.simulator import Tolerances, random_truth

    if not (np.isfinite(amplitude_rad) and amplitude_rad >= 0):
        raise InputError(f"withheld effect: amplitude must be >= 0 rad, got {amplitude_rad}")
    from pin_kpi_oed.oed.identifiability import analyse

    # the identifiable parameters only: the tracker sees the reflector, not the TCP, so an error of the flange that
    # the reflector offset absorbs would be an error at the TCP no design and no calibration can see
    p = random_truth(model, Tolerances(5e-4, 1e-3), seed=seed, only=analyse(model).base)
    gh = GearHarmonic(model.robot, joints=list(joints), orders=tuple(orders))
    phase = np.random.default_rng([seed, 1]).uniform(0.0, 2.0 * np.pi, len(gh.param_names()) // 2)
    theta = amplitude_rad * np.ravel(np.column_stack([np.cos(phase), np.sin(phase)]))
    return p, [(gh, theta)]


def true_tcp(model: Any, p: np.ndarray, effects: list, Q: np.ndarray) -> np.ndarray:
    """True TCP positions (tracker frame, m) of the simulated robot at Q (joint-angle effects applied)."""
    from pin_kpi_oed.effects.compose import sum_joint_offsets

    Q = np.atleast_2d(np.asarray(Q, float))
    dQ, _ = sum_joint_offsets(effects, Q)
    return model.kpi(p, Q + dQ)


def predicted_tcp(cm: Any, Q: np.ndarray, tcp_m: np.ndarray | None = None, station: str | None = None) -> np.ndarray:
    """TCP positions (tracker frame of ``station``, m) a calibrated model predicts at Q: its geometry (effects
    included) at the TCP ``tcp_m`` (default the model's) plus the discrepancy's mean."""
    from pin_kpi_oed.effects.compose import sum_joint_offsets

    Q = np.atleast_2d(np.asarray(Q, float))
    model, p = cm.station_model(station)
    if tcp_m is not None:
        model = dataclasses.replace(model, tcp_m=np.asarray(tcp_m, float))
    dQ, _ = sum_joint_offsets(list(zip(cm.effects, cm.thetas)), Q)
    Y = model.kpi(p, Q + dQ)
    if cm.discrepancy is not None:
        R = np.asarray(cm.setups[cm.station(station)].tracker_T_base, float)[:3, :3]
        Y = Y + cm.discrepancy.predict(Q, return_var=False)[0] @ R.T
    return Y


def withheld_case(model: Any, Q_pool: np.ndarray, Q_pilot: np.ndarray, W: np.ndarray, amplitude_rad: float,
                  seed: int, sizes: Sequence[int] = (20, 60), noise_m: float = 1e-5,
                  fixed: dict | None = None, pilot_discrepancy: str = "auto") -> dict:
    """One simulated robot and amplitude: every design of :data:`DESIGNS` and size, calibrated the same way, scored
    by the true TCP error at ``W`` (see the module docstring).

    Args:
        model: the nominal measurement model (the cell's: tracker pose, reflector, TCP); its noise is replaced by
            ``noise_m`` per axis.
        Q_pool: the fixed candidate pool (N, n) rad; Q_pilot: the pilot poses (not in the pool) (k, n) rad.
        W: working configurations (t, n) rad.
        amplitude_rad: the withheld harmonic's amplitude per component (rad).
        seed: the simulated robot (geometry, phases) and its measurement noise.
        sizes: numbers of poses.
        fixed: selections that do not depend on the robot, ``{(design, m): pool indices}``, reused when given
            (``kpi_gp_default``, ``kpi``); computed and stored into it otherwise.
        pilot_discrepancy: ``discrepancy=`` of the pilot's identification: ``auto`` (what ``identify`` and
            ``diagnose --model-out`` do for a user: a white discrepancy when the Gaussian process does not lower the
            pilot's K-fold error, and ``kpi_gp`` is then the noise-only KPI) or ``on`` (always fitted).

    Returns:
        ``{"seed", "amplitude_rad", "pilot": {...}, "error_m": {design: [per size]}, "error_geo_m": ...,
        "predicted_sigma_m": ..., "time_s"}`` (plain numbers, m).

    Raises:
        InputError: a size larger than the pool.
    """
    from pin_kpi_oed.identification.identify import identify
    from pin_kpi_oed.simulation.simulator import simulate
    from pin_kpi_oed.model.noise import NoiseModel
    from pin_kpi_oed.discrepancy.prior import DiscrepancyPrior
    from pin_kpi_oed.oed.discrepancy_kpi import DiscrepancyDesignCriterion
    from pin_kpi_oed.oed.identifiability import analyse
    from pin_kpi_oed.studies.learning_curves import calibrate_fixed

    t0 = time.perf_counter()
    if max(sizes) > len(Q_pool):
        raise InputError(f"withheld case: {max(sizes)} poses from a pool of {len(Q_pool)}")
    model = dataclasses.replace(model, noise=NoiseModel(sigma_xyz_m=(noise_m,) * 3))
    p_true, effects = withheld_truth(model, amplitude_rad, seed)
    data = simulate(model, Q_pool, p_true, effects=effects, seed=seed + 1)
    pilot = simulate(model, Q_pilot, p_true, effects=effects, seed=seed + 2)
    pfit = identify(model, pilot, discrepancy=pilot_discrepancy, seed=seed, raise_on_failure=False)
    prior = DiscrepancyPrior.from_discrepancy(pfit.discrepancy, f"pilot: {len(Q_pilot)} random poses of this robot")
    base = analyse(model).base
    p0 = np.zeros(model.n_params)
    crit = DiscrepancyDesignCriterion(model, base, prior, W, p=p0)
    Jp = crit.pool_jacobians(Q_pool)
    fixed = {} if fixed is None else fixed
    t = len(W)
    truth_W = true_tcp(model, p_true, effects, W)
    out: dict = {"seed": seed, "amplitude_rad": amplitude_rad, "sizes": list(sizes),
                 "pilot": {"rows": len(Q_pilot), "kind": pfit.discrepancy.kind,
                           "delta_sigma_m": prior.delta_sigma_m.tolist(),
                           "white_sigma_m": (prior.scale_m * np.sqrt(prior.noise)).tolist()},
                 "error_m": {d: [] for d in DESIGNS}, "error_geo_m": {d: [] for d in DESIGNS},
                 "predicted_sigma_m": {d: [] for d in DESIGNS}}
    for m in sizes:
        for d in DESIGNS:
            idx = _choose(d, m, model, crit, Q_pool, Jp, W, base, seed, fixed)
            cm, plain = calibrate_fixed(model, data.subset(idx), prior)
            e = np.linalg.norm(predicted_tcp(cm, W) - truth_W, axis=1)
            e0 = np.linalg.norm(predicted_tcp(plain, W) - truth_W, axis=1)
            out["error_m"][d].append(float(np.sqrt(np.mean(e ** 2))))
            out["error_geo_m"][d].append(float(np.sqrt(np.mean(e0 ** 2))))
            try:
                out["predicted_sigma_m"][d].append(float(np.sqrt(crit.value(Q_pool[idx]) / t)))
            except IdentifiabilityError:  # a set that does not identify the parameters under the discrepancy
                out["predicted_sigma_m"][d].append(float("nan"))
    out["time_s"] = time.perf_counter() - t0
    return out


def _choose(d: str, m: int, model: Any, crit: Any, Q_pool: np.ndarray, Jp: np.ndarray, W: np.ndarray,
            base: np.ndarray, seed: int, fixed: dict) -> np.ndarray:
    """Pool indices of design ``d`` of ``m`` poses (selections that do not depend on the robot kept in ``fixed``)."""
    from pin_kpi_oed.oed.objective import information_criterion
    from pin_kpi_oed.oed.discrepancy_defaults import default_discrepancy
    from pin_kpi_oed.oed.discrepancy_kpi import DiscrepancyDesignCriterion
    from pin_kpi_oed.oed.pool import select

    p0 = np.zeros(model.n_params)
    if d == "kpi_gp":
        return np.asarray(crit.select(Q_pool, m, J_pool=Jp, exchange_passes=1).indices, int)
    if d == "random":  # per robot: a seeded permutation of the pool, nested sizes
        return np.random.default_rng([seed, 7]).permutation(len(Q_pool))[:m]
    if (d, m) not in fixed:
        if d == "kpi_gp_default":
            c0 = DiscrepancyDesignCriterion(model, base, default_discrepancy(model.robot.nq), W, p=p0)
            idx = c0.select(Q_pool, m, J_pool=Jp, exchange_passes=1).indices
        else:  # kpi
            E = model.kpi_jacobian(p0, W)[:, base]
            Fp = model.weighted_jacobian(p0, Q_pool)[:, :, base]
            idx = select(Fp, m, information_criterion("kpi").pool_form(E, base.size), seed=0).indices
        fixed[(d, m)] = np.asarray(idx, int)
    return np.asarray(fixed[(d, m)], int)


def paired_summary(a: Sequence[float], b: Sequence[float]) -> dict:
    """Paired comparison of a against b (smaller is better): :func:`~pin_kpi_oed.studies.paired.paired_comparison`
    with the older keys beside its own (``mean_a_m``, ``mean_b_m``, ``median_ratio``, ``p`` = the Wilcoxon p)."""
    from pin_kpi_oed.studies.paired import paired_comparison

    c = paired_comparison(a, b)
    return {**c, "mean_a_m": c["mean_a"], "mean_b_m": c["mean_b"], "median_ratio": c["change_median"] + 1.0,
            "p": c["p_wilcoxon"]}
