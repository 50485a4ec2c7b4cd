"""Regenerate docs/kr15_design.png, the README's screenshot of a KR 15 design in the meshcat viewer.

    .venv/bin/python docs/make_screenshot.py                  # design the KR 15 cell, then screenshot
    .venv/bin/python docs/make_screenshot.py design.json      # screenshot an existing design JSON

Steps: ``pin-kpi-oed design --cell kr15 --criteria random,param,kpi --measurements 60 --seed 0 --json``
(or the JSON given), the scene of :func:`pin_kpi_oed.viz.scene.build_scene` written as a static page, and a
1280x800 screenshot of it in headless Chromium (software WebGL). Needs Chromium (``apt-get install chromium``).
If the design step fails, a stand-in design of random configurations is shown and the script says so.
"""

from __future__ import annotations

import json
import os
import sys
import tempfile
from pathlib import Path

import numpy as np

from pin_kpi_oed.design.design_file import load_design
from pin_kpi_oed.design.stand_in import stand_in_design
from pin_kpi_oed.viz.ellipsoids import fmt_factor
from pin_kpi_oed.viz.render import render_png
from pin_kpi_oed.viz.scene import SceneOptions, build_scene

DOCS = Path(__file__).resolve().parent
OUT = DOCS / "kr15_design.png"


def design_file(tmp: Path) -> tuple[Path, bool]:
    """(design JSON, is it a real design)."""
    if len(sys.argv) > 1:
        return Path(sys.argv[1]), True
    path = tmp / "design.json"
    try:
        from pin_kpi_oed.cli.app import main as cli

        rc = cli(["design", "--cell", "kr15", "--criteria", "random,param,kpi", "--measurements", "60", "--seed", "0",
                  "--json", str(path)])
    except Exception as exc:  # noqa: BLE001 - the design step is optional for a picture
        print(f"design step failed ({exc})", file=sys.stderr)
        rc = 1
    if rc == 0 and path.exists():
        return path, True
    print("WARNING: showing a stand-in design (random configurations, not optimised)", file=sys.stderr)
    path.write_text(json.dumps(stand_in_design("kr15", m=40, seed=0)))
    return path, False


def main() -> int:
    with tempfile.TemporaryDirectory() as tmpd:
        tmp = Path(tmpd)
        path, real = design_file(tmp)
        df = load_design(path)
        tcp = df.tcp_world().mean(axis=0)
        base = df.world_T_base.translation
        target = 0.55 * tcp + 0.45 * (base + np.array([0.0, 0.0, 0.55]))
        # from the front right of the robot, above the car, the tracker and its beam in view
        position = target + np.array([1.8, 1.0, 1.9])
        scene = build_scene(df, SceneOptions(camera=(target, position), ellipsoid_size=0.15, ghost_opacity=0.06))
        html = scene.static_html().replace("</head>", "<style>.dg.main{display:none}</style></head>", 1)
        page = tmp / "scene.html"
        page.write_text(html)
        png = DOCS / ".kr15_design.tmp.png"  # same folder as the target: the final rename is atomic
        try:
            for timeout_ms in (8000, 20000):
                render_png(page, png, 1280, 800, timeout_ms)
                if png.stat().st_size > 50_000:  # a rendered scene, not a blank page
                    break
            os.replace(png, OUT)
        finally:
            png.unlink(missing_ok=True)
    print(f"wrote {OUT} ({'real' if real else 'stand-in'} design, {len(df.designs)} designs, "
          f"ellipsoids x{fmt_factor(scene.scale)})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
