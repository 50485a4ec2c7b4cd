"""Design files: the JSON a design run writes (``pin-kpi-oed design --json``), read tolerantly.

:func:`load_design` turns a design JSON (or its dict) into a :class:`DesignFile`: the measurement
model of the set-up (robot, tracker, reflector, TCP, noise, fixed parameters and prior, as
:mod:`pin_kpi_oed.model.serialize` reads them), the :class:`~pin_kpi_oed.cell.cell.Cell` it was
designed in (the same cell model the optimiser and the independent check use), and the designs.
The viewer, the report figures and ``pin-kpi-oed view`` read designs through it.

The cell ``design --json`` stores (its ``cell`` block, with the viewer's copies of the capsules, obstacles,
half-spaces and working configurations at the top level) is read by the cell file's reader
(:func:`~pin_kpi_oed.cell.cell.cell_from_dict`: the checks of ``load_cell``, a damaged field refused with its name;
:func:`~pin_kpi_oed.design.design_cell.read_stored_cell`).

Tolerant reading: hand-written or older files may leave out most of the cell. Every field is
looked up at the top level, then under ``cell``;
alias keys are accepted (``a``/``a_m``, ``radius``/``radius_m``, ...); what is assumed or
recomputed is said in :attr:`DesignFile.notes` (one line each):

* no ``tracker_T_base``: the tracker sits at the robot base;
* no ``q_work``: the robot's neutral configuration;
* no robot capsules: the URDF's collision cylinders (:func:`~pin_kpi_oed.cell.cell.capsules_from_urdf`);
* a file without skip lists: capsule pairs in collision at *every* working configuration *and* in most
  random configurations (enclosing capsules that overlap by construction, a robot standing on its floor)
  are added to ``skip_pairs``, and such beam blockers to the beam's skip list; a file with skip lists
  gets nothing added. A working configuration that collides otherwise is never skipped: it is noted and
  kept in :attr:`DesignFile.work_collisions` (``export`` refuses it unless ``--force``);
* a stored ``cov_s_m2`` is checked against the one its ``q_meas`` give (the file's numbers are not
  trusted; a mismatch is noted and the recomputed one used, a singular design gets NaN); a missing or
  mis-shaped ``cov_s_m2`` is recomputed with :func:`pin_kpi_oed.oed.evaluate.score_design`
  (the same C_s as ``design --json`` and ``evaluate`` write, eq. 19, with the file's prior).

Frames and units: SI. ``world_T_base`` (default identity) places the robot base in the world
(cell) frame, ``tracker_T_base`` the base in the tracker frame. Obstacles and half-spaces are in
the world frame, robot capsules in their link frames; a half-space ``{"normal": n, "offset": d}``
is the free region ``n·x >= d`` (or ``{"normal": n, "point": p}``: ``n·(x - p) >= 0``).
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from functools import cached_property
from typing import Any
from collections.abc import Mapping, Sequence

import numpy as np
import pinocchio as pin

from pin_kpi_oed.cell.cell import Cell, CapsuleSpec, HalfSpace
from pin_kpi_oed.cell.feasibility import FeasibilityChecker
from pin_kpi_oed.design.design_cell import (Fields, read_array, read_cell, read_json, read_model, read_stored_cell,
                                            skip_what_collides_at_work, stored_cell)
from pin_kpi_oed.design.design_writer import design_document, write_design
from pin_kpi_oed.errors import InputError, PinKpiOedError
from pin_kpi_oed.model.tracker import TrackerModel
from pin_kpi_oed.model.robot import Robot
from pin_kpi_oed.threads import limit_threads
from pin_kpi_oed.validation.schema import validate_design_dict

__all__ = ["DESIGN_LABELS", "DesignEntry", "DesignFile", "load_design", "design_document", "write_design"]

#: Readable names of the usual criteria (a design entry's own ``label`` wins).
DESIGN_LABELS: dict[str, str] = {"random": "heuristic", "param": "A on C_p", "kpi": "KPI (A on C_s)"}

@dataclass
class DesignEntry:
    """One design of a design file.

    Attributes:
        criterion: criterion name as in the file (``random``, ``param``, ``kpi``, ...).
        label: readable name.
        q_meas: measurement configurations (m, n) rad.
        cov_s_m2: TCP covariance C_s (3t, 3t) m², tracker frame.
        trace_cs_m2: tr(C_s) (m²).
        cov_source: ``file`` or ``computed`` (recomputed because the file has none).
        info: every other field of the design entry, as read.
        cov_s_honest_m2: the honest C_s (3t, 3t) m², tracker frame like ``cov_s_m2``: the universal-kriging
            covariance with the model discrepancy included (``designs[i].discrepancy.cov_s_m2``, written by
            ``design --model``), or None (older files, no discrepancy).
    """

    criterion: str
    label: str
    q_meas: np.ndarray
    cov_s_m2: np.ndarray
    trace_cs_m2: float
    cov_source: str
    info: dict = field(default_factory=dict)
    cov_s_honest_m2: np.ndarray | None = None

    def covariance(self, honest: bool) -> np.ndarray:
        """C_s (3t, 3t) m², tracker frame: the honest one (discrepancy included) when asked and present, else the
        paper's (tracker noise only)."""
        return self.cov_s_honest_m2 if honest and self.cov_s_honest_m2 is not None else self.cov_s_m2


