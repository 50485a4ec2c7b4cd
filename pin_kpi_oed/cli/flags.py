"""The command line's words for the library's parameters: a library error names the parameter (``Q_given``,
``target_sigma_m``, ...), the command line says the option that sets it (``--given``, ``--target-sigma``)."""

from __future__ import annotations

import re

__all__ = ["PARAMETER_FLAGS", "in_flags"]

#: Library parameter -> the option of the command line that sets it (names with an underscore only: never a word).
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
}

_PATTERN = re.compile(r"(?<![\w.`])(" + "|".join(map(re.escape, PARAMETER_FLAGS)) + r")(?=[:\s(),]|$)")


def in_flags(message: str) -> str:
    """``message`` with every parameter named in it (``name:``, ``name value``, ``name (value)``) replaced by its
    option."""
    return _PATTERN.sub(lambda m: PARAMETER_FLAGS[m.group(1)], message)
