"""Animate an ordered measurement program in a design's meshcat scene (``pin-kpi-oed export --html``).

The robot (visual meshes and capsules) moves along every joint-space move of the program at
``step_deg`` joint steps, stops at each measurement point for ``hold_frames`` frames with the laser
beam drawn (the beam is hidden while moving), and passes the via poses without stopping. It
replaces the scene's pose-by-pose animation (meshcat's *Animations* panel: play / time slider).
The whole ordered path is drawn too: ``program/path``, the reflector's trace through every move
(transitions and via poses included, at the animation's steps), ``program/measure`` the
measurement points and ``program/via`` the via poses (orange dots).
"""

from __future__ import annotations

import math

import numpy as np
import pinocchio as pin

from pin_kpi_oed.viz.scene import Scene
from pin_kpi_oed.viz.scene_parts import anim_set, beam_matrix, object_placements, rot_y_to
from pin_kpi_oed.viz.style import rgb


def _draw_path(scene: Scene, trace: np.ndarray, targets: np.ndarray, kinds: list[str]) -> None:
    """The program's reflector trace (a line), its measurement points and via poses (dots), world frame (m)."""
    import meshcat.geometry as mg

    vis = scene.vis
    vis["program/path"].set_object(mg.Line(mg.PointsGeometry(trace.T.astype(np.float32)),
                                           mg.LineBasicMaterial(color=0x333333, linewidth=2)))
    for kind, colour in (("measure", 0x2CA02C), ("via", 0xFF7F0E)):
        P = targets[[k == kind for k in kinds]]
        if len(P):
            C = np.repeat(rgb(colour)[:, None], len(P), axis=1).astype(np.float32)  # the material uses vertex colours
            vis[f"program/{kind}"].set_object(mg.Points(mg.PointsGeometry(P.T.astype(np.float32), color=C),
                                                        mg.PointsMaterial(size=0.04)))


def animate_program(scene: Scene, path: np.ndarray, kinds: list[str], step_deg: float = 3.0, hold_frames: int = 6,
                    fps: int = 24) -> list[float]:
    """Replace the scene's animation with the program's moves.

    Args:
        scene: a scene of the design (:func:`pin_kpi_oed.viz.scene.build_scene`).
        path: the program's targets in order (k, n) rad / m (home, poses, vias, home).
        kinds: ``home`` / ``measure`` / ``via`` per target.
        step_deg: largest joint step between animation frames (deg; prismatic joints: step_deg mm).
        hold_frames: frames the robot holds each measurement point.
        fps: animation frames per second.

    Returns:
        Animation time (s) of every measurement point, in order.
    """
    from meshcat.animation import Animation

    viz, df = scene.viz, scene.design
    model = viz.model
    data = model.createData()
    visual, collision = viz.visual_model, viz.collision_model
    vdata = visual.createData()
    cdata = collision.createData() if collision is not None else None
    rev = np.asarray(df.robot.is_revolute, bool)
    steps = np.where(rev, math.radians(step_deg), step_deg * 1e-3)
    trk = df.world_T_tracker.translation
    anim = Animation(default_framerate=fps)
    times: list[float] = []

    path = np.atleast_2d(np.asarray(path, float))
    keys: list[tuple[np.ndarray, bool]] = []  # every frame's configuration and beam, in order
    for i in range(len(path)):
        q = path[i]
        if kinds[i] == "measure":
            times.append((len(keys) + 0.5 * hold_frames) / fps)
            keys += [(q, True)] * hold_frames
        if i + 1 < len(path):
            b = path[i + 1]
            n = max(1, int(math.ceil(float(np.max(np.abs(b - q) / steps)))))
            keys += [(q + s * (b - q), False) for s in np.linspace(0.0, 1.0, n + 1)[:-1]]
    keys.append((path[-1], False))
    refl_all = df.reflector_world(np.array([q for q, _ in keys]))  # every frame's reflector at once (m)
    for frame, ((q, beam), refl) in enumerate(zip(keys, refl_all)):
        with anim.at_frame(scene.vis, frame) as f:
            for g, M in object_placements(model, data, visual, vdata, q, pin.SE3.Identity()):
                anim_set(f[f"robot/visuals/{g.name}"], M, g.meshScale)
            if collision is not None:
                for g, M in object_placements(model, data, collision, cdata, q, pin.SE3.Identity()):
                    anim_set(f[f"robot/collisions/{g.name}"], M, g.meshScale)
            Tb = beam_matrix(trk, refl)
            length = float(np.linalg.norm(refl - trk)) if beam else 1e-6
            anim_set(f["beam"], pin.SE3(rot_y_to(refl - trk), Tb[:3, 3]), np.array([1.0, length, 1.0]))
    trace = [q for q, beam in keys if not beam]
    scene.vis.set_animation(anim, play=False, repetitions=1)
    _draw_path(scene, df.reflector_world(np.array(trace)), df.reflector_world(path), list(kinds))
    return times
