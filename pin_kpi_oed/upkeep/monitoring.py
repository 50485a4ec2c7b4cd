"""Monitoring during work: rows measured while the robot works, taken in time order, each predicted before it is
used; the set-up followed recursively, a check every few rows, poses asked for when the rows cannot tell.

Each new row is first *predicted* (:meth:`CalibratedModel.predict_with_sigma`, corrected by the set-up filter's
state): its standardised error z = (measured − predicted)/σ is what the monitor promised before it saw the row, so
the running standardised RMS of z says whether the σ stays honest (0.67–1.5 is honest). The σ is the model's honest
σ with the set-up filter's own uncertainty (:class:`~pin_kpi_oed.upkeep.setup_filter.SetupFilter`: the
tracker pose re-registered recursively, a random walk whose level is estimated from the rows' innovations). Every
``every`` rows the rows since the last check are a check (:func:`check_calibration`, the set-up re-registered on them,
the residuals tested at α) when they determine the set-up at the working configurations (rows measured near one point
do not: the window grows up to ``max_window`` rows). A *set-up moved* verdict on rows the filter rejected as outliers
(at least half: a jump — a tracker moved —, not a drift) re-registers the set-up on them and starts the filter anew.
A *robot changed*, *discrepancy level* or *re-calibrate* verdict — or a set-up filter whose share of the σ at the
working configurations exceeds the model's honest σ there (the rows measured during work no longer pin the set-up) —
asks for poses: the check design's (``check design``), once until the condition clears. One line per event; the log
holds every check and ask.

:class:`Monitor` takes rows as they come (``feed``); ``monitor --follow`` feeds it from a file that grows while it
is read (:mod:`pin_kpi_oed.cli.check`).
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass, field

import numpy as np
import pinocchio as pin

from pin_kpi_oed.data.measurements import MeasurementSet
from pin_kpi_oed.errors import InputError
from pin_kpi_oed.upkeep.check import CHECK_STATION, EXIT_CODES, check_calibration
from pin_kpi_oed.calibrated.model_file import CalibratedModel
from pin_kpi_oed.calibrated.shared_tables import row_tables
from pin_kpi_oed.identification.problem import align_data
from pin_kpi_oed.upkeep.setup_filter import SetupFilter
from pin_kpi_oed.results import Result

__all__ = ["Monitor", "MonitorLog", "monitor"]

#: Verdicts after which the monitor asks for the check design's poses.
ASK_VERDICTS = ("robot_changed", "discrepancy_level", "recalibrate")
#: The band of an honest standardised RMS; outside it (over the replay, or a block of :data:`BLOCK_ROWS` rows) a
#: warning line names the likely cause.
HONEST_BAND = (0.67, 1.5)
BLOCK_ROWS = 1000
#: Rows whose time goes backwards or repeats named one by one before the rest are only counted.
TIME_LINES = 3


@dataclass(kw_only=True)
class MonitorLog(Result):
    """What :func:`monitor` saw (SI units).

    Attributes:
        z: standardised errors of every row predicted before it was used, (m, 3).
        error_m: position error norm per row (m); sigma_m: predicted σ norm per row (m).
        batches: per check ``{first_row, last_row, verdict, chi2, dof, p_value, group, z_rms_so_far, updated,
            sigma_work_m}`` (sigma_work_m: RMS 3-D σ at the working configurations with the set-up filter's share).
        asks: per request for poses ``{row, reason, poses}`` (poses (k, n) rad: the check design's).
        events: the lines printed.
        model: the model at the end (the set-up filter's state applied to its station).
        drift_level_m_per_sqrt_s: the set-up drift level most probable at the end (m/√s; m/√row when
            ``timed`` is False); outliers: rows not used.
        timed: the rows had a time column (not constant); without one the filter takes one second per row and the
            drift level is per √row.
        time_per_row_s: wall time per row (prediction, filter and the checks).
        blocks: per block of :data:`BLOCK_ROWS` rows (the last one as long as it is) ``{first_row, last_row,
            z_rms}``: the standardised RMS of the rows predicted before use (honest within :data:`HONEST_BAND`).
    """

    z: np.ndarray
    error_m: np.ndarray
    sigma_m: np.ndarray
    batches: list = field(default_factory=list)
    asks: list = field(default_factory=list)
    events: list = field(default_factory=list)
    model: CalibratedModel | None = field(default=None, repr=False)
    drift_level_m_per_sqrt_s: float = 0.0
    outliers: int = 0
    time_per_row_s: float = float("nan")
    time_backwards: int = 0
    time_repeated: int = 0
    work_source: str = ""
    timed: bool = True
    blocks: list = field(default_factory=list)

    def exit_code(self, fail_on: int = 3) -> int:
        """The largest exit code of the checks' verdicts that is at least ``fail_on`` (1: changed and re-calibrate;
        3: re-calibrate only; above 3: never), else 0 (:data:`~pin_kpi_oed.upkeep.check.EXIT_CODES`)."""
        codes = [EXIT_CODES[b["verdict"]] for b in self.batches]
        codes = [c for c in codes if c >= fail_on]
        return max(codes) if codes else 0

    @property
    def z_rms(self) -> float:
        """Standardised RMS over the replay (per axis)."""
        return float(np.sqrt(np.mean(self.z ** 2))) if self.z.size else float("nan")

    def summary(self) -> str:
        """One line."""
        flagged = sum(b["verdict"] not in ("holds", "setup_moved") for b in self.batches)
        return (f"monitor: {len(self.error_m)} rows, {len(self.batches)} checks ({flagged} flagged a change), "
                f"{len(self.asks)} requests for poses, standardised RMS {self.z_rms:.2f} (honest within 0.67-1.5), "
                f"mean error {np.mean(self.error_m) * 1e3:.3f} mm, mean predicted sigma "
                f"{np.mean(self.sigma_m) * 1e3:.3f} mm, set-up drift level {self.drift_level_m_per_sqrt_s * 1e9:.3g} "
                f"{self.drift_unit_text()}, {self.outliers} outlier rows, {self.time_per_row_s * 1e3:.1f} ms per row")

    def drift_unit_text(self) -> str:
        """The drift level's unit: nm/sqrt(s) with a time column, else per row (said so)."""
        return "nm/sqrt(s)" if self.timed else "nm/sqrt(row) (no time column: one row taken as one second)"

    def block_text(self) -> str:
        """One line: the standardised RMS of every block of rows ("" without rows)."""
        if not self.blocks:
            return ""
        lo, hi = HONEST_BAND
        return (f"monitor: standardised RMS per block of {BLOCK_ROWS:,} rows (honest within {lo}-{hi}): " + ", ".join(
            f"{b['first_row']}-{b['last_row']} {b['z_rms']:.2f}" for b in self.blocks)
            + f"; outside the band: {sum(not lo <= b['z_rms'] <= hi for b in self.blocks)} of {len(self.blocks)}")

    def to_dict(self) -> dict:
        """Plain JSON-able dict (SI units)."""
        return {**self.result_dict(), "rows": int(len(self.error_m)), "z_rms": self.z_rms, "blocks": self.blocks,
                "error_m": self.error_m.tolist(), "sigma_m": self.sigma_m.tolist(), "batches": self.batches,
                "asks": [{**a, "poses": np.asarray(a["poses"]).tolist()} for a in self.asks],
                "events": self.events, "drift_level_m_per_sqrt_s": self.drift_level_m_per_sqrt_s, "timed": self.timed,
                "outliers": self.outliers, "time_per_row_s": self.time_per_row_s,
                "time_backwards": self.time_backwards, "time_repeated": self.time_repeated,
                "work_source": self.work_source, "exit_code": self.exit_code()}


class Monitor:
    """Rows in, predictions, checks and requests out (module docstring).

    Args:
        model: the calibrated model; station: its station the rows are measured in (default station).
        every: rows per check (≥ 3); max_window: the most rows a check waits for to determine the set-up.
        alpha, tolerance_m: as :func:`check_calibration`.
        refit: also take the re-fitted group of a *robot changed* check (the set-up filter starts anew).
        forgetting: the set-up filter's λ.
        echo: called with each event line (e.g. ``print``), or None.
        seed: seed of the check design's poses.

    Raises:
        InputError: ``every`` below 3.
    """

    def __init__(self, model: CalibratedModel, *, every: int = 10, alpha: float = 0.05, tolerance_m: float = 1e-4,
                 station: str | None = None, max_window: int = 200, refit: bool = False, forgetting: float = 0.995,
                 echo=None, seed: int = 0) -> None:
        if every < 3:
            raise InputError(f"monitor: checks of {every} rows (at least 3)")
        self.every, self.alpha, self.tolerance_m, self.max_window = every, alpha, tolerance_m, max_window
        self.refit, self.forgetting, self.echo, self.seed = refit, forgetting, echo, seed
        self.t0 = time.perf_counter()
        self.busy_s = 0.0
        self.z: list = []
        self.err: list = []
        self.sig: list = []
        self.batches: list = []
        self.asks: list = []
        self.events: list = []
        self.window: list = []
        self.all: MeasurementSet | None = None
        self.next = 0
        self.seen = 0
        self.rejected: set = set()
        self.asking = False
        self.design_Q: np.ndarray | None = None
        self.filter: SetupFilter | None = None
        self.extrapolated: list = []
        self.t_last: float | None = None
        self.t_first: float | None = None
        self.t_constant = False
        self.untimed = False
        self.time_counts = {"backwards": 0, "repeated": 0}
        self.blocks_done = 0
        self.block_list: list = []
        self._use(model, model.station(station))
        if self.work_source:
            self._event(f"monitor: {self.work_source}")

    def _use(self, model: CalibratedModel, label: str) -> None:
        """Follow ``model``'s station ``label``: its measurement model, the set-up Jacobian's columns, the honest σ at
        the working configurations."""
        self.model, self.label = model, label
        self.wm, self.p = model.station_model(label)
        L = self.wm.layout
        self.tcols = np.arange(L.tracker.start, L.tracker.stop)
        self.filter = None
        self.qw, self.work_source = working_configurations(model, self.seed)
        if self.qw is not None:
            s = model.predict_with_sigma(self.qw, station=label)[1]
            self.sigma_w = float(np.sqrt(np.mean(np.sum(s ** 2, axis=1))))
            self.G_w = self.wm.jacobian(self.p, self.qw)[:, :3][:, :, self.tcols]

    def feed(self, rows: MeasurementSet) -> None:
        """Take new rows (in time order): predict, filter, check every ``every`` rows."""
        t = time.perf_counter()
        self.all = rows if self.all is None else _concat(self.all, rows)
        with row_tables():   # a row's discrepancy and coverage, computed once for its prediction and its checks
            while len(self.all) - self.next >= self.every:
                self._chunk(np.arange(self.next, self.next + self.every))
                self.next += self.every
        self.busy_s += time.perf_counter() - t

    def flush(self) -> None:
        """Predict and use the rows that wait for a full check (the end of a replay); a standardised RMS over the
        replay outside :data:`HONEST_BAND` is a warning line with its likely cause; the rows whose time went
        backwards or repeated are counted."""
        if self.all is not None and self.next < len(self.all):
            t = time.perf_counter()
            self._predict(self.all.subset(np.arange(self.next, len(self.all))))
            self.next = len(self.all)
            self.busy_s += time.perf_counter() - t
        if self.z:
            a = self.blocks_done * BLOCK_ROWS
            self.block_list = [k for k in self.block_list if k["last_row"] <= a]    # a partial block: once
            if self.seen > a:
                self._block(a, self.seen)
            self._band(np.asarray(self.z), f"over the {self.seen} rows")
        b, r = self.time_counts["backwards"], self.time_counts["repeated"]
        if b or r:
            self._event(f"warning: {b} row(s) whose time went backwards and {r} whose time repeated the previous row's "
                        "(the set-up filter took no drift between them)")

    def _band(self, z: np.ndarray, where: str) -> None:
        """A warning line when the standardised RMS of ``z`` lies outside :data:`HONEST_BAND`, with its likely cause."""
        rms = float(np.sqrt(np.mean(z ** 2)))
        if HONEST_BAND[0] <= rms <= HONEST_BAND[1]:
            return
        self._event(f"warning: standardised RMS {rms:.2f} {where}, outside the honest {HONEST_BAND[0]}-"
                    f"{HONEST_BAND[1]}: {self._cause(rms)}")

    def _cause(self, rms: float) -> str:
        """The likely cause of an out-of-band standardised RMS, from what the rows show."""
        err = np.asarray(self.err)
        axis_rms = float(np.sqrt(np.mean(err ** 2) / 3.0))
        if rms < HONEST_BAND[0]:
            noise = float(np.sqrt(np.mean(np.square(self.model.noise.sigma_xyz_m))))
            if noise > 0.8 * axis_rms:
                return (f"the sigma is too large: the model's stated noise {noise * 1e3:.3f} mm per axis (identify "
                        f"--sigma) is above the rows' RMS error {axis_rms * 1e3:.3f} mm per axis; calibrate with the "
                        "tracker's own sigma (or without --sigma)")
            return (f"the sigma is too large: the predicted sigma (mean {np.mean(self.sig) * 1e3:.3f} mm) is above the "
                    f"errors (RMS {np.sqrt(np.mean(err ** 2)) * 1e3:.3f} mm): the discrepancy's level or the "
                    "parameters' covariance is overstated for these rows")
        if self.extrapolated and np.mean(self.extrapolated) > 0.5:
            return ("most rows lie outside the training's joint-space coverage (the sigma there extrapolates): "
                    "measure poses there (design --given)")
        if self.filter is not None and self.filter.level_m_per_sqrt_s >= max(self.filter.levels):
            return "the set-up drifts faster than the set-up filter's largest level follows (a tracker knocked?)"
        if any(b["verdict"] not in ("holds", "setup_moved") for b in self.batches):
            return "the checks say the robot or the discrepancy's level changed: measure check design's poses"
        return ("the rows' errors exceed the model's sigma everywhere alike: the robot or the discrepancy's level "
                "changed since the calibration, or the rows are of another tool or tracker")

    def _times(self, data: MeasurementSet) -> list:
        """The rows' times for the set-up filter (None: one second per row), rows whose time goes backwards or repeats
        named (the first :data:`TIME_LINES`, then counted); a time column constant over 10 rows is taken as none."""
        if data.time_s is None:
            self.untimed = True
            return [None] * len(data)
        out = []
        for i, t in enumerate(np.asarray(data.time_s, float)):
            row = self.seen + i + 1
            if self.t_first is None:
                self.t_first = t
            if self.t_last is not None and t <= self.t_last:
                kind = "backwards" if t < self.t_last else "repeated"
                self.time_counts[kind] += 1
                if sum(self.time_counts.values()) <= TIME_LINES:
                    what = "goes backwards from" if kind == "backwards" else "repeats"
                    self._event(f"warning: row {row}: its time {t:.6g} s {what} the previous row's {self.t_last:.6g} s "
                                "(no drift taken between them)")
            if not self.t_constant and row >= 10 and t == self.t_first and self.time_counts["repeated"] >= row - 1:
                self.t_constant = True
                self._event(f"warning: row {row}: the time column is constant ({t:.6g} s): one second per row is "
                            "taken for the set-up's drift")
            self.t_last = t if self.t_last is None else max(self.t_last, t)
            out.append(None if self.t_constant else t)
        return out

    def _predict(self, data: MeasurementSet) -> None:
        """Each row predicted with the filter's state, then used by the filter."""
        Q = align_data(self.model.robot, data)
        Y0, s0, extra = self.model.predict_with_sigma(Q, data, station=self.label)
        self.extrapolated += np.asarray(extra, bool).tolist()
        if self.filter is None:
            self.filter = SetupFilter(lever_m=float(np.median(np.linalg.norm(data.position_m, axis=1))),
                                      forgetting=self.forgetting)
        G = self.wm.jacobian(self.p, Q)[:, :3][:, :, self.tcols]
        times = self._times(data)
        for i in range(len(data)):
            self.filter.advance(times[i])
            mu, C = self.filter.predict(G[i], s0[i])
            r = data.position_m[i] - Y0[i] - mu
            sd = np.sqrt(np.diag(C))
            self.z.append(r / sd)
            self.err.append(float(np.linalg.norm(r)))
            self.sig.append(float(np.linalg.norm(sd)))
            if not self.filter.update(data.position_m[i] - Y0[i], G[i], s0[i]):
                self.rejected.add(self.seen + i)
        self.seen += len(data)
        while self.seen >= (self.blocks_done + 1) * BLOCK_ROWS:
            a = self.blocks_done * BLOCK_ROWS
            self._block(a, a + BLOCK_ROWS)
            self._band(np.asarray(self.z[a:a + BLOCK_ROWS]), f"in rows {a + 1}-{a + BLOCK_ROWS}")
            self.blocks_done += 1

    def _block(self, a: int, b: int) -> None:
        """Record the standardised RMS of rows a+1..b (the rows' z, predicted before use)."""
        z = np.asarray(self.z[a:b])
        self.block_list.append({"first_row": a + 1, "last_row": b, "z_rms": float(np.sqrt(np.mean(z ** 2)))})

    def _chunk(self, idx: np.ndarray) -> None:
        assert self.all is not None
        self._predict(self.all.subset(idx))
        self.window = (self.window + idx.tolist())[-self.max_window:]
        win = self.all.subset(np.asarray(self.window))
        res = check_calibration(self.model, win, station=self.label, alpha=self.alpha, tolerance_m=self.tolerance_m,
                                q_work=self.qw, propose=False)
        if self.qw is None:
            res.power = {}      # no working configurations and no training region: no power to state
        if not res.setup_determined and len(win) < self.max_window:
            return
        self.window = []
        first, last = self.seen - len(win) + 1, self.seen
        jump = res.verdict == "setup_moved" and sum(i in self.rejected for i in range(first - 1, last)) >= len(win) / 2
        updated = jump or (self.refit and res.verdict == "robot_changed" and res.determined)
        if updated:
            self._use(res.model, self.label if res.setup_held else CHECK_STATION)
        sw = self.sigma_work()
        zz = np.asarray(self.z)
        self.batches.append({"first_row": int(first), "last_row": int(last), "verdict": res.verdict, "chi2": res.chi2,
                             "dof": res.dof, "p_value": res.p_value, "group": res.group,
                             "z_rms_so_far": float(np.sqrt(np.mean(zz ** 2))), "updated": bool(updated),
                             "sigma_work_m": sw})
        if res.verdict not in ("holds", "setup_moved") or updated:
            what = "; a jump the set-up filter could not follow: re-registered" if jump else "; model updated"
            self._event(f"rows {first}-{last}: {res.summary()}" + (what if updated else ""))
        self._maybe_ask(res, sw)

    def sigma_work(self) -> float:
        """RMS 3-D σ at the working configurations: the model's honest σ with the set-up filter's share (m), NaN
        without working configurations."""
        if self.qw is None or self.filter is None:
            return float("nan")
        _, P = self.filter.state()
        share = np.einsum("wia,ab,wib->", self.G_w, P, self.G_w) / len(self.qw)
        return float(np.sqrt(self.sigma_w ** 2 + share))

    def _maybe_ask(self, res, sw: float) -> None:
        """Ask for the check design's poses once when a check cannot be followed or the set-up's share at the
        working configurations exceeds the honest σ there; again only after the condition cleared."""
        reason = ""
        if res.verdict in ASK_VERDICTS and not (self.refit and res.determined):
            reason = f"the check says {res.verdict.replace('_', ' ')}"
        elif np.isfinite(sw) and sw > np.sqrt(2.0) * self.sigma_w:
            reason = (f"the rows measured during work no longer pin the set-up: sigma at the working configurations "
                      f"{sw * 1e3:.3f} mm against the model's {self.sigma_w * 1e3:.3f} mm")
        if not reason:
            self.asking = False
            return
        if self.asking:
            return
        self.asking = True
        if self.design_Q is None and self.qw is None:
            self.design_Q = np.zeros((0, self.model.robot.nq))
        if self.design_Q is None:
            from pin_kpi_oed.upkeep.check_design import design_check

            # the poses only: not the poses the verdict needs (``size``: the greedy order grown on, the verdict's
            # power at each length)
            self.design_Q = design_check(self.model, m=10, tolerance_m=self.tolerance_m, alpha=self.alpha,
                                         seed=self.seed, station=self.label, q_work=self.qw, n_random=1,
                                         size=False).Q
        self.asks.append({"row": int(self.seen), "reason": reason, "poses": self.design_Q})
        what = (f"measure the {len(self.design_Q)} poses of 'check design' (in the JSON log)" if len(self.design_Q)
                else "measure the poses of 'check design' (the model has no working configurations: give them)")
        self._event(f"row {self.seen}: {reason}: {what}")

    def _event(self, line: str) -> None:
        self.events.append(line)
        if self.echo is not None:
            self.echo(line)

    def log(self) -> MonitorLog:
        """The log so far; its model has the set-up filter's state applied to the followed station."""
        cur = self.model
        if self.filter is not None:
            x, _ = self.filter.state()
            st = cur.setups[self.label]
            T = (pin.SE3(st.tracker_T_base) * pin.exp6(x)).homogeneous
            cur = cur.with_setup(self.label, dataclasses.replace(st, tracker_T_base=T), default=True,
                                 step={"step": "monitor", "rows": int(self.seen), "setup_correction": x.tolist()})
        z = np.asarray(self.z).reshape(-1, 3)
        return MonitorLog(z=z, error_m=np.asarray(self.err), sigma_m=np.asarray(self.sig), batches=self.batches,
                          asks=self.asks, events=self.events, model=cur,
                          drift_level_m_per_sqrt_s=self.filter.level_m_per_sqrt_s if self.filter else 0.0,
                          outliers=self.filter.outliers if self.filter else 0,
                          time_backwards=self.time_counts["backwards"], time_repeated=self.time_counts["repeated"],
                          work_source=self.work_source, timed=not (self.untimed or self.t_constant),
                          blocks=list(self.block_list),
                          time_per_row_s=self.busy_s / max(self.seen, 1), success=True, status="monitored",
                          message=f"{len(self.batches)} checks of {self.every} rows or more",
                          time_s=time.perf_counter() - self.t0)


def _concat(a: MeasurementSet, b: MeasurementSet) -> MeasurementSet:
    """Rows of a, then of b (one station: no station column when neither has one)."""
    from pin_kpi_oed.data.measurements import concat_measurements

    out = concat_measurements([a, b], ["a", "b"], source=a.source)
    return dataclasses.replace(out, station=None) if a.station is None and b.station is None else out


def monitor(model: CalibratedModel, data: MeasurementSet, **options) -> MonitorLog:
    """Replay ``data`` in its order (time order) through a :class:`Monitor` (its options by name).

    Raises:
        InputError: ``every`` below 3 or fewer rows than one check.
    """
    every = int(options.get("every", 10))
    if len(data) < every:
        raise InputError(f"{data.source or 'monitor data'}: {len(data)} rows, checks of {every} rows (at least 3, and "
                         f"at least one check's rows)")
    mon = Monitor(model, **options)
    with row_tables():
        mon.feed(data)
        mon.flush()
    return mon.log()


def working_configurations(model: CalibratedModel, seed: int = 0, n: int = 20) -> tuple[np.ndarray | None, str]:
    """The configurations the monitor's checks state their TCP σ and power at, and a line saying where they come
    from when not the model's own working configurations ("" then): without them the training's region (``n``
    seeded configurations of the training's joint-space coverage), else None (no power is stated)."""
    if model.q_work is not None:
        return np.atleast_2d(model.q_work), ""
    cov = model.coverage if model.coverage is not None else getattr(model.discrepancy, "coverage", None)
    Z = getattr(cov, "Z", None)
    if Z is None or len(Z) == 0:
        return None, ("the model has no working configurations and no training region: the checks state no power "
                      "(give working configurations to identify, or a cell)")
    pick = np.sort(np.random.default_rng(seed).choice(len(Z), min(n, len(Z)), replace=False))
    return np.asarray(Z)[pick], (f"the model has no working configurations: the checks state the TCP sigma and power "
                                 f"over the training's region ({len(pick)} seeded configurations of its coverage)")
