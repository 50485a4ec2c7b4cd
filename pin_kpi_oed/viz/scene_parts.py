"""Primitives of the meshcat scene: placements (a three.js y-cylinder onto a segment, a plane's frame, homogeneous
matrices, Pinocchio forward kinematics of a geometry model), screen-sized text labels, the camera and animation
keyframes. Frames: the scene's world frame is the cell frame; units SI.

A label is a three.js ``Sprite`` with ``sizeAttenuation: false``: :data:`LABEL_LINE_SCREEN` of the page height per
text line at any zoom, always facing the camera.
"""

from __future__ import annotations

import functools
from collections.abc import Sequence
from typing import Any

import numpy as np
import pinocchio as pin

from pin_kpi_oed.design.design_file import DesignFile

#: Vertical field of view (deg) of meshcat's default perspective camera (viewer/dist/main.min.js).
MESHCAT_FOV_DEG = 75.0
#: Height of one text line of a 3-D label, as a fraction of the page height (at any zoom).
LABEL_LINE_SCREEN = 0.028


def plane_frame(n: np.ndarray) -> np.ndarray:
    """Rotation whose z axis is n and whose y axis is as vertical as possible (x horizontal)."""
    z = n / np.linalg.norm(n)
    up = np.array([0.0, 0.0, 1.0]) - z[2] * z
    if np.linalg.norm(up) < 1e-6:
        up = np.array([0.0, 1.0, 0.0]) - z[1] * z
    y = up / np.linalg.norm(up)
    return np.column_stack([np.cross(y, z), y, z])


def rot_y_to(d: np.ndarray) -> np.ndarray:
    """Rotation taking the y axis (three.js cylinders) to direction d."""
    L = np.linalg.norm(d)
    return pin.Quaternion.FromTwoVectors(np.array([0.0, 1.0, 0.0]), d / L).toRotationMatrix() if L > 1e-12 \
        else np.eye(3)


