"""Obstacles of the cell from mesh or URDF files of the environment (tables, fixtures, guards).

A cell file lists them under ``environment`` (paths relative to the cell file; SI units)::

    environment:
      - name: table
        urdf: ur10_table.urdf          # a fixed URDF: every <collision> box / cylinder / sphere / mesh
        pose: {xyz_m: [0.9, 0.0, 0.0], rpy_deg: [0, 0, 0]}   # URDF root in the cell frame
        max_radius_m: 0.08             # capsules for the optimiser: split until each radius <= this
        max_capsules: 16               # at most this many capsules per geometry piece
      - name: fixture
        mesh: fixture.stl              # STL / OBJ / DAE / PLY (Coal's assimp loader)
        scale: 0.001                   # file units -> m (a number or [sx, sy, sz]); default 1
        pose: {xyz_m: [...], rpy_deg: [...]}

      - name: crate                    # a primitive: one Coal shape, no file
        box: {size_m: [0.3, 0.3, 0.3]}   # full side lengths along the pose's x, y, z
        pose: {xyz_m: [0.6, -0.4, 0.15]}
      - name: pillar
        cylinder: {radius_m: 0.1, length_m: 1.5}   # axis along the pose's z, centred
        pose: {xyz_m: [-0.5, 0.8, 0.75]}
      - name: lamp
        sphere: {radius_m: 0.2}
        pose: {xyz_m: [0.0, 1.2, 1.6]}

A primitive is one Coal shape: the independent check's distances to it are exact (Coal's signed
distance). The optimiser's capsules: a sphere is one capsule of length 0 and a cylinder one capsule of its
radius along its axis (both exact enclosures); a box the fewest enclosing capsules whose radius is at most
``max_radius_m`` (:func:`box_capsules`; default: the larger of 0.1 m and the box's smallest half side times √2:
a cube is one capsule, a table top a few strips).

Each file becomes, from the same geometry,

* **capsules for the optimiser** (eqs. 20–21): enclosing capsules fitted to every geometry piece
  (:func:`pin_kpi_oed.cell.meshes.fit_capsules`: every vertex inside, a large flat piece split into
  strips until each radius is at most ``max_radius_m``); they join the cell's obstacle capsules as
  ``<name>_<k>``;
* **solids for the independent check** (:mod:`pin_kpi_oed.cell.feasibility`): the geometry itself —
  Coal boxes, cylinders and spheres as given, meshes as Coal convex shapes when they are convex
  (exact signed distance) and as Coal BVH triangle meshes otherwise (distance negative when a shape
  crosses triangles, the depth per triangle as Coal reports it; degenerate contacts re-tested with
  ``coal.collide``). A robot capsule entirely inside a closed
  non-convex mesh touches no triangle and is not seen by the BVH; the enclosing capsules of the
  optimiser still keep it out.

``skip_pairs`` and ``beam.skip`` may name the environment object (all its capsules and solids).
Movable joints of an environment URDF are held at zero.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin

from pin_kpi_oed.cell.cell_model import CapsuleSpec
from pin_kpi_oed.errors import InputError

#: default largest capsule radius fitted to environment geometry (m)
DEFAULT_MAX_RADIUS_M = 0.1
#: default most capsules per geometry piece (a URDF <collision> element or a mesh file)
DEFAULT_MAX_CAPSULES = 16


@dataclass
class EnvironmentSolid:
    """One geometry piece of an environment object, as the independent check sees it.

    Attributes:
        name: ``<object>`` or ``<object>_<k>``.
        geometry: the Coal shape (Box, Cylinder, Sphere, Convex or BVH model), in its own frame.
        W_T_g: its placement in the cell frame.
        convex: whether Coal's signed distance is exact for it (False: a BVH triangle mesh).
        vertices: (k, 3) its vertices in the cell frame (m); faces: (f, 3) triangles (or None).
    """

    name: str
    geometry: Any
    W_T_g: pin.SE3
    convex: bool
    vertices: np.ndarray
    faces: np.ndarray | None


@dataclass
class EnvironmentObject:
    """An obstacle read from a mesh or URDF file (see the module docstring).

    Attributes:
        name: its name (skip lists may use it).
        kind: ``mesh``, ``urdf`` or a primitive (``box``, ``cylinder``, ``sphere``).
        path: the file (absolute; empty for a primitive).
        W_T_obj: pose of the file's frame in the cell frame.
        scale: (3,) scale of a mesh file (1 for URDFs: their meshes carry their own).
        max_radius_m: largest fitted capsule radius asked for (m).
        solids: the geometry for the independent check.
        capsules: the enclosing capsules for the optimiser (cell frame), ``<name>_<k>``.
        shape: a primitive's sizes (m), e.g. ``{"size_m": [x, y, z]}``; None for a file.
    """

    name: str
    kind: str
    path: str
    W_T_obj: pin.SE3
    scale: np.ndarray
    max_radius_m: float
    solids: list[EnvironmentSolid] = field(default_factory=list)
    capsules: list = field(default_factory=list)
    shape: dict | None = None

    def to_dict(self) -> dict:
        """Plain numbers (SI units): the file (or a primitive's sizes), its pose (4×4), scale and the fitted
        capsules."""
        out = {"name": self.name, "kind": self.kind, "path": self.path, "W_T_obj": self.W_T_obj.homogeneous.tolist(),
               "scale": [float(x) for x in self.scale], "max_radius_m": self.max_radius_m,
               "capsules": [c.name for c in self.capsules], "solids": [s.name for s in self.solids]}
        if self.shape is not None:
            out["shape"] = self.shape
        return out


def _first_line(exc: BaseException) -> str:
    lines = [ln.strip() for ln in str(exc).strip().splitlines() if ln.strip()]
    msg = next((ln for ln in lines if ln.lower().startswith("message")), lines[0] if lines else type(exc).__name__)
    return msg.split(":", 1)[-1].strip() if msg.lower().startswith("message") else msg


def _bvh_arrays(bvh) -> tuple[np.ndarray, np.ndarray]:
    """(vertices (k, 3), triangles (f, 3)) of a Coal BVH model, in its own frame."""
    V = np.asarray(bvh.vertices(), float).reshape(-1, 3)
    F = np.empty((bvh.num_tris, 3), np.int64)
    for i in range(bvh.num_tris):
        t = bvh.tri_indices(i)
        F[i] = (t[0], t[1], t[2])
    return V, F


def _solid(name: str, g: Any, W_T_g: pin.SE3, where: str) -> EnvironmentSolid:
    """The check's solid and its cell-frame triangles for one Coal geometry."""
    import coal
    import trimesh

    if isinstance(g, coal.Box):
        tm = trimesh.creation.box(extents=2.0 * np.asarray(g.halfSide, float))
        convex, geom = True, g
    elif isinstance(g, coal.Cylinder):
        n = 32  # circumscribed polygon: its vertices enclose the true cylinder
        tm = trimesh.creation.cylinder(radius=float(g.radius) / np.cos(np.pi / n), height=2.0 * float(g.halfLength),
                                       sections=n)
        convex, geom = True, g
    elif isinstance(g, coal.Sphere):
        tm = trimesh.creation.icosphere(subdivisions=1, radius=float(g.radius))
        convex, geom = True, g
    elif isinstance(g, coal.BVHModelBase):
        V, F = _bvh_arrays(g)
        if V.shape[0] == 0:
            raise InputError(f"{where}: the mesh has no vertices")
        tm = trimesh.Trimesh(V, F, process=False)
        convex = bool(tm.is_watertight and tm.is_convex)
        geom = g
        if convex:
            g.buildConvexRepresentation(False)
            geom = g.convex
    else:
        raise InputError(f"{where}: geometry {type(g).__name__} is not supported (box, cylinder, sphere or mesh)")
    V = np.asarray(tm.vertices, float) @ W_T_g.rotation.T + W_T_g.translation
    if isinstance(g, coal.Sphere):  # exact: the capsule of a sphere is itself
        V = W_T_g.translation[None, :].copy()
    return EnvironmentSolid(name, geom, W_T_g, convex, V, np.asarray(tm.faces, np.int64))


def _mesh_solids(name: str, path: Path, scale: np.ndarray, W_T_obj: pin.SE3, where: str) -> list[EnvironmentSolid]:
    import coal

    try:
        bvh = coal.MeshLoader().load(str(path), np.asarray(scale, float))
    except Exception as exc:
        raise InputError(f"{where}: cannot read the mesh {path} ({_first_line(exc)})") from None
    return [_solid(name, bvh, W_T_obj, where)]


def _urdf_solids(name: str, path: Path, W_T_obj: pin.SE3, where: str) -> list[EnvironmentSolid]:
    from pin_kpi_oed.cell.meshes import package_dirs

    try:
        model = pin.buildModelFromUrdf(str(path))
        gm = pin.buildGeomFromUrdf(model, str(path), pin.GeometryType.COLLISION, package_dirs=package_dirs(path))
    except Exception as exc:
        raise InputError(f"{where}: cannot read the URDF {path} ({_first_line(exc)})") from None
    if not gm.geometryObjects:
        raise InputError(f"{where}: {path} has no <collision> geometry")
    data, gd = model.createData(), pin.GeometryData(gm)
    pin.framesForwardKinematics(model, data, pin.neutral(model))
    pin.updateGeometryPlacements(model, data, gm, gd)
    out = []
    for i, go in enumerate(gm.geometryObjects):
        nm = name if len(gm.geometryObjects) == 1 else f"{name}_{go.name}"
        out.append(_solid(nm, go.geometry, W_T_obj * gd.oMg[i], f"{where} ({go.name})"))
    return out


def load_environment_object(d: Any, index: int, base_dir: Path | None, source: str, pose_reader) -> EnvironmentObject:
    """One entry of the cell's ``environment`` list (see the module docstring).

    Args:
        d: the entry (``name``, ``mesh`` or ``urdf``, optional ``pose``, ``scale``, ``max_radius_m``,
            ``max_capsules``).
        index: its index (for messages).
        base_dir: folder relative paths are resolved against (the cell file's).
        source: the cell file (for messages).
        pose_reader: ``(mapping, what) -> pin.SE3`` (the cell reader's pose parser).

    Returns:
        The :class:`EnvironmentObject` with its solids and fitted capsules.

    Raises:
        InputError: a missing/unreadable file or a bad field, naming the cell file and the key.
    """
    from pin_kpi_oed.cell.meshes import fit_capsules

    pre = f"{source}: " if source else ""
    w = f"{pre}environment[{index}]"
    if not isinstance(d, dict) or "name" not in d:
        raise InputError(f"{w}: expected a mapping with name and mesh or urdf")
    kinds = [k for k in ("mesh", "urdf") + PRIMITIVES if k in d]
    if len(kinds) != 1:
        raise InputError(f"{w}: give exactly one of 'mesh' or 'urdf' (a file relative to the cell file) or a "
                         f"primitive ({', '.join(PRIMITIVES)})")
    kind = kinds[0]
    name = str(d["name"])
    if kind in PRIMITIVES:
        return _primitive_object(d, kind, name, w, pose_reader)
    p = Path(str(d[kind]))
    if not p.is_absolute() and base_dir is not None:
        p = (base_dir / p).resolve()
    where = f"{w}.{kind}"
    if not p.is_file():
        raise InputError(f"{where}: no such file {p}")
    W_T_obj = pose_reader(d.get("pose"), f"{w}.pose")
    sc: Any = d.get("scale", 1.0)
    scale = np.full(3, float(np.asarray(sc, float))) if np.ndim(sc) == 0 else np.asarray(sc, float).reshape(-1)
    if scale.shape != (3,) or not np.all(np.isfinite(scale) & (scale > 0)):
        raise InputError(f"{w}.scale: expected a positive number or 3 positive numbers, got {sc!r}")
    if kind == "urdf" and "scale" in d:
        raise InputError(f"{w}.scale: only for 'mesh' (a URDF's meshes carry their own scale)")
    rmax = float(d.get("max_radius_m", DEFAULT_MAX_RADIUS_M))
    ncap = int(d.get("max_capsules", DEFAULT_MAX_CAPSULES))
    if not (rmax > 0 and np.isfinite(rmax)) or ncap < 1:
        raise InputError(f"{w}: max_radius_m must be > 0 and max_capsules >= 1")
    solids = (_mesh_solids(name, p, scale, W_T_obj, where) if kind == "mesh"
              else _urdf_solids(name, p, W_T_obj, where))
    obj = EnvironmentObject(name, kind, str(p), W_T_obj, scale if kind == "mesh" else np.ones(3), rmax, solids)
    caps = []
    for s in solids:
        if s.vertices.shape[0] == 1:  # a sphere: exactly one capsule
            caps.append((s.vertices[0], s.vertices[0], float(s.geometry.radius)))
        else:
            caps += fit_capsules(s.vertices, s.faces, rmax, ncap)
    obj.capsules = [CapsuleSpec(f"{name}_{k}", np.asarray(a, float), np.asarray(b, float), float(r))
                    for k, (a, b, r) in enumerate(caps)]
    return obj


#: obstacle shapes a cell file may give without a file (one Coal shape each)
PRIMITIVES = ("box", "cylinder", "sphere")


def _positive(spec: dict, key: str, n: int | None, where: str) -> Any:
    v = spec.get(key) if isinstance(spec, dict) else None
    try:
        a = np.asarray(v, float)
    except (TypeError, ValueError):
        a = np.array([np.nan])
    if v is None or a.shape != (() if n is None else (n,)) or not np.all(np.isfinite(a) & (a > 0)):
        want = "a positive number" if n is None else f"{n} positive numbers"
        raise InputError(f"{where}.{key}: expected {want} (m), got {v!r}")
    return float(a) if n is None else a


def box_capsules(half: np.ndarray, max_radius: float, max_pieces: int = DEFAULT_MAX_CAPSULES
                 ) -> list[tuple[np.ndarray, np.ndarray, float]]:
    """Enclosing capsules of a box (its own frame): strips along its longest side, the cross-section split into
    k1 × k2 cells, the fewest whose radius is at most ``max_radius`` (at most ``max_pieces``; else the smallest
    radius within them). A strip of half-sizes (h0, c1, c2) is enclosed by the capsule of radius sqrt(c1² + c2²)
    whose segment spans ±h0 (its corners lie on the end caps).

    Returns:
        [(a, b, radius)] in the box frame (m).
    """
    order = np.argsort(-np.asarray(half, float))
    h0, h1, h2 = (float(half[i]) for i in order)
    best = None
    for k1 in range(1, max_pieces + 1):
        for k2 in range(1, max_pieces // k1 + 1):
            r = float(np.hypot(h1 / k1, h2 / k2))
            key = (r > max_radius, k1 * k2 if r <= max_radius else r)
            if best is None or key < best[0]:
                best = (key, k1, k2, r)
    _, k1, k2, r = best
    out = []
    for i in range(k1):
        for j in range(k2):
            c = np.zeros(3)
            c[order[1]] = -h1 + h1 / k1 * (2 * i + 1)
            c[order[2]] = -h2 + h2 / k2 * (2 * j + 1)
            e = np.zeros(3)
            e[order[0]] = h0
            out.append((c - e, c + e, r))
    return out


def _primitive_object(d: dict, kind: str, name: str, w: str, pose_reader) -> EnvironmentObject:
    """A box / cylinder / sphere entry: one Coal shape for the check, its enclosing capsules for the optimiser."""
    import coal

    spec, where = d[kind], f"{w}.{kind}"
    extra = set(spec) - {"box": {"size_m"}, "cylinder": {"radius_m", "length_m"}, "sphere": {"radius_m"}}[kind] \
        if isinstance(spec, dict) else set()
    if not isinstance(spec, dict) or extra:
        raise InputError(f"{where}: expected {{size_m: [x, y, z]}} for a box, {{radius_m, length_m}} for a cylinder, "
                         f"{{radius_m}} for a sphere (m)" + (f"; unknown {', '.join(sorted(extra))}" if extra else ""))
    if "scale" in d:
        raise InputError(f"{w}.scale: only for 'mesh' (give a primitive's sizes in m)")
    W_T_obj = pose_reader(d.get("pose"), f"{w}.pose")
    if kind == "box":
        size = _positive(spec, "size_m", 3, where)
        geom, shape = coal.Box(*size), {"size_m": size.tolist()}
        rmax_default = max(DEFAULT_MAX_RADIUS_M, float(np.min(size)) / 2.0 * np.sqrt(2.0) * 1.001)
    elif kind == "cylinder":
        r, length = _positive(spec, "radius_m", None, where), _positive(spec, "length_m", None, where)
        geom, shape, rmax_default = coal.Cylinder(r, length), {"radius_m": r, "length_m": length}, r
    else:
        r = _positive(spec, "radius_m", None, where)
        geom, shape, rmax_default = coal.Sphere(r), {"radius_m": r}, r
    rmax = float(d.get("max_radius_m", rmax_default))
    ncap = int(d.get("max_capsules", DEFAULT_MAX_CAPSULES))
    if not (rmax > 0 and np.isfinite(rmax)) or ncap < 1:
        raise InputError(f"{w}: max_radius_m must be > 0 and max_capsules >= 1")
    solid = _solid(name, geom, W_T_obj, where)
    if kind == "sphere":
        caps = [(solid.vertices[0], solid.vertices[0], r)]
    elif kind == "cylinder":  # its own capsule: the axis, the radius (encloses the cylinder exactly)
        caps = [(W_T_obj.act(np.array([0.0, 0.0, -length / 2])), W_T_obj.act(np.array([0.0, 0.0, length / 2])), r)]
    else:
        caps = [(W_T_obj.act(a), W_T_obj.act(b), rr) for a, b, rr in box_capsules(size / 2.0, rmax, ncap)]
    obj = EnvironmentObject(name, kind, "", W_T_obj, np.ones(3), rmax, [solid], shape=shape)
    obj.capsules = [CapsuleSpec(f"{name}_{k}", np.asarray(a, float), np.asarray(b, float), float(rr))
                    for k, (a, b, rr) in enumerate(caps)]
    return obj


def ball_distance(solid: EnvironmentSolid, p: np.ndarray, radius: float = 0.0) -> float:
    """Distance (m) of a ball of ``radius`` at ``p`` (cell frame) to a solid, negative when they overlap (Coal;
    exact for boxes, cylinders, spheres and convex meshes)."""
    import coal

    M = coal.Transform3s(np.asarray(solid.W_T_g.rotation), np.asarray(solid.W_T_g.translation))
    T = coal.Transform3s(np.eye(3), np.asarray(p, float))
    return float(coal.distance(coal.Sphere(max(float(radius), 1e-9)), T, solid.geometry, M, coal.DistanceRequest(),
                               coal.DistanceResult()))


def environment_from_dicts(entries: Any, obstacles: list, where: str, notes: list[str]) -> list[EnvironmentObject]:
    """The environment files of a design JSON's cell (:meth:`EnvironmentObject.to_dict`), read again.

    The optimiser's capsules are the design file's obstacles of the names listed (not re-fitted); the
    files give the independent check its solids. A file that is no longer there (a design JSON moved to
    another machine) leaves its capsules as ordinary obstacles (conservative) and adds a note.

    Args:
        entries: the ``environment`` list of the JSON (None: none).
        obstacles: the design file's obstacle capsules.
        where: the design file (for messages); notes: list the notes are appended to.

    Returns:
        The environment objects found.
    """
    from pin_kpi_oed.model.serialize import se3_from_matrix

    out: list[EnvironmentObject] = []
    by_name = {o.name: o for o in obstacles}
    for i, e in enumerate(entries or []):
        if not isinstance(e, dict) or not {"name", "kind", "path", "W_T_obj"} <= set(e):
            continue
        caps = [by_name[n] for n in e.get("capsules") or [] if n in by_name]
        d = {"name": e["name"], e["kind"]: e.get("shape") if e["kind"] in PRIMITIVES else e["path"],
             "max_radius_m": e.get("max_radius_m", DEFAULT_MAX_RADIUS_M)}
        if e["kind"] == "mesh":
            d["scale"] = list(e.get("scale", [1.0, 1.0, 1.0]))
        try:
            M = se3_from_matrix(e["W_T_obj"], f"{where}: cell.environment[{i}].W_T_obj")
            obj = load_environment_object(d, i, None, where, lambda _p, _w, M=M: M)
        except InputError as exc:
            notes.append(f"environment '{e['name']}' checked as its capsules: {exc}")
            continue
        obj.capsules = caps
        out.append(obj)
    return out
