"""``python -m pin_kpi_oed`` = ``pin-kpi-oed``."""

import sys

from .cli import main

sys.exit(main())
