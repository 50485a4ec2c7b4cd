"""Meshcat scene of a design file: cell, poses, laser beam and the TCP's confidence ellipsoids.

Engineers check measurement poses by eye before running them on a real robot.
:func:`build_scene` turns a :class:`~pin_kpi_oed.design.design_file.DesignFile` (or what
:func:`~pin_kpi_oed.design.design_file.load_design` reads) into a meshcat scene:

* the cell: floor / wall (half-spaces, drawn as thin slabs on the forbidden side of their
  boundary plane), obstacle capsules and spheres, the environment files' geometry
  (``cell/environment``; their fitted capsules hidden under ``cell/environment_capsules``), the laser tracker;
* the robot, drawn from its URDF visuals through Pinocchio's
  :class:`pinocchio.visualize.MeshcatVisualizer` (meshes where the URDF has them, URDF primitives
  otherwise, and the cell's capsules - or a stick figure - when the URDF has no visual geometry),
  standing at the first working configuration;
* an animation (meshcat's *Animations* panel: play / time slider) that steps the robot and the
  laser beam through every measurement configuration, design after design;
  ``ghosts/<design>/<k>``: all measurement configurations at once, ghosted in the design's colour,
  only for designs of at most :data:`MAX_GHOSTS` poses unless asked (``SceneOptions.max_ghosts``,
  ``view --all-ghosts``): beyond a handful they hide the robot; ``markers/<design>``: the reflector
  position of every measurement configuration, a dot in the design's colour (cheap, always drawn);
* ``robot/collisions``: the robot's capsules (hidden; tick the box to show them);
* ``beam``: the laser beam from the tracker to the reflector;
* ``ellipsoids/<design>/w<j>``: at each working configuration, the TCP's 95 % confidence
  ellipsoid of every design, side by side in the design's colour, magnified by a displayed
  factor (``ellipsoids/label``, the page's legend) so that µm-level ellipsoids are visible; a
  black dot marks the nominal TCP. The ellipsoids are the honest C_s (model discrepancy included,
  ``designs[i].discrepancy.cov_s_m2`` of ``design --model``: the same σ as ``predict``) when every design
  has it, else the paper's (tracker noise only); :attr:`SceneOptions.sigma` picks one, the labels say which. The labels
  are screen-sized sprites (three.js ``Sprite`` with
  ``sizeAttenuation: false``): :data:`LABEL_LINE_SCREEN` of the page height per text line at any
  zoom, always facing the camera.

The scene is drawn into a :class:`~pin_kpi_oed.viz.recorder.SceneRecorder` (in process, no
server); :meth:`Scene.static_html` is the self-contained page, :mod:`pin_kpi_oed.viz.render`
screenshots it or replays it into a live meshcat server. Frames: the scene's world frame is the
cell frame. Units SI; the legend shows tr(C_s) in mm² and σ in µm, as ``pin-kpi-oed design``.
"""

from __future__ import annotations

import html as html_mod
import os
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any
from collections.abc import Mapping, Sequence

import numpy as np
import pinocchio as pin

from pin_kpi_oed.design.design_file import DesignEntry, DesignFile, load_design
from pin_kpi_oed.errors import InputError
from pin_kpi_oed.threads import limit_threads
from pin_kpi_oed.viz.ellipsoids import DEFAULT_LEVEL, confidence_ellipsoid, fmt_factor, nice_factor
from pin_kpi_oed.viz.scene_parts import (MESHCAT_FOV_DEG, anim_set, beam_matrix, default_camera, homogeneous,
                                         label_height, label_sprite, object_placements, place_camera, plane_frame,
                                         rot_y_to, working_paths)
from pin_kpi_oed.viz.recorder import SceneRecorder, import_meshcat
from pin_kpi_oed.viz.robot_geometry import (add_reflector, capsule_geometry, capsule_mesh, is_primitive,
                                            meshcat_visualizer, slug, stick_geometry, visual_model)
from pin_kpi_oed.viz.style import BEAM_COLOUR, ROBOT_RGBA, design_colours, rgb

#: Designs with more poses than this get no ghosts by default (the animation shows the current pose).
MAX_GHOSTS = 8


