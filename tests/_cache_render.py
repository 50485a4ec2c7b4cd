"""The expensive inputs the certificate tests share (tests/test_report.py, tests/test_certificate_gum.py), made once
per test process: the simulated UR10 calibrated by the command line, its plain certificate (JSON, HTML, PDF and the
figures drawn for it) and one headless Chromium view of that page.

Each builder keeps its result in this module, so the module fixtures of both test files that call it share one
computation in a process; ``make test`` pins the tests that use them to one worker (``xdist_group``
:data:`GROUP`).
"""

from __future__ import annotations

import html as html_text
import json
import re
import subprocess
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

#: The xdist group of every test that uses these inputs (one worker computes them once).
GROUP = "render_certificate"
#: The tracker noise of the simulated UR10 (m, per axis).
SIGMA = 2e-5
#: The browser's window at an A4 page's width (794 × 1123 CSS px).
A4_PX = (794, 1123)

_CACHE: dict[str, Any] = {}


def _with_goals(ms: Any, goals: np.ndarray) -> Any:
    from pin_kpi_oed.data.measurements import MeasurementSet

    return MeasurementSet(ms.joint_names, ms.q, ms.position_m, sigma_m=None, source=ms.source,
                          extra={"goal_x": goals[:, 0], "goal_y": goals[:, 1], "goal_z": goals[:, 2]})


def calibrated_folder(tmp_path_factory: Any) -> Path:
    """A simulated UR10 (random geometric errors), 240 training rows, 150 held-out rows (30 commanded positions of 5
    rows, and 4 configurations measured 3 times), identified by the CLI with --validate, --json and --model-out:
    the folder holding ``train.csv``, ``test.csv``, ``id.json`` and ``model.json`` (made once per process)."""
    if "calibrated" in _CACHE:
        return _CACHE["calibrated"]
    from pin_kpi_oed import NoiseModel, TrackerModel, load_robot
    from pin_kpi_oed.cli.app import main
    from pin_kpi_oed.data.measurements import write_measurements
    from pin_kpi_oed.oed.identifiability import analyse
    from pin_kpi_oed.simulation.simulator import Tolerances, default_tracker_pose, random_truth, simulate

    d = tmp_path_factory.mktemp("report")
    robot = load_robot("ur10")
    tm = TrackerModel(robot, tracker_T_base=default_tracker_pose(robot), reflector_m=np.array([0.02, 0.01, 0.1]),
                      noise=NoiseModel((SIGMA,) * 3))
    base = [i for i in analyse(tm).base if i < 6 * robot.nq]
    truth = random_truth(tm, Tolerances(5e-4, 1e-3, 0.01, 0.01), seed=4, only=base)
    rng = np.random.default_rng(2)
    Qt = robot.random_q(rng, 240)
    Qv = robot.random_q(rng, 150)
    Qv[138:141] = Qv[137]  # repeated configurations: 4 groups of 3 (rows 137-140 are 4 repeats)
    Qv[141:144] = Qv[141]
    Qv[144:147] = Qv[144]
    Qv[147:150] = Qv[147]
    train = simulate(tm, Qt, truth, seed=5, record_sigma=False)
    test = simulate(tm, Qv, truth, seed=6, record_sigma=False)
    goals = np.repeat(rng.uniform(-1, 1, size=(30, 3)), 5, axis=0)
    write_measurements(_with_goals(train, rng.uniform(-1, 1, size=(240, 3))), d / "train.csv")
    write_measurements(_with_goals(test, goals), d / "test.csv")
    args = ["identify", "--robot", "ur10", "--data", str(d / "train.csv"), "--validate", str(d / "test.csv"),
            "--reflector", "0.02,0.01,0.1", "--sigma", str(SIGMA), "--json", str(d / "id.json"),
            "--model-out", str(d / "model.json"), "--quiet"]
    assert main(args) == 0
    _CACHE["calibrated"] = d
    return d


def browser() -> str | None:
    """The Chromium / Chrome the package prints and renders with, or None."""
    from pin_kpi_oed.viz.render import find_browser

    return find_browser()


@dataclass
class Certificate:
    """The plain certificate of the calibrated UR10: ``report --json cert.json --html cert.html`` (and ``--pdf
    cert.pdf`` where a browser is installed), with every figure the report drew (``report.figures.png_bytes``)."""

    folder: Path
    cert: dict
    html: str
    figures: list = field(default_factory=list)
    pdf: Path | None = None


