"""``python -m pin_kpi_oed`` = ``pin-kpi-oed``."""

import sys

try:
    from pin_kpi_oed.cli.app import main
except KeyboardInterrupt:  # an interrupt while the command line itself loads: one line, like any later one
    print("interrupted", file=sys.stderr)
    sys.exit(130)

sys.exit(main())
