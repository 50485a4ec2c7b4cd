"""Report figures (matplotlib, Agg, PNG): ellipsoid projections, design comparison, pose quality.

* :func:`plot_ellipsoid_projections`: the TCP's confidence ellipsoid of each design projected on
  the xy, xz and yz planes, one row per working configuration (as the paper's Figure 7, heuristic
  vs KPI design). The curve drawn is the *shadow* of the 3-D ellipsoid {x : xᵀC⁻¹x <= χ²₃(level)}
  on the plane, i.e. the ellipse of the 2×2 marginal covariance with the same χ²₃ bound.
* :func:`plot_design_bars`: tr(C_s) (mm², as ``pin-kpi-oed design``) and the RMS TCP σ (µm) of each design, with the
change
  relative to the heuristic.
* :func:`plot_pose_quality`: per measurement pose, the clearance (mm) and the laser incidence (°).
* :func:`design_figures`: the three from a design JSON (:func:`pin_kpi_oed.design.design_file.load_design`).

Figures are drawn on :class:`matplotlib.figure.Figure` with the Agg canvas (no pyplot, no display,
thread-safe) and written atomically (a temporary file in the target folder, then renamed).
Values are SI in the arguments and converted for display only (the axis labels say the unit).
"""

from __future__ import annotations

import io
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any
from collections.abc import Mapping, Sequence

import numpy as np

from pin_kpi_oed.errors import InputError
from pin_kpi_oed.viz.style import design_colours, hex_colour

UNITS = {"m": 1.0, "mm": 1e3, "um": 1e6}
UNIT_LABEL = {"m": "m", "mm": "mm", "um": "µm"}
#: zlib level of the PNGs written (lossless at every level): 3 encodes the package's figures in about three quarters
#: of the time of the default 6 (one to two tenths of a second less per figure at 150 dpi), files up to 15 % larger.
PNG_COMPRESS_LEVEL = 3


def _colours(names: Sequence[str], colours: Mapping[str, str] | None) -> dict[str, str]:
    """Colour of each design: the given one, else the scene's (:func:`pin_kpi_oed.viz.style.design_colours`)."""
    given = colours or {}
    default = design_colours([n for n in names if not given.get(n)])
    return {n: given.get(n) or hex_colour(default[n]) for n in names}


def agg_figure(w: float, h: float):
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(w, h), dpi=100, layout="constrained")
    FigureCanvasAgg(fig)
    return fig


def save_png(fig: Any, path: str | os.PathLike, dpi: int = 150) -> Path:
    """Render ``fig`` in the format its file name says (``.pdf``, ``.svg``, else PNG: :func:`write_png`) and write it
    atomically; returns the path.

    Raises:
        InputError: the target folder does not exist, or ``path`` is a folder.
    """
    from pin_kpi_oed.data.atomic import atomic_write_bytes

    buf = io.BytesIO()
    suffix = Path(path).suffix.lower()
    if suffix in (".pdf", ".svg"):
        fig.savefig(buf, format=suffix[1:], dpi=dpi)
    else:
        write_png(fig, buf, dpi)
    atomic_write_bytes(path, buf.getvalue())
    return Path(path)