@dataclass
class SceneOptions:
    """How to draw a design file.

    Attributes:
        scale: magnification of the ellipsoids; default a 1-2-5 number making the largest semi-axis
            about ``ellipsoid_size``.
        level: confidence level of the ellipsoids.
        ghosts: draw every measurement configuration at once (translucent, design colour).
        max_ghosts: ghosts only for designs of at most this many poses (None: every design).
        capsules_visible: show the robot's capsules initially (they can be toggled in the viewer).
        animate: add the animation stepping through the measurement configurations.
        camera: (target, position) in the world frame (m); default :func:`default_camera`.
        ellipsoid_size: displayed size (m) of the largest semi-axis; default 6 % of the reach.
        ghost_opacity: opacity of the ghosts (0…1).
        frames_per_pose: animation frames each pose is held; fps: animation frames per second.
        background: ``white`` (light grey gradient) or ``meshcat`` (meshcat's default blue).
        ghosts_visible: criteria whose ghosts are shown initially (the others can be ticked in the
            viewer); default the last design only (usually the KPI design), to keep the picture readable.
        sigma: which C_s the ellipsoids and the legend show: ``honest`` (model discrepancy included:
            :attr:`~pin_kpi_oed.design.design_file.DesignEntry.cov_s_honest_m2`), ``paper`` (tracker noise
            only), or None: honest when every design has it, else paper.
    """

    scale: float | None = None
    level: float = DEFAULT_LEVEL
    ghosts: bool = True
    max_ghosts: int | None = MAX_GHOSTS
    capsules_visible: bool = False
    animate: bool = True
    camera: tuple[Sequence[float], Sequence[float]] | None = None
    ellipsoid_size: float | None = None
    ghost_opacity: float = 0.1
    frames_per_pose: int = 8
    fps: int = 8
    background: str = "white"
    ghosts_visible: Sequence[str] | None = None
    sigma: str | None = None


@dataclass
class EllipsoidView:
    """One displayed ellipsoid.

    Attributes:
        design: criterion; work_index: working configuration.
        tcp_world: world position of the nominal TCP (m); centre_world: displayed centre (side by side, m).
        radii_m: semi-axes (m, unscaled); axes: principal axes (world frame, columns).
        colour: 0xRRGGBB; path: scene path.
    """

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
        animation_poses: (criterion, k) of every animation step, in order.
        colours: colour (0xRRGGBB) of every design.
        sigma: the C_s shown, ``honest`` (model discrepancy included) or ``paper`` (tracker noise only).
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
    colours: dict[str, int] = field(default_factory=dict)
    sigma: str = "paper"

    @property
    def recorder(self) -> SceneRecorder | None:
        """The in-process recorder (None when drawn into a live visualiser)."""
        w = self.vis.window
        return w if isinstance(w, SceneRecorder) else None

    def set_visible(self, path: str, visible: bool) -> None:
        """Show or hide a scene node (``robot``, ``ellipsoids``, ``ghosts``, ``robot/collisions`` ...)."""
        self.vis[path].set_property("visible", bool(visible))

    def legend_html(self) -> str:
        """An HTML legend (designs, colours, tr(C_s) in mm², TCP σ in µm, magnification) for the static page."""
        rows = []
        t = self.design.q_work.shape[0]
        honest = self.sigma == "honest"
        for d in self.design.designs:
            tr = float(np.trace(d.cov_s_honest_m2)) if honest else d.trace_cs_m2
            sig = np.sqrt(max(tr, 0.0) / t) * 1e6
            rows.append(f"<div><span style='display:inline-block;width:12px;height:12px;"
                        f"background:#{self.colours[d.criterion]:06x};margin-right:6px;vertical-align:middle'></span>"
                        f"{html_mod.escape(d.label)}: {d.q_meas.shape[0]} poses, tr(C<sub>s</sub>) = "
                        f"{tr * 1e6:.4e} mm&sup2;, TCP &sigma; = {sig:.3g} &micro;m</div>")
        return ("<div id='pko-legend' style='position:fixed;left:8px;bottom:8px;padding:6px 10px;"
                "background:rgba(255,255,255,0.85);font:13px sans-serif;color:#111;border-radius:4px;"
                "pointer-events:none'>"
                f"<div><b>{html_mod.escape(self.design.robot.name)}</b> &mdash; "
                f"{int(round(self.level * 100))} % confidence ellipsoids of the TCP, magnified "
                f"&times;{fmt_factor(self.scale)} (left to right: designs below); {SIGMA_TEXT[self.sigma]}</div>"
                + "".join(rows)
                + "<div style='color:#555'>Controls &rarr; Animations: step through the measurement poses; "
                "Scene &rarr; meshcat/robot/collisions: capsules; meshcat/ghosts: all poses (designs of at most "
                f"{MAX_GHOSTS} poses; view --all-ghosts for all); meshcat/markers: reflector positions.</div></div>")

    def pose_time(self, criterion: str, k: int) -> float:
        """Animation time (s) at which the robot holds measurement configuration ``k`` of a design.

        Raises:
            InputError: no such design or configuration in the animation.
        """
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
                      f"{{ requestAnimationFrame(seek); return; }} a.play(); a.pause(); a.seek({t!r}); }})();</script>")
        if self.recorder is not None:
            return self.recorder.get_scene(title=f"pin-kpi-oed: {self.design.robot.name} design", extra_body=extra)
        return self.vis.static_html().replace("</body>", extra + "\n</body>", 1)

    def write_html(self, path: str | os.PathLike, legend: bool = True, pose: tuple[str, int] | None = None) -> Path:
        """Write the static page atomically (see :meth:`static_html`); returns the path."""
        from pin_kpi_oed.data.atomic import atomic_write_text

        atomic_write_text(path, self.static_html(legend, pose))
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


