"""Scoring a given measurement design under every criterion (``pin-kpi-oed evaluate``).

Given the set-up (robot, tracker, reflector, noise; see :mod:`pin_kpi_oed.model.serialize`),
measurement configurations ``q_meas`` and working configurations ``q_work``,
compute the identifiable set, C_p, the KPI covariance C_s = E C_p Eᵀ
(eq. 19/24c) and every criterion of :mod:`pin_kpi_oed.oed.criteria`.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from pin_kpi_oed.oed.covariance import param_covariance
from pin_kpi_oed.oed.criteria import evaluate_all
from pin_kpi_oed.errors import IdentifiabilityError, InputError
from pin_kpi_oed.oed.identifiability import Identifiability, analyse, check_kpi
from pin_kpi_oed.data.atomic import atomic_write_json
from pin_kpi_oed.model.tracker import TrackerModel
from pin_kpi_oed.model.serialize import model_from_dict, model_to_dict


@dataclass
class DesignScore:
    """Scores of one measurement design.

    Attributes:
        trace_cs_m2: tr(C_s) over all working configurations (m²).
        tcp_sigma_m: sqrt(tr(C_s)/t): RMS TCP standard deviation per working configuration (m).
        cov_s_m2: C_s (3t × 3t, m², tracker frame).
        trace_cp: tr(C_p) (mixed units m² and rad²).
        criteria: every criterion value.
        rank: identifiable rank; n_meas: number of measurements.
    """

    trace_cs_m2: float
    tcp_sigma_m: float
    cov_s_m2: np.ndarray
    trace_cp: float
    criteria: dict[str, float]
    rank: int
    n_meas: int
    identifiable: list[str] = field(default_factory=list)

    def to_dict(self) -> dict:
        """Plain JSON-able dict (SI units)."""
        return {"trace_cs_m2": self.trace_cs_m2, "tcp_sigma_m": self.tcp_sigma_m, "cov_s_m2": self.cov_s_m2.tolist(),
                "trace_cp": self.trace_cp, "criteria": self.criteria, "rank": self.rank, "n_meas": self.n_meas,
                "identifiable": self.identifiable}


def score_design(model: TrackerModel, Q_meas: np.ndarray, Q_work: np.ndarray,
                 ident: Identifiability | None = None) -> DesignScore:
    """Score measurement configurations ``Q_meas`` for the KPI at ``Q_work``.

    ``ident``: the identifiability analysis of ``model`` if already at hand (else computed).

    Raises:
        InputError: configurations outside the joint limits or not finite.
        IdentifiabilityError: too few or degenerate measurements, or a non-estimable KPI.
    """
    Q_meas = model.robot.check_q(Q_meas, "q_meas")
    Q_work = model.robot.check_q(Q_work, "q_work")
    ident = ident or analyse(model)
    p0 = np.zeros(model.n_params)
    E_full = model.kpi_jacobian(p0, Q_work)
    check_kpi(ident, model, E_full, "the TCP at q_work")
    if Q_meas.shape[0] * model.nh < ident.rank:
        raise IdentifiabilityError(f"{Q_meas.shape[0]} measurements give {Q_meas.shape[0] * model.nh} equations "
                                   f"for {ident.rank} identifiable parameters: measure at least "
                                   f"{int(np.ceil(ident.rank / model.nh))} configurations")
    b = ident.base
    F = model.weighted_jacobian(p0, Q_meas)[:, :, b].reshape(-1, b.size)
    prior = model.layout.prior_sigma[b]
    prior = prior if np.isfinite(prior).any() else None
    C_p = param_covariance(F, prior, ident.base_names)
    E = E_full[:, b]
    C_s = E @ C_p @ E.T
    t = Q_work.shape[0]
    crit = evaluate_all(model, b, Q_meas, E)
    return DesignScore(float(np.trace(C_s)), float(np.sqrt(np.trace(C_s) / t)), C_s, float(np.trace(C_p)), crit,
                       ident.rank, Q_meas.shape[0], ident.base_names)


def evaluate_file(path: Path, out: Path | None = None) -> dict:
    """Read a design JSON (set-up + ``q_meas`` + ``q_work``), score it, optionally write the scores.

    Raises:
        InputError: unreadable JSON or a missing field (named with the file).
    """
    try:
        d = json.loads(Path(path).read_text())
    except FileNotFoundError:
        raise InputError(f"{path}: no such file") from None
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise InputError(f"{path}: not valid JSON ({exc})") from None
    model = model_from_dict(d, str(path))
    for key in ("q_meas", "q_work"):
        if key not in d:
            raise InputError(f"{path}: missing field '{key}' (list of joint configurations, rad)")
    score = score_design(model, np.asarray(d["q_meas"], float), np.asarray(d["q_work"], float))
    res = {"setup": model_to_dict(model), **score.to_dict()}
    if out is not None:
        atomic_write_json(out, res)
    return res