def write_png(fig: Any, out: Any, dpi: int = 150, tight: bool = False) -> None:
    """Write ``fig`` as PNG to ``out`` (a binary file object): the pixels of ``fig.savefig(out, format="png",
    dpi=dpi)`` (with ``bbox_inches="tight"`` when ``tight``), drawn once instead of twice and compressed at
    :data:`PNG_COMPRESS_LEVEL`.

    ``savefig`` draws a figure with a layout engine (``layout="constrained"``, or the placeholder ``tight_layout()``
    leaves), or one cropped to ``"tight"``, twice: once without output to lay it out or measure it, then into the
    image. Here the Agg canvas draws it once at the output's dpi (``Figure.draw`` runs the layout engine itself,
    then draws); a tight crop is measured on the figure's extents (:meth:`Figure.get_tightbbox`) before that one
    draw. The figure keeps its dpi and layout engine afterwards. A figure on another canvas (a window's canvas among
    them: changing its dpi would resize the window), a constrained figure to crop, or a ``savefig.facecolor`` /
    ``edgecolor`` set in the rc parameters is written by ``savefig`` as it stands.

    Args:
        fig: a :class:`matplotlib.figure.Figure`.
        out: binary file object the PNG is written to.
        dpi: resolution (dots per inch).
        tight: crop to what the figure draws, padded by ``savefig.pad_inches``.
    """
    import matplotlib
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.layout_engine import PlaceHolderLayoutEngine

    rc = matplotlib.rcParams
    pil = {"compress_level": PNG_COMPRESS_LEVEL}
    engine = fig.get_layout_engine()
    plain = (type(fig.canvas) is not FigureCanvasAgg or rc["savefig.facecolor"] != "auto"
             or rc["savefig.edgecolor"] != "auto"
             or (tight and (rc["figure.autolayout"] or rc["figure.constrained_layout.use"]
                            or not (engine is None or isinstance(engine, PlaceHolderLayoutEngine)))))
    if plain:
        fig.savefig(out, format="png", dpi=dpi, bbox_inches="tight" if tight else None, pil_kwargs=pil)
        return
    dpi0 = fig.dpi
    fig.dpi = dpi
    try:
        if not tight:
            fig.canvas.print_png(out, pil_kwargs=pil)
            return
        box = fig.get_tightbbox(fig.canvas.get_renderer()).padded(rc["savefig.pad_inches"])
        fig.set_layout_engine(None)   # a placeholder engine lays out nothing, but would make savefig draw twice
        fig.savefig(out, format="png", dpi=dpi, bbox_inches=box, pil_kwargs=pil)
    finally:
        fig.set_layout_engine(engine)
        fig.dpi = dpi0


def _blocks(C: np.ndarray) -> np.ndarray:
    """(3t, 3t) or (t, 3, 3) or (3, 3) -> (t, 3, 3) diagonal blocks."""
    C = np.asarray(C, float)
    if C.ndim == 3 and C.shape[1:] == (3, 3):
        return C
    if C.ndim == 2 and C.shape[0] == C.shape[1] and C.shape[0] % 3 == 0:
        t = C.shape[0] // 3
        return np.array([C[3 * j:3 * j + 3, 3 * j:3 * j + 3] for j in range(t)])
    raise InputError(f"covariance must be (3t, 3t) or (t, 3, 3) (m^2), got shape {C.shape}")


def ellipse_points(C2: np.ndarray, k: float, n: int = 181) -> np.ndarray:
    """Points (n, 2) of the ellipse {x : xᵀ C2⁻¹ x = k}."""
    w, V = np.linalg.eigh(0.5 * (C2 + C2.T))
    a = np.linspace(0, 2 * np.pi, n)
    circle = np.stack([np.cos(a), np.sin(a)], axis=1)
    return circle * np.sqrt(k * np.clip(w, 0.0, None)) @ V.T


def shade(ax: Any, P: np.ndarray, colour: str, alpha: float) -> Any:
    """Fill the polygon ``P`` on ``ax``: the patch ``ax.fill(P[:, 0], P[:, 1], color=colour, alpha=alpha)`` adds,
    drawn alike, without updating the axes' data limits (for axes whose limits the caller sets: ``fill`` walks
    every edge of the polygon for them, which costs more than the drawing).

    Args:
        ax: matplotlib axes.
        P: the polygon's vertices (n, 2), data units.
        colour: face and edge colour.
        alpha: opacity in [0, 1].

    Returns:
        The :class:`matplotlib.patches.Polygon` added.
    """
    from matplotlib.patches import Polygon

    patch = Polygon(P, closed=True)
    patch.set(color=colour, alpha=alpha)
    ax.add_artist(patch)
    return patch


