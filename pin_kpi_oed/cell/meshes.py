"""Capsules fitted to meshes: robot capsules from a URDF's collision (or visual) meshes.

For ``robot_capsules: urdf`` (collision geometry) or ``urdf_visual`` (visual geometry) in a cell
file, every geometry object of the URDF becomes one enclosing capsule in its link frame:
cylinders, capsules and spheres exactly (as before), meshes and boxes by :func:`fit_capsule` on
their vertices. The fit is *enclosing* (every vertex inside, so the optimiser's and the check's
capsules are conservative), its axis a principal axis of the vertices (of the three, the one giving the smallest capsule
volume) through the centre of their bounding box across it, its radius the largest distance of a vertex
from that axis, and its segment the shortest one whose spherical caps still cover the vertices
beyond the ends.

What is read from mesh files is kept per process (two cells of one robot in one process read its meshes
once): the meshes Coal loads (one shared ``coal.CachedMeshLoader``, dropped as soon as a file it read
changed: another file at its path, another size or modification time), the vertices trimesh reads (keyed by
:func:`file_stamp`: resolved path, size and modification time in ns) and the capsules fitted to a point set or
mesh (keyed by the points' bytes). A changed file is read again; what a caller gets is a copy or a read-only
array, never the cached object itself.
"""

from __future__ import annotations

import hashlib
import os
from collections import OrderedDict
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin

from pin_kpi_oed.errors import InputError

#: the most fitted results kept per process (least recently used dropped first)
FIT_CACHE_SIZE = 256


def file_stamp(path: str | Path) -> tuple[str, int, int] | None:
    """What the per-process mesh caches key a file on.

    Args:
        path: a file.

    Returns:
        (resolved path, size in bytes, modification time in ns), or None when the file cannot be stat'ed
        (then nothing is cached and the reader reports the error).
    """
    try:
        p = Path(path).resolve()
        st = p.stat()
    except (OSError, RuntimeError, ValueError):
        return None
    return str(p), int(st.st_size), int(st.st_mtime_ns)


def _loader_stamp(path: str) -> tuple[int, int, int, int] | None:
    """What the shared Coal loader's check keys a mesh file on: the file the path reaches (device, inode), its size
    and modification time in ns (one ``stat``, no resolution of the path's folders: this check runs for every
    mesh read so far at every geometry built), or None when it cannot be stat'ed."""
    try:
        st = os.stat(path)
    except (OSError, ValueError):
        return None
    return int(st.st_dev), int(st.st_ino), int(st.st_size), int(st.st_mtime_ns)


class _MeshCaches:
    """The process's mesh caches (see the module docstring)."""

    def __init__(self) -> None:
        self.loader: Any = None                 # coal.CachedMeshLoader shared by every URDF geometry
        self.loaded: dict[str, tuple[int, int, int, int] | None] = {}   # mesh file -> stamp when the loader read it
        self.vertices: dict[str, tuple[tuple[str, int, int], np.ndarray]] = {}   # resolved path -> (stamp, V)
        self.fits: OrderedDict[tuple, Any] = OrderedDict()

    def mesh_loader(self) -> Any:
        """The shared Coal loader, a new one when a mesh file it read has changed since."""
        import coal

        if self.loader is None or any(_loader_stamp(f) != s for f, s in self.loaded.items()):
            self.loader, self.loaded = coal.CachedMeshLoader(), {}
        return self.loader

    def note_loaded(self, gm: pin.GeometryModel) -> None:
        """Records the stamps of the mesh files of a geometry model built with :meth:`mesh_loader`."""
        for go in gm.geometryObjects:
            if go.meshPath and go.meshPath not in self.loaded:
                self.loaded[go.meshPath] = _loader_stamp(go.meshPath)

    def fit(self, key: tuple, compute: Any) -> Any:
        """``compute()``, kept under ``key`` (least recently used dropped beyond :data:`FIT_CACHE_SIZE`)."""
        if key in self.fits:
            self.fits.move_to_end(key)
            return self.fits[key]
        value = compute()
        self.fits[key] = value
        while len(self.fits) > FIT_CACHE_SIZE:
            self.fits.popitem(last=False)
        return value


