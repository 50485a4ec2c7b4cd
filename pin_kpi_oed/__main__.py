"""``python -m pin_kpi_oed`` = ``pin-kpi-oed``."""

import sys

from pin_kpi_oed.cli.app import main

sys.exit(main())
