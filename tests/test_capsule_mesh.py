"""The scene's capsule mesh is Pinocchio's ``createCapsule`` mesh, bit for bit, made by array operations."""

from __future__ import annotations

import numpy as np
import pytest

from pin_kpi_oed.viz.robot_geometry import capsule_arrays, capsule_mesh, meshcat_visualizer


@pytest.mark.parametrize("length, radius", [(1e-6, 0.05), (0.3, 0.1), (1.2345, 0.0731),
                                            (np.float64(0.7), np.float64(0.12)), (2.0, 1e-3)])
def test_capsule_mesh_is_pinocchios_bit_for_bit(length, radius, monkeypatch):
    import pinocchio.visualize.meshcat_visualizer as pmv

    ref, mesh = pmv.createCapsule(length, radius), capsule_mesh(length, radius)  # as meshcat stores them (float32)
    for got, want in ((mesh.vertices, ref.vertices), (mesh.faces, ref.faces)):
        assert got.dtype == want.dtype and got.shape == want.shape and got.tobytes() == want.tobytes()
    made = {}  # the float64 arrays createCapsule hands to meshcat

    class Capture:
        def __init__(self, vertices, faces):
            made.update(vertices=vertices, faces=faces)

    monkeypatch.setattr(pmv.mg, "TriangularMeshGeometry", Capture)
    pmv.createCapsule(length, radius)
    V, F = capsule_arrays(length, radius)
    for got, want in ((V, made["vertices"]), (F, made["faces"])):
        assert got.dtype == want.dtype and got.shape == want.shape and got.tobytes() == want.tobytes()
    assert capsule_arrays(length, radius)[1] is not F  # each call its own triangles: the cached ones never leave


def test_the_scene_visualiser_draws_capsules_with_it_and_the_rest_as_pinocchio():
    import coal
    import pinocchio as pin
    from pinocchio.visualize import MeshcatVisualizer

    cls = meshcat_visualizer()
    assert issubclass(cls, MeshcatVisualizer) and meshcat_visualizer() is cls
    viz = cls(pin.Model(), None, pin.GeometryModel())
    cap = pin.GeometryObject("c", 0, pin.SE3.Identity(), coal.Capsule(0.08, 0.4))
    box = pin.GeometryObject("b", 0, pin.SE3.Identity(), coal.Box(0.1, 0.2, 0.3))
    drawn = viz.loadPrimitive(cap)
    want = capsule_mesh(0.4, 0.08)
    assert drawn.vertices.tobytes() == want.vertices.tobytes() and drawn.faces.tobytes() == want.faces.tobytes()
    assert viz.loadPrimitive(box).lower(None)["type"] == MeshcatVisualizer.loadPrimitive(viz, box).lower(None)["type"]
