"""Figures of a sim-to-real gap diagnosis (drawn from a :class:`~pin_kpi_oed.diagnosis.diagnose.DiagnosisReport`).

The diagnosis returns the data (held-out residuals, regressors, binned associations, effect
scores); this module draws them, so that the diagnosis does not depend on the plotting code:

* ``residuals_vs_<regressor>.png``: the held-out residuals (x, y, z, tracker frame) against each
  of the ``n_top`` most strongly associated regressors, with the bin means;
* ``effects_heldout_rms.png``: the held-out RMS error with each candidate effect, against the
  geometry-only RMS and the noise floor (green = significant).

Every PNG is written atomically (:func:`pin_kpi_oed.viz.figures.save_png`).
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np

from pin_kpi_oed.errors import InputError
from pin_kpi_oed.viz.figures import save_png

__all__ = ["diagnosis_figures"]


def diagnosis_figures(report: Any, folder: str | os.PathLike, n_top: int = 4) -> list[str]:
    """Draw the figures of a diagnosis report into ``folder`` (created if missing).

    Args:
        report: a :class:`~pin_kpi_oed.diagnosis.diagnose.DiagnosisReport` (its ``plot_data``,
            ``where``, ``effects``, ``noise_floor_m``, ``heldout_before``).
        folder: output folder.
        n_top: number of regressors plotted (the strongest associations first).

    Returns:
        The PNG files written.

    Raises:
        InputError: the report carries no plot data (e.g. read back from JSON), or ``folder`` is a file.
    """
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    data = getattr(report, "plot_data", None) or {}
    if "residuals_m" not in data or "regressors" not in data:
        raise InputError("diagnosis figures need the report returned by diagnose() (plot data are not stored in JSON)")
    out = Path(folder)
    if out.exists() and not out.is_dir():
        raise InputError(f"{out}: exists and is not a folder")
    out.mkdir(parents=True, exist_ok=True)
    R, regs = np.asarray(data["residuals_m"], float), data["regressors"]
    floor, before_rms = report.noise_floor_m, report.heldout_before.get("rms_m") or 0.0
    files = []
    unit, f = ("mm", 1e3) if np.sqrt(np.mean(np.sum(R ** 2, 1))) > 1e-3 else ("µm", 1e6)
    for item in report.where["regressors"][:n_top]:
        name = item["name"]
        x = regs[name][0]
        fig, axes = plt.subplots(1, 3, figsize=(12, 3.4), sharey=True)
        for a, ax in enumerate(axes):
            ax.scatter(x, R[:, a] * f, s=4, alpha=0.35, color="tab:blue", lw=0)
            xs = [(b["lo"] + b["hi"]) / 2 for b in item["bins"]]
            ms = [b["mean_residual_m"][a] * f for b in item["bins"]]
            ax.plot(xs, ms, "o-", color="tab:red", lw=1.5, ms=4, label="bin mean")
            ax.axhline(0, color="k", lw=0.6)
            ax.set_xlabel(f"{name} ({regs[name][1]})")
            ax.set_title(f"residual {'xyz'[a]}")
        axes[0].set_ylabel(f"held-out residual ({unit}, tracker frame)")
        axes[0].legend(loc="best", fontsize=8)
        fig.suptitle(f"held-out residuals vs {name}: eta2 = {item['eta2']:.3f}, p = {item['p_value']:.2g}")
        fig.tight_layout()
        path = out / f"residuals_vs_{name}.png"
        save_png(fig, path, dpi=110)
        plt.close(fig)
        files.append(str(path))
    ok = [e for e in report.effects if e.status == "ok"]
    if ok:
        fig, ax = plt.subplots(figsize=(7, 3.6))
        ax.barh([e.name for e in ok], [e.heldout_rms_after_m * f for e in ok],
                color=["tab:green" if e.significant else "tab:gray" for e in ok])
        ax.axvline(before_rms * f, color="tab:red", lw=1.5, label="geometry only")
        ax.axvline(floor * f, color="k", ls="--", lw=1.2, label="noise floor")
        ax.set_xlabel(f"held-out RMS error ({unit}); green = significant")
        ax.invert_yaxis()
        ax.legend(loc="lower right", fontsize=8)
        fig.tight_layout()
        path = out / "effects_heldout_rms.png"
        save_png(fig, path, dpi=110)
        plt.close(fig)
        files.append(str(path))
    return files
