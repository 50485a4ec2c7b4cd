"""The scene's capsule mesh is Pinocchio's ``createCapsule`` mesh, made once per size, each geometry its own."""

from __future__ import annotations

import numpy as np
import pytest

from pin_kpi_oed.viz.robot_geometry import capsule_mesh, meshcat_visualizer


@pytest.mark.parametrize("length, radius", [(1e-6, 0.05), (0.3, 0.1), (1.2345, 0.0731),
                                            (np.float64(0.7), np.float64(0.12)), (2.0, 1e-3)])
def test_capsule_mesh_is_pinocchios_and_each_geometry_its_own(length, radius):
    cls = meshcat_visualizer()  # Pinocchio's visualiser imported as the scene imports it
    import pinocchio.visualize.meshcat_visualizer as pmv

    assert cls.__mro__[1] is pmv.MeshcatVisualizer
    ref, a, b = pmv.createCapsule(length, radius), capsule_mesh(length, radius), capsule_mesh(length, radius)
    for mesh in (a, b):
        for got, want in ((mesh.vertices, ref.vertices), (mesh.faces, ref.faces)):
            assert got.dtype == want.dtype and got.shape == want.shape and got.tobytes() == want.tobytes()
    assert a is not b and a.uuid != b.uuid, "two capsules drawn share one geometry"
    with pytest.raises(ValueError):
        a.vertices[0, 0] = 1.0  # the arrays made once are shared: nobody may change them
    assert capsule_mesh(length * 1.5, radius).vertices.tobytes() != a.vertices.tobytes()


def test_the_scene_visualiser_draws_capsules_with_it_and_the_rest_as_pinocchio():
    import coal
    import pinocchio as pin

    cls = meshcat_visualizer()
    from pinocchio.visualize import MeshcatVisualizer
    assert issubclass(cls, MeshcatVisualizer) and meshcat_visualizer() is cls
    viz = cls(pin.Model(), None, pin.GeometryModel())
    cap = pin.GeometryObject("c", 0, pin.SE3.Identity(), coal.Capsule(0.08, 0.4))
    box = pin.GeometryObject("b", 0, pin.SE3.Identity(), coal.Box(0.1, 0.2, 0.3))
    drawn, want = viz.loadPrimitive(cap), MeshcatVisualizer.loadPrimitive(viz, cap)
    assert drawn.vertices.tobytes() == want.vertices.tobytes() and drawn.faces.tobytes() == want.faces.tobytes()
    assert viz.loadPrimitive(box).lower(None)["type"] == MeshcatVisualizer.loadPrimitive(viz, box).lower(None)["type"]
