"""How a model file was made, written into it by the commands that make one (``identify``, ``diagnose``).

The last ``history`` step of the model file gets ``command`` (the command line that reproduces it),
``train_files`` / ``validate_files`` (path, rows, SHA-256), ``software`` (package and library versions),
``options`` (the fit's weighting, loss, orientation use: what ``report`` needs to repeat the nominal
comparison), the nominal reflector, and the fit-quality verdict (``fit.quality``). ``pin-kpi-oed report``
prints them and refuses training data whose SHA-256 differs from the recorded one.
"""

from __future__ import annotations

import argparse
from typing import Any

__all__ = ["stamp_model"]


def _records(paths: Any, args: argparse.Namespace, robot: Any) -> list[dict]:
    from pin_kpi_oed.cli.util import table_options
    from pin_kpi_oed.data.measurements import read_measurements
    from pin_kpi_oed.data.provenance import file_record

    out = []
    for p in ([paths] if isinstance(paths, str) else list(paths or [])):
        ms = read_measurements(p, joint_names=robot.joint_names, reach_m=robot.reach(), **table_options(args, robot))
        out.append(file_record(p, len(ms)))
    return out


def stamp_model(model_dict: dict, args: argparse.Namespace, robot: Any, *, train: Any, validate: Any = None,
                options: Any = None, reflector_nominal_m: Any = None, quality: Any = None, extra: dict | None = None
                ) -> dict:
    """Add the provenance of this run to ``model_dict`` (in place; also returned).

    Args:
        model_dict: the model file content (``CalibratedModel.to_dict()``).
        args: the parsed command line (``args.argv``: the arguments as given).
        robot: the robot (its joint names read the files again for their row counts).
        train, validate: the data file path(s) of the fit and of the held-out comparison.
        options: the :class:`~pin_kpi_oed.identification.identify_options.IdentifyOptions` of the fit.
        reflector_nominal_m: the nominal reflector the fit started from (m).
        quality: the fit-quality verdict (:class:`~pin_kpi_oed.identification.quality.FitQuality`).
        extra: more fields of the step (e.g. the diagnosis summary).
    """
    from pin_kpi_oed.data.provenance import command_line, software_versions

    step = model_dict.setdefault("history", [{}])[-1]
    step["command"] = command_line(getattr(args, "argv", None) or [])
    step["train_files"] = _records(train, args, robot)
    step["validate_files"] = _records(validate, args, robot)
    step["software"] = software_versions()
    if options is not None:
        step["options"] = {"weights": options.weights, "loss": options.loss, "use_orientation": options.use_orientation,
                           "scale_covariance": options.scale_covariance, "max_nfev": options.max_nfev,
                           "reflector_per_station": options.reflector_per_station}
    if reflector_nominal_m is not None:
        step["reflector_nominal_m"] = [float(v) for v in reflector_nominal_m]
    if extra:
        step.update(extra)
    if quality is not None:
        from pin_kpi_oed.cli.flags import in_flags_all

        model_dict.setdefault("fit", {})["quality"] = in_flags_all(quality.to_dict())
    from pin_kpi_oed.data.atomic import to_jsonable

    model_dict["history"][-1] = to_jsonable(step)
    if "fit" in model_dict:
        model_dict["fit"] = to_jsonable(model_dict["fit"])
    return model_dict
