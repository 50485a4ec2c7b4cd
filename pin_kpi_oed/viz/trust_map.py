"""The trust map: where a calibration can be trusted, drawn over the configurations it will be used at.

A calibrated model with a model discrepancy predicts, for any configuration, both the reflector position and
the standard deviation of measured − predicted (:meth:`~pin_kpi_oed.calibrated.model_file.CalibratedModel.
predict_with_sigma`: the discrepancy's posterior variance, its white level and, outside the measured coverage,
the parametric part's error). :func:`plot_trust_map` puts that σ where the robot is: the reflector positions of
the given rows in the robot base frame, a top view (x–y) and a side view (x–z), each point coloured by its
predicted 3-D σ, √(σ_x² + σ_y² + σ_z²) (a rotation keeps it: the same in the tracker and the base frame).
Rows outside the measured coverage (:meth:`~pin_kpi_oed.discrepancy.gp.Discrepancy.extrapolation`) get a
distinct marker and are counted in the legend; the discrepancy's training configurations (its ``Z``: every
training row for the exact kind, the inducing subset of them for the sparse one) are small grey dots. Blue,
close to the grey dots: trusted; yellow, or a cross far from them: measure there first.

The σ drawn is exactly the one ``predict`` writes (the same call); values SI in, mm on the colour bar and the
axes. The PNG is written atomically (:func:`pin_kpi_oed.viz.figures.save_png`).
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from pin_kpi_oed.errors import InputError
from pin_kpi_oed.viz.figures import agg_figure, save_png

__all__ = ["TrustMap", "trust_map", "plot_trust_map", "sigma_contents", "trust_map_title"]

#: Colour of the measured (training) configurations.
TRAINING_COLOUR = "#9a9a9a"


@dataclass
class TrustMap:
    """What the trust map draws (SI).

    Attributes:
        positions_base_m: predicted reflector positions of the rows, robot base frame (m, 3) m.
        sigma_m: predicted 3-D σ of every row, √(σ_x² + σ_y² + σ_z²) of ``predict_with_sigma`` (m,) m.
        sigma_xyz_m: the per-axis σ of ``predict_with_sigma`` (tracker frame of the row's station), (m, 3) m.
        extrapolation: rows outside the measured coverage (m,) bool.
        training_base_m: reflector positions of the discrepancy's training configurations, base frame (k, 3) m
            (empty without a discrepancy or for the white kind).
        training_label: legend text of the training configurations.
        path: the PNG written (None before :func:`plot_trust_map`).
        figure: the matplotlib figure (None before :func:`plot_trust_map`).
    """

    positions_base_m: np.ndarray
    sigma_m: np.ndarray
    sigma_xyz_m: np.ndarray
    extrapolation: np.ndarray
    training_base_m: np.ndarray
    training_label: str
    path: Path | None = None
    figure: Any = None

    @property
    def n_extrapolated(self) -> int:
        """Rows outside the measured coverage."""
        return int(np.count_nonzero(self.extrapolation))


def _to_base(model: Any, Y: np.ndarray, labels: np.ndarray) -> np.ndarray:
    """Tracker-frame points of each row's station -> robot base frame (y = R p + t, so p = Rᵀ(y − t))."""
    out = np.empty((len(Y), 3))
    for lab in dict.fromkeys(labels):
        rows = np.flatnonzero(labels == lab)
        T = np.asarray(model.setups[lab].tracker_T_base, float)
        out[rows] = (Y[rows, :3] - T[:3, 3]) @ T[:3, :3]
    return out


def _training(model: Any, label: str) -> tuple[np.ndarray, str]:
    """Reflector positions (base frame) of the discrepancy's training configurations, and their legend text."""
    d = model.discrepancy
    if d is None or d.Z is None or len(d.Z) == 0:
        what = "no discrepancy" if d is None else f"discrepancy '{d.kind}' stores no configurations"
        return np.zeros((0, 3)), f"measured (training): none stored ({what})"
    tm, p = model.station_model(label)
    Yz = tm.predict(p, np.asarray(d.Z, float))[:, :3]  # calibrated geometry: where the arm was, to the mm
    pts = _to_base(model, Yz, np.array([label] * len(Yz), dtype=object))
    if d.kind == "inducing":
        return pts, f"measured (training): inducing subset of the training rows, {len(pts)} of {d.n_rows}"
    return pts, f"measured (training), {len(pts)} rows"


def trust_map(model: Any, Q: np.ndarray, aux: Any = None, station: str | None = None) -> TrustMap:
    """The trust map's numbers: positions (base frame), predicted σ and extrapolation flags of the rows Q.

    Args:
        model: a :class:`~pin_kpi_oed.calibrated.model_file.CalibratedModel`.
        Q: configurations (m, n) rad, the robot's joint order.
        aux, station: as :meth:`~pin_kpi_oed.calibrated.model_file.CalibratedModel.predict_with_sigma`.

    Raises:
        InputError: no rows, or what ``predict_with_sigma`` raises (unknown station, joints outside the limits).
    """
    Q = np.atleast_2d(np.asarray(Q, float))
    if Q.shape[0] == 0:
        raise InputError("trust map: no rows to draw")
    Y, sig, extra = model.predict_with_sigma(Q, aux, station)
    labels = model.row_stations(len(Q), aux, station)
    train, train_label = _training(model, labels[0])
    return TrustMap(_to_base(model, Y, labels), np.sqrt(np.sum(sig ** 2, axis=1)), sig, np.asarray(extra, bool),
                    train, train_label)


def sigma_contents(model: Any) -> str:
    """What the predicted σ of ``model`` holds, for a title
    (:func:`~pin_kpi_oed.calibrated.prediction_sigma.sigma_contents`, the words ``predict`` prints)."""
    from pin_kpi_oed.calibrated.prediction_sigma import sigma_contents as contents

    return "σ: " + contents(model)


def trust_map_title(model: Any, tm: TrustMap) -> str:
    """The trust map's default title: the robot, the number of rows, what the σ holds (:func:`sigma_contents`), the
    median and largest σ (mm).

    Args:
        model: the :class:`~pin_kpi_oed.calibrated.model_file.CalibratedModel` the map was computed with.
        tm: the map (:func:`trust_map`).

    Returns:
        The title text.
    """
    s_mm = tm.sigma_m * 1e3
    return (f"{model.robot.name}: predicted TCP σ over {len(s_mm)} configurations ({sigma_contents(model)}); "
            f"median {np.median(s_mm):.3f} mm, max {s_mm.max():.3f} mm")


def plot_trust_map(model: Any, Q: np.ndarray, aux: Any = None, station: str | None = None, *,
                   out: str | os.PathLike, title: str | None = None, computed: TrustMap | None = None) -> TrustMap:
    """Write the trust map (PNG): top (x–y) and side (x–z) views of the rows' reflector positions, base frame,
    coloured by the predicted σ (mm); extrapolated rows marked and counted; the training configurations in grey.

    Args:
        model, Q, aux, station: as :func:`trust_map`.
        out: the PNG to write (atomically).
        title: figure title (default: :func:`trust_map_title`).
        computed: the :class:`TrustMap` of these arguments when the caller already has it (not computed again).

    Returns:
        The :class:`TrustMap` drawn (``path`` and ``figure`` set).

    Raises:
        InputError: as :func:`trust_map`; the target folder does not exist, or ``out`` is a folder.
    """
    tm = trust_map(model, Q, aux, station) if computed is None else computed
    P, T = tm.positions_base_m * 1e3, tm.training_base_m * 1e3       # mm for display
    s_mm = tm.sigma_m * 1e3
    far = tm.extrapolation
    fig = agg_figure(11.0, 5.0)
    axes = fig.subplots(1, 2)
    vmin, vmax = float(s_mm.min()), float(s_mm.max())
    if vmax <= vmin:
        vmax = vmin + max(1e-6, 1e-3 * vmin)
    sc = None
    for ax, (j, name) in zip(axes, ((1, "top view (x–y)"), (2, "side view (x–z)"))):
        if len(T):
            ax.scatter(T[:, 0], T[:, j], s=4, c=TRAINING_COLOUR, alpha=0.6, linewidths=0, label=tm.training_label,
                       zorder=1)
        inside = ~far
        sc = ax.scatter(P[inside, 0], P[inside, j], s=26, c=s_mm[inside], cmap="viridis", vmin=vmin, vmax=vmax,
                        edgecolors="k", linewidths=0.3, label=f"inside the measured coverage "
                                                              f"({int(inside.sum())} rows)", zorder=2)
        ax.scatter(P[far, 0], P[far, j], s=60, c=s_mm[far], cmap="viridis", vmin=vmin, vmax=vmax, marker="X",
                   edgecolors="#d62728", linewidths=0.9,
                   label=f"extrapolation: outside the measured coverage ({int(far.sum())} rows)", zorder=3)
        ax.set_xlabel("x (mm, robot base frame)")
        ax.set_ylabel(("y" if j == 1 else "z") + " (mm, robot base frame)")
        ax.set_aspect("equal", adjustable="datalim")
        ax.set_title(name, fontsize=10)
        ax.grid(True, alpha=0.3)
    axes[0].legend(loc="best", fontsize=7, framealpha=0.85)
    fig.colorbar(sc, ax=list(axes), label="predicted σ (mm)", shrink=0.9)
    fig.suptitle(title or trust_map_title(model, tm), fontsize=11)
    tm.path = save_png(fig, out)
    tm.figure = fig
    return tm
