"""The compensation CSV: the compensated joints a controller receives (rad / m), with the nominal joints, the
correction, the residuals, the predicted TCP σ and the status of every target (SI units)."""

from __future__ import annotations

import csv
import io
import os
from typing import TYPE_CHECKING

from pin_kpi_oed.data.atomic import atomic_write_text

if TYPE_CHECKING:
    from pin_kpi_oed.identification.compensate import CompensationResult

__all__ = ["write_compensation"]


def write_compensation(path: str | os.PathLike, res: CompensationResult) -> None:
    """Write the compensated joints as CSV, atomically (SI units).

    Columns: ``name``, the joint columns (compensated, rad / m: send these), ``<joint>_nominal``,
    ``correction_m``, ``residual_m``, ``residual_rad``, ``inv_cond``, ``sigma_m`` (predicted 3-D TCP σ, m),
    ``start`` (where the branch came from), ``branch_step_rad`` (largest joint change from the nominal solution),
    ``extrapolation`` (1: outside the calibration's joint-space coverage), ``status``; a 6-D model adds
    ``sigma_rot_rad`` (the tool orientation's 3-D σ, rad) and ``sigma_at_length_m`` (the σ it causes at the tool
    length, m); a program adds ``correction_jump_rad`` (the correction's change from the previous row, rad / m).
    """
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(["name"] + res.joint_names + [f"{j}_nominal" for j in res.joint_names]
               + ["correction_m", "residual_m", "residual_rad", "inv_cond", "sigma_m", "start", "branch_step_rad",
                  "extrapolation", "status"]
               + (["sigma_rot_rad", "sigma_at_length_m"] if res.sigma_rot_rad.size else [])
               + (["correction_jump_rad"] if res.correction_jump_rad.size else []))
    for i, n in enumerate(res.names):
        w.writerow([n] + [repr(float(v)) for v in res.q[i]] + [repr(float(v)) for v in res.q_nominal[i]]
                   + [repr(float(res.correction_m[i])), repr(float(res.residual_m[i])),
                      repr(float(res.residual_rad[i])), repr(float(res.inv_cond[i])),
                      repr(float(res.sigma_m[i])) if res.sigma_m.size else "",
                      res.start[i] if res.start else "",
                      repr(float(res.branch_step_rad[i])) if res.branch_step_rad.size else "",
                      str(int(res.extrapolation[i])) if res.extrapolation.size else "", res.target_status[i]]
                   + ([repr(float(res.sigma_rot_rad[i])), repr(float(res.sigma_at_length_m[i]))]
                      if res.sigma_rot_rad.size else [])
                   + ([repr(float(res.correction_jump_rad[i]))] if res.correction_jump_rad.size else []))
    atomic_write_text(path, buf.getvalue())
