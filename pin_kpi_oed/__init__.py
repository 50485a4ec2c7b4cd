"""pin_kpi_oed: KPI-based optimum experimental design for robot calibration.

The package reads as the pipeline it implements (Jost et al., J. Math. Industry 2017):

robot -> parameters -> measurement -> identifiability / covariance -> criteria
-> design -> identification -> the calibrated model -> compensation, upkeep -> diagnosis,
with the CLI and visualisation at the edge.

The top level offers that pipeline by name (each subpackage exports its own names too)::

    import pin_kpi_oed as pko

    cell = pko.load_cell("kr15")                          # a shipped cell or a YAML file
    kpi = pko.run_designs(cell, ["kpi"], m=30)[-1]        # the heuristic design first, then the KPI design
    model = cell.tracker_model()
    truth = pko.random_truth(model, seed=0)               # a simulated "real" robot
    result = pko.identify(model, pko.simulate(model, kpi.q_meas, truth, seed=1))

(the README's example continues to the held-out error).

Every name is imported on first use: ``import pin_kpi_oed`` loads neither NumPy nor Pinocchio (the command
line declares its options before any of them is needed).
"""

# BLAS / OpenMP threads are limited at run time around every entry point (threads.py, threadpoolctl),
# whatever the caller imported first; environment variables are not used for that.
from pin_kpi_oed._lazy import lazy_exports
from pin_kpi_oed.errors import (IdentifiabilityError, InfeasibleError, InputError, PinKpiOedError, RobotLoadError,
                                SolverError)

__version__ = "0.1.0"

#: The pipeline, imported on first use: public name -> module that defines it.
_PIPELINE = {
    # BLAS / OpenMP threads
    "get_max_threads": "pin_kpi_oed.threads", "limited_threads": "pin_kpi_oed.threads",
    "set_max_threads": "pin_kpi_oed.threads",
    # the robot and its measurement
    "Robot": "pin_kpi_oed.model.robot", "load_robot": "pin_kpi_oed.model.robot",
    "ParameterLayout": "pin_kpi_oed.model.parameters", "MeasurementModel": "pin_kpi_oed.model.device",
    "NoiseModel": "pin_kpi_oed.model.noise", "TrackerModel": "pin_kpi_oed.model.tracker",
    # cell
    "Cell": "pin_kpi_oed.cell.cell", "load_cell": "pin_kpi_oed.cell.cell",
    "FeasibilityChecker": "pin_kpi_oed.cell.feasibility",
    # design
    "run_designs": "pin_kpi_oed.design.optimize", "DesignOptions": "pin_kpi_oed.design.optimize",
    "DesignProblem": "pin_kpi_oed.design.optimize", "DesignResult": "pin_kpi_oed.design.optimize",
    "load_design": "pin_kpi_oed.design.design_file", "DesignFile": "pin_kpi_oed.design.design_file",
    "write_design": "pin_kpi_oed.design.design_file",
    "design_run": "pin_kpi_oed.design.runner", "DesignRun": "pin_kpi_oed.design.runner",
    "DesignSettings": "pin_kpi_oed.design.runner",
    "analyse": "pin_kpi_oed.oed.identifiability", "score_design": "pin_kpi_oed.oed.evaluate",
    # measurements
    "MeasurementSet": "pin_kpi_oed.data.measurements", "read_measurements": "pin_kpi_oed.data.measurements",
    "write_measurements": "pin_kpi_oed.data.measurements", "concat_measurements": "pin_kpi_oed.data.measurements",
    "read_targets": "pin_kpi_oed.data.targets",
    # simulation
    "Tolerances": "pin_kpi_oed.model.tolerances", "random_truth": "pin_kpi_oed.simulation.simulator",
    "simulate": "pin_kpi_oed.simulation.simulator",
    # identification, held-out validation, model files
    "identify": "pin_kpi_oed.identification.identify",
    "IdentifyOptions": "pin_kpi_oed.identification.identify_options",
    "IdentificationResult": "pin_kpi_oed.identification.identify_result",
    "validate": "pin_kpi_oed.identification.heldout",
    "CalibratedModel": "pin_kpi_oed.calibrated.model_file",
    "load_model_file": "pin_kpi_oed.calibrated.model_file",
    "register_setup": "pin_kpi_oed.upkeep.transfer", "predict_table": "pin_kpi_oed.upkeep.transfer",
    "write_model_urdf": "pin_kpi_oed.calibrated.urdf_export",
    # model formats: UR kinematics files in and out, the calibrated URDF
    "read_ur_kinematics": "pin_kpi_oed.model.ur_kinematics", "URKinematics": "pin_kpi_oed.model.ur_kinematics",
    "export_model": "pin_kpi_oed.calibrated.formats.registry",
    "MODEL_FORMATS": "pin_kpi_oed.calibrated.formats.registry",
    # the calibration certificate
    "build_certificate": "pin_kpi_oed.report.content", "write_certificate": "pin_kpi_oed.report.write",
    # diagnosis
    "diagnose": "pin_kpi_oed.diagnosis.diagnose", "DiagnoseOptions": "pin_kpi_oed.diagnosis.diagnose_options",
    "DiagnosisReport": "pin_kpi_oed.diagnosis.report",
    # compensation
    "compensate": "pin_kpi_oed.compensation.compensator",
    "CompensationOptions": "pin_kpi_oed.compensation.compensator",
    "compensate_program": "pin_kpi_oed.compensation.compensator",
    # keeping the calibration: the quick check
    "check_calibration": "pin_kpi_oed.upkeep.check", "design_check": "pin_kpi_oed.upkeep.check_design",
    # measurement programs
    "plan_program": "pin_kpi_oed.program.ordering", "ProgramOptions": "pin_kpi_oed.program.ordering",
    "write_program": "pin_kpi_oed.program.export", "ProgramInfo": "pin_kpi_oed.program.export",
}

__getattr__, __dir__ = lazy_exports(globals(), _PIPELINE)

__all__ = ["IdentifiabilityError", "InfeasibleError", "InputError", "PinKpiOedError", "RobotLoadError", "SolverError",
           *_PIPELINE]