def plot_ellipsoid_projections(covs: Mapping[str, np.ndarray], path: str | os.PathLike, *,
                               colours: Mapping[str, str] | None = None, labels: Mapping[str, str] | None = None,
                               level: float = 0.95, unit: str = "um", frame: str = "tracker frame",
                               title: str | None = None, max_rows: int = 3) -> Path:
    """Projections of the TCP confidence ellipsoids on the xy, xz and yz planes (as the paper's Figure 7).

    Args:
        covs: per design, C_s (3t × 3t or t × 3 × 3, m²).
        path: PNG to write.
        colours, labels: per design (defaults by criterion name).
        level: confidence level (χ²₃ bound of the 3-D ellipsoid).
        unit: ``um``, ``mm`` or ``m`` for the axes.
        frame: name of the frame the covariances are expressed in (axis labels).
        title: figure title.
        max_rows: at most this many working configurations (rows).
    """
    from scipy.special import chdtri

    if not covs:
        raise InputError("no covariance to plot")
    if unit not in UNITS:
        raise InputError(f"unit must be one of {', '.join(UNITS)}, got '{unit}'")
    names = list(covs)
    blocks = {n: _blocks(covs[n]) for n in names}
    t = min(b.shape[0] for b in blocks.values())
    rows = min(t, max_rows)
    col = _colours(names, colours)
    lab = {n: (labels or {}).get(n, n) for n in names}
    k = float(chdtri(3, 1.0 - level))  # chi-square quantile, 3 degrees of freedom
    s = UNITS[unit]
    u = UNIT_LABEL[unit]
    fig = agg_figure(10.5, 3.4 * rows + 0.5)
    axes = fig.subplots(rows, 3, squeeze=False)
    planes = [((0, 1), "xy"), ((0, 2), "xz"), ((1, 2), "yz")]
    for r in range(rows):
        lim = 0.0
        for c, ((i, j), pname) in enumerate(planes):
            ax = axes[r, c]
            for n in names:
                C2 = blocks[n][r][np.ix_([i, j], [i, j])] * s ** 2
                P = ellipse_points(C2, k)
                ax.plot(P[:, 0], P[:, 1], color=col[n], lw=2, label=lab[n])
                shade(ax, P, col[n], 0.12)
                lim = max(lim, float(np.abs(P).max()))
            ax.plot([0], [0], marker="+", color="k", ms=8)
            ax.set_aspect("equal", adjustable="box")
            ax.grid(True, alpha=0.3)
            ax.set_xlabel(f"{'xyz'[i]} ({u})")
            ax.set_ylabel(f"{'xyz'[j]} ({u})")
            ax.set_title(f"{pname} plane" + (f", working configuration {r}" if t > 1 else ""), fontsize=10)
        for c in range(3):
            axes[r, c].set_xlim(-1.1 * lim, 1.1 * lim)
            axes[r, c].set_ylim(-1.1 * lim, 1.1 * lim)
    axes[0, 0].legend(loc="upper left", fontsize=8, framealpha=0.8)
    fig.suptitle(title or f"TCP {int(round(level * 100))} % confidence ellipsoids, projected ({frame})", fontsize=12)
    return save_png(fig, path)


def _baseline(names: Sequence[str], baseline: str | None) -> str | None:
    if baseline is not None:
        return baseline if baseline in names else None
    for b in ("random", "heuristic"):
        if b in names:
            return b
    return None