def plain_certificate(folder: Path) -> Certificate:
    """The plain report of the calibrated model, made once per process (the command every reading test ran); the
    matplotlib figures it drew are kept for the legend test."""
    if "certificate" in _CACHE:
        return _CACHE["certificate"]
    from pin_kpi_oed.cli.app import main
    from pin_kpi_oed.report import figures

    pdf = folder / "cert.pdf" if browser() is not None else None
    made: list = []
    orig = figures.png_bytes

    def keep(fig: Any, dpi: int = figures.DPI) -> bytes:
        made.append(fig)
        return orig(fig, dpi)

    figures.png_bytes = keep
    try:
        argv = ["report", "--model", str(folder / "model.json"), "--train", str(folder / "train.csv"), "--validate",
                str(folder / "test.csv"), "--json", str(folder / "cert.json"), "--html", str(folder / "cert.html")]
        assert main(argv + (["--pdf", str(pdf)] if pdf else [])) == 0
    finally:
        figures.png_bytes = orig
    _CACHE["certificate"] = Certificate(folder, json.loads((folder / "cert.json").read_text()),
                                        (folder / "cert.html").read_text(), made, pdf)
    return _CACHE["certificate"]


_LAYOUT_JS = """<script>window.addEventListener('load', function () {
  var W = document.documentElement.clientWidth, bad = [];
  document.querySelectorAll('pre, p, td, th, h1, h2, h3, code, li, div').forEach(function (el) {
    var r = el.getBoundingClientRect();
    if (el.scrollWidth > el.clientWidth + 1 && getComputedStyle(el).display !== 'inline')
      bad.push('cut: ' + el.tagName + ' ' + el.textContent.slice(0, 40));
    if (r.width > 0 && r.right > W + 1) bad.push('beyond the page: ' + el.tagName + ' ' + el.textContent.slice(0, 40));
  });
  var s = document.getElementById('summary').getBoundingClientRect();
  var v = document.querySelector('#summary .verdict'), t = document.querySelector('#summary table');
  var first = v && t && v.getBoundingClientRect().bottom <= window.innerHeight &&
              t.getBoundingClientRect().top < window.innerHeight;
  var imgs = Array.prototype.slice.call(document.images);
  var drawn = imgs.filter(function (im) { return im.complete && im.naturalWidth > 0 && im.naturalHeight > 0; });
  var out = document.createElement('pre'); out.id = 'layout-result';
  out.textContent = JSON.stringify({bad: bad, first: !!first, summaryTop: s.top, W: W, images: imgs.length,
                                    images_drawn: drawn.length});
  document.body.appendChild(out);
});</script>"""


@dataclass
class BrowserView:
    """What one headless Chromium launch made of the plain certificate at an A4 width: the page's layout (elements
    whose text is cut or runs beyond the page, the verdict and headline table on the first screen, the images the
    browser decoded), the DOM it built and a screenshot of the first screen."""

    layout: dict
    dom: str
    screenshot: Path


def browser_view(cert: Certificate) -> BrowserView:
    """The plain certificate with a layout script, opened once in headless Chromium at :data:`A4_PX`: ``--dump-dom``
    and ``--screenshot`` of the same launch (made once per process)."""
    if "view" in _CACHE:
        return _CACHE["view"]
    exe = browser()
    assert exe is not None
    width, height = A4_PX
    page = cert.folder / "layout.html"
    page.write_text(cert.html.replace("</body>", _LAYOUT_JS + "</body>"))
    shot = cert.folder / "layout.png"
    shot.unlink(missing_ok=True)
    dom = subprocess.run([exe, "--headless", "--no-sandbox", "--disable-gpu", "--no-first-run",
                          f"--window-size={width},{height}", "--virtual-time-budget=5000",
                          f"--user-data-dir={cert.folder / 'profile'}", "--dump-dom", f"--screenshot={shot}",
                          page.resolve().as_uri()], capture_output=True, text=True, timeout=120).stdout
    m = re.search(r'<pre id="layout-result">(.*?)</pre>', dom, re.S)
    assert m, "the layout script did not run"
    _CACHE["view"] = BrowserView(json.loads(html_text.unescape(m.group(1))), dom, shot)
    return _CACHE["view"]
