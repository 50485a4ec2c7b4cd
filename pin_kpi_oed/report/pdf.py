"""The certificate as PDF: the HTML page printed by headless Chromium (``--print-to-pdf``), where one is installed.

Without a browser the PDF is not made and the caller says so (:func:`pdf_available`); the HTML is the
certificate, the PDF a print of it.
"""

from __future__ import annotations

import os
import subprocess
import tempfile
from pathlib import Path

from pin_kpi_oed.errors import PinKpiOedError

__all__ = ["pdf_available", "print_pdf"]


def pdf_available() -> str | None:
    """The Chromium / Chrome executable that prints PDFs, or None."""
    from pin_kpi_oed.viz.render import find_browser

    return find_browser()


def print_pdf(html_text: str, pdf_path: str | os.PathLike, timeout_s: float = 120.0) -> Path:
    """Print an HTML page to ``pdf_path`` (written atomically: printed to a temporary file, then moved).

    Raises:
        PinKpiOedError: no browser, or it wrote no PDF.
    """
    from pin_kpi_oed.data.atomic import atomic_write_bytes

    browser = pdf_available()
    if browser is None:
        raise PinKpiOedError("no Chromium/Chrome found for the PDF: install one (Debian: apt-get install chromium)")
    with tempfile.TemporaryDirectory() as tmp:
        page, pdf = Path(tmp) / "certificate.html", Path(tmp) / "certificate.pdf"
        page.write_text(html_text)
        cmd = [browser, "--headless", "--no-sandbox", "--disable-gpu", "--no-first-run", "--disable-extensions",
               "--proxy-server=127.0.0.1:9", f"--user-data-dir={tmp}/profile", "--no-pdf-header-footer",
               f"--print-to-pdf={pdf}", page.as_uri()]
        proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
        try:
            proc.wait(timeout=timeout_s)
        except subprocess.TimeoutExpired:
            import signal

            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
        if not pdf.exists() or pdf.stat().st_size == 0:
            raise PinKpiOedError(f"{browser} wrote no PDF")
        atomic_write_bytes(pdf_path, pdf.read_bytes())
    return Path(pdf_path)
