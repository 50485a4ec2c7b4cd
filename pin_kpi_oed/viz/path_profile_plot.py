"""The σ profile along a cell's working paths: the TCP's position σ and the tool's orientation σ per path sample, one
line per design (the ``path_profiles`` of a design file, :mod:`pin_kpi_oed.design.path_profile`).

Written by ``view DESIGN.json --figures DIR`` for a design file with paths (``<prefix>_path_sigma.png``); display
units: arc length in mm, position σ in µm, orientation σ in µrad (the file holds m and rad).
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from pin_kpi_oed.errors import InputError
from pin_kpi_oed.viz.figures import agg_figure, save_png
from pin_kpi_oed.viz.style import design_colours, hex_colour

__all__ = ["PROFILE_UNITS", "plot_path_profiles"]

#: what the figure shows, in its display units (printed with the file name)
PROFILE_UNITS = ("TCP sigma in um and tool orientation sigma in urad per path sample (with the discrepancy: TCP "
                 "sigma in um), against the arc length in mm")


def plot_path_profiles(profiles: Sequence[Mapping], path: str | os.PathLike, *, title: str | None = None,
                       colours: Mapping[str, str] | None = None) -> Path:
    """Per working path (a row of panels), σ_pos (µm) and σ_rot (µrad) against the arc length (mm), per design; a
    third panel with the TCP σ with the discrepancy (µm) when the profiles hold it.

    Args:
        profiles: the design file's ``path_profiles``: per design ``criterion`` and ``paths`` (``name``, ``s_m``,
            ``sigma_pos_m``, ``sigma_rot_rad``, ``worst_sigma_pos_m``, ``rms_sigma_pos_m``).
        path: PNG to write.
        title: the figure's title.
        colours: per design, a colour (default the viewer's).

    Returns:
        The path written.

    Raises:
        InputError: no design with a path, or a profile whose arrays differ in length or hold negative σ.
    """
    entries = [e for e in profiles if e.get("paths")]
    if not entries:
        raise InputError("no design with a working-path profile to plot (a design file of a cell with working_paths)")
    names = [str(e["criterion"]) for e in entries]
    default = design_colours([n for n in names if not (colours or {}).get(n)])
    col = {n: (colours or {}).get(n) or hex_colour(default[n]) for n in names}
    paths = list(dict.fromkeys(p["name"] for e in entries for p in e["paths"]))
    gp = any("sigma_pos_gp_m" in p for e in entries for p in e["paths"])
    fig = agg_figure(16.0 if gp else 11.0, 3.4 * len(paths) + 0.6)
    axes = np.atleast_2d(fig.subplots(len(paths), 3 if gp else 2, squeeze=False))
    for row, pname in enumerate(paths):
        ax_pos, ax_rot = axes[row][:2]
        for e, n in zip(entries, names):
            for p in e["paths"]:
                if p["name"] != pname:
                    continue
                s = np.asarray(p["s_m"], float) * 1e3
                pos = np.asarray(p["sigma_pos_m"], float) * 1e6
                rot = np.asarray(p["sigma_rot_rad"], float) * 1e6
                if not (s.shape == pos.shape == rot.shape) or np.any(pos < 0) or np.any(rot < 0):
                    raise InputError(f"path profile of design {n}, path {pname}: s_m, sigma_pos_m and sigma_rot_rad "
                                     f"must be equally long and sigma >= 0 (lengths {s.size}, {pos.size}, {rot.size})")
                ax_pos.plot(s, pos, color=col[n], label=f"{n} (worst {pos.max():.3f} µm)")
                ax_rot.plot(s, rot, color=col[n], label=f"{n} (worst {rot.max():.3f} µrad)")
                if gp and "sigma_pos_gp_m" in p:
                    g = np.asarray(p["sigma_pos_gp_m"], float) * 1e6
                    axes[row][2].plot(s, g, color=col[n], label=f"{n} (worst {g.max():.2f} µm)")
        ax_pos.set_ylabel("TCP σ (µm)")
        ax_rot.set_ylabel("tool orientation σ (µrad)")
        panels = [(ax_pos, "position"), (ax_rot, "orientation")]
        if gp:
            axes[row][2].set_ylabel("TCP σ with the discrepancy (µm)")
            panels.append((axes[row][2], "position (discrepancy included)"))
        for ax, what in panels:
            ax.set_xlabel(f"arc length along path '{pname}' (mm)")
            ax.set_title(f"{pname}: {what} σ per sample", fontsize=10)
            ax.grid(alpha=0.3)
            ax.legend(fontsize=8)
    if title:
        fig.suptitle(title)
    return save_png(fig, path)