@dataclass
class DesignFile:
    """A design JSON, parsed tolerantly (see :func:`load_design`).

    Attributes:
        model: the tracker measurement model (robot, tracker_T_base, reflector, TCP, noise, prior).
        cell: the cell the designs live in (robot capsules, obstacles, half-spaces, skip lists,
            beam, incidence limit, clearance, joint bounds, working configurations).
        designs: the designs.
        notes: what was assumed or recomputed (one line each).
        source: file name (or ``<dict>``).
        raw: the parsed JSON.
        work_collisions: working configurations in collision (one line each; never skipped: ``export``
            refuses them unless ``--force``).
    """

    model: TrackerModel
    cell: Cell
    designs: list[DesignEntry]
    notes: list[str] = field(default_factory=list)
    source: str = "<dict>"
    raw: dict = field(default_factory=dict)
    work_collisions: list[str] = field(default_factory=list)

    @property
    def robot(self) -> Robot:
        """The robot."""
        return self.model.robot

    @property
    def world_T_base(self) -> pin.SE3:
        """Pose of the robot base in the world (cell) frame."""
        return self.cell.W_T_base

    @property
    def world_T_tracker(self) -> pin.SE3:
        """Pose of the tracker in the world frame."""
        return self.cell.W_T_tracker

    @property
    def q_work(self) -> np.ndarray:
        """Working configurations (t, n) rad."""
        return self.cell.q_work

    @property
    def capsules(self) -> list[CapsuleSpec]:
        """Robot capsules (link frames)."""
        return self.cell.robot_capsules

    @property
    def obstacles(self) -> list[CapsuleSpec]:
        """Obstacle capsules (world frame)."""
        return self.cell.obstacles

    @property
    def half_spaces(self) -> list[HalfSpace]:
        """Half-spaces (world frame)."""
        return self.cell.half_spaces

    @property
    def incidence_limit_deg(self) -> float:
        """Laser incidence limit (deg, eq. 4)."""
        return self.cell.incidence_max_deg

    @cached_property
    def checker(self) -> FeasibilityChecker:
        """The independent dense check of the cell (Pinocchio + Coal)."""
        return FeasibilityChecker(self.cell)

    def pose_clearance(self, Q: np.ndarray) -> np.ndarray:
        """Smallest clearance (m) of each configuration over every checked pair, the beam included.

        The same value as the design table's ``min clr`` (:class:`FeasibilityChecker`): robot capsules
        against each other (non-adjacent links), obstacles and half-spaces, the beam against all of them,
        minus the cell's required clearance. Negative = penetration; ``inf`` when nothing is checked.
        """
        return self.checker.check(Q).clearance_m

    def to_world(self, Y_tracker: np.ndarray) -> np.ndarray:
        """Points (k, 3) from the tracker frame to the world frame (m)."""
        T = self.world_T_tracker
        return np.atleast_2d(Y_tracker) @ T.rotation.T + T.translation

    def tcp_world(self, Q: np.ndarray | None = None) -> np.ndarray:
        """TCP positions (k, 3) in the world frame at configurations Q (default the working ones), m."""
        Q = self.q_work if Q is None else Q
        return self.to_world(self.model.kpi(np.zeros(self.model.n_params), Q))

    def reflector_world(self, Q: np.ndarray) -> np.ndarray:
        """Reflector positions (k, 3) in the world frame (m)."""
        return self.to_world(self.model.predict(np.zeros(self.model.n_params), Q)[:, :3])

    def incidence_deg(self, Q: np.ndarray) -> np.ndarray:
        """Laser incidence angle of every configuration (deg, eq. 4)."""
        c = self.model.incidence_cos(np.zeros(self.model.n_params), Q)
        return np.degrees(np.arccos(np.clip(c, -1.0, 1.0)))

    @property
    def default_criterion(self) -> str:
        """The design a command takes when none is named (``export``, ``simulate --design``, ``evaluate``): the
        file's ``q_meas`` design (``q_meas_criterion``: the ``kpi`` design, else the last one the run made), else
        the file's last design.

        Raises:
            InputError: the file holds no design.
        """
        named = self.raw.get("q_meas_criterion") if isinstance(self.raw, Mapping) else None
        if named and any(d.criterion == named for d in self.designs):
            return str(named)
        if not self.designs:
            raise InputError(f"{self.source}: holds no design")
        return self.designs[-1].criterion

    def design(self, criterion: str) -> DesignEntry:
        """The design of a criterion.

        Raises:
            InputError: no such design (the known ones are listed).
        """
        for d in self.designs:
            if d.criterion == criterion:
                return d
        raise InputError(f"{self.source}: no design '{criterion}' (designs: "
                         f"{', '.join(d.criterion for d in self.designs)})")


