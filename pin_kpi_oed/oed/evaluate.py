"""Scoring a given measurement design under every criterion (``pin-kpi-oed evaluate``).

Given the set-up (robot, tracker, reflector, noise; see :mod:`pin_kpi_oed.model.serialize`),
measurement configurations ``q_meas`` and working configurations ``q_work``,
compute the identifiable set, C_p, the KPI covariance C_s = E C_p Eᵀ
(eq. 19/24c) and every criterion of :mod:`pin_kpi_oed.oed.criteria`.
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from pin_kpi_oed.data.atomic import atomic_write_json
from pin_kpi_oed.errors import IdentifiabilityError, InputError
from pin_kpi_oed.model.tracker import TrackerModel
from pin_kpi_oed.model.serialize import model_from_dict, model_to_dict
from pin_kpi_oed.oed.covariance import check_covariance, design_covariances, weakest_direction
from pin_kpi_oed.oed.criteria import CRITERIA, evaluate_all
from pin_kpi_oed.oed.held import HeldShare, design_held
from pin_kpi_oed.oed.identifiability import Identifiability, analyse, check_kpi
from pin_kpi_oed.oed.objective import DesignContext
# every criterion of the configurations the package defines is registered, so that a design is scored under each
from pin_kpi_oed.oed.path_kpi import PathKpi  # noqa: F401  (registers kpi_path)
from pin_kpi_oed.oed.pose_kpi import PoseKpi  # noqa: F401  (registers kpi6)
from pin_kpi_oed.oed.path_kpi_gp import PathDiscrepancyKpi  # noqa: F401  (registers kpi_path_gp)
from pin_kpi_oed.oed.pose_kpi_gp import PoseDiscrepancyKpi  # noqa: F401  (registers kpi6_gp)
from pin_kpi_oed.oed.path_kpi_max import PathMaxKpi  # noqa: F401  (registers kpi_path_max)
from pin_kpi_oed.results import Result


@dataclass(kw_only=True)
class DesignScore(Result):
    """Scores of one measurement design (a :class:`~pin_kpi_oed.results.Result`: ``status`` ``scored``).

    Attributes:
        trace_cs_m2: tr(C_s) over all working configurations (m²): the identified parameters' part (eq. 19), what
            the criteria and certificates use.
        tcp_sigma_m: sqrt((tr(C_s) + held_trace_m2)/t): RMS TCP standard deviation per working configuration (m),
            with the joint-placement parameters held at nominal under their tolerance.
        held_trace_m2: tr(G Σ_N Gᵀ) (m²): the held parameters' part, which no measurement of the reflector removes
            (:func:`~pin_kpi_oed.oed.held.design_held`); held: its :class:`~pin_kpi_oed.oed.held.HeldShare`.
        cov_s_m2: C_s (3t × 3t, m², tracker frame).
        trace_cp: tr(C_p) (mixed units m² and rad²).
        criteria: every registered criterion's value (units: :attr:`Criterion.unit`).
        rank: identifiable rank; n_meas: number of measurements.
        identifiable: names of the identifiable parameters.
        setup: the set-up dict (robot, tracker, reflector, noise) when scored from a file, else empty.
        design: what was scored when scored from a file: ``file``, ``criterion`` (the file's ``q_meas_criterion``,
            None for a hand-written file), ``n_meas``, ``n_work``; else empty.
        not_scored: the registered criteria of the configurations this design cannot be scored under, each with
            the reason (``kpi_gp`` without a discrepancy, ``kpi_path`` without working paths).
        singular: the criteria whose information is singular for this design (their value is inf: printed as
            "singular", never as a number), each with the reason and what to change; ``status`` is then
            ``singular`` and ``success`` False.
    """

    trace_cs_m2: float
    tcp_sigma_m: float
    cov_s_m2: np.ndarray
    trace_cp: float
    criteria: dict[str, float]
    rank: int
    n_meas: int
    identifiable: list[str] = field(default_factory=list)
    setup: dict = field(default_factory=dict)
    design: dict = field(default_factory=dict)
    not_scored: dict[str, str] = field(default_factory=dict)
    singular: dict[str, str] = field(default_factory=dict)
    held_trace_m2: float = 0.0
    held: HeldShare = field(default_factory=HeldShare, repr=False)

    def to_dict(self) -> dict:
        """Plain JSON-able dict (SI units): the common result keys, the scores, ``setup`` and ``design`` when known."""
        out = {"setup": self.setup} if self.setup else {}
        out.update({"design": self.design} if self.design else {})
        return {**out, **self.result_dict(), "trace_cs_m2": self.trace_cs_m2, "tcp_sigma_m": self.tcp_sigma_m,
                "cov_s_m2": self.cov_s_m2.tolist(), "trace_cp": self.trace_cp, "criteria": self.criteria,
                "rank": self.rank, "n_meas": self.n_meas, "identifiable": self.identifiable,
                "not_scored": self.not_scored, "singular": self.singular, "held_trace_m2": self.held_trace_m2,
                "held": {"names": self.held.names, "tcp_contribution_m": self.held.contrib_m.tolist()}}

    def summary(self) -> str:
        """The design scored (from a file), every criterion with its unit and label, then tr(C_s) (mm²) and the TCP σ
        (µm)."""
        lines = []
        if self.design:
            d = self.design
            which = f"design '{d['criterion']}' (its q_meas)" if d.get("criterion") else "q_meas"
            lines.append(f"scored {which} of {d['file']}: {d['n_meas']} measurement configurations, KPI at "
                         f"{d['n_work']} working configuration(s)")
        for k, v in self.criteria.items():
            crit = CRITERIA.get(k)
            val = f"{v: .6g}" if np.isfinite(v) or np.isnan(v) else " singular"
            lines.append(f"{k:<7}{val}  [{crit.unit if crit else '?'}] {crit.label if crit else ''}".rstrip())
        lines.extend(f"{k:<7}not scored: {why}" for k, why in self.not_scored.items())
        lines.append(f"tr(C_s) = {self.trace_cs_m2 * 1e6:.6g} mm^2   TCP sigma = {self.tcp_sigma_m * 1e6:.3f} um"
                     + (f" (with the parameters held at nominal: {self.held_trace_m2 * 1e6:.6g} mm^2 more, "
                        f"{100 * self.held_trace_m2 / (self.held_trace_m2 + self.trace_cs_m2):.0f} % of the variance)"
                        if self.held_trace_m2 > 0 else ""))
        line = self.held.line(self.trace_cs_m2, int(round(self.cov_s_m2.shape[0] / 3)))
        if line:
            lines.append(line)
        if self.singular:
            lines.append(f"status: {self.status}: {self.message}")
        return "\n".join(lines)


def score_design(model: TrackerModel, Q_meas: np.ndarray, Q_work: np.ndarray,
                 ident: Identifiability | None = None) -> DesignScore:
    """Score measurement configurations ``Q_meas`` for the KPI at ``Q_work``.

    Args:
        model: the measurement model (nominal parameters; its prior, if any, enters C_p).
        Q_meas: measurement configurations, (m, n) rad.
        Q_work: working configurations, (t, n) rad.
        ident: the identifiability analysis of ``model`` if already at hand (else computed).

    Returns:
        The scores (C_s from :func:`pin_kpi_oed.oed.covariance.design_covariances`, eq. 19).

    Raises:
        InputError: configurations outside the joint limits or not finite.
        IdentifiabilityError: too few or degenerate measurements, or a non-estimable KPI.
    """
    t0 = time.perf_counter()
    Q_meas = model.robot.check_q(Q_meas, "q_meas")
    Q_work = model.robot.check_q(Q_work, "q_work")
    ident = ident or analyse(model)
    p0 = np.zeros(model.n_params)
    E_full = model.kpi_jacobian(p0, Q_work)
    if getattr(model, "n_nests", 1) > 1:  # several nests: the TCP need be estimable with all of them
        from pin_kpi_oed.oed.nests import nests_identifiability

        check_kpi(nests_identifiability(model), model, E_full, "the TCP at q_work")
    else:
        check_kpi(ident, model, E_full, "the TCP at q_work")
    if Q_meas.shape[0] * model.nh < ident.rank:
        raise IdentifiabilityError(f"{Q_meas.shape[0]} measurements give {Q_meas.shape[0] * model.nh} equations "
                                   f"for {ident.rank} identifiable parameters: measure at least "
                                   f"{int(np.ceil(ident.rank / model.nh))} configurations")
    b = ident.base
    E = E_full[:, b]
    C_p, C_s = design_covariances(model, b, Q_meas, E, p0, ident.base_names)
    t = Q_work.shape[0]
    check_covariance(C_s, "C_s at q_work")
    not_scored: dict[str, str] = {}
    singular: dict[str, str] = {}
    crit = evaluate_all(model, b, Q_meas, E, context=DesignContext(model, b, E, p0, Q_work), not_scored=not_scored,
                        singular=singular)
    message = (f"{Q_meas.shape[0]} measurements, {ident.rank} identifiable parameters, "
               f"{t} working configuration(s)")
    if singular:
        F = model.weighted_jacobian(p0, Q_meas)[:, :, b].reshape(-1, b.size)
        message = (f"{', '.join(singular)} singular without the prior: "
                   f"{weakest_direction(F.T @ F, ident.base_names)}; add measurement configurations that tell "
                   "them apart (spread over the joint ranges)")
    held = design_held(model, b, Q_meas, Q_work, p=p0)
    return DesignScore(trace_cs_m2=float(np.trace(C_s)), cov_s_m2=C_s, held_trace_m2=held.trace_m2, held=held,
                       tcp_sigma_m=float(np.sqrt((np.trace(C_s) + held.trace_m2) / t)),
                       trace_cp=float(np.trace(C_p)), criteria=crit, rank=ident.rank, n_meas=Q_meas.shape[0],
                       identifiable=ident.base_names, not_scored=not_scored, singular=singular,
                       success=not singular, status="singular" if singular else "scored", message=message,
                       time_s=time.perf_counter() - t0)


def evaluate_file(path: Path, out: Path | None = None) -> DesignScore:
    """Read a design JSON (set-up + ``q_meas`` + ``q_work``), score it, optionally write the scores.

    Args:
        path: the design JSON (e.g. written by ``pin-kpi-oed design``).
        out: where to write the scores as JSON (``setup`` + :meth:`DesignScore.to_dict`), or None.

    Returns:
        The scores, with ``setup`` filled.

    Raises:
        InputError: unreadable JSON or a missing field (named with the file).
    """
    try:
        d = json.loads(Path(path).read_text())
    except FileNotFoundError:
        raise InputError(f"{path}: no such file") from None
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise InputError(f"{path}: not valid JSON ({exc})") from None
    from pin_kpi_oed.validation.schema import validate_design_dict

    validate_design_dict(d, str(path))
    model = model_from_dict(d, str(path))
    for key in ("q_meas", "q_work"):
        if key not in d:
            raise InputError(f"{path}: missing field '{key}' (list of joint configurations, rad)")
    score = score_design(model, np.asarray(d["q_meas"], float), np.asarray(d["q_work"], float))
    score.setup = model_to_dict(model)
    crit = d.get("q_meas_criterion")
    score.design = {"file": str(path), "criterion": crit if isinstance(crit, str) else None,
                    "n_meas": int(np.shape(d["q_meas"])[0]), "n_work": int(np.shape(d["q_work"])[0])}
    if out is not None:
        atomic_write_json(out, score.to_dict())
    return score
