"""Visualisation at the edge: meshcat scene, static HTML, matplotlib figures.

User-facing names (imported on first use): :func:`build_scene`, :class:`SceneOptions` (a design file
as a meshcat scene; ``scene.write_html(path)``).
"""
from pin_kpi_oed._lazy import lazy_exports

_EXPORTS = {"build_scene": "pin_kpi_oed.viz.scene", "SceneOptions": "pin_kpi_oed.viz.scene"}
__getattr__, __dir__ = lazy_exports(globals(), _EXPORTS)
__all__ = list(_EXPORTS)
