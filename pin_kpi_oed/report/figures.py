"""The certificate's figures as PNG bytes (embedded in the HTML as base64): errors before / after, against the
reach and each joint, the parameters' correlations, ISO 9283 AP per commanded position, the trust map.

Values are SI in, mm (and degrees for joint angles) on the axes. The trust map is
:func:`~pin_kpi_oed.viz.trust_map.plot_trust_map`'s figure, the same call ``predict --figure`` makes.
"""

from __future__ import annotations

import io
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["draw_figures", "trust_numbers", "png_bytes", "outside_legend", "DPI"]

#: Resolution of the embedded figures (keeps the certificate small).
DPI = 90
BEFORE, AFTER = "#c44e52", "#4c72b0"


def _fig(w: float, h: float):
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(w, h))
    FigureCanvasAgg(fig)
    return fig


def png_bytes(fig: Any, dpi: int = DPI) -> bytes:
    """A figure as PNG bytes, cropped to what it draws (``bbox_inches="tight"``), drawn once
    (:func:`~pin_kpi_oed.viz.figures.write_png`).

    Args:
        fig: a :class:`matplotlib.figure.Figure`.
        dpi: resolution (dots per inch).

    Returns:
        The PNG file's bytes.
    """
    from pin_kpi_oed.viz.figures import write_png

    buf = io.BytesIO()
    write_png(fig, buf, dpi, tight=True)
    return buf.getvalue()


def outside_legend(ax: Any, fontsize: float = 9) -> Any:
    """The axes' legend above its plotting area, never on the data."""
    return ax.legend(loc="lower left", bbox_to_anchor=(0.0, 1.02), ncol=2, fontsize=fontsize, frameon=False,
                     borderaxespad=0.0)


def _histogram(acc: dict, ho: Any) -> bytes:
    fig = _fig(7.0, 3.2)
    ax = fig.subplots()
    eb, ea = np.asarray(ho.before["errors_m"]) * 1e3, np.asarray(ho.after["errors_m"]) * 1e3
    bins = np.linspace(0.0, float(max(eb.max(), ea.max())), 40)
    ax.hist(eb, bins=bins, color=BEFORE, alpha=0.6, label=f"before (RMS {acc['before']['rms_m'] * 1e3:.3f} mm)")
    ax.hist(ea, bins=bins, color=AFTER, alpha=0.6, label=f"after (RMS {acc['after']['rms_m'] * 1e3:.3f} mm)")
    ax.set_xlabel("3-D position error (mm)")
    ax.set_ylabel("held-out rows")
    outside_legend(ax)
    return png_bytes(fig)


def _binned_plot(ax: Any, b: dict, a: dict, scale: float) -> None:
    edges = np.asarray(b["edges"]) * scale
    mid = 0.5 * (edges[1:] + edges[:-1])
    for d, c, lab in ((b, BEFORE, "before"), (a, AFTER, "after")):
        y = np.array([np.nan if v is None else v * 1e3 for v in d["mean_m"]])
        ax.plot(mid, y, "o-", color=c, label=lab)


def _reach_and_joints(acc: dict, ho: Any) -> bytes:
    fig = _fig(10.0, 5.2)
    axes = fig.subplots(2, 4).ravel()
    axes[0].scatter(ho.reach_m, np.asarray(ho.after["errors_m"]) * 1e3, s=3, color=AFTER, alpha=0.3)
    _binned_plot(axes[0], acc["before"]["vs_reach"], acc["after"]["vs_reach"], 1.0)
    axes[0].set_xlabel("reach (m)")
    axes[0].set_ylabel("mean error (mm)")
    outside_legend(axes[0], fontsize=8)
    for ax, (name, b) in zip(axes[1:], acc["before"]["per_joint"].items()):
        _binned_plot(ax, b, acc["after"]["per_joint"][name], 180.0 / np.pi)
        ax.set_xlabel(f"{name} (deg)", fontsize=8)
    axes[-1].axis("off")
    fig.tight_layout()
    return png_bytes(fig)


def _correlation(data: dict, cm: Any) -> bytes | None:
    P = cm.parameters or {}
    C = P.get("covariance")
    if C is None or not len(P.get("names") or []):
        return None
    C = np.asarray(C, float)
    d = np.sqrt(np.clip(np.diag(C), 1e-300, None))
    fig = _fig(6.5, 5.5)
    ax = fig.subplots()
    im = ax.imshow(C / np.outer(d, d), vmin=-1, vmax=1, cmap="RdBu_r")
    names = list(P["names"])
    fs = float(np.clip(260.0 / max(len(names), 1), 6.0, 9.0))  # ≥ 6 pt: legible on an A4 print
    fig.set_size_inches(max(6.5, 0.16 * len(names) + 3.0), max(5.5, 0.16 * len(names) + 2.5))
    ax.set_xticks(range(len(names)), names, rotation=90, fontsize=fs)
    ax.set_yticks(range(len(names)), names, fontsize=fs)
    fig.colorbar(im, ax=ax, label="correlation")
    return png_bytes(fig)


def _iso(data: dict) -> bytes | None:
    iso = data["iso9283"].get("AP_vAP")
    if not iso:
        return None
    fig = _fig(7.0, 3.0)
    ax = fig.subplots()
    for k, c in (("before", BEFORE), ("after", AFTER)):
        ap = np.array([r["AP_m"] for r in iso[k]["per_position"]]) * 1e3
        ax.hist(ap, bins=30, color=c, alpha=0.6, label=f"AP {k} (mean {ap.mean():.3f} mm)")
    ax.set_xlabel("AP per commanded position (mm)")
    ax.set_ylabel("positions")
    outside_legend(ax)
    return png_bytes(fig)


def trust_numbers(cm: Any, Q: np.ndarray, scored: Any, station: str | None = None, tm: Any = None) -> dict:
    """The trust map's numbers on the scored rows: predicted 3-D σ (min, median, max, m) and extrapolated share
    (``cm``'s ``station``, default its default or first; ``tm``: the :func:`trust_map` of these arguments, when
    computed already)."""
    from pin_kpi_oed.viz.trust_map import trust_map

    if tm is None:
        tm = trust_map(cm, Q, scored, station or cm.default_station or next(iter(cm.setups)))
    return {"n": int(len(Q)), "sigma_min_m": float(tm.sigma_m.min()), "sigma_median_m": float(np.median(tm.sigma_m)),
            "sigma_max_m": float(tm.sigma_m.max()), "extrapolated": int(np.sum(tm.extrapolation)),
            "discrepancy": cm.discrepancy is not None}


def _trust_png(cm: Any, Q: np.ndarray, scored: Any, station: str, tm: Any = None) -> bytes:
    from pin_kpi_oed.viz.trust_map import plot_trust_map

    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "trust.png"
        plot_trust_map(cm, Q, scored, station, out=out,
                       title=f"{cm.robot.name}: predicted σ on the held-out rows", computed=tm)
        return out.read_bytes()


def draw_figures(cm: Any, ho: Any, scored: Any, data: dict, tm: Any = None) -> dict:
    """The certificate's figures, name -> PNG bytes (absent where the data give none); ``tm``: the held-out rows'
    trust map when computed already (:func:`~pin_kpi_oed.viz.trust_map.trust_map`)."""
    acc = data["accuracy"]
    out = {"histogram": _histogram(acc, ho), "reach_joints": _reach_and_joints(acc, ho),
           "correlation": _correlation(data, cm), "iso_ap": _iso(data)}
    out["trust_map"] = _trust_png(ho.model, ho.Q, scored, ho.station, tm)
    return {k: v for k, v in out.items() if v is not None}
