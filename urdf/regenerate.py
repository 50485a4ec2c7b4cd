"""Regenerate the shipped KUKA-like URDFs (kr15, kr300, kr500) next to this script.

Usage: ``.venv/bin/python urdf/regenerate.py``. The files are written atomically
by :func:`pin_kpi_oed.model.kuka.write_urdf`; their values are documented stand-ins.
"""

from __future__ import annotations

import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))

from pin_kpi_oed.model.kuka import KR15, KR300, KR500, write_urdf  # noqa: E402


def main() -> None:
    """Write kr15.urdf, kr300.urdf and kr500.urdf into the directory of this script."""
    for stem, geom in (("kr15", KR15), ("kr300", KR300), ("kr500", KR500)):
        print(write_urdf(geom, HERE / f"{stem}.urdf"))


if __name__ == "__main__":
    main()
