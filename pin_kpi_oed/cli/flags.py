"""The command line's words for the library's parameters: a library error names the parameter (``Q_given``,
``target_sigma_m``, ``parameter 'kfold'``, ``units='mm,deg'``), the command line says the option that sets it
(``--given``, ``--target-sigma``, ``--kfold``, ``--units mm,deg``).

How a message names a parameter so that :func:`in_flags` rewrites it, and never an ordinary word:

- a name with an underscore, bare (``Q_given: 3 poses``, ``target_sigma_m (0)``): rewritten where it stands as a
  word followed by ``:``, a space, ``(``, ``)``, ``,`` or the end of the message — except the names that are also
  fields of the files the command line reads (:data:`FILE_FIELDS`: a cell file's ``reflector_m: 134.2 m`` stays the
  field), which need one of the two forms below;
- any name of the table, marked ``parameter 'name'`` (``parameter 'kfold' must be an integer``): the mark and the
  name become the option (``--kfold must be an integer``); this is how a one-word parameter (``kfold``, ``sigma``,
  ``units``) is named, since the bare word is never rewritten;
- any name of the table with a value as a Python keyword, ``name='value'`` (``declare the units (units='mm,deg')``)
  or ``name=NUMBER`` (``transfer_prior_rad=1e-4``): becomes the option and its value (``--units mm,deg``,
  ``--term-prior 1e-4``); an empty list, ``name=[]`` (``effects=[]``), is the option's ``none``.

A name outside the table is left as written in every form.
"""

from __future__ import annotations

import re
from typing import Any

__all__ = ["PARAMETER_FLAGS", "FILE_FIELDS", "in_flags", "in_flags_all"]

#: Library parameter -> the option of the command line that sets it.
PARAMETER_FLAGS = {
    "Q_given": "--given",
    "given_prior": "--given-prior",
    "Q_register": "--reregister",
    "model_file": "--model",
    "model_prior": "--prior",
    "robot_class": "--robot-class",
    "effects_spec": "--effects",
    "truth_file": "--truth",
    "program_format": "--format",
    "model_format": "--format",
    "register_rows": "--register-rows",
    "register_data": "--register-data",
    "transfer_prior_rad": "--term-prior",
    "work_radius_rad": "--work-radius",
    "work_samples": "--work-samples",
    "Q_candidates": "--pool",
    "target_sigma_m": "--target-sigma",
    "clearance_margin_m": "--clearance-margin",
    "incidence_margin_deg": "--incidence-margin",
    "train_paths": "--train",
    "validate_path": "--validate",
    "tool_frame": "--tool",
    # one-word parameters: rewritten only when marked (``parameter 'kfold'``, ``units='mm,deg'``)
    "kfold": "--kfold",
    "harmonics": "--harmonics",
    "validate": "--validate",
    "sigma": "--sigma",
    "units": "--units",
    "angle_unit": "--angle-unit",
    "columns": "--columns",
    "kinematics": "--kinematics",
    "scheduler": "--scheduler",
    "discrepancy": "--discrepancy",
    "effects": "--effects",
    "station": "--station",
    "cell": "--cell",
    "loss": "--loss",
    "sigma_xyz_m": "--sigma",
    "reflector_m": "--reflector",
}

#: Parameters that are also fields of the files the command line reads (a cell file's ``reflector_m``,
#: ``tool_frame``; a model file's ``sigma_xyz_m``): a message naming the field of a file
#: means the field, so these are rewritten only when marked or given as keywords, never bare.
FILE_FIELDS = frozenset({"reflector_m", "tool_frame", "sigma_xyz_m"})

_NAMES = "|".join(map(re.escape, sorted(PARAMETER_FLAGS, key=len, reverse=True)))
_BARE = re.compile(r"(?<![\w.`])(" + "|".join(re.escape(k) for k in PARAMETER_FLAGS
                                                if "_" in k and k not in FILE_FIELDS)
                   + r")(?=[:\s(),]|$)")
_MARKED = re.compile(r"\bparameter '(" + _NAMES + r")'")
_KEYWORD = re.compile(r"(?<![\w.`'])(" + _NAMES + r")=(?:'([^']*)'|([-+]?[0-9.]+(?:e[-+]?[0-9]+)?)(?![\w.])|(\[\]))")


def in_flags(message: str) -> str:
    """``message`` with every parameter named in it (see the module docstring) replaced by its option."""
    message = _MARKED.sub(lambda m: PARAMETER_FLAGS[m.group(1)], message)
    message = _KEYWORD.sub(lambda m: f"{PARAMETER_FLAGS[m.group(1)]} "
                                     f"{m.group(2) if m.group(2) is not None else m.group(3) or 'none'}", message)
    return _BARE.sub(lambda m: PARAMETER_FLAGS[m.group(1)], message)


def in_flags_all(value: Any) -> Any:
    """``value`` (a JSON-ready dict, list or string: a fit-quality verdict, a report) with :func:`in_flags` applied
    to every string in it; keys and other values unchanged."""
    if isinstance(value, str):
        return in_flags(value)
    if isinstance(value, dict):
        return {k: in_flags_all(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return type(value)(in_flags_all(v) for v in value)
    return value