# ============================================================================ tolerant field access
def _raw_designs(d: Mapping, where: str) -> list:
    """The design entries: ``designs`` (a list or {criterion: entry}) or a top-level ``q_meas``."""
    raw = d.get("designs")
    if raw is None and "q_meas" in d:
        raw = [{"criterion": d.get("criterion", "design"),
                **{k: d[k] for k in d if k in ("q_meas", "cov_s_m2", "trace_cs_m2")}}]
    if not raw:
        raise InputError(f"{where}: no designs (field 'designs': list of {{criterion, q_meas, ...}})")
    if isinstance(raw, Mapping):
        raw = [dict(v, criterion=v.get("criterion", k)) for k, v in raw.items()]
    return list(raw)


class _Covariances:
    """C_s of designs whose file has none: :func:`~pin_kpi_oed.oed.evaluate.score_design` (one identifiability
    analysis)."""

    def __init__(self, model: TrackerModel, q_work: np.ndarray):
        self.model, self.q_work = model, q_work
        self.ident: Any = None

    def __call__(self, Q: np.ndarray) -> np.ndarray:
        from pin_kpi_oed.oed.evaluate import score_design
        from pin_kpi_oed.oed.identifiability import analyse

        self.ident = analyse(self.model) if self.ident is None else self.ident
        return score_design(self.model, Q, self.q_work, self.ident).cov_s_m2


