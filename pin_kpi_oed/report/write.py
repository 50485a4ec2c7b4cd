"""Writing a certificate: the HTML, the JSON and the PDF, all made before the first file is written."""

from __future__ import annotations

import json
import os
from typing import Any

from pin_kpi_oed.report.content import Certificate

__all__ = ["write_certificate", "certificate_json"]


def certificate_json(cert: Certificate) -> dict:
    """The certificate's data as JSON-ready values (SI; per-row arrays of the statistics left out)."""
    from pin_kpi_oed.data.atomic import to_jsonable

    return to_jsonable(cert.data)


def write_certificate(cert: Certificate, *, html: str | os.PathLike | None = None,
                      json_path: str | os.PathLike | None = None, pdf: str | os.PathLike | None = None
                      ) -> dict[str, Any]:
    """Write the certificate's files (atomically); returns what was written and why the PDF was not.

    Raises:
        PinKpiOedError: the browser failed to print the PDF (the HTML and JSON are not written either).
    """
    from pin_kpi_oed.data.atomic import atomic_write_text
    from pin_kpi_oed.report.html import render_html
    from pin_kpi_oed.report.pdf import pdf_available, print_pdf

    text = render_html(cert)
    doc = json.dumps(certificate_json(cert), indent=1, allow_nan=False)  # not finite: null (certificate_json)
    out: dict[str, Any] = {"written": [], "pdf_skipped": None, "html_bytes": len(text.encode())}
    if pdf is not None:
        if pdf_available() is None:
            out["pdf_skipped"] = "no Chromium/Chrome found: PDF not made (the HTML is the certificate)"
        else:
            print_pdf(text, pdf)
            out["written"].append(str(pdf))
    if html is not None:
        atomic_write_text(html, text)
        out["written"].append(str(html))
    if json_path is not None:
        atomic_write_text(json_path, doc)
        out["written"].append(str(json_path))
    return out