_CACHES = _MeshCaches()


def clear_mesh_caches() -> None:
    """Forgets every mesh, vertex set and fit this process read or computed (the next read is from the files)."""
    global _CACHES
    _CACHES = _MeshCaches()


def build_geometry(model: pin.Model, urdf_path: str | Path, geom_type: pin.GeometryType,
                   dirs: list[str]) -> pin.GeometryModel:
    """A URDF's geometry model with its meshes loaded once per process (``pin.buildGeomFromUrdf`` with the
    process's shared ``coal.CachedMeshLoader``; a mesh file changed since is loaded again).

    The geometry model and its objects are new on every call (a caller may add objects or colour them); the
    Coal meshes inside are shared and must not be modified.

    Args:
        model: the Pinocchio model of the URDF.
        urdf_path: the URDF file.
        geom_type: ``pin.GeometryType.COLLISION`` or ``VISUAL``.
        dirs: folders resolving ``package://`` URIs.

    Returns:
        The geometry model.

    Raises:
        Whatever ``pin.buildGeomFromUrdf`` raises for an unreadable URDF or mesh.
    """
    caches = _CACHES
    gm = pin.buildGeomFromUrdf(model, str(urdf_path), geom_type, package_dirs=dirs,
                               mesh_loader=caches.mesh_loader())
    caches.note_loaded(gm)
    return gm


def _points_key(kind: str, *arrays: np.ndarray | None, params: tuple = ()) -> tuple:
    """A cache key of arrays' exact values (shape, dtype and a BLAKE2 digest of their bytes) and parameters."""
    h = hashlib.blake2b(digest_size=20)
    shapes: list[tuple | None] = []
    for a in arrays:
        if a is None:
            shapes.append(None)
            continue
        c = np.ascontiguousarray(a)
        shapes.append((c.shape, c.dtype.str))
        h.update(c.tobytes())
    return (kind, tuple(shapes), h.hexdigest(), params)


def _copy_caps(caps: list) -> list[tuple[np.ndarray, np.ndarray, float]]:
    return [(np.array(a, float), np.array(b, float), float(r)) for a, b, r in caps]


def fit_capsule(points: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """The enclosing capsule of a point set (see the module docstring); a point set fitted before in this
    process is not fitted again (the same numbers, new arrays).

    Args:
        points: (k, 3) points (m).

    Returns:
        (a, b, radius): segment end points (m) and radius (m); every point within ``radius`` of [a, b].

    Raises:
        InputError: no points or non-finite points.
    """
    P = _finite_points(points)
    return _copy_caps(_CACHES.fit(_points_key("capsule", P), lambda: [_fit_capsule(P)]))[0]


def _finite_points(points: np.ndarray) -> np.ndarray:
    """``points`` as (k, 3) floats, at least one and all finite.

    Raises:
        InputError: no points, or a NaN / inf among them.
    """
    P = np.asarray(points, float).reshape(-1, 3)
    if P.shape[0] == 0 or not np.all(np.isfinite(P)):
        raise InputError("fit_capsule: need finite points")
    return P


def _fit_capsule(P: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """:func:`fit_capsule` of finite (k, 3) points, computed."""
    c = P.mean(axis=0)
    X = P - c
    _, _, Vt = np.linalg.svd(X, full_matrices=False) if P.shape[0] > 1 else (None, None, np.eye(3))
    best = None
    for k, u in enumerate(Vt):
        # the axis through the centre of the bounding box across it (tighter than the centroid)
        o = sum(0.5 * (np.max(X @ w) + np.min(X @ w)) * w for j, w in enumerate(Vt) if j != k)
        Xo = X - o
        t = Xo @ u
        rho = np.linalg.norm(Xo - t[:, None] * u, axis=1)
        r = float(rho.max())
        h = np.sqrt(np.maximum(r * r - rho * rho, 0.0))
        ta, tb = float(np.min(t + h)), float(np.max(t - h))
        if ta > tb:  # a sphere-like set: a ball around the middle
            mid = 0.5 * (ta + tb)
            ta = tb = mid
            r = float(np.max(np.linalg.norm(Xo - mid * u, axis=1)))
        vol = np.pi * r * r * (tb - ta) + 4.0 / 3.0 * np.pi * r ** 3
        if best is None or vol < best[0]:
            best = (vol, c + o + ta * u, c + o + tb * u, r)
    return best[1], best[2], best[3]


def mesh_vertices(go: pin.GeometryObject) -> np.ndarray:
    """Vertices of a mesh or box geometry object in its own frame (m).

    A mesh file is read (trimesh) once per process while its :func:`file_stamp` stays the same.

    Args:
        go: the geometry object (a Coal box, or a mesh with ``meshPath`` and ``meshScale``).

    Returns:
        (k, 3) vertices (m), a new array.
    """
    import coal

    g = go.geometry
    if isinstance(g, coal.Box):
        h = np.asarray(g.halfSide, float)
        return np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)]) * h
    return file_vertices(go.meshPath) * np.asarray(go.meshScale, float)


