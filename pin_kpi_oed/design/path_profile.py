r"""The TCP's predicted σ along the working paths and the tool's orientation σ, for every design of a run.

For a design Q with the noise-only parameter covariance C_p = (F(Q)ᵀF(Q) + P)⁻¹ (eq. 19) and the sensitivities
E_i (position, m) and R_i (tool orientation, rad) at path sample i::

    σ_pos,i = sqrt(tr(E_i C_p E_iᵀ))  (m),    σ_rot,i = sqrt(tr(R_i C_p R_iᵀ))  (rad),
    σ_L,i   = sqrt(σ_pos,i² + L² σ_rot,i²)  (m: position and orientation at the cell's ``orientation_length_m``)

the profile along the path (``path_profiles`` of the design file), its RMS over the samples and its worst sample
(the design table's path lines). ``kpi_path`` minimises the mean of σ_pos,i² along the path, ``kpi_path_max`` its
smooth worst sample; ``kpi6`` the mean of σ_L,i² at the working configurations.

With the discrepancy (a design run whose criteria or ``--model`` bring one) the profile also holds the TCP's σ with
it, σ_gp,i = sqrt(tr C_s,i^UK): the universal-kriging C_s of ``kpi_path_gp`` at the path samples
(:meth:`~pin_kpi_oed.oed.discrepancy_kpi.DiscrepancyDesignCriterion.covariance`, its 3×3 diagonal block i): what the
noise-only σ leaves out along the path. The discrepancy is a position term: the orientation σ stays the noise-only one.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from pin_kpi_oed.errors import IdentifiabilityError
from pin_kpi_oed.oed.covariance import information

__all__ = ["path_profile", "discrepancy_profile", "path_profiles", "profile_lines"]


def path_profile(problem: Any, Q: np.ndarray, Q_samples: np.ndarray, length_m: float) -> dict:
    """σ_pos, σ_rot and σ_L (module docstring) at the configurations ``Q_samples`` for the design Q.

    Args:
        problem: a design problem (model, p0, base, the layout's prior).
        Q: the design's configurations (m, n) rad.
        Q_samples: the path's samples (S, n) rad.
        length_m: the orientation's lever L (m).

    Returns:
        ``sigma_pos_m``, ``sigma_rot_rad``, ``sigma_at_length_m`` (lists, per sample), their ``rms_*`` (the root
        of the mean of the squares: ``rms_sigma_pos_m``² is ``kpi_path``) and ``worst_*`` (largest sample).

    Raises:
        IdentifiabilityError: Q does not identify the parameters.
    """
    model, base = problem.model, problem.base
    F = model.weighted_jacobian(problem.p0, np.atleast_2d(Q))[:, :, base].reshape(-1, base.size)
    try:
        C = np.linalg.inv(information(F, problem.kpi_criterion.prior))
    except np.linalg.LinAlgError:
        raise IdentifiabilityError("the design does not identify the parameters (singular information)") from None
    S = len(Q_samples)
    E = model.kpi_jacobian(problem.p0, Q_samples)[:, base].reshape(S, 3, -1)
    R = model.kpi_rotation_jacobian(problem.p0, Q_samples)[:, base].reshape(S, 3, -1)
    pos = np.sqrt(np.maximum(np.einsum("sap,pq,saq->s", E, C, E), 0.0))
    rot = np.sqrt(np.maximum(np.einsum("sap,pq,saq->s", R, C, R), 0.0))
    at_l = np.sqrt(pos ** 2 + length_m ** 2 * rot ** 2)
    out: dict = {"length_m": float(length_m)}
    for key, v in (("sigma_pos_m", pos), ("sigma_rot_rad", rot), ("sigma_at_length_m", at_l)):
        out[key] = v.tolist()
        out[f"rms_{key}"], out[f"worst_{key}"] = float(np.sqrt(np.mean(v ** 2))), float(v.max())
    return out


def discrepancy_profile(problem: Any, Q: np.ndarray, Q_samples: np.ndarray) -> dict:
    """σ_gp per path sample (module docstring) for the design Q: ``sigma_pos_gp_m`` (list, m), its ``rms_`` and
    ``worst_``.

    Raises:
        IdentifiabilityError: Q does not identify the parameters.
    """
    C = problem.gp_criterion(Q_work=Q_samples).covariance(Q)
    S = len(Q_samples)
    i = np.arange(S)
    blocks = C.reshape(S, 3, S, 3)[i, :, i, :]  # (S, 3, 3): the 3×3 diagonal block of every sample
    v = np.sqrt(np.maximum(np.einsum("saa->s", blocks), 0.0))
    return {"sigma_pos_gp_m": v.tolist(), "rms_sigma_pos_gp_m": float(np.sqrt(np.mean(v ** 2))),
            "worst_sigma_pos_gp_m": float(v.max())}


def path_profiles(problem: Any, results: Sequence[Any], discrepancy: bool = False) -> list[dict] | None:
    """The profile of every working path of the problem's cell for every design with poses (None without paths).

    Args:
        problem: the design problem (its cell's paths).
        results: the designs.
        discrepancy: also the σ with the problem's discrepancy (:func:`discrepancy_profile`).

    Returns:
        One entry per design: ``criterion`` and ``paths`` (per path: ``name``, ``s_m``, :func:`path_profile` and
        with ``discrepancy`` :func:`discrepancy_profile`).
    """
    cell = problem.cell
    if not getattr(cell, "paths", None):
        return None
    out = []
    for r in results:
        if r.q_meas is None or len(r.q_meas) == 0:
            continue
        entry: dict = {"criterion": r.criterion, "paths": []}
        for p in cell.paths:
            try:
                prof = path_profile(problem, r.q_meas, p.Q, cell.orientation_length_m)
                if discrepancy:
                    prof.update(discrepancy_profile(problem, r.q_meas, p.Q))
            except IdentifiabilityError:
                continue
            entry["paths"].append({"name": p.name, "s_m": p.s_m.tolist(), **prof})
        out.append(entry)
    return out


def profile_lines(profiles: Sequence[dict] | None) -> list[str]:
    """The design table's path lines: per design and path, σ_pos (µm) and σ_rot (µrad) as RMS and worst sample."""
    lines = []
    for e in profiles or []:
        for p in e["paths"]:
            lines.append(f"  {e['criterion']:>12} path {p['name']}: TCP sigma RMS {p['rms_sigma_pos_m'] * 1e6:.3f} um,"
                         f" worst {p['worst_sigma_pos_m'] * 1e6:.3f} um; orientation RMS "
                         f"{p['rms_sigma_rot_rad'] * 1e6:.3f} urad, worst {p['worst_sigma_rot_rad'] * 1e6:.3f} urad; "
                         f"at {p['length_m'] * 1e3:g} mm RMS {p['rms_sigma_at_length_m'] * 1e6:.3f} um"
                         + (f"; with the discrepancy TCP sigma RMS {p['rms_sigma_pos_gp_m'] * 1e6:.3f} um, worst "
                            f"{p['worst_sigma_pos_gp_m'] * 1e6:.3f} um" if "rms_sigma_pos_gp_m" in p else ""))
    return lines
