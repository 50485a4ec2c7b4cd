"""Step 3 of :func:`~pin_kpi_oed.identification.identify.identify`: the identifiable parameters and the data checks.

The structural identifiable set of one station (:func:`pin_kpi_oed.oed.identifiability.analyse` on a
seeded random excitation, cached) lifted to every station; the residual model over it; then the
checks on the stacked Jacobian: enough equations, every station determines its own set-up and adds
robot information, every unknown determined by the data of all stations together.
"""

from __future__ import annotations

import copy
from typing import Any
from collections.abc import Sequence

import numpy as np

from pin_kpi_oed.data.measurements import MeasurementSet
from pin_kpi_oed.errors import IdentifiabilityError
from pin_kpi_oed.identification.fit_inputs import FitInputs
from pin_kpi_oed.identification.identify_options import IdentifyOptions
from pin_kpi_oed.identification.problem import ResidualModel, StationSet
from pin_kpi_oed.model.tracker import TrackerModel
from pin_kpi_oed.oed.identifiability import Identifiability, analyse

__all__ = ["N_EXCITATION", "identifiable_set", "build_problem", "structural_identifiability"]

#: Number of seeded random configurations of the structural identifiability analysis.
N_EXCITATION = 60

#: Structural analyses by robot geometry and set-up (at most 65 kept).
IDENT_CACHE: dict[tuple, Identifiability] = {}


def structural_identifiability(model: TrackerModel, seed: int, nests: Sequence[int] = (0,)) -> Identifiability:
    """:func:`analyse` on a seeded random excitation, cached per robot geometry and set-up.

    Args:
        model: the measurement model; seed: the excitation's seed;
        nests: the reflector nests measured (each at every excitation configuration; :mod:`~pin_kpi_oed.model.nests`).

    Returns:
        The :class:`~pin_kpi_oed.oed.identifiability.Identifiability` (a copy).
    """
    rb = model.robot
    nests = sorted({int(i) for i in nests}) or [0]
    key = (rb.urdf_path, rb.tool_frame, tuple(rb.joint_names),
           np.array([rb.model.jointPlacements[j].homogeneous for j in rb.joint_ids]).round(12).tobytes(),
           model.reflector_m.round(12).tobytes(), bool(model.pose6d), model.layout.fixed.tobytes(),
           repr(model.noise.to_dict()), seed, model.nests_m[nests].round(12).tobytes())
    hit = IDENT_CACHE.get(key)
    if hit is None:
        Qx = rb.random_q(np.random.default_rng(seed), N_EXCITATION)
        if nests == [0]:
            hit = analyse(model, Q=Qx)
        else:
            hit = analyse(model.at_nests(np.repeat(nests, len(Qx))), Q=np.tile(Qx, (len(nests), 1)))
        if len(IDENT_CACHE) > 64:
            IDENT_CACHE.clear()
        IDENT_CACHE[key] = hit
    return copy.deepcopy(hit)  # callers may keep or modify their copy


def identifiable_set(stations: StationSet, opts: IdentifyOptions, nests: Sequence[int] = (0,)) -> Identifiability:
    """Step 3a: the structural identifiable set of one station (at the reflector ``nests`` the data measure),
    lifted to every station."""
    ident = (opts.ident if opts.ident is not None
             else structural_identifiability(stations.models[0], opts.seed, nests))
    return stations.layout.lift(ident)


def _rank(A: np.ndarray, tol: float = 1e-8) -> int:
    if A.size == 0:
        return 0
    s = np.linalg.svd(A, compute_uv=False)
    return int(np.sum(s > tol * max(s[0], 1e-300)))