def file_vertices(path: str | Path) -> np.ndarray:
    """A mesh file's vertices as trimesh reads them (file units), read once per process per :func:`file_stamp`.

    Args:
        path: the mesh file (STL, OBJ, DAE, ...).

    Returns:
        (k, 3) vertices, read-only (the cached array: copy it to change it).

    Raises:
        Whatever ``trimesh.load`` raises for a missing or unreadable file.
    """
    import trimesh

    stamp = file_stamp(path)
    cached = _CACHES.vertices.get(stamp[0]) if stamp is not None else None
    if cached is not None and cached[0] == stamp:
        return cached[1]
    mesh: Any = trimesh.load(str(path), force="mesh")
    V = np.array(mesh.vertices, float)
    V.flags.writeable = False
    if stamp is not None:
        _CACHES.vertices[stamp[0]] = (stamp, V)
    return V


def package_dirs(urdf_path: str | Path) -> list[str]:
    """Folders to resolve ``package://`` URIs of a URDF: example-robot-data's share folder and the URDF's parents."""
    from pin_kpi_oed.model.robot import erd_root

    p = Path(urdf_path).resolve()
    dirs = [str(d) for d in list(p.parents)[:3]]
    try:
        dirs.insert(0, str(erd_root().parents[1]))
    except Exception:  # example-robot-data missing: local folders only
        pass
    return dirs


def geometry_model(robot, kind: str = "collision") -> pin.GeometryModel:
    """The URDF's collision or visual geometry with meshes resolved.

    Raises:
        InputError: unknown kind or unreadable geometry (naming the URDF).
    """
    types = {"collision": pin.GeometryType.COLLISION, "visual": pin.GeometryType.VISUAL}
    if kind not in types:
        raise InputError(f"robot_capsules: unknown geometry kind '{kind}' (collision or visual)")
    try:
        return build_geometry(robot.model, robot.urdf_path, types[kind], package_dirs(robot.urdf_path))
    except Exception as exc:
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise InputError(f"robot_capsules: cannot read the {kind} geometry of {robot.urdf_path} ({first}); "
                         "list the robot capsules explicitly in the cell file") from None


def capsule_of(robot, go: pin.GeometryObject) -> tuple[np.ndarray, np.ndarray, float]:
    """One enclosing capsule (link frame of ``go.parentFrame``) of a geometry object: exact for
    cylinders / capsules / spheres, fitted for meshes and boxes."""
    import coal

    g = go.geometry
    # geometry placement is in the parent *joint* frame: express it in the link (body) frame
    M = robot.model.frames[go.parentFrame].placement.inverse() * go.placement
    if isinstance(g, (coal.Cylinder, coal.Capsule, coal.Sphere)):
        h = 0.0 if isinstance(g, coal.Sphere) else float(g.halfLength)
        return M.act(np.array([0.0, 0.0, -h])), M.act(np.array([0.0, 0.0, h])), float(g.radius)
    if isinstance(g, coal.Box) or go.meshPath:
        V = mesh_vertices(go)
        a, b, r = fit_capsule(V @ M.rotation.T + M.translation)
        return a, b, r
    raise InputError(f"robot_capsules: the geometry of link '{robot.model.frames[go.parentFrame].name}' in "
                     f"{robot.urdf_path} is a {type(g).__name__}; list its capsules explicitly")


