"""``python -m pin_kpi_oed`` = ``pin-kpi-oed``."""

import os
import sys

try:
    from pin_kpi_oed.cli.app import run
except KeyboardInterrupt:  # an interrupt while the command line itself loads: one line, like any later one
    print("interrupted", file=sys.stderr, flush=True)
    os._exit(130)

run()
