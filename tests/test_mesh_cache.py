"""Meshes read once per process: a cell or a scene built twice reads its mesh files once, gives the same numbers,
hands out nothing a caller could change the cache through, and reads a changed file again (a change of size or of
the modification time in ns, even within one second)."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
import trimesh

from pin_kpi_oed.cell.cell import load_cell
from pin_kpi_oed.cell.meshes import build_geometry, clear_mesh_caches, file_stamp, file_vertices, fit_capsules
from pin_kpi_oed.model.robot import load_robot
from pin_kpi_oed.viz.robot_geometry import add_reflector, visual_model


def _write_box(path: Path, scale: float) -> None:
    """A binary STL box of side ``scale`` m (the same byte size whatever the scale)."""
    trimesh.creation.box([scale, scale, scale]).export(path)


def _rewrite(path: Path, scale: float, mtime_ns: int) -> None:
    """The box rewritten at another scale, its modification time set to ``mtime_ns`` afterwards."""
    size = path.stat().st_size
    _write_box(path, scale)
    assert path.stat().st_size == size
    os.utime(path, ns=(mtime_ns, mtime_ns))


def _counting_trimesh_load(monkeypatch) -> list:
    calls: list = []
    real = trimesh.load

    def load(*args, **kwargs):
        calls.append(args[0])
        return real(*args, **kwargs)

    monkeypatch.setattr(trimesh, "load", load)
    return calls


def _cell_numbers(cell) -> list:
    caps = [c.to_dict() for c in cell.robot_capsules] + [c.to_dict() for c in cell.obstacles]
    env = [(e.to_dict(), [c.to_dict() for c in e.capsules]) for e in cell.environment]
    return [caps, env, cell.q_work.tolist()]


def test_a_cell_loaded_twice_reads_its_meshes_once_and_gives_the_same_numbers(monkeypatch):
    clear_mesh_caches()
    calls = _counting_trimesh_load(monkeypatch)
    first = load_cell("ur10")  # robot_capsules: urdf on the UR10's collision meshes, a table from a URDF
    n_read = len(calls)
    assert n_read >= 7  # one per collision mesh of the UR10
    numbers = _cell_numbers(first)
    first.robot_capsules[0].a[:] = 99.0  # a caller changing its cell changes no other cell
    first.environment[0].capsules[0].b[:] = -99.0
    second = load_cell("ur10")
    assert len(calls) == n_read  # nothing read again
    assert _cell_numbers(second) == numbers
    clear_mesh_caches()
    assert _cell_numbers(load_cell("ur10")) == numbers  # the same numbers as from the files
    assert len(calls) == 2 * n_read


def test_a_changed_mesh_file_is_read_again_even_within_one_second(tmp_path, monkeypatch):
    path = tmp_path / "box.stl"
    _write_box(path, 0.1)
    t0 = (path.stat().st_mtime_ns // 1_000_000_000) * 1_000_000_000  # a whole second: +100 ns stays within it
    os.utime(path, ns=(t0, t0))
    calls = _counting_trimesh_load(monkeypatch)
    V = file_vertices(path)
    assert np.abs(V).max() == pytest.approx(0.05)
    with pytest.raises(ValueError):
        V[0, 0] = 1.0  # read-only: no caller changes the cache
    _rewrite(path, 0.2, t0)  # same size, same time: the cache cannot tell (so it is the cache answering)
    assert np.abs(file_vertices(path)).max() == pytest.approx(0.05) and len(calls) == 1
    _rewrite(path, 0.2, t0 + 100)  # 100 ns later: read again
    assert file_stamp(path) == (str(path.resolve()), path.stat().st_size, t0 + 100)
    assert np.abs(file_vertices(path)).max() == pytest.approx(0.1) and len(calls) == 2
    size = path.stat().st_size
    trimesh.creation.box([0.3, 0.3, 0.3]).export(path, file_type="stl_ascii")  # another size, the old time
    assert path.stat().st_size != size
    os.utime(path, ns=(t0 + 100, t0 + 100))
    assert np.abs(file_vertices(path)).max() == pytest.approx(0.15) and len(calls) == 3


def _one_mesh_urdf(folder: Path, mesh: Path, visual: bool) -> tuple[pin.Model, Path]:
    """A one-link URDF in ``folder`` whose collision (with ``visual``, also visual) geometry is ``mesh``; its model."""
    vis = f'<visual><geometry><mesh filename="{mesh}"/></geometry></visual>' if visual else ""
    urdf = folder / "part.urdf"
    urdf.write_text(f"""<robot name="part"><link name="base">{vis}<collision><geometry><mesh filename="{mesh}"/>
        </geometry></collision></link></robot>""")
    return pin.buildModelFromUrdf(str(urdf)), urdf


def _half_side(model: pin.Model, urdf: Path, folder: Path) -> float:
    """Half the side of the (box) collision mesh the geometry built now holds (m)."""
    gm = build_geometry(model, urdf, pin.GeometryType.COLLISION, [str(folder)])
    return float(np.abs(np.asarray(gm.geometryObjects[0].geometry.vertices())).max())


def test_urdf_geometry_keeps_coals_meshes_and_reloads_a_changed_one(tmp_path):
    mesh = tmp_path / "part.stl"
    _write_box(mesh, 0.1)
    t0 = (mesh.stat().st_mtime_ns // 1_000_000_000) * 1_000_000_000
    os.utime(mesh, ns=(t0, t0))
    model, urdf = _one_mesh_urdf(tmp_path, mesh, visual=True)
    clear_mesh_caches()
    assert _half_side(model, urdf, tmp_path) == pytest.approx(0.05)
    _rewrite(mesh, 0.2, t0)  # unchanged stamp: Coal's mesh kept
    assert _half_side(model, urdf, tmp_path) == pytest.approx(0.05)
    _rewrite(mesh, 0.2, t0 + 100)  # 100 ns later (Coal's own check sees whole seconds): loaded again
    assert _half_side(model, urdf, tmp_path) == pytest.approx(0.1)
    gm = build_geometry(model, urdf, pin.GeometryType.VISUAL, [str(tmp_path)])
    gm.addGeometryObject(pin.GeometryObject("extra", 0, pin.SE3.Identity(), gm.geometryObjects[0].geometry))
    assert len(build_geometry(model, urdf, pin.GeometryType.VISUAL, [str(tmp_path)]).geometryObjects) == 1


def test_visual_model_twice_is_the_same_geometry_in_new_objects():
    rb = load_robot("ur10")
    m1, v1, n1 = visual_model(rb)
    m2, v2, n2 = visual_model(rb)
    assert v1 is not None and v2 is not None and n1 == n2 == []
    assert m1 is not m2 and v1 is not v2 and m1 == m2
    assert [g.name for g in v1.geometryObjects] == [g.name for g in v2.geometryObjects]
    for a, b in zip(v1.geometryObjects, v2.geometryObjects):
        assert a.meshPath == b.meshPath and a.parentJoint == b.parentJoint and a.placement.isApprox(b.placement)
        np.testing.assert_array_equal(np.asarray(a.geometry.vertices()), np.asarray(b.geometry.vertices()))
    add_reflector(m1, v1, rb, np.array([0.0, 0.0, 0.1]))  # a scene adds to its own copy only
    v1.geometryObjects[0].meshColor = np.array([1.0, 0.0, 0.0, 1.0])
    _, v3, _ = visual_model(rb)
    assert v3 is not None and len(v3.geometryObjects) == len(v2.geometryObjects)
    assert not np.array_equal(v3.geometryObjects[0].meshColor, [1.0, 0.0, 0.0, 1.0])


def test_fitted_capsules_are_the_computed_ones_and_copies():
    plate = trimesh.creation.box([1.0, 0.6, 0.02])
    clear_mesh_caches()
    fresh = fit_capsules(plate.vertices, plate.faces, 0.08)
    assert len(fresh) > 1
    again = fit_capsules(plate.vertices, plate.faces, 0.08)
    for (a, b, r), (a2, b2, r2) in zip(fresh, again, strict=True):
        assert np.array_equal(a, a2) and np.array_equal(b, b2) and r == r2 and a is not a2
    again[0][0][:] = 7.0
    assert np.array_equal(fit_capsules(plate.vertices, plate.faces, 0.08)[0][0], fresh[0][0])
    assert len(fit_capsules(plate.vertices, plate.faces, 0.3)) < len(fresh)  # other parameters: another fit


def test_urdf_geometry_reloads_when_its_path_reaches_another_file_of_the_same_size_and_time(tmp_path):
    """A symbolic link in the mesh's path pointed at another file (same byte size, same modification time): the
    shared loader's check sees another file and the geometry is read from the new one."""
    small, big = tmp_path / "small.stl", tmp_path / "big.stl"
    _write_box(small, 0.1)
    _write_box(big, 0.2)
    t0 = (small.stat().st_mtime_ns // 1_000_000_000) * 1_000_000_000
    for p in (small, big):
        os.utime(p, ns=(t0, t0))
    link = tmp_path / "part.stl"
    link.symlink_to(small)
    model, urdf = _one_mesh_urdf(tmp_path, link, visual=False)
    clear_mesh_caches()
    assert _half_side(model, urdf, tmp_path) == pytest.approx(0.05)
    link.unlink()
    link.symlink_to(big)
    assert _half_side(model, urdf, tmp_path) == pytest.approx(0.1)
