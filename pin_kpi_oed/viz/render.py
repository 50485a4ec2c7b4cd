"""Showing a built scene: a screenshot of its static page in headless Chromium, or a live meshcat server."""

from __future__ import annotations

import os
from pathlib import Path

from pin_kpi_oed.errors import PinKpiOedError
from pin_kpi_oed.viz.recorder import import_meshcat
from pin_kpi_oed.viz.scene import Scene


def find_browser() -> str | None:
    """A Chromium / Chrome executable (``chromium`` on PATH, /usr/bin/chromium, ...) or None."""
    import shutil

    for name in ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable"):
        path = shutil.which(name)
        if path:
            return path
    return "/usr/bin/chromium" if os.path.exists("/usr/bin/chromium") else None


def render_png(html_path: str | os.PathLike, png_path: str | os.PathLike, width: int = 1280, height: int = 800,
               timeout_ms: int = 8000, browser: str | None = None) -> Path:
    """Screenshot a static page with headless Chromium (software WebGL, no network, throw-away profile).

    Args:
        html_path: the page.
        png_path: the screenshot to write.
        width, height: window size (pixels).
        timeout_ms: time the browser is given to draw the page (ms).
        browser: executable (default :func:`find_browser`).

    Returns:
        The screenshot's path.

    Raises:
        PinKpiOedError: no browser, or no screenshot was written.
    """
    import subprocess
    import tempfile

    browser = browser or find_browser()
    if browser is None:
        raise PinKpiOedError("no Chromium/Chrome found: install one (Debian: apt-get install chromium)")
    png = Path(png_path).resolve()
    png.unlink(missing_ok=True)
    with tempfile.TemporaryDirectory() as profile:
        cmd = [browser, "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
               "--disable-background-networking", "--disable-component-update", "--disable-sync",
               "--disable-extensions", "--hide-scrollbars", "--enable-unsafe-swiftshader",
               "--proxy-server=127.0.0.1:9", "--proxy-bypass-list=<-loopback>", f"--user-data-dir={profile}",
               f"--screenshot={png}", f"--window-size={width},{height}", f"--timeout={timeout_ms}",
               Path(html_path).resolve().as_uri()]
        # own process group: if the browser hangs, stop that group (and only it)
        proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
        try:
            proc.wait(timeout=timeout_ms / 1000 + 60)
        except subprocess.TimeoutExpired:
            import signal

            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
    if not png.exists():
        raise PinKpiOedError(f"{browser} wrote no screenshot of {html_path}")
    return png


def serve(scene: Scene, open_browser: bool = True, zmq_url: str | None = None):
    """Replay a recorded scene into a live meshcat server (started unless ``zmq_url``); returns the Visualizer.

    The server is a subprocess of this Python process (meshcat stops it at exit).

    Raises:
        PinKpiOedError: the scene was drawn into a live visualiser already (nothing recorded to replay).
    """
    meshcat = import_meshcat()
    rec = scene.recorder
    if rec is None:
        raise PinKpiOedError("the scene is already drawn into a live meshcat visualiser")
    live = meshcat.Visualizer(zmq_url=zmq_url)
    rec.replay(live.window)
    if open_browser:
        live.open()
    return live
