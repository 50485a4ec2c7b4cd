"""pin_kpi_oed: KPI-based optimum experimental design for robot calibration.

The package reads as the pipeline it implements (Jost et al., J. Math. Industry 2017):

robot -> parameters -> measurement -> identifiability / covariance -> criteria
-> design -> identification -> diagnosis, with the CLI and visualisation at the edge.
"""

import os as _os

# The matrices here are small (tens of columns): BLAS threads only add contention (a 25-column
# information matrix took 10 ms with 2 OpenBLAS threads on a loaded 2-core machine, 0.35 ms with one).
# Only takes effect if NumPy is not imported yet and the user has not chosen.
for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    _os.environ.setdefault(_var, "1")

from pin_kpi_oed.errors import (IdentifiabilityError, InfeasibleError, InputError, PinKpiOedError, RobotLoadError,
                     SolverError)
from pin_kpi_oed.model.robot import Robot, load_robot
from pin_kpi_oed.model.parameters import ParameterLayout
from pin_kpi_oed.model.device import MeasurementModel
from pin_kpi_oed.model.noise import NoiseModel
from pin_kpi_oed.model.tracker import TrackerModel

__version__ = "0.1.0"

__all__ = ["IdentifiabilityError", "InfeasibleError", "InputError", "PinKpiOedError", "RobotLoadError",
           "SolverError", "Robot", "load_robot", "ParameterLayout", "MeasurementModel", "NoiseModel",
           "TrackerModel"]