#: What each kind of C_s includes (the ellipsoids' labels and the page's legend).
SIGMA_TEXT = {"honest": "discrepancy included", "paper": "tracker noise only"}


def sigma_kind(df: DesignFile, sigma: str | None = None) -> str:
    """The C_s to show: ``honest`` or ``paper``; None: honest when every design of ``df`` has it, else paper.

    Raises:
        InputError: an unknown kind, or ``honest`` asked of a file without the honest C_s.
    """
    have = bool(df.designs) and all(d.cov_s_honest_m2 is not None for d in df.designs)
    if sigma is None:
        return "honest" if have else "paper"
    if sigma not in SIGMA_TEXT:
        raise InputError(f"parameter 'sigma': must be honest or paper, got '{sigma}'")
    if sigma == "honest" and not have:
        missing = [d.criterion for d in df.designs if d.cov_s_honest_m2 is None]
        raise InputError(f"sigma='honest': design(s) {', '.join(missing)} of {df.source} have no "
                         "discrepancy.cov_s_m2 (write the file with a design on model_file, a model with a "
                         "discrepancy; or give sigma='paper')")
    return sigma


def _world_ellipsoids(df: DesignFile, level: float, sigma: str = "paper"
                      ) -> list[tuple[int, int, DesignEntry, np.ndarray, np.ndarray]]:
    """(design index, work index, design, semi-axes (m), axes (world)) for every design and working configuration;
    ``sigma``: the honest C_s (discrepancy included) or the paper's."""
    Rw = df.world_T_tracker.rotation
    out = []
    for di, d in enumerate(df.designs):
        Cs = d.covariance(sigma == "honest")
        for j in range(df.q_work.shape[0]):
            C = Cs[3 * j:3 * j + 3, 3 * j:3 * j + 3]
            radii, axes = confidence_ellipsoid(Rw @ C @ Rw.T, level)
            out.append((di, j, d, radii, axes))
    return out