def plot_design_bars(traces_m2: Mapping[str, float], path: str | os.PathLike, *, n_work: int = 1,
                     colours: Mapping[str, str] | None = None, labels: Mapping[str, str] | None = None,
                     baseline: str | None = None, title: str | None = None) -> Path:
    """Bar chart comparing designs: tr(C_s) (mm²) and RMS TCP σ = sqrt(tr(C_s)/t) (µm).

    Each bar is annotated with its change relative to ``baseline`` (default the ``random`` /
    ``heuristic`` design when present).

    Args:
        traces_m2: per design, tr(C_s) (m²).
        path: PNG to write.
        n_work: number t of working configurations (for the RMS σ).
    """
    if not traces_m2:
        raise InputError("no design to plot")
    names = list(traces_m2)
    tr = np.array([float(traces_m2[n]) for n in names])
    if not np.all(np.isfinite(tr)) or np.any(tr < 0):
        raise InputError(f"tr(C_s) must be finite and >= 0 (m^2), got {tr.tolist()}")
    col = _colours(names, colours)
    lab = [(labels or {}).get(n, n) for n in names]
    base = _baseline(names, baseline)
    sig = np.sqrt(tr / max(n_work, 1)) * 1e6
    fig = agg_figure(max(6.0, 1.6 * len(names) + 3.0), 3.8)
    ax1, ax2 = fig.subplots(1, 2)
    x = np.arange(len(names))
    for ax, vals, ylabel in ((ax1, tr * 1e6, "tr(C$_s$) (mm²)"), (ax2, sig, "RMS TCP σ (µm)")):
        bars = ax.bar(x, vals, color=[col[n] for n in names])
        ax.set_xticks(x, lab, rotation=20 if max(len(s) for s in lab) > 10 else 0, ha="right"
                      if max(len(s) for s in lab) > 10 else "center")
        ax.set_ylabel(ylabel)
        ax.grid(True, axis="y", alpha=0.3)
        ax.set_ylim(0, 1.18 * max(vals.max(), 1e-30))
        for i, b in enumerate(bars):
            txt = f"{vals[i]:.3g}"
            if base is not None and names[i] != base:
                ref = vals[names.index(base)]
                if ref > 0:
                    txt += f"\n({100 * (vals[i] / ref - 1):+.0f} %)"
            ax.annotate(txt, (b.get_x() + b.get_width() / 2, b.get_height()), ha="center", va="bottom", fontsize=8,
                        xytext=(0, 2), textcoords="offset points")
    fig.suptitle(title or "Designs compared" + (f" (change vs {base})" if base else ""), fontsize=12)
    return save_png(fig, path)


def plot_pose_quality(clearance_m: Mapping[str, np.ndarray], incidence_deg: Mapping[str, np.ndarray],
                      path: str | os.PathLike, *, colours: Mapping[str, str] | None = None,
                      labels: Mapping[str, str] | None = None, incidence_limit_deg: float | None = 30.0,
                      min_clearance_m: float = 0.0, title: str | None = None) -> Path:
    """Per measurement pose: clearance (mm) and laser incidence angle (°), one row per design.

    Poses below ``min_clearance_m`` or above ``incidence_limit_deg`` are drawn in red.

    Args:
        clearance_m: per design, the smallest clearance of each pose (m); ``inf`` = nothing to compare.
        incidence_deg: per design, the incidence angle of each pose (deg).
        path: PNG to write.
    """
    names = list(dict.fromkeys(list(clearance_m) + list(incidence_deg)))
    if not names:
        raise InputError("no design to plot")
    col = _colours(names, colours)
    fig = agg_figure(10.0, 2.3 * len(names) + 0.8)
    axes = fig.subplots(len(names), 2, squeeze=False)
    for r, n in enumerate(names):
        lab = (labels or {}).get(n, n)
        ax = axes[r, 0]
        c = np.asarray(clearance_m.get(n, []), float) * 1e3
        if c.size:
            finite = np.isfinite(c)
            x = np.arange(c.size)
            bad = finite & (c < min_clearance_m * 1e3)
            ax.bar(x[finite & ~bad], c[finite & ~bad], color=col[n])
            ax.bar(x[bad], c[bad], color="#d62728")
            ax.axhline(min_clearance_m * 1e3, color="k", lw=1, ls="--")
            ax.set_title(f"{lab}: clearance, min {np.min(c[finite]) if finite.any() else np.inf:.0f} mm", fontsize=10)
        else:
            ax.set_title(f"{lab}: clearance not available", fontsize=10)
        ax.set_ylabel("clearance (mm)")
        ax.grid(True, axis="y", alpha=0.3)
        ax = axes[r, 1]
        a = np.asarray(incidence_deg.get(n, []), float)
        if a.size:
            x = np.arange(a.size)
            bad = (a > incidence_limit_deg) if incidence_limit_deg is not None else np.zeros(a.size, bool)
            ax.bar(x[~bad], a[~bad], color=col[n])
            ax.bar(x[bad], a[bad], color="#d62728")
            if incidence_limit_deg is not None:
                ax.axhline(incidence_limit_deg, color="k", lw=1, ls="--")
            ax.set_title(f"{lab}: laser incidence, max {a.max():.1f}°", fontsize=10)
        else:
            ax.set_title(f"{lab}: incidence not available", fontsize=10)
        ax.set_ylabel("incidence (°)")
        ax.grid(True, axis="y", alpha=0.3)
    for ax in axes[-1]:
        ax.set_xlabel("measurement pose")
    fig.suptitle(title or "Measurement poses: clearance and laser incidence", fontsize=12)
    return save_png(fig, path)


