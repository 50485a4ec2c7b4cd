"""Meshcat preview of a measurement design: cell, poses, laser beam and KPI confidence ellipsoids.

Engineers check measurement poses by eye before running them on a real robot.
:func:`build_scene` turns a design JSON (``pin-kpi-oed design --json``, see
:func:`load_design` for the fields read) into a meshcat scene:

* the cell: floor / wall (half-spaces, drawn as thin slabs on the forbidden side
  of their boundary plane), obstacles (capsules, spheres, boxes), the laser tracker;
* the robot, drawn from its URDF visuals through Pinocchio's
  :class:`pinocchio.visualize.MeshcatVisualizer` (meshes where the URDF has them,
  URDF primitives otherwise, and the cell's capsules - or a stick figure - when
  the URDF has no visual geometry), standing at the first working configuration;
* an animation (meshcat's *Animations* panel: play / time slider) that steps the
  robot and the laser beam through every measurement configuration, design after
  design; ``ghosts/<design>/<k>``: all measurement configurations at once, ghosted
  in the design's colour;
* ``robot/collisions``: the robot's capsules (hidden; tick the box to show them);
* ``beam``: the laser beam from the tracker to the reflector;
* ``ellipsoids/<design>/w<j>``: at each working configuration, the TCP's 95 %
  confidence ellipsoid of every design, side by side in the design's colour,
  magnified by a displayed factor (``ellipsoids/label``, the page's legend) so
  that µm-level ellipsoids are visible; a black dot marks the nominal TCP.

``Scene.static_html(pose=("kpi", 5))`` opens the page paused at one measurement configuration;
:func:`render_png` screenshots a page with headless Chromium (``docs/make_screenshot.py``).

The scene is recorded in process by :class:`SceneRecorder`, a meshcat window that
keeps meshcat's scene tree itself (no server, no ports) and produces the same
self-contained static page as a meshcat server (``Visualizer.static_html()``,
the viewer's JavaScript inlined, so the page opens offline). :func:`serve` replays
the scene into a live meshcat server for interactive viewing.

Frames: the scene's world frame is the cell frame; ``world_T_base`` (optional,
default identity) places the robot base in it, ``tracker_T_base`` the base in the
tracker frame. Obstacles and half-spaces are in the world frame, robot capsules in
their link frames. Half-space ``{"normal": n, "offset": d}`` is the free region
``n·x >= d`` (or ``{"normal": n, "point": p}``: ``n·(x - p) >= 0``). All units SI.
"""

from __future__ import annotations

import base64
import html as html_mod
import json
import os
import re
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np
import pinocchio as pin

from pin_kpi_oed.errors import InfeasibleError, InputError, PinKpiOedError, RobotLoadError
from pin_kpi_oed.model.noise import NoiseModel
from pin_kpi_oed.model.tracker import TrackerModel
from pin_kpi_oed.model.robot import Robot, load_robot

#: Colours (0xRRGGBB) of the usual design criteria; the robot itself is orange, so none of these is.
DESIGN_COLOURS: dict[str, int] = {
    "random": 0x1F77B4,     # heuristic: blue
    "heuristic": 0x1F77B4,
    "param": 0x9467BD,      # A on C_p: purple
    "kpi": 0x2CA02C,        # A on C_s (the paper's KPI design): green
}
#: Colours handed out, in order, to any other criterion.
EXTRA_COLOURS: tuple[int, ...] = (0x17BECF, 0xE377C2, 0x7F7F7F, 0xBCBD22, 0x8C564B, 0x393B79, 0x637939)
#: Human-readable names of the usual criteria.
DESIGN_LABELS: dict[str, str] = {"random": "heuristic", "param": "A on C_p", "kpi": "KPI (A on C_s)"}

BEAM_COLOUR = 0xE41A1C
CAPSULE_RGBA = np.array([0.1, 0.75, 0.95, 0.35])
DEFAULT_LEVEL = 0.95
#: Vertical field of view (deg) of meshcat's default perspective camera (viewer/dist/main.min.js).
MESHCAT_FOV_DEG = 75.0


# ============================================================================ design file
@dataclass
class Capsule:
    """A capsule: segment a-b (m) of radius ``radius`` (m); ``link`` = frame it is attached to (None = world)."""

    a: np.ndarray
    b: np.ndarray
    radius: float
    link: str | None = None
    name: str = ""


@dataclass
class HalfSpace:
    """Free region ``normal · x >= offset`` (world frame, m); the obstacle is the other side."""

    normal: np.ndarray
    offset: float
    name: str = ""


@dataclass
class Obstacle:
    """A world-frame obstacle: ``kind`` in capsule / sphere / box.

    capsule: ``a``, ``b``, ``radius``; sphere: ``center``, ``radius``; box: ``center``, ``size`` (full
    edge lengths), ``rotation`` (3×3).
    """

    kind: str
    name: str
    a: np.ndarray | None = None
    b: np.ndarray | None = None
    radius: float = 0.0
    center: np.ndarray | None = None
    size: np.ndarray | None = None
    rotation: np.ndarray | None = None

    def capsule(self) -> Capsule | None:
        """The obstacle as a capsule (spheres are capsules of zero length), None for boxes."""
        if self.kind == "capsule":
            return Capsule(self.a, self.b, self.radius, None, self.name)
        if self.kind == "sphere":
            return Capsule(self.center, self.center, self.radius, None, self.name)
        return None


@dataclass
class DesignView:
    """One design of the file, ready to display.

    Attributes:
        criterion: criterion name as in the file (``random``, ``param``, ``kpi``, ...).
        label: readable name; colour: 0xRRGGBB.
        q_meas: measurement configurations (m, n) rad.
        cov_s_m2: TCP covariance (3t, 3t) m², tracker frame.
        trace_cs_m2: tr(C_s) (m²).
        cov_source: ``file`` or ``computed`` (recomputed with pin_kpi_oed when absent).
        info: every other field of the design entry, as read.
    """

    criterion: str
    label: str
    colour: int
    q_meas: np.ndarray
    cov_s_m2: np.ndarray
    trace_cs_m2: float
    cov_source: str
    info: dict = field(default_factory=dict)

    @property
    def key(self) -> str:
        """Scene-path-safe name."""
        return _slug(self.criterion)


@dataclass
class DesignFile:
    """A design JSON, parsed tolerantly (see :func:`load_design`).

    Attributes:
        model: the tracker measurement model (robot, tracker_T_base, reflector, TCP, noise).
        world_T_base: pose of the robot base in the world (cell) frame.
        q_work: working configurations (t, n) rad.
        capsules: robot capsules (link frames); obstacles, half_spaces: world frame.
        skip_pairs: robot capsule pairs (link names) not checked for self-collision.
        incidence_limit_deg: laser incidence limit (deg).
        designs: the designs.
        notes: what was assumed or recomputed (one line each).
        source: file name (or ``<dict>``).
    """

    model: TrackerModel
    world_T_base: pin.SE3
    q_work: np.ndarray
    capsules: list[Capsule]
    obstacles: list[Obstacle]
    half_spaces: list[HalfSpace]
    skip_pairs: list[tuple[str, str]]
    incidence_limit_deg: float
    designs: list[DesignView]
    notes: list[str] = field(default_factory=list)
    source: str = "<dict>"
    raw: dict = field(default_factory=dict)

    @property
    def robot(self) -> Robot:
        return self.model.robot

    @property
    def world_T_tracker(self) -> pin.SE3:
        """Pose of the tracker in the world frame."""
        return self.world_T_base * self.model.tracker_T_base.inverse()

    def to_world(self, Y_tracker: np.ndarray) -> np.ndarray:
        """Points (k, 3) from the tracker frame to the world frame (m)."""
        T = self.world_T_tracker
        return np.atleast_2d(Y_tracker) @ T.rotation.T + T.translation

    def tcp_world(self, Q: np.ndarray | None = None) -> np.ndarray:
        """TCP positions (k, 3) in the world frame at configurations Q (default the working ones)."""
        Q = self.q_work if Q is None else Q
        return self.to_world(self.model.kpi(np.zeros(self.model.n_params), Q))

    def reflector_world(self, Q: np.ndarray) -> np.ndarray:
        """Reflector positions (k, 3) in the world frame (m)."""
        return self.to_world(self.model.predict(np.zeros(self.model.n_params), Q)[:, :3])

    def incidence_deg(self, Q: np.ndarray) -> np.ndarray:
        """Laser incidence angle of every configuration (deg, eq. 4)."""
        c = self.model.incidence_cos(np.zeros(self.model.n_params), Q)
        return np.degrees(np.arccos(np.clip(c, -1.0, 1.0)))

    def design(self, criterion: str) -> DesignView:
        for d in self.designs:
            if d.criterion == criterion:
                return d
        raise InputError(f"{self.source}: no design '{criterion}' (designs: "
                         f"{', '.join(d.criterion for d in self.designs)})")


def _slug(name: str) -> str:
    s = re.sub(r"[^A-Za-z0-9_.-]+", "_", str(name)).strip("_")
    return s or "design"


