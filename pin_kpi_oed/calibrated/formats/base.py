"""The abstract base of a model format: what a calibrated model becomes in a robot's or a tool's own file.

A format writes a :class:`~pin_kpi_oed.calibrated.model_file.CalibratedModel` (geometry, effects,
set-ups) into a file another program reads. No such file holds everything the model file holds; each
format says what it keeps and what it leaves out (:attr:`ExportReport.lost`), checks that the written
file reproduces the calibrated forward kinematics (:attr:`ExportReport.check_m`) and writes atomically
only when it does. Add a format: subclass :class:`ModelFormat` in a module of this package and add one
line to :data:`~pin_kpi_oed.calibrated.formats.registry.MODEL_FORMATS`.
"""

from __future__ import annotations

import os
from abc import ABC, abstractmethod
from dataclasses import dataclass, field

import numpy as np
import pinocchio as pin

__all__ = ["ModelFormat", "ExportReport", "calibrated_placements", "lost_parts"]


@dataclass
class ExportReport:
    """What an export wrote.

    Attributes:
        path: the file written.
        format: the format's name.
        check_m: largest tool-frame position difference between the file reloaded and the calibrated
            model at the check configurations (m).
        lost: what the file cannot carry, one phrase each.
    """

    path: str
    format: str
    check_m: float
    lost: list[str] = field(default_factory=list)

    def summary(self) -> str:
        """Printable lines."""
        lines = [f"wrote {self.path} ({self.format}); reloaded, it reproduces the calibrated tool frame to "
                 f"{self.check_m:.2g} m"]
        lines += [f"  not in this file: {x}" for x in self.lost]
        return "\n".join(lines)


def calibrated_placements(cm) -> list[pin.SE3]:
    """The calibrated joint placements M_k · exp6(δ_k) of a calibrated model, base to tip."""
    from pin_kpi_oed.model.parameters import ParameterLayout

    rb = cm.robot
    L = ParameterLayout(list(rb.joint_names))
    return [rb.model.jointPlacements[j] * pin.exp6(np.asarray(cm.joint_p)[L.joint_slice(k)])
            for k, j in enumerate(rb.joint_ids)]


def lost_parts(cm, keeps_setups: bool = False) -> list[str]:
    """What a geometry-only file leaves out of a calibrated model (effects, discrepancy, set-ups, covariance)."""
    out = []
    if cm.effects:
        out.append("the effects " + ", ".join(e.name for e in cm.effects)
                   + " (joint-angle / non-geometric errors: predict and compensate apply them)")
    if getattr(cm, "discrepancy", None) is not None:
        out.append("the discrepancy δ(q) and its honest sigma")
    if not keeps_setups:
        out.append("the stations' set-ups (tracker pose, reflector) and the TCP")
    out.append("the parameters' covariance")
    return out


class ModelFormat(ABC):
    """A file format of calibrated kinematics.

    Attributes:
        name: the ``--format`` name.
        suffix: the usual file suffix.
        description: one line for the help.
    """

    name: str = ""
    suffix: str = ""
    description: str = ""

    @abstractmethod
    def write(self, cm, path: str | os.PathLike, *, tcp_m: np.ndarray | None = None, frames: bool = True,
              source: str = "") -> ExportReport:
        """Write ``cm`` to ``path`` (atomically, after the forward-kinematics check).

        Args:
            cm: the calibrated model.
            path: output file.
            tcp_m: TCP point in the tool frame (m), where the format can carry one.
            frames: add the set-up frames, where the format can carry them.
            source: where the model comes from (a comment in the file).

        Returns:
            The :class:`ExportReport`.

        Raises:
            InputError: a model the format cannot hold (named).
            SolverError: the file reloaded does not reproduce the calibrated kinematics (nothing written).
        """
