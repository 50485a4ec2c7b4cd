"""Regenerate the shipped KUKA-like URDFs (kr15, kr300, kr500, kr15_track) next to this script.

Usage: ``.venv/bin/python urdf/regenerate.py``. The files are written atomically
by :func:`pin_kpi_oed.model.kuka.write_urdf`; their values are documented stand-ins.
"""

from __future__ import annotations

import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))

from pin_kpi_oed.model.kuka import KR15, KR15_TRACK, KR300, KR500, write_urdf  # noqa: E402


def main() -> None:
    """Write kr15.urdf, kr300.urdf, kr500.urdf and kr15_track.urdf into the directory of this script."""
    for stem, geom, track in (("kr15", KR15, None), ("kr300", KR300, None), ("kr500", KR500, None),
                              ("kr15_track", KR15, KR15_TRACK)):
        print(write_urdf(geom, HERE / f"{stem}.urdf", track))


if __name__ == "__main__":
    main()
