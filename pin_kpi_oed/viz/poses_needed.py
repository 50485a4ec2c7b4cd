"""The poses-needed figure: predicted TCP σ at the working configurations (discrepancy included) vs number of poses.

:func:`plot_poses_needed` draws the curve of :class:`~pin_kpi_oed.oed.discrepancy_kpi.PosesNeeded` (``design
--target-sigma`` / ``--curve``): the greedy kpi_gp design and random subsets of the same feasible pool (mean ± one
standard deviation), the target and the measured poses' σ when given. Values SI in, µm on the axis.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any
from collections.abc import Mapping

import numpy as np

from pin_kpi_oed.viz.figures import agg_figure, save_png


def plot_poses_needed(curve: Mapping[str, Any], path: str | os.PathLike, title: str = "") -> Path:
    """Write the poses-needed figure (PNG).

    Args:
        curve: :meth:`PosesNeeded.to_dict` (``n``, ``sigma_designed_m``, ``sigma_random_m``, ``sigma_random_sd_m``,
            optional ``target_sigma_m``, ``sigma_now_m``), SI units.
        path: PNG file.
        title: optional title.

    Returns:
        The written path.
    """
    n = np.asarray(curve["n"], float)
    des = np.asarray(curve["sigma_designed_m"], float) * 1e6
    rnd = np.asarray(curve["sigma_random_m"], float) * 1e6
    sd = np.asarray(curve.get("sigma_random_sd_m", np.zeros_like(rnd)), float) * 1e6
    fig = agg_figure(6.0, 4.0)
    ax = fig.add_subplot()
    ax.plot(n, des, "o-", color="#1f77b4", label="designed (kpi_gp, greedy)")
    ax.plot(n, rnd, "s--", color="#7f7f7f", label="random (mean)")
    ax.fill_between(n, np.maximum(rnd - sd, 1e-9), rnd + sd, color="#7f7f7f", alpha=0.2, linewidth=0)
    if curve.get("target_sigma_m"):
        ax.axhline(curve["target_sigma_m"] * 1e6, color="#d62728", lw=1, label="target")
    if curve.get("sigma_now_m") is not None and np.isfinite(curve["sigma_now_m"]):
        ax.axhline(curve["sigma_now_m"] * 1e6, color="#2ca02c", lw=1, ls=":", label="measured poses alone")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("number of poses")
    ax.set_ylabel("predicted TCP σ at the working configurations (µm)")
    ax.set_title(title or "poses needed (model discrepancy included)")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    return save_png(fig, path)