def fit_capsules(vertices: np.ndarray, faces: np.ndarray | None, max_radius: float,
                 max_pieces: int = 16) -> list[tuple[np.ndarray, np.ndarray, float]]:
    """Enclosing capsules of a triangle mesh, split until each radius is at most ``max_radius``.

    One capsule (:func:`fit_capsule`) encloses the mesh's vertices, hence its convex hull. While the
    largest capsule's radius exceeds ``max_radius`` (and fewer than ``max_pieces`` capsules exist), its
    piece of mesh is cut in two by the plane through the middle of its extent along the principal axis
    that sets the radius (the second-longest extent; trimesh's exact plane slicing, whose cut edges add
    vertices), and each half gets its own capsule. Every piece's capsule encloses that piece's vertices
    and so the piece (a capsule is convex): the union of the capsules encloses the mesh, whatever its
    shape (a table top becomes strips, a leg stays one capsule).

    Args:
        vertices: (k, 3) vertices (m).
        faces: (f, 3) vertex indices of the triangles, or None (a point set: one capsule).
        max_radius: largest wanted capsule radius (m), > 0.
        max_pieces: most capsules returned (the radius bound may then be exceeded).

    Returns:
        [(a, b, radius)] segment end points (m) and radius (m), every vertex inside one of them.

    Raises:
        InputError: no finite vertices.
    """
    V = _finite_points(vertices)
    F = None if faces is None else np.asarray(faces, np.int64)
    key = _points_key("capsules", V, F, params=(float(max_radius), int(max_pieces)))
    return _copy_caps(_CACHES.fit(key, lambda: _fit_capsules(V, F, max_radius, max_pieces)))


def _fit_capsules(V: np.ndarray, faces: np.ndarray | None, max_radius: float,
                  max_pieces: int) -> list[tuple[np.ndarray, np.ndarray, float]]:
    """:func:`fit_capsules` of finite (k, 3) vertices, computed."""
    import heapq

    a, b, r = _fit_capsule(V)
    if faces is None or len(faces) == 0 or r <= max_radius or max_pieces <= 1:
        return [(a, b, r)]
    import trimesh

    heap: list = [(-r, 0, (a, b, r), trimesh.Trimesh(V, faces, process=False))]
    done: list[tuple[np.ndarray, np.ndarray, float]] = []
    tick = 1
    while heap and len(heap) + len(done) < max_pieces:
        negr, _, cap, mesh = heapq.heappop(heap)
        if -negr <= max_radius:
            done.append(cap)
            continue
        halves = _split(mesh)
        if halves is None:
            done.append(cap)
            continue
        for h in halves:
            ca = _fit_capsule(np.asarray(h.vertices, float).reshape(-1, 3))
            heapq.heappush(heap, (-ca[2], tick, ca, h))
            tick += 1
    return done + [c for _, _, c, _ in heap]


def _split(mesh) -> tuple | None:
    """The two halves of a mesh cut across its second-longest principal extent (None if it cannot be cut)."""
    from trimesh.intersections import slice_mesh_plane

    V = np.asarray(mesh.vertices, float)
    c = V.mean(axis=0)
    _, _, Vt = np.linalg.svd(V - c, full_matrices=False)
    ext = [(float(np.ptp((V - c) @ u)), u) for u in Vt]
    ext.sort(key=lambda e: -e[0])
    width, u = ext[1] if len(ext) > 1 and ext[1][0] > 1e-9 else ext[0]
    t = (V - c) @ u
    origin = c + 0.5 * (t.max() + t.min()) * u
    try:
        halves = [slice_mesh_plane(mesh, s * u, origin, cap=False) for s in (1.0, -1.0)]
    except Exception:  # degenerate cut: keep the piece whole
        return None
    if any(h is None or len(h.faces) == 0 for h in halves):
        return None
    if any(np.ptp((np.asarray(h.vertices) - c) @ u) > 0.999 * width for h in halves):  # no progress
        return None
    return tuple(halves)