# ============================================================================ the drawing steps
class _SceneBuilder:
    """Draws a design file into a meshcat visualiser, one step per part of the scene."""

    def __init__(self, df: DesignFile, vis: Any, opts: SceneOptions):
        import meshcat.geometry as mg

        self.mg, self.df, self.vis, self.opts = mg, df, vis, opts
        self.sigma = sigma_kind(df, opts.sigma)
        self.colours = design_colours([d.criterion for d in df.designs])
        self.model, visual, notes = visual_model(df.robot)
        df.notes.extend(n for n in notes if n not in df.notes)
        self.reach = df.robot.reach()
        self.visual, self.ghost_geom = self._robot_geometries(visual)
        add_reflector(self.model, self.visual, df.robot, df.model.reflector_m)
        self.collision = capsule_geometry(self.model, df.capsules) if df.capsules else None
        self.data = self.model.createData()
        self.W, self.Wt = df.world_T_base, df.world_T_tracker
        floors = [h.offset for h in df.half_spaces if h.normal[2] > 0.9]
        self.has_floor = bool(floors)
        self.floor_z = max(floors, default=min(0.0, self.W.translation[2]))
        self.viz: Any = None  # pinocchio's MeshcatVisualizer once the robot is drawn

    def _robot_geometries(self, visual: pin.GeometryModel | None) -> tuple[pin.GeometryModel, pin.GeometryModel]:
        """(visual geometry, ghost geometry): the URDF visuals, else the capsules or a stick figure; ghosts
        reuse the visuals when they are primitives (cheap), else the capsules or a stick figure."""
        df, model = self.df, self.model
        if visual is None:
            visual = capsule_geometry(model, df.capsules, "link") if df.capsules else \
                stick_geometry(model, df.robot.tool_frame_id, self.reach)
            for g in visual.geometryObjects:
                g.meshColor = ROBOT_RGBA.copy()
            return visual, visual
        if is_primitive(visual):
            return visual, visual
        if df.capsules:
            return visual, capsule_geometry(model, df.capsules, "ghost")
        return visual, stick_geometry(model, df.robot.tool_frame_id, self.reach)

    def background_and_camera(self) -> tuple[np.ndarray, np.ndarray]:
        """Background colours and the camera; returns (target, position), world frame (m)."""
        vis = self.vis
        if self.opts.background == "white":
            vis["/Background"].set_property("top_color", [0.98, 0.98, 0.98])
            vis["/Background"].set_property("bottom_color", [0.78, 0.80, 0.83])
        if self.opts.camera is None:
            target, position = default_camera(self.df)
        else:
            target, position = (np.asarray(c, float) for c in self.opts.camera)
        place_camera(vis, target, position)
        return np.asarray(target, float), np.asarray(position, float)

    def half_spaces(self) -> None:
        """Each half-space as a thin slab just below its boundary plane (walls from the floor up)."""
        mg, centre = self.mg, self.W.translation.copy()
        for h in self.df.half_spaces:
            size, th = 8.0 * max(1.0, self.reach / 1.5), 0.02
            foot = centre - (h.normal @ centre - h.offset) * h.normal  # projection of the base on the plane
            R = plane_frame(h.normal)
            dims = [size, size, th]
            if abs(h.normal[2]) < 0.9 and self.has_floor:  # a wall: from the floor up
                height = max(2.5, 1.6 * self.reach)
                dims = [size, height, th]
                foot = foot + (self.floor_z + 0.5 * height - foot[2]) / max(R[2, 1], 1e-6) * R[:, 1]
            colour, opacity = (0xB8B8B0, 1.0) if h.normal[2] > 0.9 else (0xC9CED6, 0.55)
            node = self.vis["cell/half_spaces"][slug(h.name)]
            node.set_object(mg.Box(dims), mg.MeshLambertMaterial(color=colour, opacity=opacity))
            # 1 cm below the plane: no z-fighting with the grid
            node.set_transform(homogeneous(R, foot - (0.5 * th + 0.01) * h.normal))

    def environment(self) -> None:
        """The environment files' geometry as the check sees it (``cell/environment/<solid>``); their fitted
        capsules (the optimiser's) are drawn hidden under ``cell/environment_capsules`` (tick to show)."""
        mg = self.mg
        for e in self.df.cell.environment:
            for sd in e.solids:
                node = self.vis["cell/environment"][slug(sd.name)]
                mat = mg.MeshLambertMaterial(color=0xA89F91)
                if sd.vertices.shape[0] == 1:  # a sphere
                    node.set_object(mg.Sphere(float(sd.geometry.radius)), mat)
                    node.set_transform(homogeneous(t=sd.vertices[0]))
                else:
                    node.set_object(mg.TriangularMeshGeometry(sd.vertices, sd.faces), mat)
        if self.df.cell.environment:
            self.vis["cell/environment_capsules"].set_property("visible", False)

    def obstacles(self) -> None:
        """Obstacle capsules (spheres when of length 0); environment files' capsules under their own toggle."""
        mg = self.mg
        env_caps = self.df.cell.environment_capsule_names
        for o in self.df.obstacles:
            node = self.vis["cell/environment_capsules" if o.name in env_caps else "cell/obstacles"][slug(o.name)]
            mat = mg.MeshPhongMaterial(color=0x8899AA, opacity=0.8)
            L = float(np.linalg.norm(o.b - o.a))
            node.set_object(capsule_mesh(max(L, 1e-6), o.radius) if L > 1e-9 else mg.Sphere(o.radius), mat)
            R = pin.Quaternion.FromTwoVectors(np.array([0.0, 0.0, 1.0]), (o.b - o.a) / L).toRotationMatrix() \
                if L > 1e-9 else None
            node.set_transform(homogeneous(R, 0.5 * (o.a + o.b)))

    def tracker(self) -> None:
        """The tracker: head at its frame origin, body, a stand down to the floor, its axes."""
        mg, Wt = self.mg, self.Wt
        tr = self.vis["tracker"]
        tr["head"].set_object(mg.Sphere(0.09), mg.MeshPhongMaterial(color=0x333333))
        tr["head"].set_transform(homogeneous(t=Wt.translation))
        tr["body"].set_object(mg.Box([0.16, 0.16, 0.16]), mg.MeshPhongMaterial(color=0xDDDDDD))
        tr["body"].set_transform(homogeneous(Wt.rotation, Wt.translation - 0.13 * Wt.rotation[:, 2]))
        h_stand = Wt.translation[2] - 0.21 - self.floor_z
        if h_stand > 0.05:
            tr["stand"].set_object(mg.Cylinder(h_stand, 0.025), mg.MeshPhongMaterial(color=0x555555))
            tr["stand"].set_transform(homogeneous(rot_y_to(np.array([0.0, 0.0, 1.0])),
                                                   [Wt.translation[0], Wt.translation[1],
                                                    self.floor_z + 0.5 * h_stand]))
        tr["axes"].set_object(mg.triad(0.25))
        tr["axes"].set_transform(Wt.homogeneous.copy())

    def robot(self) -> None:
        """The robot through Pinocchio's meshcat visualiser, at the first working configuration."""
        vis = self.vis
        self.viz = viz = meshcat_visualizer()(self.model, self.collision, self.visual)
        viz.initViewer(viewer=vis)
        viz.loadViewerModel(rootNodeName="robot")
        vis["robot"].set_transform(self.W.homogeneous)  # world placement of the robot
        if self.collision is not None:
            viz.display_collisions = True  # keep the capsules placed, hidden until toggled
            vis["robot/collisions"].set_property("visible", bool(self.opts.capsules_visible))
        viz.display(self.df.q_work[0])

    def _ghost(self, q: np.ndarray, root: str, rgba) -> None:
        """A translucent copy of the robot at q under ``root`` (own colour), via Pinocchio's loader."""
        viz = self.viz
        saved = viz.viewerVisualGroupName
        viz.viewerVisualGroupName = root
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                for g in self.ghost_geom.geometryObjects:
                    viz.loadViewerGeometryObject(g, pin.GeometryType.VISUAL, np.asarray(rgba, float))
            gdata = self.ghost_geom.createData()
            for g, M in object_placements(self.model, self.data, self.ghost_geom, gdata, q, self.W):
                T = M.homogeneous
                T[:3, :3] = T[:3, :3] @ np.diag(g.meshScale)
                self.vis[f"{root}/{g.name}"].set_transform(T)
        finally:
            viz.viewerVisualGroupName = saved

    def working_ghosts(self) -> None:
        """Working configurations other than the first: light grey ghosts."""
        for j in range(1, self.df.q_work.shape[0]):
            self._ghost(self.df.q_work[j], f"working/w{j}", [0.9, 0.9, 0.9, 0.35])

    def beam(self) -> None:
        """The laser beam at the first working configuration."""
        refl0 = self.df.reflector_world(self.df.q_work[:1])[0]
        self.vis["beam"].set_object(self.mg.Cylinder(1.0, 0.004), self.mg.MeshBasicMaterial(color=BEAM_COLOUR))
        self.vis["beam"].set_transform(beam_matrix(self.Wt.translation, refl0))

    def markers(self) -> None:
        """The reflector position of every measurement configuration, one point cloud per design
        (its colour; shown for the designs whose ghosts are shown)."""
        mg, df = self.mg, self.df
        for d in df.designs:
            P = df.reflector_world(d.q_meas).T.astype(np.float32)
            colour = np.repeat(rgb(self.colours[d.criterion])[:, None], P.shape[1], axis=1).astype(np.float32)
            self.vis[f"markers/{slug(d.criterion)}"].set_object(
                mg.Points(mg.PointsGeometry(P, color=colour), mg.PointsMaterial(size=0.025)))
        shown = self._shown()
        for d in df.designs:
            self.vis[f"markers/{slug(d.criterion)}"].set_property("visible", d.criterion in shown)

    def _shown(self) -> set[str]:
        """Criteria whose ghosts and markers are shown initially."""
        df = self.df
        return set(self.opts.ghosts_visible) if self.opts.ghosts_visible is not None else \
            {df.designs[-1].criterion} if df.designs else set()

    def design_ghosts(self) -> None:
        """Every measurement configuration of every design of at most ``max_ghosts`` poses, ghosted in the
        design's colour."""
        df, opts = self.df, self.opts
        for d in df.designs:
            if opts.max_ghosts is not None and d.q_meas.shape[0] > opts.max_ghosts:
                continue
            rgba = [*rgb(self.colours[d.criterion]), opts.ghost_opacity]
            for k, q in enumerate(d.q_meas):
                self._ghost(q, f"ghosts/{slug(d.criterion)}/{k:03d}", rgba)
        shown = self._shown()
        for d in df.designs:
            if opts.max_ghosts is None or d.q_meas.shape[0] <= opts.max_ghosts:
                self.vis[f"ghosts/{slug(d.criterion)}"].set_property("visible", d.criterion in shown)

    def ellipsoids(self, target: np.ndarray, position: np.ndarray) -> tuple[float, list[EllipsoidView]]:
        """The ellipsoids of every design side by side at each working configuration, and their label.

        Returns:
            (magnification, the ellipsoids drawn).
        """
        df, opts, mg = self.df, self.opts, self.mg
        ells = _world_ellipsoids(df, opts.level, self.sigma)
        rmax = max((float(e[3].max()) for e in ells), default=0.0)
        scale = opts.scale
        if scale is None:
            size = opts.ellipsoid_size if opts.ellipsoid_size is not None else 0.06 * self.reach
            scale = nice_factor(size / rmax) if rmax > 0 else 1.0
        fwd = target - position
        side = np.cross(fwd, [0.0, 0.0, 1.0])
        side = side / np.linalg.norm(side) if np.linalg.norm(side) > 1e-9 else np.array([0.0, 1.0, 0.0])
        views: list[EllipsoidView] = []
        nd = len(df.designs)
        for j, tcp in enumerate(df.tcp_world()):
            rj = max((float(e[3].max()) for e in ells if e[1] == j), default=0.0) * scale
            spacing = 2.3 * rj + 0.01
            dot = self.vis["ellipsoids/tcp"][f"w{j}"]
            dot.set_object(mg.Sphere(max(0.006, 0.15 * rj)), mg.MeshPhongMaterial(color=0x111111))
            dot.set_transform(homogeneous(t=tcp))
            for (di, jj, d, radii, axes) in ells:
                if jj != j:
                    continue
                c = tcp + (di - (nd - 1) / 2) * spacing * side
                path = f"ellipsoids/{slug(d.criterion)}/w{j}"
                colour = self.colours[d.criterion]
                self.vis[path].set_object(mg.Ellipsoid(list(np.maximum(radii * scale, 1e-5))),
                                          mg.MeshLambertMaterial(color=colour))
                self.vis[path].set_transform(homogeneous(axes, c))
                views.append(EllipsoidView(d.criterion, j, tcp, c, radii, axes, colour, "/meshcat/" + path))
            self._label(j, tcp, rj, float(scale), position, fwd)
        return float(scale), views

    def _label(self, j: int, tcp: np.ndarray, rj: float, scale: float, camera: np.ndarray, fwd: np.ndarray) -> None:
        """Label above the ellipsoids of working configuration j (level, magnification, designs): a screen-sized
        sprite (:func:`label_sprite`), :data:`LABEL_LINE_SCREEN` of the page height per line at any zoom."""
        lines = [(f"{int(round(self.opts.level * 100))} % ellipsoids x{fmt_factor(scale)}, {SIGMA_TEXT[self.sigma]}",
                  "#111111")]
        lines += [(d.label, f"#{self.colours[d.criterion]:06x}") for d in self.df.designs]
        up = np.array([0.0, 0.0, 1.0])
        depth = float((tcp - camera) @ (fwd / np.linalg.norm(fwd)))
        # the sprite's world height at the ellipsoids' depth is (its height) · depth: sit just above them
        h = label_height(len(lines)) * depth
        label_sprite(self.vis["ellipsoids/label"][f"w{j}"], lines, tcp + (rj + 0.5 * h + 0.02) * up)

    def animation(self) -> list[tuple[str, int]]:
        """Keyframes stepping the robot, its capsules and the beam through every measurement configuration,
        design after design; returns the (criterion, k) of every step."""
        from meshcat.animation import Animation

        df, opts = self.df, self.opts
        fpp = opts.frames_per_pose
        anim = Animation(default_framerate=opts.fps)
        vdata = self.visual.createData()
        cdata = self.collision.createData() if self.collision is not None else None
        poses: list[tuple[str, int]] = []
        frame = 0
        trk = self.Wt.translation
        for d in df.designs:
            refl = df.reflector_world(d.q_meas)
            for k, q in enumerate(d.q_meas):
                poses.append((d.criterion, k))
                for fr in (frame, frame + fpp - 1):
                    with anim.at_frame(self.vis, fr) as f:
                        for g, M in object_placements(self.model, self.data, self.visual, vdata, q, pin.SE3.Identity()):
                            anim_set(f[f"robot/visuals/{g.name}"], M, g.meshScale)
                        if self.collision is not None:
                            for g, M in object_placements(self.model, self.data, self.collision, cdata, q,
                                                    pin.SE3.Identity()):
                                anim_set(f[f"robot/collisions/{g.name}"], M, g.meshScale)
                        Tb = beam_matrix(trk, refl[k])
                        Mb = pin.SE3(rot_y_to(refl[k] - trk), Tb[:3, 3])
                        anim_set(f["beam"], Mb, np.array([1.0, np.linalg.norm(refl[k] - trk), 1.0]))
                frame += fpp
        self.vis.set_animation(anim, play=False, repetitions=1)
        return poses