def _read_design(e: Mapping, crit: str, w: str, cell: Cell, covariances: _Covariances, compute_missing: bool,
                 notes: list[str]) -> DesignEntry:
    """One design entry: configurations (checked against the cell's bounds), C_s (read or recomputed)."""
    robot, t = cell.robot, cell.q_work.shape[0]
    if e.get("q_meas") is None:
        raise InputError(f"{w} ({crit}): missing field 'q_meas' (m x {robot.nq} joint values, rad)")
    Q = np.atleast_2d(read_array(e["q_meas"], None, f"{w}.q_meas"))
    if Q.shape[1] != robot.nq:
        raise InputError(f"{w}.q_meas: {Q.shape[1]} joint values per configuration, {robot.name} has {robot.nq}")
    out = (Q < cell.q_lower - 1e-9) | (Q > cell.q_upper + 1e-9)
    if out.any():
        k, j = np.argwhere(out)[0]
        notes.append(f"design {crit}: {int(out.any(axis=1).sum())} configuration(s) outside the joint "
                     f"limits (first: #{k}, {robot.joint_names[j]} = {Q[k, j]:.4g} rad)")
    C, source = e.get("cov_s_m2"), "file"
    if C is not None:
        C = np.asarray(C, dtype=float)
        if C.shape != (3 * t, 3 * t):
            notes.append(f"design {crit}: cov_s_m2 has shape {C.shape}, expected {(3 * t, 3 * t)}: recomputed")
            C = None
        elif not np.all(np.isfinite(C)):
            notes.append(f"design {crit}: cov_s_m2 contains NaN or inf: recomputed")
            C = None
    stored = C
    if C is None or compute_missing:  # never trust stored numbers the file's poses do not give
        if C is None and not compute_missing:
            raise InputError(f"{w} ({crit}): missing field 'cov_s_m2' (3t x 3t TCP covariance, m^2)")
        try:
            C = covariances(Q)
        except PinKpiOedError as exc:
            if stored is None:
                raise type(exc)(f"{w} ({crit}): {exc}") from None
            notes.append(f"design {crit}: its q_meas do not determine C_s ({exc}); the stored cov_s_m2 is not "
                         "shown")
            C = np.full_like(stored, np.nan)
        source = "computed"
        if stored is not None and np.all(np.isfinite(C)):
            gap = float(np.max(np.abs(stored - C))) / max(float(np.max(np.abs(C))), 1e-300)
            if gap > 1e-6:
                notes.append(f"design {crit}: stored cov_s_m2 differs from the one its q_meas give (relative "
                             f"{gap:.2g}): the recomputed one is shown")
            else:
                source = "file"
    elif stored is not None:
        sym = 0.5 * (C + C.T)
        if np.max(np.abs(C - C.T)) > 1e-9 * max(np.max(np.abs(C)), 1e-300) or np.linalg.eigvalsh(sym)[0] < \
                -1e-9 * max(np.max(np.abs(C)), 1e-300):
            raise InputError(f"{w} ({crit}).cov_s_m2: not a covariance (not symmetric positive semi-definite)")
    tr = e.get("trace_cs_m2")
    tr = float(tr) if (source == "file" and isinstance(tr, (int, float)) and np.isfinite(tr)) else float(np.trace(C))
    info = {k: v for k, v in e.items() if k not in ("q_meas", "cov_s_m2")}
    return DesignEntry(crit, str(e.get("label") or DESIGN_LABELS.get(crit, crit)), Q, C, tr, source, info,
                       _honest_covariance(e, crit, t, notes))


def _honest_covariance(e: Mapping, crit: str, t: int, notes: list[str]) -> np.ndarray | None:
    """``discrepancy.cov_s_m2`` of a design entry (3t × 3t m², tracker frame), or None (absent, or unusable: noted)."""
    disc = e.get("discrepancy")
    if not isinstance(disc, Mapping) or disc.get("cov_s_m2") is None:
        return None
    try:
        C = np.asarray(disc["cov_s_m2"], dtype=float)
    except (TypeError, ValueError):
        C = np.zeros(0)
    if C.shape != (3 * t, 3 * t) or not np.all(np.isfinite(C)):
        notes.append(f"design {crit}: discrepancy.cov_s_m2 is not a finite {3 * t} x {3 * t} matrix: the paper's "
                     "C_s is shown")
        return None
    big = max(float(np.max(np.abs(C))), 1e-300)
    if np.max(np.abs(C - C.T)) > 1e-9 * big or np.linalg.eigvalsh(0.5 * (C + C.T))[0] < -1e-9 * big:
        notes.append(f"design {crit}: discrepancy.cov_s_m2 is not symmetric positive semi-definite: the paper's "
                     "C_s is shown")
        return None
    return C


