"""pin_kpi_oed: KPI-based optimum experimental design for robot calibration.

The package reads as the pipeline it implements (Jost et al., J. Math. Industry 2017):

robot -> parameters -> measurement -> identifiability / covariance -> criteria
-> design -> identification -> diagnosis, with the CLI and visualisation at the edge.
"""

# BLAS / OpenMP threads are limited at run time around every entry point (threads.py, threadpoolctl),
# whatever the caller imported first; environment variables are not used for that.
from pin_kpi_oed.threads import get_max_threads, limited_threads, set_max_threads
from pin_kpi_oed.errors import (IdentifiabilityError, InfeasibleError, InputError, PinKpiOedError, RobotLoadError,
                     SolverError)
from pin_kpi_oed.model.robot import Robot, load_robot
from pin_kpi_oed.model.parameters import ParameterLayout
from pin_kpi_oed.model.device import MeasurementModel
from pin_kpi_oed.model.noise import NoiseModel
from pin_kpi_oed.model.tracker import TrackerModel

__version__ = "0.1.0"

__all__ = ["get_max_threads", "limited_threads", "set_max_threads", "IdentifiabilityError", "InfeasibleError", "InputError", "PinKpiOedError", "RobotLoadError",
           "SolverError", "Robot", "load_robot", "ParameterLayout", "MeasurementModel", "NoiseModel",
           "TrackerModel"]
