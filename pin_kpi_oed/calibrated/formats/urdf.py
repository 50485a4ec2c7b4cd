"""The calibrated URDF (``export-model --format urdf``): :mod:`pin_kpi_oed.calibrated.urdf_export`.

ROS conventions: the robot's own link and joint names (``base_link`` … ``tool0``), metres and radians
(REP 103), mesh references kept as the source URDF has them (``package://`` URIs unchanged, relative paths
made absolute), the calibrated placements written as each actuated joint's ``<origin>``, and the set-up
frames as fixed links (``tracker_<station>`` under the root link, ``reflector_<station>`` and ``tcp`` under
the tool frame) so TF shows the whole measurement chain.
"""

from __future__ import annotations

import os

import numpy as np

from pin_kpi_oed.calibrated.formats.base import ExportReport, ModelFormat, lost_parts

__all__ = ["UrdfFormat"]


class UrdfFormat(ModelFormat):
    """The calibrated URDF with the set-up frames."""

    name = "urdf"
    suffix = ".urdf"
    description = "calibrated URDF (joint origins) with tracker / reflector / TCP frames"

    def write(self, cm, path: str | os.PathLike, *, tcp_m: np.ndarray | None = None, frames: bool = True,
              source: str = "") -> ExportReport:
        from pin_kpi_oed.calibrated.urdf_export import write_model_urdf

        gap = write_model_urdf(cm, path, frames=frames, tcp_m=tcp_m)
        return ExportReport(str(path), self.name, gap, lost_parts(cm, keeps_setups=frames))
