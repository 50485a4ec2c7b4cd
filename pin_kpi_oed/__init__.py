"""pin_kpi_oed: KPI-based optimum experimental design for robot calibration.

The package reads as the pipeline it implements (Jost et al., J. Math. Industry 2017):

robot -> parameters -> measurement -> identifiability / covariance -> criteria
-> design -> identification -> diagnosis, with the CLI and visualisation at the edge.
"""

from .errors import (IdentifiabilityError, InfeasibleError, InputError, PinKpiOedError, RobotLoadError,
                     SolverError)
from .robot import Robot, load_robot
from .parameters import ParameterLayout
from .measurement import NoiseModel, TrackerModel

__version__ = "0.1.0"

__all__ = ["IdentifiabilityError", "InfeasibleError", "InputError", "PinKpiOedError", "RobotLoadError",
           "SolverError", "Robot", "load_robot", "ParameterLayout", "NoiseModel", "TrackerModel"]
