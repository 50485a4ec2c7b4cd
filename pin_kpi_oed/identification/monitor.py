"""Monitoring during work: measurements taken while the robot works, replayed in time order, each row predicted
before it is used, a check every few rows.

Each new row is first *predicted* by the current model (position and honest σ,
:meth:`CalibratedModel.predict_with_sigma`): its standardised error z = (measured − predicted)/σ is what the model
promised before it saw the row, so the running standardised RMS of z says whether the σ stays honest over the
replay (0.67–1.5 is honest). Every ``every`` rows the rows since the last check are a check
(:func:`check_calibration`) — when they determine the set-up at the working configurations; rows measured near one
point (an orientation series) do not, and the window grows until they do (at most ``max_window`` rows, the oldest
dropped): the set-up re-registered, the residuals tested at α; the model is updated by the verdict — *set-up
moved*: the re-registered set-up (*robot changed* with a determined group: the re-fitted model, with ``refit``);
otherwise kept, and the event says what to do (measure ``check design``'s poses; re-calibrate). One line per event;
the log holds every check. The file is read once (a file that grows while it is read is not followed).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from pin_kpi_oed.data.measurements import MeasurementSet
from pin_kpi_oed.errors import InputError
from pin_kpi_oed.identification.check import CHECK_STATION, check_calibration
from pin_kpi_oed.identification.model_file import CalibratedModel
from pin_kpi_oed.identification.problem import align_data
from pin_kpi_oed.results import Result

__all__ = ["MonitorLog", "monitor"]


@dataclass(kw_only=True)
class MonitorLog(Result):
    """What :func:`monitor` saw (SI units).

    Attributes:
        z: standardised errors of every row predicted before it was used, (m, 3).
        error_m: position error norm per row (m); sigma_m: predicted σ norm per row (m).
        batches: per check ``{first_row, last_row, verdict, chi2, dof, p_value, group, z_rms_so_far, updated}``.
        events: the lines printed (verdicts other than *holds*).
        model: the model at the end of the replay.
        time_per_row_s: wall time per row (prediction and the checks).
    """

    z: np.ndarray
    error_m: np.ndarray
    sigma_m: np.ndarray
    batches: list = field(default_factory=list)
    events: list = field(default_factory=list)
    model: CalibratedModel | None = field(default=None, repr=False)
    time_per_row_s: float = float("nan")

    @property
    def z_rms(self) -> float:
        """Standardised RMS over the replay (per axis)."""
        return float(np.sqrt(np.mean(self.z ** 2))) if self.z.size else float("nan")

    def summary(self) -> str:
        """One line."""
        flagged = sum(b["verdict"] not in ("holds", "setup_moved") for b in self.batches)
        return (f"monitor: {len(self.error_m)} rows, {len(self.batches)} checks ({flagged} flagged a change), "
                f"standardised RMS {self.z_rms:.2f} (honest within 0.67-1.5), mean error "
                f"{np.mean(self.error_m) * 1e3:.3f} mm, mean predicted sigma {np.mean(self.sigma_m) * 1e3:.3f} mm, "
                f"{self.time_per_row_s * 1e3:.1f} ms per row")

    def to_dict(self) -> dict:
        """Plain JSON-able dict (SI units)."""
        return {**self.result_dict(), "rows": int(len(self.error_m)), "z_rms": self.z_rms,
                "error_m": self.error_m.tolist(), "sigma_m": self.sigma_m.tolist(), "batches": self.batches,
                "events": self.events, "time_per_row_s": self.time_per_row_s}


def monitor(model: CalibratedModel, data: MeasurementSet, *, every: int = 10, alpha: float = 0.05,
            tolerance_m: float = 1e-4, station: str | None = None, max_window: int = 200, refit: bool = False,
            echo=None) -> MonitorLog:
    """Replay ``data`` in its order (time order): predict each row, check every ``every`` rows, update the model.

    Args:
        model: the calibrated model; station: its station the first rows are predicted in (default station).
        data: the rows measured during work (joint columns, x, y, z in m), in time order.
        every: rows per check (≥ 3); max_window: the most rows a check waits for to determine the set-up.
        refit: also take the re-fitted group of a *robot changed* check (default: only a moved set-up is followed;
            rows measured during work are rarely spread enough to re-fit a group of the robot, and on the real UR10
            replay taking their re-fits made the σ dishonest after a few thousand rows: measure the poses of
            ``check design`` instead, which the event line says).
        alpha, tolerance_m: as :func:`check_calibration`.
        echo: called with each event line (e.g. ``print``), or None.

    Raises:
        InputError: ``every`` below 3 or fewer rows than one check.
    """
    t0 = time.perf_counter()
    if every < 3 or len(data) < every:
        raise InputError(f"{data.source or 'monitor data'}: {len(data)} rows, checks of {every} rows (at least 3, and "
                         f"at least one check's rows)")
    Q = align_data(model.robot, data)
    label = model.station(station)
    cur = model
    z, err, sig, batches, events = [], [], [], [], []
    window: list[int] = []
    for start in range(0, len(data) - every + 1, every):
        rows = np.arange(start, start + every)
        Y, s, _ = cur.predict_with_sigma(Q[rows], data.subset(rows), station=label)
        r = data.position_m[rows] - Y
        z.append(r / s)
        err.append(np.linalg.norm(r, axis=1))
        sig.append(np.linalg.norm(s, axis=1))
        window = (window + rows.tolist())[-max_window:]
        if len(window) < 3:
            continue
        res = check_calibration(cur, data.subset(window), station=label, alpha=alpha, tolerance_m=tolerance_m)
        if not res.setup_determined and len(window) < max_window:
            continue
        first, window = window[0], []
        updated = res.verdict == "setup_moved" or (refit and res.verdict == "robot_changed" and res.determined)
        if updated:
            cur, label = res.model, CHECK_STATION
        zz = np.concatenate(z)
        batches.append({"first_row": int(first + 1), "last_row": int(start + every), "verdict": res.verdict,
                        "chi2": res.chi2, "dof": res.dof, "p_value": res.p_value, "group": res.group,
                        "z_rms_so_far": float(np.sqrt(np.mean(zz ** 2))), "updated": bool(updated)})
        if res.verdict != "holds":
            line = f"rows {first + 1}-{start + every}: {res.summary()}" + ("; model updated" if updated else "")
            if res.verdict in ("discrepancy_level", "recalibrate", "robot_changed") and not updated:
                line += "; measure the poses of 'check design' (or re-calibrate)"
            events.append(line)
            if echo is not None:
                echo(line)
    n = len(np.concatenate(err))
    return MonitorLog(z=np.concatenate(z), error_m=np.concatenate(err), sigma_m=np.concatenate(sig), batches=batches,
                      events=events, model=cur, time_per_row_s=(time.perf_counter() - t0) / max(n, 1),
                      success=True, status="replayed", message=f"{len(batches)} checks of {every} rows",
                      time_s=time.perf_counter() - t0)