def _read_designs(d: Mapping, cell: Cell, model: TrackerModel, where: str, criteria: Sequence[str] | None,
                  compute_missing: bool, notes: list[str]) -> list[DesignEntry]:
    """The designs kept (``criteria``: only these, in this order)."""
    raw = _raw_designs(d, where)
    covariances = _Covariances(model, cell.q_work)
    designs = []
    for i, e in enumerate(raw):
        w = f"{where}: designs[{i}]"
        if not isinstance(e, Mapping):
            raise InputError(f"{w}: expected an object with criterion and q_meas")
        crit = str(e.get("criterion") or e.get("name") or f"design{i}")
        if not criteria or crit in criteria:
            designs.append(_read_design(e, crit, w, cell, covariances, compute_missing, notes))
    if criteria:
        missing = [c for c in criteria if c not in {dv.criterion for dv in designs}]
        if missing:
            raise InputError(f"{where}: no design '{missing[0]}' (designs: "
                             f"{', '.join(str(e.get('criterion')) for e in raw if isinstance(e, Mapping))})")
        designs.sort(key=lambda dv: list(criteria).index(dv.criterion))
    computed = [dv.criterion for dv in designs if dv.cov_source == "computed"]
    if computed:
        notes.append("C_s recomputed with pin_kpi_oed for: " + ", ".join(computed))
    return designs


@limit_threads  # C_s recomputed (an identifiability analysis: QR, lstsq) with every BLAS thread on a busy machine
def load_design(source: str | os.PathLike | Mapping, criteria: Sequence[str] | None = None,
                compute_missing: bool = True) -> DesignFile:
    """Read a design JSON (or dict) tolerantly (see the module docstring).

    Fields read (anything else is ignored; ``cell.<field>`` is looked up too):

    * ``robot``: a name or ``{"urdf_path", "tool_frame", "name"}``; a ``urdf_path`` that does not exist
      (file moved) falls back to ``name``;
    * ``tracker_T_base`` (4×4, m), ``world_T_base`` / ``W_T_base`` (4×4, default identity), ``reflector_m``,
      ``tcp_m``, ``noise``, ``fixed``, ``prior`` (as :mod:`pin_kpi_oed.model.serialize`);
    * ``q_work`` (t × n, rad; default the robot's neutral configuration), ``q_lower_rad`` / ``q_upper_rad``;
    * ``capsules`` (robot, per link: ``link``, ``a``, ``b``, ``radius``; default from the URDF's collision
      cylinders), ``obstacles`` (capsules / spheres), ``half_spaces``, ``skip_pairs``, ``beam``
      (``radius_m``, ``skip``), ``incidence_limit_deg`` / ``incidence_max_deg`` (default 30), ``clearance_m``;
    * ``designs``: list of ``{criterion, q_meas (m × n rad), cov_s_m2 (3t × 3t m², tracker frame),
      trace_cs_m2, label, discrepancy, ...}``, or a single design given by a top-level ``q_meas``; optional
      ``discrepancy.cov_s_m2`` (3t × 3t m², tracker frame, written by ``design --model``): the honest C_s, model
      discrepancy included (:attr:`DesignEntry.cov_s_honest_m2`; unusable ones are noted and ignored).

    Args:
        source: path of the JSON file, or the parsed dict.
        criteria: keep only these designs (by criterion name), in this order.
        compute_missing: recompute a missing C_s (else a missing ``cov_s_m2`` is an error).

    Returns:
        The :class:`DesignFile`.

    Raises:
        InputError: unreadable file, or a missing / invalid field (named with the file).
        RobotLoadError: the robot cannot be loaded.
        IdentifiabilityError: a C_s to recompute is not determined by the design's measurements.
    """
    d, where, base_dir = read_json(source)
    validate_design_dict(d, where)
    f = Fields(d)
    notes: list[str] = []
    model = read_model(f, where, base_dir, notes)
    stored = stored_cell(d)
    cell = read_cell(f, model, where, notes) if stored is None else read_stored_cell(f, stored, model, where, notes)
    has_skips = any(k in d or k in (d.get("cell") if isinstance(d.get("cell"), Mapping) else {})
                    for k in ("skip_pairs", "pairs_to_skip", "ignore_pairs"))
    work_collisions = skip_what_collides_at_work(cell, notes, has_skips)
    designs = _read_designs(d, cell, model, where, criteria, compute_missing, notes)
    return DesignFile(model, cell, designs, notes, where, d, work_collisions)