def _per_pose(info: Mapping, keys: Sequence[str], m: int) -> np.ndarray | None:
    for k in keys:
        v = info.get(k)
        if isinstance(v, (list, tuple)) and len(v) == m:
            try:
                return np.asarray(v, float)
            except (TypeError, ValueError):
                return None
    return None


@dataclass
class DesignFigureData:
    """What the three figures of a design file show, per design (criterion).

    Attributes:
        covs_m2: C_s blocks (t, 3, 3) m², in the frame the figure names.
        traces_m2: tr(C_s) (m²).
        clearance_m: per pose, smallest clearance (m): the file's ``clearance_m`` list, else the
            independent check of the file's cell (:meth:`~pin_kpi_oed.design.design_file.DesignFile.pose_clearance`).
        incidence_deg: per pose, laser incidence (deg): the file's ``incidence_deg`` list, else the model's.
        colours: ``#rrggbb``; labels: readable names.
        sigma: the C_s shown, ``honest`` (discrepancy included: every design of the file holds one) or ``paper``
            (tracker noise only).
    """

    covs_m2: dict[str, np.ndarray]
    traces_m2: dict[str, float]
    clearance_m: dict[str, np.ndarray]
    incidence_deg: dict[str, np.ndarray]
    colours: dict[str, str]
    labels: dict[str, str]
    sigma: str = "paper"


def design_figure_data(df: Any, frame: str = "world", sigma: str = "honest") -> DesignFigureData:
    """The values :func:`design_figures` plots, from a :class:`~pin_kpi_oed.design.design_file.DesignFile`.

    Args:
        df: the design file.
        frame: ``world`` (the cell frame, z up) or ``tracker`` for the covariances.
        sigma: ``honest``: the C_s with the discrepancy when every design of the file holds one (``design
            --model``), else the paper's; ``paper``: the paper's (tracker noise only).
    """
    R = df.world_T_tracker.rotation if frame == "world" else np.eye(3)
    colours = design_colours([d.criterion for d in df.designs])
    honest = sigma == "honest" and all(d.cov_s_honest_m2 is not None for d in df.designs)
    out = DesignFigureData({}, {}, {}, {}, {}, {}, "honest" if honest else "paper")
    for d in df.designs:
        m = d.q_meas.shape[0]
        C = d.covariance(honest)
        out.covs_m2[d.criterion] = np.array([R @ B @ R.T for B in _blocks(C)])
        out.traces_m2[d.criterion] = float(np.trace(C)) if honest else d.trace_cs_m2
        c = _per_pose(d.info, ("clearance_m", "pose_clearance_m", "clearances_m"), m)
        out.clearance_m[d.criterion] = c if c is not None else df.pose_clearance(d.q_meas)
        a = _per_pose(d.info, ("incidence_deg", "pose_incidence_deg"), m)
        out.incidence_deg[d.criterion] = a if a is not None else df.incidence_deg(d.q_meas)
        out.colours[d.criterion] = hex_colour(colours[d.criterion])
        out.labels[d.criterion] = d.label
    return out