@limit_threads  # small eigen-decompositions and placements: one BLAS thread (pin_kpi_oed.threads)
def build_scene(design: DesignFile | str | os.PathLike | Mapping, options: SceneOptions | None = None,
                vis: Any = None) -> Scene:
    """Build the meshcat scene of a design file (see the module docstring for its nodes).

    Args:
        design: a :class:`DesignFile`, or what :func:`load_design` reads.
        options: how to draw it (:class:`SceneOptions`; default all defaults).
        vis: a meshcat Visualizer to draw into; default one on a :class:`SceneRecorder`.

    Returns:
        The :class:`Scene`.

    Raises:
        PinKpiOedError: the design file cannot be read (see :func:`load_design`).
    """
    meshcat = import_meshcat()
    opts = options or SceneOptions()
    df = design if isinstance(design, DesignFile) else load_design(design)
    if vis is None:
        vis = meshcat.Visualizer(window=SceneRecorder())
    b = _SceneBuilder(df, vis, opts)
    target, position = b.background_and_camera()
    b.half_spaces()
    b.obstacles()
    b.environment()
    b.tracker()
    b.robot()
    b.working_ghosts()
    working_paths(vis, b.mg, df)
    b.beam()
    b.markers()
    if opts.ghosts:
        b.design_ghosts()
    scale, views = b.ellipsoids(target, position)
    poses = b.animation() if opts.animate and df.designs else []
    return Scene(vis, b.viz, df, scale, float(opts.level), views, target, position, opts.frames_per_pose, opts.fps,
                 poses, b.colours, b.sigma)
