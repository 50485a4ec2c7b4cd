"""Deliverables of a calibration: the certificate (HTML, JSON, PDF) from a model file and its measurements.

User-facing names (imported on first use): :func:`build_certificate`, :class:`Certificate`, :func:`render_html`,
:func:`write_certificate`, :func:`iso_figures`.
"""
from pin_kpi_oed._lazy import lazy_exports

_EXPORTS = {"build_certificate": "pin_kpi_oed.report.content", "Certificate": "pin_kpi_oed.report.content",
            "render_html": "pin_kpi_oed.report.html", "write_certificate": "pin_kpi_oed.report.write",
            "iso_figures": "pin_kpi_oed.report.iso9283"}
__getattr__, __dir__ = lazy_exports(globals(), _EXPORTS)
__all__ = list(_EXPORTS)
