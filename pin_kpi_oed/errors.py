"""Small exception hierarchy of pin_kpi_oed.

Every error a user can cause (bad file, unknown frame, ill-posed problem) is a
:class:`PinKpiOedError`: the CLI prints its message on one line and exits with
a non-zero code, without a traceback. Messages name the file, field or value.
"""

from __future__ import annotations


class PinKpiOedError(Exception):
    """Base class of every user-facing error of the package."""


class RobotLoadError(PinKpiOedError):
    """A URDF is missing or malformed, a frame is unknown, or the model is not a serial arm."""


class InputError(PinKpiOedError):
    """A value given by the user is invalid (NaN, out of joint limits, wrong shape, wrong unit)."""


class IdentifiabilityError(PinKpiOedError):
    """A parameter or KPI cannot be estimated from the chosen measurements."""


class InfeasibleError(PinKpiOedError):
    """No feasible configuration or design exists under the given constraints."""


class SolverError(PinKpiOedError):
    """A numerical solver failed; the message says what to change."""
