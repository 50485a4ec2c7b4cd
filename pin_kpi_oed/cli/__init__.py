"""The ``pin-kpi-oed`` command line: a thin layer over the API (one module per topic)."""
from pin_kpi_oed.cli.app import main, run

__all__ = ["main", "run"]