def design_figures(design: Any, out_dir: str | os.PathLike, prefix: str = "design", level: float = 0.95,
                   frame: str = "world", sigma: str = "honest") -> dict[str, Path]:
    """The three figures of a design file, written to ``out_dir`` (values: :func:`design_figure_data`).

    Args:
        design: a :class:`~pin_kpi_oed.design.design_file.DesignFile`, a design JSON path or dict.
        out_dir: existing folder.
        prefix: file-name prefix.
        level: confidence level of the ellipsoids.
        frame: ``world`` (the cell frame, z up) or ``tracker`` for the ellipsoid projections.
        sigma: the C_s of the ellipsoids and bars (:func:`design_figure_data`); the titles name it.

    Returns:
        ``{"ellipsoids": path, "bars": path, "poses": path}``.

    Raises:
        InputError: ``out_dir`` is not a folder, or the design file cannot be read.
    """
    from pin_kpi_oed.design.design_file import DesignFile, load_design

    df = design if isinstance(design, DesignFile) else load_design(design)
    out = Path(out_dir)
    if not out.is_dir():
        raise InputError(f"cannot write figures to '{out}': no such folder")
    v = design_figure_data(df, frame, sigma)
    name = df.robot.name
    which = "discrepancy included" if v.sigma == "honest" else "tracker noise only"
    return {
        "ellipsoids": plot_ellipsoid_projections(
            v.covs_m2, out / f"{prefix}_ellipsoids.png", colours=v.colours, labels=v.labels, level=level,
            frame="cell frame" if frame == "world" else "tracker frame",
            title=f"{name}: TCP {int(round(level * 100))} % confidence ellipsoids, projected ({which})"),
        "bars": plot_design_bars(v.traces_m2, out / f"{prefix}_designs.png", n_work=df.q_work.shape[0],
                                 colours=v.colours, labels=v.labels, title=f"{name}: designs compared ({which})"),
        "poses": plot_pose_quality(v.clearance_m, v.incidence_deg, out / f"{prefix}_poses.png", colours=v.colours,
                                   labels=v.labels, incidence_limit_deg=df.incidence_limit_deg,
                                   title=f"{name}: clearance and laser incidence per pose"),
    }


# --------------------------------------------------------------------------- study figures
def plot_notional(rows: list[dict], path: Path) -> None:
    """Figure-8-like: improvement of the KPI design per arm, over the (a2, d4) grid, vs heuristic and vs A on C_p."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    a2 = sorted({r["a2_m"] for r in rows})
    d4 = sorted({r["d4_m"] for r in rows})
    fig, axes = plt.subplots(1, 2, figsize=(12, 4.6), constrained_layout=True)
    for ax, key, title in ((axes[0], "improvement_vs_heuristic", "KPI design vs heuristic"),
                           (axes[1], "improvement_vs_param", "KPI design vs A on C_p")):
        grid = np.full((len(d4), len(a2)), np.nan)
        for r in rows:
            grid[d4.index(r["d4_m"]), a2.index(r["a2_m"])] = 100 * r[key]
        im = ax.imshow(grid, origin="lower", cmap="viridis", aspect="auto")
        for (i, j), v in np.ndenumerate(grid):
            if np.isfinite(v):
                ax.text(j, i, f"{v:.0f}", ha="center", va="center", fontsize=7, color="w")
        ax.set_xticks(range(len(a2)), [f"{1e3 * v:.0f}" for v in a2], rotation=90)
        ax.set_yticks(range(len(d4)), [f"{1e3 * v:.0f}" for v in d4])
        ax.set_xlabel("segment two a2 (mm)")
        ax.set_ylabel("segment four d4 (mm)")
        ax.set_title(f"{title}: mean {np.nanmean(grid):.1f} %")
        fig.colorbar(im, ax=ax, label="reduction of tr(C_s) (%)")
    save_png(fig, path)
    plt.close(fig)


def plot_study_figure7(rec: dict, path: Path) -> None:
    """Figure-7-like ellipsoid projections of one KUKA study task record (``figure7_<cell>.png``)."""
    covs = {("heuristic" if d["criterion"] == "random" else f"A on C_{'s' if d['criterion'] == 'kpi' else 'p'}"):
            np.array(d["cov_s_m2"])[:3, :3] for d in rec["designs"]}
    plot_ellipsoid_projections(covs, path)