def check_stations(prob: ResidualModel, J: np.ndarray, src: str) -> None:
    """Step 3b (several stations): each station's rows determine its own set-up and add robot information.

    J is the weighted Jacobian (m, nh, nx) at the start; columns are scaled to unit norm over
    all rows. Station s's own columns are its tracker pose (and own reflector/probe); the
    others (robot, effects, shared reflector) are common to all stations.

    Raises:
        IdentifiabilityError: a station whose rows do not determine its set-up, or whose rows carry
            no information beyond its own set-up (no common robot information).
    """
    lay = prob.layout
    if lay.n_stations < 2:
        return
    norms = np.linalg.norm(J.reshape(-1, prob.nx), axis=0)
    Js = J / np.where(norms > 0, norms, 1.0)
    owner = np.full(prob.nx, -1)
    owner[:prob.nb] = lay.owner[prob.base]
    for s, (lab, rows) in enumerate(zip(lay.labels, prob.rows)):
        A = Js[rows].reshape(-1, prob.nx)
        own = A[:, owner == s]
        r_own = _rank(own)
        if r_own < own.shape[1]:
            raise IdentifiabilityError(
                f"{src}: station '{lab}': its {rows.size} rows do not determine its own set-up ({own.shape[1]} "
                f"parameters: tracker pose{', reflector' if lay.reflector_per_station else ''}); measure it at more "
                "configurations spread over the workspace")
        gain = _rank(A) - r_own
        if gain == 0:
            raise IdentifiabilityError(
                f"{src}: station '{lab}': its {rows.size} rows determine no more than its own set-up ({own.shape[1]} "
                f"parameters) and carry no information on the robot common to the stations; measure more rows "
                "there or leave the station out")


def data_rank_check(F: np.ndarray, names: list[str], m: int, nh: int) -> None:
    """Step 3c: raise if the data (of all stations together) do not determine every unknown (pivoted QR)."""
    import scipy.linalg as sla

    norms = np.linalg.norm(F, axis=0)
    if np.any(norms == 0):
        k = int(np.flatnonzero(norms == 0)[0])
        raise IdentifiabilityError(f"the measurements do not move '{names[k]}': add configurations that do, "
                                   "or fix it as known")
    _, R, piv = sla.qr(F / norms, mode="economic", pivoting=True)
    d = np.abs(np.diag(R))
    bad = np.flatnonzero(d < 1e-8 * d[0])
    if bad.size:
        who = names[piv[bad[0]]]
        raise IdentifiabilityError(f"the {m} measurements do not determine '{who}' (and {bad.size - 1} more "
                                   f"direction(s)); the configurations are too similar: spread them over the "
                                   f"joint ranges, or fix the parameter as known")


def effect_prior(effects: Sequence[Any], prior_rad: float | None, robot: Any) -> np.ndarray | None:
    """σ per effect parameter: an effect's own ``prior_rad`` attribute (a SubsetEffect: its base's), else
    ``effect_prior_rad`` on the rad-valued effects; inf (no prior) elsewhere."""
    sig, any_prior = [], prior_rad is not None
    for e in effects:
        own = getattr(e, "prior_rad", None)
        if own is None:
            own = getattr(getattr(e, "base", None), "prior_rad", None)
        if own is not None:
            any_prior = True
        s = own if own is not None else (prior_rad if getattr(e, "unit", "") == "rad" else None)
        sig.append(np.full(len(e.param_names(robot)), np.inf if s is None else float(s)))
    if not any_prior:
        return None
    return np.concatenate(sig) if sig else np.zeros(0)


def build_problem(stations: StationSet, data: MeasurementSet, inp: FitInputs, effects: Sequence[Any], P: np.ndarray,
             ident: Identifiability, opts: IdentifyOptions | None = None) -> ResidualModel:
    """Step 3: the residual model over the identifiable parameters, with every data check."""
    opts = opts or IdentifyOptions()
    prob = ResidualModel(stations, data, np.asarray(ident.base, int), effects, sigma=inp.sigma, p_ref=P, Q=inp.Q,
                         held=opts.held_effects,
                         effect_prior_sigma=effect_prior(effects, opts.effect_prior_rad, stations.robot),
                         theta0=opts.theta0)
    n_eq = prob.m * prob.nh
    if n_eq < prob.nx:
        raise IdentifiabilityError(
            f"{inp.src}: {prob.m} measurements give {n_eq} equations for {prob.nx} identifiable parameters "
            f"({prob.nb} geometric/set-up{f' + {prob.k} effect' if prob.k else ''}); measure at least "
            f"{int(np.ceil(prob.nx / prob.nh))} configurations (better 2–3× as many)")
    J0 = prob.jacobian_full(prob.x0())
    check_stations(prob, J0, inp.src)
    Jr = J0.reshape(-1, prob.nx)
    eff_prior = prob.prior_idx[prob.prior_idx >= prob.nb]  # an effect prior determines its parameter
    if eff_prior.size:
        Pm = np.zeros((eff_prior.size, prob.nx))
        Pm[np.arange(eff_prior.size), eff_prior] = 1.0 / prob.prior_sigma[prob.prior_idx >= prob.nb]
        Jr = np.vstack([Jr, Pm])
    data_rank_check(Jr, prob.names, prob.m, prob.nh)
    return prob