def beam_matrix(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Transform of a unit-length y-cylinder onto the segment a-b."""
    T = np.eye(4)
    T[:3, :3] = rot_y_to(b - a) @ np.diag([1.0, max(np.linalg.norm(b - a), 1e-9), 1.0])
    T[:3, 3] = 0.5 * (a + b)
    return T


def homogeneous(R: np.ndarray | None = None, t: np.ndarray | Sequence[float] | None = None) -> np.ndarray:
    """4×4 transform from a rotation and a translation (defaults identity / zero)."""
    T = np.eye(4)
    if R is not None:
        T[:3, :3] = R
    if t is not None:
        T[:3, 3] = t
    return T


def object_placements(model, data, gmodel, gdata, q, world: pin.SE3):
    """(geometry object, world placement) of every object of ``gmodel`` at configuration q (Pinocchio FK)."""
    pin.forwardKinematics(model, data, np.asarray(q, float))
    pin.updateGeometryPlacements(model, data, gmodel, gdata)
    return [(g, world * gdata.oMg[i]) for i, g in enumerate(gmodel.geometryObjects)]


def _text_png(lines: Sequence[tuple[str, str]], dpi: int = 150) -> tuple[bytes, float]:
    """A transparent PNG of coloured text lines [(text, '#rrggbb')]; returns (png, width / height).

    The same lines are drawn once per process (a scene labels every working configuration alike, 40-60 ms a PNG):
    the PNG's bytes are the same either way."""
    return _text_png_of(tuple((str(text), str(colour)) for text, colour in lines), int(dpi))


@functools.lru_cache(maxsize=64)
def _text_png_of(lines: tuple[tuple[str, str], ...], dpi: int) -> tuple[bytes, float]:
    """:func:`_text_png` of hashable lines (bytes and a float: nothing a caller can change)."""
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


def label_height(n_lines: int, line_screen: float = LABEL_LINE_SCREEN) -> float:
    """Height ``s`` of a :func:`label_sprite` of ``n_lines`` lines (``s`` × depth = its world height, m)."""
    return n_lines * line_screen * 2.0 * float(np.tan(np.radians(MESHCAT_FOV_DEG) / 2))


def label_sprite(node: Any, lines: Sequence[tuple[str, str]], position: np.ndarray,
                 line_screen: float = LABEL_LINE_SCREEN) -> float:
    """A text label of constant screen size at a world position, always facing the camera.

    A three.js ``Sprite`` whose ``SpriteMaterial`` has ``sizeAttenuation: false``: three.js then
    multiplies the sprite's scale by its depth, so that a sprite of height ``s`` covers
    ``s / (2 tan(fov / 2))`` of the page height whatever the zoom. Drawn over everything (no depth test).

    Args:
        node: the meshcat node to draw into.
        lines: [(text, '#rrggbb')] lines of the label.
        position: world position of the label's centre (m).
        line_screen: height of one line as a fraction of the page height.

    Returns:
        The sprite's height ``s`` (its world height is ``s`` × depth from the camera).
    """
    import meshcat.geometry as mg

    class SpriteMaterial(mg.GenericMaterial):
        _type = "SpriteMaterial"

    class Sprite(mg.Object):
        _type = "Sprite"

    png, aspect = _text_png(lines)
    sy = label_height(len(lines), line_screen)
    mat = SpriteMaterial(map=mg.ImageTexture(mg.PngImage(png)), transparent=True, depthTest=False, depthWrite=False,
                         sizeAttenuation=False)
    node.set_object(Sprite(mg.Box([1.0, 1.0, 1e-4]), mat))
    node.set_transform(homogeneous(np.diag([sy * aspect, sy, 1.0]), np.asarray(position, float)))
    return float(sy)


def place_camera(vis: Any, target: np.ndarray, position: np.ndarray) -> None:
    """Look at ``target`` from ``position`` (world frame).

    Meshcat's orbit controls always look at (and orbit about) the three.js origin, so the scene
    (``/meshcat``, and meshcat's ``/Grid`` and ``/Axes``) is shifted by ``-target`` and the camera placed
    at ``position - target`` (in the camera's y-up frame: (x, z, -y)).
    """
    T = homogeneous(t=-np.asarray(target, float))
    for path in ("/meshcat", "/Grid", "/Axes"):
        vis[path].set_transform(T)
    off = np.asarray(position, float) - np.asarray(target, float)
    vis["/Cameras/default/rotated/<object>"].set_property("position", [float(off[0]), float(off[2]), float(-off[1])])


def default_camera(df: DesignFile) -> tuple[np.ndarray, np.ndarray]:
    """A camera (target, position), world frame (m), that frames the robot and the working configurations."""
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


#: np.allclose's default tolerance of a value against 1 (atol + rtol · 1): a scale within it is no scale
_UNIT_TOL = 1e-8 + 1e-5 * 1.0


def anim_set(node, M: pin.SE3, scale: np.ndarray) -> None:
    """Position / quaternion (/ scale) keyframe of an animated node."""
    q = pin.Quaternion(M.rotation)
    clip = node.get_clip()
    clip.set_property(node.current_frame, "position", "vector3", [float(x) for x in M.translation])
    clip.set_property(node.current_frame, "quaternion", "quaternion", [float(q.x), float(q.y), float(q.z), float(q.w)])
    values = [float(x) for x in scale]
    if not all(abs(x - 1.0) <= _UNIT_TOL for x in values):  # np.allclose(scale, 1.0) of a few numbers, in Python
        clip.set_property(node.current_frame, "scale", "vector3", values)


def working_paths(vis: Any, mg: Any, df: DesignFile) -> int:
    """Draw the cell's working paths (the design file's ``cell.paths``: TCP positions in the cell frame, m) as
    lines under ``working/paths/<name>``, with a point at every sample. Returns the number of paths drawn."""
    paths = (df.raw.get("cell") or {}).get("paths") or []
    for p in paths:
        X = np.asarray(p.get("xyz_m", []), dtype=np.float32).reshape(-1, 3)
        if len(X) < 2:
            continue
        node = vis[f"working/paths/{p.get('name', 'path')}"]
        node["line"].set_object(mg.Line(mg.PointsGeometry(X.T), mg.LineBasicMaterial(color=0xD62728, linewidth=3)))
        node["samples"].set_object(mg.Points(mg.PointsGeometry(X.T), mg.PointsMaterial(size=0.006, color=0xD62728)))
    return len(paths)

