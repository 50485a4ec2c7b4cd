"""One result vocabulary for every solver-like step of the pipeline (scipy's ``OptimizeResult`` words).

Every result object of the package (a design, an identification, a pool selection, a diagnosis, a
validation) derives from :class:`Result` and therefore answers the same questions:

==============  ======================================================================
``success``     bool: the step reached what it was asked for (converged, feasible, ...)
``status``      short text: ``"converged"``, ``"feasible"``, ``"max_iter"``, ``"infeasible"``, ...
``message``     one readable line: why it stopped, or what to change
``nit``         iterations of the underlying solver (0 when not iterative)
``nfev``        function evaluations (0 when not counted)
``time_s``      wall-clock time of the step (s)
==============  ======================================================================

plus ``to_dict()`` (JSON-ready, SI units) and ``summary()`` (a few readable lines).
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from typing import Any

from pin_kpi_oed.data.atomic import to_jsonable

__all__ = ["Result"]


@dataclass(kw_only=True)
class Result:
    """Base of every result object: the common vocabulary (see the module docstring).

    Attributes:
        success: Whether the step achieved what it was asked for.
        status: Short machine-readable status text.
        message: One readable line.
        nit: Solver iterations.
        nfev: Function evaluations.
        time_s: Wall-clock time (s).
    """

    success: bool = False
    status: str = ""
    message: str = ""
    nit: int = 0
    nfev: int = 0
    time_s: float = 0.0

    def result_dict(self) -> dict[str, Any]:
        """The common fields as a JSON-ready dict (subclasses merge it into their ``to_dict``)."""
        return {"success": bool(self.success), "status": self.status, "message": self.message,
                "nit": int(self.nit), "nfev": int(self.nfev), "time_s": float(self.time_s)}

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict of every dataclass field (SI units); subclasses refine it."""
        return to_jsonable({f.name: getattr(self, f.name) for f in fields(self)})

    def summary(self) -> str:
        """A readable line: status, message, iterations and time; subclasses refine it."""
        ok = "ok" if self.success else "FAILED"
        return f"{ok}: {self.status} ({self.nit} iterations, {self.time_s:.2f} s) {self.message}".rstrip()

    def __str__(self) -> str:
        return self.summary()