def _arr(v: Any, shape: tuple[int, ...] | None, what: str) -> np.ndarray:
    try:
        a = np.asarray(v, dtype=float)
    except (TypeError, ValueError):
        raise InputError(f"{what}: expected numbers, got {str(v)[:60]!r}") from None
    if shape is not None:
        if a.size == int(np.prod(shape)):
            a = a.reshape(shape)
        else:
            raise InputError(f"{what}: expected shape {shape}, got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise InputError(f"{what}: contains NaN or inf")
    return a


def _first(d: Mapping, *keys: str, default: Any = None) -> Any:
    for k in keys:
        if k in d and d[k] is not None:
            return d[k]
    return default


def _se3(T: Any, what: str) -> pin.SE3:
    from pin_kpi_oed.model.serialize import se3_from_matrix

    return se3_from_matrix(T, what)


def _parse_capsules(items: Any, where: str) -> list[Capsule]:
    """Robot capsules: list of {link, a, b, radius} or {link: [{a, b, radius}, ...]}."""
    out: list[Capsule] = []
    if isinstance(items, Mapping):
        items = [dict(c, link=link) for link, cs in items.items() for c in (cs if isinstance(cs, list) else [cs])]
    for i, c in enumerate(items or []):
        w = f"{where}[{i}]"
        if not isinstance(c, Mapping):
            raise InputError(f"{w}: expected an object with link, a, b, radius")
        a = _arr(_first(c, "a_m", "a", "p0", "start"), (3,), f"{w}.a_m")
        b = _arr(_first(c, "b_m", "b", "p1", "end", default=a), (3,), f"{w}.b_m")
        r = float(_arr(_first(c, "radius_m", "radius", "r"), (1,), f"{w}.radius_m")[0])
        link = _first(c, "link", "frame", "parent")
        out.append(Capsule(a, b, r, str(link) if link is not None else None,
                           str(_first(c, "name", default=f"{link or 'capsule'}_{i}"))))
    return out


def _parse_obstacles(items: Any, where: str) -> list[Obstacle]:
    out: list[Obstacle] = []
    for i, o in enumerate(items or []):
        w = f"{where}[{i}]"
        if not isinstance(o, Mapping):
            raise InputError(f"{w}: expected an object (capsule: a, b, radius; sphere: center, radius; "
                             "box: center, size)")
        kind = str(_first(o, "type", "kind", "shape", default="")).lower()
        if not kind:
            kind = "capsule" if ("a" in o or "a_m" in o or "p0" in o) else "box" if "size" in o else "sphere"
        name = _slug(_first(o, "name", default=f"{kind}_{i}"))
        if kind in ("capsule", "cylinder", "segment"):
            a = _arr(_first(o, "a_m", "a", "p0", "start"), (3,), f"{w}.a_m")
            b = _arr(_first(o, "b_m", "b", "p1", "end", default=a), (3,), f"{w}.b_m")
            out.append(Obstacle("capsule", name, a=a, b=b,
                                radius=float(_arr(_first(o, "radius_m", "radius", "r"), (1,), f"{w}.radius_m")[0])))
        elif kind in ("sphere", "point"):
            c = _arr(_first(o, "center_m", "center", "centre", "c", "a_m", "a"), (3,), f"{w}.center")
            out.append(Obstacle("sphere", name, center=c, radius=float(
                _arr(_first(o, "radius_m", "radius", "r", default=0.0), (1,), f"{w}.radius_m")[0])))
        elif kind in ("box", "cuboid"):
            c = _arr(_first(o, "center_m", "center", "centre", "c"), (3,), f"{w}.center")
            s = _arr(_first(o, "size_m", "size", "lengths", "extent"), (3,), f"{w}.size")
            R = _arr(_first(o, "rotation", "R", default=np.eye(3)), (3, 3), f"{w}.rotation")
            out.append(Obstacle("box", name, center=c, size=s, rotation=R))
        else:
            raise InputError(f"{w}: unknown obstacle type '{kind}' (capsule, sphere, box)")
    return out


def _parse_half_spaces(items: Any, where: str) -> list[HalfSpace]:
    """Half-spaces: {normal, offset} (free where normal·x >= offset), {normal, point}, or [nx, ny, nz, offset]."""
    out: list[HalfSpace] = []
    for i, h in enumerate(items or []):
        w = f"{where}[{i}]"
        name = None
        if isinstance(h, Mapping):
            n = _arr(_first(h, "normal", "n"), (3,), f"{w}.normal")
            if "point" in h:
                d = float(n @ _arr(h["point"], (3,), f"{w}.point"))
            else:
                d = float(_arr(_first(h, "offset", "d", "offset_m", default=0.0), (1,), f"{w}.offset")[0])
            name = _first(h, "name")
        else:
            a = _arr(h, (4,), w)
            n, d = a[:3], float(a[3])
        nn = float(np.linalg.norm(n))
        if nn < 1e-12:
            raise InputError(f"{w}.normal: zero vector")
        n, d = n / nn, d / nn
        if name is None:
            name = "floor" if n[2] > 0.9 else ("ceiling" if n[2] < -0.9 else f"wall_{i}")
        out.append(HalfSpace(n, d, _slug(name)))
    return out


def capsules_from_urdf(robot: Robot) -> list[Capsule]:
    """Robot capsules from the URDF's cylinder/capsule collision geometry (segment = the axis)."""
    import coal

    full = pin.buildModelFromUrdf(robot.urdf_path)
    try:
        geom = pin.buildGeomFromUrdf(full, robot.urdf_path, pin.GeometryType.COLLISION,
                                     package_dirs=_package_dirs(robot))
    except Exception:  # missing meshes: no capsules
        return []
    out = []
    for g in geom.geometryObjects:
        s = g.geometry
        if isinstance(s, (coal.Cylinder, coal.Capsule)):
            h = float(s.halfLength)
            a = g.placement.act(np.array([0.0, 0.0, -h]))
            b = g.placement.act(np.array([0.0, 0.0, h]))
            fr = full.frames[g.parentFrame]
            # placement is relative to the parent joint; re-express in the link frame
            Mf = fr.placement
            out.append(Capsule(Mf.actInv(a), Mf.actInv(b), float(s.radius), fr.name, g.name))
    return out


def design_covariance(model: TrackerModel, q_meas: np.ndarray, q_work: np.ndarray, ident: Any = None
                      ) -> np.ndarray:
    """C_s (3t × 3t, m², tracker frame) of a design: identifiable set, F, E, C_s = E C_p Eᵀ.

    Raises:
        IdentifiabilityError: the measurements do not determine the identifiable parameters.
    """
    from pin_kpi_oed.oed.covariance import kpi_covariance
    from pin_kpi_oed.oed.identifiability import analyse

    ident = analyse(model) if ident is None else ident
    b = ident.base
    p0 = np.zeros(model.n_params)
    F = model.weighted_jacobian(p0, q_meas)[:, :, b].reshape(-1, b.size)
    E = model.kpi_jacobian(p0, q_work)[:, b]
    prior = model.layout.prior_sigma[b]
    return kpi_covariance(F, E, prior if np.isfinite(prior).any() else None)


def load_design(source: str | os.PathLike | Mapping, criteria: Sequence[str] | None = None,
                compute_missing: bool = True) -> DesignFile:
    """Read a design JSON (or dict) tolerantly.

    Fields read (anything else is ignored; ``cell.<field>`` is looked up too):

    * ``robot``: a name or ``{"urdf_path", "tool_frame", "name"}``; a ``urdf_path`` that does not exist
      (file moved) falls back to ``name``;
    * ``tracker_T_base`` (4×4, m), ``world_T_base`` (4×4, default identity), ``reflector_m``, ``tcp_m``,
      ``noise``, ``fixed``, ``prior`` (as :mod:`pin_kpi_oed.model.serialize`);
    * ``q_work`` (t × n, rad; default the robot's neutral configuration);
    * ``capsules`` (robot, per link: ``link``, ``a``, ``b``, ``radius``; default from the URDF's collision
      cylinders), ``obstacles`` (capsule / sphere / box), ``half_spaces``, ``skip_pairs``,
      ``incidence_limit_deg`` (default 30);
    * ``designs``: list of ``{criterion, q_meas (m × n rad), cov_s_m2 (3t × 3t m², tracker frame),
      trace_cs_m2, ...}``, or a single design given by a top-level ``q_meas``. A missing or mis-shaped
      ``cov_s_m2`` is recomputed (:func:`design_covariance`) when ``compute_missing``.

    Args:
        source: path of the JSON file, or the parsed dict.
        criteria: keep only these designs (by criterion name), in this order.
        compute_missing: recompute a missing C_s.

    Raises:
        InputError: unreadable file, or a missing / invalid field (named with the file).
        RobotLoadError: the robot cannot be loaded.
    """
    from pin_kpi_oed.model.serialize import model_from_dict

    if isinstance(source, Mapping):
        d, where, base_dir = dict(source), "<dict>", Path.cwd()
    else:
        p = Path(source)
        where, base_dir = str(p), p.resolve().parent
        try:
            d = json.loads(p.read_text())
        except FileNotFoundError:
            raise InputError(f"{p}: no such file") from None
        except (OSError, UnicodeDecodeError) as exc:
            raise InputError(f"{p}: cannot read ({exc})") from None
        except json.JSONDecodeError as exc:
            raise InputError(f"{p}: not valid JSON ({exc})") from None
    if not isinstance(d, Mapping):
        raise InputError(f"{where}: expected a JSON object at the top level")
    cell = d.get("cell") if isinstance(d.get("cell"), Mapping) else {}

    def get(*keys, default=None):
        v = _first(d, *keys)
        return _first(cell, *keys, default=default) if v is None else v

    notes: list[str] = []
    setup = {k: get(k) for k in ("robot", "tool_frame", "tracker_T_base", "reflector_m", "tcp_m", "noise",
                                 "fixed", "prior") if get(k) is not None}
    rob = setup.get("robot")
    if rob is None:
        raise InputError(f"{where}: missing field 'robot' (a name such as kr15, or {{urdf_path, tool_frame}})")
    if isinstance(rob, Mapping):
        rob = dict(rob)
        up = rob.get("urdf_path")
        if up and not Path(up).is_absolute() and (base_dir / up).exists():
            rob["urdf_path"] = str(base_dir / up)
        elif up and not Path(up).exists() and rob.get("name"):
            notes.append(f"robot.urdf_path {up} does not exist: loading robot '{rob['name']}' instead")
            rob["urdf_path"] = None
        setup["robot"] = rob
    if "tracker_T_base" not in setup:
        notes.append("no tracker_T_base: the tracker is drawn at the robot base")
    setup.setdefault("reflector_m", [0.0, 0.0, 0.0])
    if isinstance(setup.get("noise"), (int, float)):
        setup["noise"] = {"sigma_xyz_m": [float(setup["noise"])] * 3}
    model = model_from_dict(setup, where)
    robot = model.robot
    n = robot.nq
    world_T_base = _se3(get("world_T_base", "W_T_base", default=np.eye(4)), f"{where}: world_T_base")

    qw = get("q_work")
    if qw is None:
        q_work = robot.neutral()[None]
        notes.append("no q_work: the working configuration is the robot's neutral one")
    else:
        q_work = np.atleast_2d(_arr(qw, None, f"{where}: q_work"))
        if q_work.shape[1] != n:
            raise InputError(f"{where}: q_work has {q_work.shape[1]} joint values per configuration, "
                             f"{robot.name} has {n}")
    t = q_work.shape[0]

    caps_raw = get("capsules", "robot_capsules")
    if caps_raw is None or isinstance(caps_raw, str):  # absent, or "urdf" as in a cell file
        capsules = capsules_from_urdf(robot)
        if capsules:
            notes.append("no capsules in the file: robot capsules taken from the URDF's collision cylinders")
    else:
        capsules = _parse_capsules(caps_raw, f"{where}: capsules")
    for c in capsules:
        if c.link is None or not robot.model.existFrame(c.link):
            raise InputError(f"{where}: capsule '{c.name}' is attached to unknown link '{c.link}'")
    obs_raw, hs_raw = get("obstacles"), get("half_spaces", "halfspaces", "planes")
    if isinstance(obs_raw, Mapping):  # a cell's {capsules: [...], half_spaces: [...]}
        hs_raw = hs_raw if hs_raw is not None else obs_raw.get("half_spaces")
        obs_raw = obs_raw.get("capsules")
    obstacles = _parse_obstacles(obs_raw, f"{where}: obstacles")
    half_spaces = _parse_half_spaces(hs_raw, f"{where}: half_spaces")
    skip = [tuple(map(str, p))[:2] for p in (get("skip_pairs", "pairs_to_skip", "ignore_pairs") or [])
            if isinstance(p, (list, tuple)) and len(p) >= 2]
    inc_lim = float(get("incidence_limit_deg", "incidence_max_deg", default=30.0))

    raw_designs = d.get("designs")
    if raw_designs is None and "q_meas" in d:
        raw_designs = [{"criterion": d.get("criterion", "design"), **{k: d[k] for k in d if k in (
            "q_meas", "cov_s_m2", "trace_cs_m2")}}]
    if not raw_designs:
        raise InputError(f"{where}: no designs (field 'designs': list of {{criterion, q_meas, ...}})")
    if isinstance(raw_designs, Mapping):  # {criterion: {...}}
        raw_designs = [dict(v, criterion=v.get("criterion", k)) for k, v in raw_designs.items()]
    designs: list[DesignView] = []
    ident = None
    extra = iter(EXTRA_COLOURS * 4)
    for i, e in enumerate(raw_designs):
        w = f"{where}: designs[{i}]"
        if not isinstance(e, Mapping):
            raise InputError(f"{w}: expected an object with criterion and q_meas")
        crit = str(e.get("criterion") or e.get("name") or f"design{i}")
        if criteria and crit not in criteria:
            continue
        if e.get("q_meas") is None:
            raise InputError(f"{w} ({crit}): missing field 'q_meas' (m x {n} joint values, rad)")
        Q = np.atleast_2d(_arr(e["q_meas"], None, f"{w}.q_meas"))
        if Q.shape[1] != n:
            raise InputError(f"{w}.q_meas: {Q.shape[1]} joint values per configuration, {robot.name} has {n}")
        out_lim = (Q < robot.q_lower - 1e-9) | (Q > robot.q_upper + 1e-9)
        if out_lim.any():
            k, j = np.argwhere(out_lim)[0]
            notes.append(f"design {crit}: {int(out_lim.any(axis=1).sum())} configuration(s) outside the joint "
                         f"limits (first: #{k}, {robot.joint_names[j]} = {Q[k, j]:.4g} rad)")
        C = e.get("cov_s_m2")
        source_c = "file"
        if C is not None:
            C = np.asarray(C, dtype=float)
            if C.shape != (3 * t, 3 * t) or not np.all(np.isfinite(C)):
                notes.append(f"design {crit}: cov_s_m2 has shape {C.shape}, expected {(3 * t, 3 * t)}: recomputed")
                C = None
        if C is None:
            if not compute_missing:
                raise InputError(f"{w} ({crit}): missing field 'cov_s_m2' (3t x 3t TCP covariance, m^2)")
            from pin_kpi_oed.oed.identifiability import analyse

            ident = analyse(model) if ident is None else ident
            try:
                C = design_covariance(model, Q, q_work, ident)
            except PinKpiOedError as exc:
                raise type(exc)(f"{w} ({crit}): {exc}") from None
            source_c = "computed"
        tr = e.get("trace_cs_m2")
        tr = float(tr) if isinstance(tr, (int, float)) and np.isfinite(tr) else float(np.trace(C))
        colour = DESIGN_COLOURS.get(crit)
        if colour is None:
            colour = next(extra)
        info = {k: v for k, v in e.items() if k not in ("q_meas", "cov_s_m2")}
        label = str(e.get("label") or DESIGN_LABELS.get(crit, crit))
        designs.append(DesignView(crit, label, int(colour), Q, C, tr, source_c, info))
    if criteria:
        missing = [c for c in criteria if c not in {dv.criterion for dv in designs}]
        if missing:
            raise InputError(f"{where}: no design '{missing[0]}' (designs: "
                             f"{', '.join(str(e.get('criterion')) for e in raw_designs)})")
        designs.sort(key=lambda dv: list(criteria).index(dv.criterion))
    if any(dv.cov_source == "computed" for dv in designs):
        notes.append("C_s recomputed with pin_kpi_oed for: "
                     + ", ".join(dv.criterion for dv in designs if dv.cov_source == "computed"))
    return DesignFile(model, world_T_base, q_work, capsules, obstacles, half_spaces, skip, inc_lim, designs,
                      notes, where, dict(d))


# ============================================================================ geometry helpers
def confidence_ellipsoid(C: np.ndarray, level: float = DEFAULT_LEVEL) -> tuple[np.ndarray, np.ndarray]:
    """Semi-axes (m) and axes (columns of a proper rotation) of the ``level`` confidence ellipsoid of N(0, C).

    The ellipsoid is {x : xᵀ C⁻¹ x <= χ²₃(level)}; χ²₃(0.95) = 7.815, so the semi-axes are
    2.80 σ along the principal directions.
    """
    from scipy.special import chdtri  # chi-square quantile, without importing scipy.stats (slow)

    k = float(chdtri(C.shape[0], 1.0 - level))
    w, V = np.linalg.eigh(0.5 * (C + C.T))
    radii = np.sqrt(k * np.clip(w, 0.0, None))
    if np.linalg.det(V) < 0:
        V[:, -1] *= -1
    return radii, V


def nice_factor(raw: float) -> float:
    """The number 1, 2 or 5 × 10^k closest to ``raw`` on a log scale (a readable magnification)."""
    if not np.isfinite(raw) or raw <= 0:
        return 1.0
    e = np.floor(np.log10(raw))
    cands = [m * 10 ** (e + de) for de in (0, 1) for m in (1.0, 2.0, 5.0)]
    return float(min(cands, key=lambda c: abs(np.log(c / raw))))


def fmt_factor(f: float) -> str:
    """``20000`` -> ``"20 000"`` (thin grouping, readable in the legend)."""
    if f >= 1 and abs(f - round(f)) < 1e-9:
        return f"{int(round(f)):,}".replace(",", " ")
    return f"{f:g}"


def seg_seg_distance(p1: np.ndarray, q1: np.ndarray, p2: np.ndarray, q2: np.ndarray) -> float:
    """Distance between segments p1-q1 and p2-q2 (Ericson, Real-Time Collision Detection 5.1.9)."""
    d1, d2, r = q1 - p1, q2 - p2, p1 - p2
    a, e, f = d1 @ d1, d2 @ d2, d2 @ r
    eps = 1e-15
    if a <= eps and e <= eps:
        return float(np.linalg.norm(r))
    if a <= eps:
        s, t = 0.0, np.clip(f / e, 0.0, 1.0)
    else:
        c = d1 @ r
        if e <= eps:
            t, s = 0.0, np.clip(-c / a, 0.0, 1.0)
        else:
            b = d1 @ d2
            den = a * e - b * b
            s = np.clip((b * f - c * e) / den, 0.0, 1.0) if den > eps else 0.0
            t = (b * s + f) / e
            if t < 0.0:
                t, s = 0.0, np.clip(-c / a, 0.0, 1.0)
            elif t > 1.0:
                t, s = 1.0, np.clip((b - c) / a, 0.0, 1.0)
    return float(np.linalg.norm(p1 + d1 * s - (p2 + d2 * t)))


def _capsule_world(df: DesignFile, q: np.ndarray, data: pin.Data | None = None) -> list[tuple[np.ndarray, np.ndarray]]:
    """World endpoints of every robot capsule at configuration q."""
    model = df.robot.model
    data = data or model.createData()
    pin.framesForwardKinematics(model, data, np.asarray(q, float))
    out = []
    for c in df.capsules:
        M = df.world_T_base * data.oMf[model.getFrameId(c.link)]
        out.append((M.act(c.a), M.act(c.b)))
    return out


def pair_distances(df: DesignFile, Q: np.ndarray, self_collision: bool = False
                   ) -> tuple[np.ndarray, list[tuple[str, str]]]:
    """Distances (m, P) of every (robot capsule, obstacle / half-space / other capsule) pair, and the pair names.

    Capsules on links no joint moves (the base) are compared with nothing; link pairs of adjacent
    joints are skipped; ``skip_pairs`` of the file are honoured (link, link / obstacle / half-space name).
    """
    Q = np.atleast_2d(Q)
    obst = [c for c in (o.capsule() for o in df.obstacles) if c is not None]
    model = df.robot.model
    data = model.createData()
    parent = [int(model.frames[model.getFrameId(c.link)].parentJoint) for c in df.capsules]
    skip = {frozenset(p) for p in df.skip_pairs}
    pairs: list[tuple[int, str, int]] = []
    names: list[tuple[str, str]] = []
    for i, c in enumerate(df.capsules):
        if parent[i] == 0:
            continue
        for j, o in enumerate(obst):
            if not ({frozenset((c.link, o.name)), frozenset((c.name, o.name))} & skip):
                pairs.append((i, "o", j))
                names.append((c.link, o.name))
        for j, h in enumerate(df.half_spaces):
            if not ({frozenset((c.link, h.name)), frozenset((c.name, h.name))} & skip):
                pairs.append((i, "h", j))
                names.append((c.link, h.name))
        if self_collision:
            for j in range(i + 1, len(df.capsules)):
                cj, ji, jj = df.capsules[j], parent[i], parent[j]
                if jj == 0 or ji == jj or model.parents[max(ji, jj)] == min(ji, jj) or \
                        {frozenset((x, y)) for x in (c.link, c.name) for y in (cj.link, cj.name)} & skip:
                    continue
                pairs.append((i, "c", j))
                names.append((c.link, cj.link))
    D = np.empty((Q.shape[0], len(pairs)))
    for k, q in enumerate(Q):
        segs = _capsule_world(df, q, data)
        for p, (i, kind, j) in enumerate(pairs):
            (a, b), c = segs[i], df.capsules[i]
            if kind == "o":
                o = obst[j]
                D[k, p] = seg_seg_distance(a, b, o.a, o.b) - c.radius - o.radius
            elif kind == "h":
                h = df.half_spaces[j]
                D[k, p] = min(h.normal @ a, h.normal @ b) - h.offset - c.radius
            else:
                D[k, p] = seg_seg_distance(a, b, *segs[j]) - c.radius - df.capsules[j].radius
    return D, names


def pose_clearance(df: DesignFile, Q: np.ndarray, self_collision: bool | None = None) -> np.ndarray:
    """Smallest clearance (m) of each configuration: robot capsules vs obstacles, half-spaces (and itself).

    A display aid, not the design's authoritative check (Coal, in ``collision.py``): capsules are
    compared as segments, boxes are skipped, and pairs that touch at every working configuration
    (e.g. the first link's capsule and the floor it stands on) are treated as pairs to skip.
    Self-collision of non-adjacent links is included when the file lists ``skip_pairs`` (enclosing
    capsules of some non-adjacent links overlap by construction) or when ``self_collision`` is True.
    Negative = penetration; ``inf`` when there is nothing to compare.
    """
    Q = np.atleast_2d(Q)
    if self_collision is None:
        self_collision = bool(df.skip_pairs)
    D, _ = pair_distances(df, Q, self_collision)
    if D.shape[1] == 0:
        return np.full(Q.shape[0], np.inf)
    Dw, _ = pair_distances(df, df.q_work, self_collision)
    keep = ~np.all(Dw < 0, axis=0)
    if not keep.any():
        return np.full(Q.shape[0], np.inf)
    return D[:, keep].min(axis=1)


# ============================================================================ meshcat recording window
def _command_js(data: bytes) -> str:
    """A drawing command for the static page (as meshcat's server writes it)."""
    return ('\nfetch("data:application/octet-binary;base64,{}")\n    .then(res => res.arrayBuffer())\n'
            '    .then(buffer => viewer.handle_command_bytearray(new Uint8Array(buffer)));\n'
            ).format(base64.b64encode(data).decode("ascii"))


class _Lowered:
    """A command already lowered to a dict (for replaying into another window)."""

    def __init__(self, d: dict) -> None:
        self.d = d

    def lower(self) -> dict:
        return self.d


class SceneRecorder:
    """A meshcat window that keeps the scene tree in process (no server, no sockets).

    It implements what :class:`meshcat.Visualizer` needs from its window (``send``,
    ``get_scene``, ``get_image``, ``open``, ``close``) with the same bookkeeping as
    meshcat's ZMQ server (``meshcat.servers.zmqserver``): ``set_object`` replaces a
    node's object and clears its properties, ``set_transform`` / ``set_property`` /
    ``delete`` act on the tree. :meth:`get_scene` writes the same self-contained page as
    the server (``main.min.js`` inlined), except that animations come last so that
    they bind to the objects they animate.

    Attributes:
        commands: every command received, lowered (dicts), in order.
    """

    web_url = None

    def __init__(self) -> None:
        from meshcat.servers.tree import SceneTree

        self.tree = SceneTree()
        self.commands: list[dict] = []
        self.animation: bytes | None = None

    def send(self, command: Any) -> None:
        import umsgpack
        from meshcat.servers.tree import SceneTree, find_node

        d = command.lower()
        self.commands.append(d)
        kind = d["type"]
        path = [p for p in str(d.get("path", "")).split("/") if p]
        data = umsgpack.packb(d)
        if kind == "set_animation":
            self.animation = data
            return
        if kind == "delete":
            if path:
                parent = find_node(self.tree, path[:-1])
                parent.pop(path[-1], None)
            else:
                self.tree = SceneTree()
            return
        node = find_node(self.tree, path)
        if kind == "set_object":
            node.object, node.properties = data, []
        elif kind == "set_transform":
            node.transform = data
        elif kind == "set_property":
            node.properties.append(data)

    def get_scene(self, title: str = "MeshCat", extra_body: str = "") -> str:
        """The static page: meshcat's viewer and the scene's drawing commands."""
        import meshcat
        from meshcat.servers.tree import walk

        VIEWER_ROOT = Path(meshcat.__file__).resolve().parent / "viewer" / "dist"  # as meshcat.servers.zmqserver

        cmds = []
        for node in walk(self.tree):
            if node.object is not None:
                cmds.append(_command_js(node.object))
            cmds.extend(_command_js(p) for p in node.properties)
            if node.transform is not None:
                cmds.append(_command_js(node.transform))
        if self.animation is not None:
            cmds.append(_command_js(self.animation))
        js = (Path(VIEWER_ROOT) / "main.min.js").read_text(encoding="utf-8")
        return ("<!DOCTYPE html>\n<html>\n<head><meta charset=utf-8><title>" + html_mod.escape(title)
                + "</title></head>\n<body>\n<div id=\"meshcat-pane\"></div>\n<script>\n" + js
                + "\n</script>\n<script>\nvar viewer = new MeshCat.Viewer(document.getElementById(\"meshcat-pane\"));\n"
                + "".join(cmds) + "\n</script>\n<style>body {margin: 0;} #meshcat-pane {width: 100vw; height: 100vh; "
                "overflow: hidden;}</style>\n" + extra_body + "\n</body>\n</html>\n")

    # --- inspection
    def node(self, path: str):
        """The tree node at ``path`` (``/meshcat/robot``) or None."""
        node = self.tree
        for p in [p for p in path.split("/") if p]:
            if p not in node:
                return None
            node = node[p]
        return node

    def object_paths(self) -> list[str]:
        """Paths of every node holding an object."""
        out: list[str] = []

        def rec(node, prefix):
            for k, v in node.items():
                p = f"{prefix}/{k}"
                if v.object is not None:
                    out.append(p)
                rec(v, p)

        rec(self.tree, "")
        return out

    def properties(self, path: str) -> dict:
        """Properties set on ``path`` (last value wins), e.g. ``{"visible": False}``."""
        import umsgpack

        node = self.node(path)
        out: dict = {}
        for p in (node.properties if node is not None else []):
            d = umsgpack.unpackb(p)
            out[d["property"]] = d["value"]
        return out

    def object_dict(self, path: str) -> dict | None:
        """The lowered ``set_object`` command of ``path``."""
        import umsgpack

        node = self.node(path)
        return umsgpack.unpackb(node.object) if node is not None and node.object is not None else None

    def replay(self, window: Any) -> None:
        """Send every recorded command, in order, to another meshcat window (a live server)."""
        for d in self.commands:
            window.send(_Lowered(d))

    # --- meshcat window interface
    def get_image(self, *args, **kwargs):
        raise PinKpiOedError("the recorded scene has no browser attached: write it with --html or view it live")

    def open(self) -> "SceneRecorder":
        return self

    def close(self) -> None:
        pass

    def wait(self) -> str:
        return "ok"


# ============================================================================ the scene
@dataclass
class EllipsoidView:
    """One displayed ellipsoid: design, working configuration, world centre of the true TCP,
    displayed centre (side by side), semi-axes (m, unscaled) and axes (world frame)."""

    design: str
    work_index: int
    tcp_world: np.ndarray
    centre_world: np.ndarray
    radii_m: np.ndarray
    axes: np.ndarray
    colour: int
    path: str


@dataclass
class Scene:
    """A built meshcat scene.

    Attributes:
        vis: the meshcat visualiser (its window a :class:`SceneRecorder` unless given).
        viz: Pinocchio's MeshcatVisualizer of the robot.
        design: the design file shown.
        scale: magnification of the ellipsoids; level: their confidence level.
        ellipsoids: every ellipsoid drawn.
        camera_target, camera_position: world frame (m).
        frames_per_pose, fps: animation timing (each pose is held ``frames_per_pose`` frames).
    """

    vis: Any
    viz: Any
    design: DesignFile
    scale: float
    level: float
    ellipsoids: list[EllipsoidView]
    camera_target: np.ndarray
    camera_position: np.ndarray
    frames_per_pose: int
    fps: int
    animation_poses: list[tuple[str, int]]

    @property
    def recorder(self) -> SceneRecorder | None:
        w = self.vis.window
        return w if isinstance(w, SceneRecorder) else None

    def set_visible(self, path: str, visible: bool) -> None:
        """Show or hide a scene node (``robot``, ``ellipsoids``, ``ghosts``, ``robot/collisions`` ...)."""
        self.vis[path].set_property("visible", bool(visible))

    def legend_html(self) -> str:
        """An HTML legend (designs, colours, tr(C_s), magnification) overlaid on the static page."""
        rows = []
        for d in self.design.designs:
            t = self.design.q_work.shape[0]
            sig = np.sqrt(max(d.trace_cs_m2, 0.0) / t) * 1e6
            rows.append(f"<div><span style='display:inline-block;width:12px;height:12px;background:#{d.colour:06x};"
                        f"margin-right:6px;vertical-align:middle'></span>{html_mod.escape(d.label)}: "
                        f"{d.q_meas.shape[0]} poses, tr(C<sub>s</sub>) = {d.trace_cs_m2 * 1e12:.4g} &micro;m&sup2;, "
                        f"TCP &sigma; = {sig:.3g} &micro;m</div>")
        return ("<div id='pko-legend' style='position:fixed;left:8px;bottom:8px;padding:6px 10px;"
                "background:rgba(255,255,255,0.85);font:13px sans-serif;color:#111;border-radius:4px;"
                "pointer-events:none'>"
                f"<div><b>{html_mod.escape(self.design.robot.name)}</b> &mdash; "
                f"{int(round(self.level * 100))} % confidence ellipsoids of the TCP, magnified "
                f"&times;{fmt_factor(self.scale)} (left to right: designs below)</div>" + "".join(rows)
                + "<div style='color:#555'>Controls &rarr; Animations: step through the measurement poses; "
                "Scene &rarr; meshcat/robot/collisions: capsules; meshcat/ghosts: all poses.</div></div>")

    def pose_time(self, criterion: str, k: int) -> float:
        """Animation time (s) at which the robot holds measurement configuration ``k`` of a design."""
        try:
            i = self.animation_poses.index((criterion, int(k)))
        except ValueError:
            raise InputError(f"no measurement configuration {k} of design '{criterion}' in the animation") from None
        return (i * self.frames_per_pose + 0.5 * (self.frames_per_pose - 1)) / self.fps

    def static_html(self, legend: bool = True, pose: tuple[str, int] | None = None) -> str:
        """The self-contained static page (meshcat's ``static_html()``, plus the legend overlay).

        Args:
            legend: overlay the legend (designs, colours, tr(C_s), magnification).
            pose: open the page with the robot at measurement configuration ``(criterion, k)``
                (the animation paused there) instead of the first working configuration.
        """
        extra = self.legend_html() if legend else ""
        if pose is not None:
            t = self.pose_time(*pose)
            extra += ("<script>(function seek() { const a = viewer.animator; if (!a.actions.length) "
                      "{ requestAnimationFrame(seek); return; } a.play(); a.pause(); a.seek(%r); })();</script>" % t)
        if self.recorder is not None:
            return self.recorder.get_scene(title=f"pin-kpi-oed: {self.design.robot.name} design", extra_body=extra)
        return self.vis.static_html().replace("</body>", extra + "\n</body>", 1)

    def write_html(self, path: str | os.PathLike, legend: bool = True) -> Path:
        """Write the static page atomically; returns the path."""
        from pin_kpi_oed.data.atomic import atomic_write_text

        atomic_write_text(path, self.static_html(legend))
        return Path(path)

    def project(self, points: np.ndarray, width: int, height: int) -> np.ndarray:
        """Pixel coordinates (k, 2) (x right, y down) of world points in a ``width`` × ``height`` page,
        through meshcat's default camera (75° vertical field of view) placed by this scene."""
        P = np.atleast_2d(points)
        fwd = self.camera_target - self.camera_position
        fwd = fwd / np.linalg.norm(fwd)
        right = np.cross(fwd, [0.0, 0.0, 1.0])
        right /= np.linalg.norm(right)
        up = np.cross(right, fwd)
        rel = P - self.camera_position
        depth = rel @ fwd
        f = (height / 2) / np.tan(np.radians(MESHCAT_FOV_DEG) / 2)
        x = width / 2 + f * (rel @ right) / depth
        y = height / 2 - f * (rel @ up) / depth
        return np.stack([x, y], axis=1)


def _package_dirs(robot: Robot) -> list[str]:
    dirs = [str(Path(robot.urdf_path).resolve().parent), str(Path(robot.urdf_path).resolve().parents[1])]
    try:
        from pin_kpi_oed.model.robot import erd_root

        dirs.append(str(erd_root().parents[1]))
    except RobotLoadError:
        pass
    return dirs


def _robot_models(df: DesignFile) -> tuple[pin.Model, pin.GeometryModel | None, list[str]]:
    """Pinocchio model of the serial chain (as the Robot's) and its URDF visual geometry (or None)."""
    robot = df.robot
    notes: list[str] = []
    full = pin.buildModelFromUrdf(robot.urdf_path)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            visual = pin.buildGeomFromUrdf(full, robot.urdf_path, pin.GeometryType.VISUAL,
                                           package_dirs=_package_dirs(robot))
    except Exception as exc:  # missing mesh files etc.
        notes.append(f"URDF visuals not loaded ({str(exc).strip().splitlines()[0][:120] if str(exc).strip() else exc}):"
                     " drawing primitives")
        visual = None
    if visual is not None and len(visual.geometryObjects) == 0:
        notes.append("the URDF has no visual geometry: drawing primitives")
        visual = None
    locked = [full.getJointId(n) for n in robot.locked_joints]
    if locked:
        if visual is not None:
            model, visual = pin.buildReducedModel(full, visual, locked, pin.neutral(full))
        else:
            model = pin.buildReducedModel(full, locked, pin.neutral(full))
    else:
        model = full
    if model.nq != robot.nq:
        raise RobotLoadError(f"{robot.urdf_path}: visual model has {model.nq} joints, the robot {robot.nq}")
    return model, visual, notes


def _capsule_geometry(model: pin.Model, capsules: Sequence[Capsule], prefix: str = "capsule") -> pin.GeometryModel:
    """Capsules attached to their link frames, as a Pinocchio geometry model."""
    import coal

    gm = pin.GeometryModel()
    for i, c in enumerate(capsules):
        fid = model.getFrameId(c.link)
        fr = model.frames[fid]
        d = c.b - c.a
        L = float(np.linalg.norm(d))
        R = pin.Quaternion.FromTwoVectors(np.array([0.0, 0.0, 1.0]), d / L).toRotationMatrix() if L > 1e-12 \
            else np.eye(3)
        local = pin.SE3(R, 0.5 * (c.a + c.b))
        go = pin.GeometryObject(f"{prefix}_{i}_{_slug(c.name)}", int(fr.parentJoint), int(fid), fr.placement * local,
                                coal.Capsule(float(c.radius), max(L, 1e-6)))
        go.meshColor = CAPSULE_RGBA.copy()
        gm.addGeometryObject(go)
    return gm


def _stick_geometry(model: pin.Model, tool_frame_id: int, reach: float) -> pin.GeometryModel:
    """A stick figure: a cylinder from each joint to the next (and to the tool frame)."""
    import coal

    gm = pin.GeometryModel()
    r = max(0.02, 0.03 * reach)
    ends = [(j, model.jointPlacements[j].translation, model.parents[j]) for j in range(2, model.njoints)]
    tf = model.frames[tool_frame_id]
    ends.append((None, tf.placement.translation, tf.parentJoint))
    for k, (_, t, parent) in enumerate(ends):
        L = float(np.linalg.norm(t))
        if L < 1e-6:
            continue
        R = pin.Quaternion.FromTwoVectors(np.array([0.0, 0.0, 1.0]), t / L).toRotationMatrix()
        go = pin.GeometryObject(f"stick_{k}", int(parent), pin.SE3(R, 0.5 * t), coal.Cylinder(r, L))
        go.meshColor = np.array([0.96, 0.47, 0.13, 1.0])
        gm.addGeometryObject(go)
    return gm


def _add_reflector(model: pin.Model, visual: pin.GeometryModel, df: DesignFile) -> None:
    """The reflector (a small silver sphere) on the tool, part of the robot's visuals."""
    import coal

    tf = model.frames[df.robot.tool_frame_id]
    at = pin.SE3(np.eye(3), tf.placement.act(df.model.reflector_m))
    go = pin.GeometryObject("reflector", int(tf.parentJoint), at, coal.Sphere(max(0.012, 0.008 * df.robot.reach())))
    go.meshColor = np.array([0.85, 0.85, 0.9, 1.0])
    visual.addGeometryObject(go)


def _plane_frame(n: np.ndarray) -> np.ndarray:
    """Rotation whose z axis is n and whose y axis is as vertical as possible (x horizontal)."""
    z = n / np.linalg.norm(n)
    up = np.array([0.0, 0.0, 1.0]) - z[2] * z
    if np.linalg.norm(up) < 1e-6:
        up = np.array([0.0, 1.0, 0.0]) - z[1] * z
    y = up / np.linalg.norm(up)
    return np.column_stack([np.cross(y, z), y, z])


def _rot_y_to(d: np.ndarray) -> np.ndarray:
    """Rotation taking the y axis (three.js cylinders) to direction d."""
    L = np.linalg.norm(d)
    return pin.Quaternion.FromTwoVectors(np.array([0.0, 1.0, 0.0]), d / L).toRotationMatrix() if L > 1e-12 \
        else np.eye(3)


def _beam_matrix(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Transform of a unit-length y-cylinder onto the segment a-b."""
    T = np.eye(4)
    T[:3, :3] = _rot_y_to(b - a) @ np.diag([1.0, max(np.linalg.norm(b - a), 1e-9), 1.0])
    T[:3, 3] = 0.5 * (a + b)
    return T


def _placements(model, data, gmodel, gdata, q, world: pin.SE3):
    pin.forwardKinematics(model, data, np.asarray(q, float))
    pin.updateGeometryPlacements(model, data, gmodel, gdata)
    return [(g, world * gdata.oMg[i]) for i, g in enumerate(gmodel.geometryObjects)]


def _text_png(lines: Sequence[tuple[str, str]], dpi: int = 150) -> tuple[bytes, float]:
    """A transparent PNG of coloured text lines [(text, '#rrggbb')]; returns (png, width / height)."""
    import io
    import struct

    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    n = len(lines)
    fig = Figure(figsize=(4.0, 0.3 * n), dpi=dpi)
    FigureCanvasAgg(fig)
    for i, (text, colour) in enumerate(lines):
        fig.text(0.0, 1.0 - (i + 1) / n, text, color=colour, fontsize=14, fontweight="bold", va="bottom", ha="left")
    buf = io.BytesIO()
    fig.savefig(buf, format="png", transparent=True, bbox_inches="tight", pad_inches=0.04)
    png = buf.getvalue()
    w, h = struct.unpack(">II", png[16:24])  # IHDR
    return png, w / h


def _place_camera(vis: Any, target: np.ndarray, position: np.ndarray) -> None:
    """Look at ``target`` from ``position`` (world frame).

    Meshcat's orbit controls always look at (and orbit about) the three.js origin, so the scene
    (``/meshcat``, and meshcat's ``/Grid`` and ``/Axes``) is shifted by ``-target`` and the camera placed
    at ``position - target`` (in the camera's y-up frame: (x, z, -y)).
    """
    T = np.eye(4)
    T[:3, 3] = -np.asarray(target, float)
    for path in ("/meshcat", "/Grid", "/Axes"):
        vis[path].set_transform(T)
    off = np.asarray(position, float) - np.asarray(target, float)
    vis["/Cameras/default/rotated/<object>"].set_property("position", [float(off[0]), float(off[2]), float(-off[1])])


def default_camera(df: DesignFile) -> tuple[np.ndarray, np.ndarray]:
    """A camera (target, position) that frames the robot and the working configurations."""
    base = df.world_T_base.translation
    reach = df.robot.reach()
    tcp = df.tcp_world()
    target = 0.4 * (base + np.array([0.0, 0.0, 0.3 * reach])) + 0.6 * tcp.mean(axis=0)
    fwd = tcp.mean(axis=0) - base
    fwd[2] = 0.0
    if np.linalg.norm(fwd) < 1e-6:
        fwd = np.array([1.0, 0.0, 0.0])
    fwd /= np.linalg.norm(fwd)
    az = np.arctan2(fwd[1], fwd[0]) + np.radians(30.0)
    el = np.radians(32.0)
    dist = 1.5 * reach
    pos = target + dist * np.array([np.cos(az) * np.cos(el), np.sin(az) * np.cos(el), np.sin(el)])
    return target, pos


def _import_meshcat():
    """meshcat, imported without its pyzmq DeprecationWarning (zmq.eventloop.ioloop, harmless)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        import meshcat
        import meshcat.visualizer  # noqa: F401
    return meshcat


def build_scene(design: DesignFile | str | os.PathLike | Mapping, vis: Any = None, *, scale: float | None = None,
                level: float = DEFAULT_LEVEL, ghosts: bool = True, capsules_visible: bool = False,
                animate: bool = True, camera: tuple[Sequence[float], Sequence[float]] | None = None,
                ellipsoid_size: float | None = None, ghost_opacity: float = 0.1, frames_per_pose: int = 8,
                fps: int = 8, background: str = "white", ghosts_visible: Sequence[str] | None = None) -> Scene:
    """Build the meshcat scene of a design file (see the module docstring for its nodes).

    Args:
        design: a :class:`DesignFile`, or what :func:`load_design` reads.
        vis: a meshcat Visualizer to draw into; default one on a :class:`SceneRecorder`.
        scale: magnification of the ellipsoids; default a 1-2-5 number making the largest semi-axis
            about ``ellipsoid_size``.
        level: confidence level of the ellipsoids (0.95).
        ghosts: draw every measurement configuration at once (translucent, design colour).
        capsules_visible: show the robot's capsules initially (they can be toggled in the viewer).
        animate: add the animation stepping through the measurement configurations.
        camera: (target, position) in the world frame; default :func:`default_camera`.
        ellipsoid_size: displayed size (m) of the largest semi-axis; default 6 % of the reach.
        ghost_opacity: opacity of the ghosts.
        frames_per_pose, fps: animation timing.
        background: ``white`` (light grey gradient) or ``meshcat`` (meshcat's default blue).
        ghosts_visible: criteria whose ghosts are shown initially (the others can be ticked in the
            viewer); default the last design only (usually the KPI design), to keep the picture readable.

    Returns:
        The :class:`Scene`.
    """
    meshcat = _import_meshcat()
    import meshcat.geometry as mg
    from meshcat.animation import Animation
    from pinocchio.visualize import MeshcatVisualizer

    df = design if isinstance(design, DesignFile) else load_design(design)
    if vis is None:
        vis = meshcat.Visualizer(window=SceneRecorder())
    model, visual, notes = _robot_models(df)
    df.notes.extend(n for n in notes if n not in df.notes)
    reach = df.robot.reach()
    primitives_only = True
    if visual is None:
        visual = _capsule_geometry(model, df.capsules, "link") if df.capsules else \
            _stick_geometry(model, df.robot.tool_frame_id, reach)
        for g in visual.geometryObjects:
            g.meshColor = np.array([0.96, 0.47, 0.13, 1.0])
    else:
        import coal

        primitives_only = all(isinstance(g.geometry, coal.ShapeBase) and not str(g.meshPath).lower().endswith(
            (".dae", ".stl", ".obj")) for g in visual.geometryObjects)
    _add_reflector(model, visual, df)
    collision = _capsule_geometry(model, df.capsules) if df.capsules else None
    # ghost geometry: the visuals when they are primitives (cheap), else capsules or a stick figure
    if primitives_only:
        ghost_geom = visual
    elif df.capsules:
        ghost_geom = _capsule_geometry(model, df.capsules, "ghost")
    else:
        ghost_geom = _stick_geometry(model, df.robot.tool_frame_id, reach)
    data = model.createData()
    vdata = visual.createData()
    W = df.world_T_base

    # --- background, camera
    if background == "white":
        vis["/Background"].set_property("top_color", [0.98, 0.98, 0.98])
        vis["/Background"].set_property("bottom_color", [0.78, 0.80, 0.83])
    if camera is None:
        target, position = default_camera(df)
    else:
        target, position = (np.asarray(c, float) for c in camera)
    _place_camera(vis, target, position)

    # --- the cell
    centre = W.translation.copy()
    floor_z = max([h.offset for h in df.half_spaces if h.normal[2] > 0.9], default=min(0.0, W.translation[2]))
    has_floor = any(h.normal[2] > 0.9 for h in df.half_spaces)
    for h in df.half_spaces:
        size, th = 8.0 * max(1.0, reach / 1.5), 0.02
        foot = centre - (h.normal @ centre - h.offset) * h.normal  # projection of the base on the plane
        R = _plane_frame(h.normal)
        dims = [size, size, th]
        if abs(h.normal[2]) < 0.9 and has_floor:  # a wall: from the floor up
            height = max(2.5, 1.6 * reach)
            dims = [size, height, th]
            foot = foot + (floor_z + 0.5 * height - foot[2]) / max(R[2, 1], 1e-6) * R[:, 1]
        T = np.eye(4)
        T[:3, :3] = R
        T[:3, 3] = foot - (0.5 * th + 0.01) * h.normal  # 1 cm below the plane: no z-fighting with the grid
        colour, opacity = (0xB8B8B0, 1.0) if h.normal[2] > 0.9 else (0xC9CED6, 0.55)
        node = vis["cell/half_spaces"][h.name]
        node.set_object(mg.Box(dims), mg.MeshLambertMaterial(color=colour, opacity=opacity))
        node.set_transform(T)
    for o in df.obstacles:
        node = vis["cell/obstacles"][o.name]
        mat = mg.MeshPhongMaterial(color=0x8899AA, opacity=0.8)
        if o.kind == "box":
            node.set_object(mg.Box(list(map(float, o.size))), mat)
            T = np.eye(4)
            T[:3, :3], T[:3, 3] = o.rotation, o.center
            node.set_transform(T)
        else:
            from pinocchio.visualize.meshcat_visualizer import createCapsule

            a, b = (o.a, o.b) if o.kind == "capsule" else (o.center, o.center)
            L = float(np.linalg.norm(b - a))
            node.set_object(createCapsule(max(L, 1e-6), o.radius) if L > 1e-9 else mg.Sphere(o.radius), mat)
            T = np.eye(4)
            if L > 1e-9:
                T[:3, :3] = pin.Quaternion.FromTwoVectors(np.array([0.0, 0.0, 1.0]), (b - a) / L).toRotationMatrix()
            T[:3, 3] = 0.5 * (a + b)
            node.set_transform(T)
    # tracker: head at its frame origin, a stand down to the floor
    Wt = df.world_T_tracker
    tr = vis["tracker"]
    tr["head"].set_object(mg.Sphere(0.09), mg.MeshPhongMaterial(color=0x333333))
    Th = np.eye(4)
    Th[:3, 3] = Wt.translation
    tr["head"].set_transform(Th)
    body_R = Wt.rotation
    Tb = np.eye(4)
    Tb[:3, :3] = body_R
    Tb[:3, 3] = Wt.translation - 0.13 * body_R[:, 2]
    tr["body"].set_object(mg.Box([0.16, 0.16, 0.16]), mg.MeshPhongMaterial(color=0xDDDDDD))
    tr["body"].set_transform(Tb)
    h_stand = Wt.translation[2] - 0.21 - floor_z
    if h_stand > 0.05:
        tr["stand"].set_object(mg.Cylinder(h_stand, 0.025), mg.MeshPhongMaterial(color=0x555555))
        Ts = np.eye(4)
        Ts[:3, :3] = _rot_y_to(np.array([0.0, 0.0, 1.0]))
        Ts[:3, 3] = [Wt.translation[0], Wt.translation[1], floor_z + 0.5 * h_stand]
        tr["stand"].set_transform(Ts)
    tr["axes"].set_object(mg.triad(0.25))
    Ta = Wt.homogeneous.copy()
    tr["axes"].set_transform(Ta)

    # --- the robot through Pinocchio's meshcat visualiser
    viz = MeshcatVisualizer(model, collision, visual)
    viz.initViewer(viewer=vis)
    viz.loadViewerModel(rootNodeName="robot")
    # world placement of the robot
    vis["robot"].set_transform(W.homogeneous)
    if collision is not None:
        viz.display_collisions = True  # keep the capsules placed, hidden until toggled
        vis["robot/collisions"].set_property("visible", bool(capsules_visible))
    q0 = df.q_work[0]
    viz.display(q0)

    # --- working configurations other than the first: light ghosts
    for j in range(1, df.q_work.shape[0]):
        _ghost(viz, vis, model, data, ghost_geom, df.q_work[j], f"working/w{j}", [0.9, 0.9, 0.9, 0.35], W)

    # --- beam (static: first working configuration)
    refl0 = df.reflector_world(df.q_work[:1])[0]
    vis["beam"].set_object(mg.Cylinder(1.0, 0.004), mg.MeshBasicMaterial(color=BEAM_COLOUR))
    vis["beam"].set_transform(_beam_matrix(Wt.translation, refl0))

    # --- ghosts: every measurement configuration of every design
    if ghosts:
        for d in df.designs:
            rgba = [((d.colour >> 16) & 255) / 255, ((d.colour >> 8) & 255) / 255, (d.colour & 255) / 255,
                    ghost_opacity]
            for k, q in enumerate(d.q_meas):
                _ghost(viz, vis, model, data, ghost_geom, q, f"ghosts/{d.key}/{k:03d}", rgba, W)
        shown = set(ghosts_visible) if ghosts_visible is not None else {df.designs[-1].criterion} if df.designs \
            else set()
        for d in df.designs:
            vis[f"ghosts/{d.key}"].set_property("visible", d.criterion in shown)

    # --- ellipsoids
    ells = _ellipsoids(df, level)
    rmax = max((float(e[4].max()) for e in ells), default=0.0)
    if scale is None:
        size = ellipsoid_size if ellipsoid_size is not None else 0.06 * reach
        scale = nice_factor(size / rmax) if rmax > 0 else 1.0
    fwd = target - position
    side = np.cross(fwd, [0.0, 0.0, 1.0])
    side = side / np.linalg.norm(side) if np.linalg.norm(side) > 1e-9 else np.array([0.0, 1.0, 0.0])
    views: list[EllipsoidView] = []
    nd = len(df.designs)
    for j, tcp in enumerate(df.tcp_world()):
        rj = max((float(e[4].max()) for e in ells if e[1] == j), default=0.0) * scale
        spacing = 2.3 * rj + 0.01
        vis["ellipsoids/tcp"][f"w{j}"].set_object(mg.Sphere(max(0.006, 0.15 * rj)),
                                                   mg.MeshPhongMaterial(color=0x111111))
        T = np.eye(4)
        T[:3, 3] = tcp
        vis["ellipsoids/tcp"][f"w{j}"].set_transform(T)
        for (di, jj, d, _, radii, axes) in ells:
            if jj != j:
                continue
            c = tcp + (di - (nd - 1) / 2) * spacing * side
            path = f"ellipsoids/{d.key}/w{j}"
            vis[path].set_object(mg.Ellipsoid(list(np.maximum(radii * scale, 1e-5))),
                                 mg.MeshLambertMaterial(color=d.colour))
            T = np.eye(4)
            T[:3, :3], T[:3, 3] = axes, c
            vis[path].set_transform(T)
            views.append(EllipsoidView(d.criterion, j, tcp, c, radii, axes, d.colour, "/meshcat/" + path))
        # label above the group, facing the camera
        lines = [(f"{int(round(level * 100))} % ellipsoids x{fmt_factor(scale)}", "#111111")]
        lines += [(d.label, f"#{d.colour:06x}") for d in df.designs]
        png, aspect = _text_png(lines)
        h = max(0.1, 0.6 * rj * len(lines))
        w = h * aspect
        # front faces only (the back face of the thin box would show the text mirrored through it),
        # drawn over the robot (no depth test) so that the legend is never hidden
        mat = mg.MeshBasicMaterial(map=mg.ImageTexture(mg.PngImage(png)), transparent=True, side=0, depthTest=False,
                                   depthWrite=False)
        lab = vis["ellipsoids/label"][f"w{j}"]
        lab.set_object(mg.Box([w, h, 1e-4]), mat)
        back = -fwd / np.linalg.norm(fwd)
        R = np.column_stack([side, np.cross(back, side), back])
        T = np.eye(4)
        T[:3, :3] = R
        T[:3, 3] = tcp + (rj + 0.6 * h + 0.02) * R[:, 1]
        lab.set_transform(T)

    # --- animation: step through every measurement configuration, design after design
    poses: list[tuple[str, int]] = []
    if animate and df.designs:
        anim = Animation(default_framerate=fps)
        cdata = collision.createData() if collision is not None else None
        frame = 0
        for d in df.designs:
            refl = df.reflector_world(d.q_meas)
            for k, q in enumerate(d.q_meas):
                poses.append((d.criterion, k))
                for fr in (frame, frame + frames_per_pose - 1):
                    with anim.at_frame(vis, fr) as f:
                        for g, M in _placements(model, data, visual, vdata, q, pin.SE3.Identity()):
                            _anim_set(f[f"robot/visuals/{g.name}"], M, g.meshScale)
                        if collision is not None:
                            for g, M in _placements(model, data, collision, cdata, q, pin.SE3.Identity()):
                                _anim_set(f[f"robot/collisions/{g.name}"], M, g.meshScale)
                        Tb = _beam_matrix(Wt.translation, refl[k])
                        Mb = pin.SE3(_rot_y_to(refl[k] - Wt.translation), Tb[:3, 3])
                        _anim_set(f["beam"], Mb, np.array([1.0, np.linalg.norm(refl[k] - Wt.translation), 1.0]))
                frame += frames_per_pose
        vis.set_animation(anim, play=False, repetitions=1)
    return Scene(vis, viz, df, float(scale), float(level), views, np.asarray(target, float),
                 np.asarray(position, float), frames_per_pose, fps, poses)


def _anim_set(node, M: pin.SE3, scale: np.ndarray) -> None:
    """Position / quaternion (/ scale) keyframe of an animated node."""
    q = pin.Quaternion(M.rotation)
    clip = node.get_clip()
    clip.set_property(node.current_frame, "position", "vector3", [float(x) for x in M.translation])
    clip.set_property(node.current_frame, "quaternion", "quaternion", [float(q.x), float(q.y), float(q.z), float(q.w)])
    if not np.allclose(scale, 1.0):
        clip.set_property(node.current_frame, "scale", "vector3", [float(x) for x in scale])


def _ghost(viz, vis, model, data, gmodel: pin.GeometryModel, q: np.ndarray, root: str, rgba, W: pin.SE3) -> None:
    """A translucent copy of the robot at q under ``root`` (own colour), via Pinocchio's loader."""
    saved = viz.viewerVisualGroupName
    viz.viewerVisualGroupName = root
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            for g in gmodel.geometryObjects:
                viz.loadViewerGeometryObject(g, pin.GeometryType.VISUAL, np.asarray(rgba, float))
        gdata = gmodel.createData()
        for g, M in _placements(model, data, gmodel, gdata, q, W):
            T = M.homogeneous
            T[:3, :3] = T[:3, :3] @ np.diag(g.meshScale)
            vis[f"{root}/{g.name}"].set_transform(T)
    finally:
        viz.viewerVisualGroupName = saved


def _ellipsoids(df: DesignFile, level: float) -> list[tuple[int, int, DesignView, np.ndarray, np.ndarray, np.ndarray]]:
    """(design index, work index, design, C_world, radii, axes) for every design and working configuration."""
    Rw = df.world_T_tracker.rotation
    out = []
    for di, d in enumerate(df.designs):
        for j in range(df.q_work.shape[0]):
            C = d.cov_s_m2[3 * j:3 * j + 3, 3 * j:3 * j + 3]
            Cw = Rw @ C @ Rw.T
            radii, axes = confidence_ellipsoid(Cw, level)
            out.append((di, j, d, Cw, radii, axes))
    return out


# ============================================================================ live view and CLI helper
def serve(scene: Scene, open_browser: bool = True, zmq_url: str | None = None):
    """Replay a recorded scene into a live meshcat server (started unless ``zmq_url``); returns the Visualizer.

    The server is a subprocess of this Python process (meshcat stops it at exit).
    """
    meshcat = _import_meshcat()
    rec = scene.recorder
    if rec is None:
        raise PinKpiOedError("the scene is already drawn into a live meshcat visualiser")
    live = meshcat.Visualizer(zmq_url=zmq_url)
    rec.replay(live.window)
    if open_browser:
        live.open()
    return live


def view(design_json: str | os.PathLike, html: str | os.PathLike | None = None, open_browser: bool = True,
         **kwargs) -> Scene:
    """Load a design JSON, build its scene, write the static page (``html``) and/or open it."""
    scene = build_scene(load_design(design_json, criteria=kwargs.pop("criteria", None)), **kwargs)
    if html is not None:
        scene.write_html(html)
        if open_browser:
            import webbrowser

            webbrowser.open(Path(html).resolve().as_uri(), new=2)
    return scene


# ============================================================================ headless screenshots
def find_browser() -> str | None:
    """A Chromium / Chrome executable (``chromium`` on PATH, /usr/bin/chromium, ...) or None."""
    import shutil

    for name in ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable"):
        path = shutil.which(name)
        if path:
            return path
    return "/usr/bin/chromium" if os.path.exists("/usr/bin/chromium") else None


def render_png(html_path: str | os.PathLike, png_path: str | os.PathLike, width: int = 1280, height: int = 800,
               timeout_ms: int = 8000, browser: str | None = None) -> Path:
    """Screenshot a static page with headless Chromium (software WebGL, no network, throw-away profile).

    Raises:
        PinKpiOedError: no browser, or no screenshot was written.
    """
    import subprocess
    import tempfile

    browser = browser or find_browser()
    if browser is None:
        raise PinKpiOedError("no Chromium/Chrome found: install one (Debian: apt-get install chromium)")
    png = Path(png_path).resolve()
    png.unlink(missing_ok=True)
    with tempfile.TemporaryDirectory() as profile:
        cmd = [browser, "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
               "--disable-background-networking", "--disable-component-update", "--disable-sync",
               "--disable-extensions", "--hide-scrollbars", "--enable-unsafe-swiftshader",
               "--proxy-server=127.0.0.1:9", "--proxy-bypass-list=<-loopback>", f"--user-data-dir={profile}",
               f"--screenshot={png}", f"--window-size={width},{height}", f"--timeout={timeout_ms}",
               Path(html_path).resolve().as_uri()]
        # own process group: if the browser hangs, stop that group (and only it)
        proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
        try:
            proc.wait(timeout=timeout_ms / 1000 + 60)
        except subprocess.TimeoutExpired:
            import signal

            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
    if not png.exists():
        raise PinKpiOedError(f"{browser} wrote no screenshot of {html_path}")
    return png


# ============================================================================ a stand-in design
def stand_in_design(robot: str = "kr15", m: int = 30, seed: int = 0, n_sets: int = 24) -> dict:
    """A design JSON (dict) built from random configurations, for previews before a real design exists.

    **Not an optimised design**: a cell modelled on the paper's (floor, a wall behind the robot, a car body
    in front as two capsules, the tracker in a corner), visible collision-free random poses (display
    check only), ``random`` = one random set, ``kpi*`` = the best of ``n_sets`` random sets by tr(C_s)
    (labelled ``best-of-random``). The real one comes from ``pin-kpi-oed design ... --json``.
    """
    rb = load_robot(robot)
    reach = rb.reach()
    k = reach / 2.147  # the KR 15's reach
    world_T_base = pin.SE3(np.eye(3), np.array([0.0, 0.0, 0.0]))
    world_T_tracker = pin.SE3(pin.rpy.rpyToMatrix(0.0, 0.0, np.radians(135.0)), np.array([3.2, -2.4, 1.2]) * k)
    tracker_T_base = world_T_tracker.inverse() * world_T_base
    caps = capsules_from_urdf(rb)
    d = {
        "robot": {"name": robot, "urdf_path": rb.urdf_path, "tool_frame": rb.tool_frame},
        "tracker_T_base": tracker_T_base.homogeneous.tolist(),
        "world_T_base": world_T_base.homogeneous.tolist(),
        "reflector_m": [0.05, 0.0, 0.06],
        "tcp_m": [0.0, 0.0, 0.0],
        "noise": NoiseModel(sigma_xyz_m=(10e-6, 10e-6, 10e-6)).to_dict(),
        "capsules": [{"link": c.link, "a": c.a.tolist(), "b": c.b.tolist(), "radius": c.radius} for c in caps],
        "obstacles": [
            {"name": "car_body", "type": "capsule", "a": [1.55 * k, -0.9 * k, 0.45 * k],
             "b": [1.55 * k, 0.9 * k, 0.45 * k], "radius": 0.4 * k},
            {"name": "car_roof", "type": "capsule", "a": [1.55 * k, -0.45 * k, 0.85 * k],
             "b": [1.55 * k, 0.45 * k, 0.85 * k], "radius": 0.3 * k},
        ],
        "half_spaces": [{"name": "floor", "normal": [0, 0, 1], "offset": 0.0},
                        {"name": "wall", "normal": [1, 0, 0], "offset": -0.45 * k}],
        "incidence_limit_deg": 30.0,
        "stand_in": "random configurations, not an optimised design (pin_kpi_oed.viz.viewer.stand_in_design)",
    }
    # working configuration over the car: arm stretched forward and down
    q_work = rb.neutral()
    if rb.nq >= 6:
        # KR 15: TCP at about (1.26, 0, 1.37) m, tool pointing down, over the car roof
        q_work[:6] = np.clip(np.radians([0.0, -41.26, 14.04, 0.0, 114.24, 0.0]), rb.q_lower[:6], rb.q_upper[:6])
    d["q_work"] = [q_work.tolist()]
    df = load_design({**d, "designs": [{"criterion": "tmp", "q_meas": [q_work.tolist()] * 1,
                                        "cov_s_m2": np.eye(3).tolist()}]})
    rng = np.random.default_rng(seed)
    pool = []
    tries = 0
    while len(pool) < m * 4 and tries < 60:
        tries += 1
        Q = rb.random_q(rng, 400)
        ok = df.incidence_deg(Q) <= d["incidence_limit_deg"]
        Q = Q[ok]
        if Q.size == 0:
            continue
        clear = pose_clearance(df, Q, self_collision=False)
        pool.extend(Q[clear > 0.02])
    if len(pool) < m:
        raise InfeasibleError(f"stand-in design: only {len(pool)} visible collision-free random poses found for "
                              f"{m} measurements")
    pool_a = np.array(pool)
    from pin_kpi_oed.oed.identifiability import analyse

    ident = analyse(df.model)
    qw = np.atleast_2d(q_work)
    sets = [pool_a[rng.choice(len(pool_a), m, replace=False)] for _ in range(n_sets)]
    covs = [design_covariance(df.model, S, qw, ident) for S in sets]
    traces = [float(np.trace(C)) for C in covs]
    ib = int(np.argmin(traces))
    designs = [{"criterion": "random", "q_meas": sets[0].tolist(), "trace_cs_m2": traces[0],
                "cov_s_m2": covs[0].tolist(), "status": "stand-in"}]
    designs.append({"criterion": "kpi", "label": "best-of-random", "q_meas": sets[ib].tolist(),
                    "trace_cs_m2": traces[ib], "cov_s_m2": covs[ib].tolist(), "status": "stand-in"})
    d["designs"] = designs
    return d
