"""The one cell model shared by optimiser, check and viewer: ``Cell``, ``CapsuleSpec``, ``HalfSpace`` (SI units).

The cell file that builds it: :mod:`pin_kpi_oed.cell.cell`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pinocchio as pin

from pin_kpi_oed.cell.camera_setup import CameraSetup
from pin_kpi_oed.data.tool_header import ToolSpec
from pin_kpi_oed.model.noise import NoiseModel
from pin_kpi_oed.model.device import MeasurementModel
from pin_kpi_oed.model.robot import Robot
from pin_kpi_oed.model.tracker import TrackerModel

__all__ = ["CapsuleSpec", "HalfSpace", "Cell", "DEFAULT_BEAM_RADIUS_M", "DEFAULT_INCIDENCE_MAX_DEG"]

#: The laser beam's capsule radius (m) of a cell (or design file) that does not give one.
DEFAULT_BEAM_RADIUS_M = 0.005
#: The largest incidence angle of the beam on the reflector (deg, eq. 4) of a cell that does not give one.
DEFAULT_INCIDENCE_MAX_DEG = 30.0


@dataclass
class CapsuleSpec:
    """A capsule: segment [a, b] and radius (m).

    Attributes:
        name: unique name (robot capsules: ``<link>`` or ``<link>_<k>``).
        a: first end point (m) — link frame for robot capsules, cell frame for obstacles.
        b: second end point (m).
        radius: radius (m).
        link: robot link name (None for obstacles).
    """

    name: str
    a: np.ndarray
    b: np.ndarray
    radius: float
    link: str | None = None

    def to_dict(self) -> dict:
        """Plain numbers (m)."""
        d = {"name": self.name, "a_m": [float(x) for x in self.a], "b_m": [float(x) for x in self.b],
             "radius_m": float(self.radius)}
        if self.link is not None:
            d["link"] = self.link
        return d


@dataclass
class HalfSpace:
    """The free side ``{x : normal·x ≥ offset}`` of a plane (cell frame).

    Attributes:
        name: unique name.
        normal: unit normal pointing into the free side.
        offset: offset (m).
    """

    name: str
    normal: np.ndarray
    offset: float

    def to_dict(self) -> dict:
        """Plain numbers (m)."""
        return {"name": self.name, "normal": [float(x) for x in self.normal], "offset_m": float(self.offset)}


@dataclass
class Cell:
    """A measurement cell (see the module docstring for the file format).

    Attributes:
        name: cell name.
        source: file the cell was read from ("" if built in code).
        robot: the loaded robot.
        W_T_base: robot base pose in the cell frame.
        W_T_tracker: tracker pose in the cell frame.
        reflector_m: reflector in the tool frame (m).
        nests_m: the reflector nests on the tool, (k, 3) m in the tool frame, nest 0 = ``reflector_m``; None: one
            nest (:mod:`pin_kpi_oed.model.nests`).
        tcp_m: KPI point in the tool frame (m).
        noise: tracker noise model.
        hidden_work: the working configurations out of the tracker's sight (index -> what blocks the beam), found
            when the cell's constraint model is built; a working configuration need not be seen by the tracker.
        noise_stated: the cell file states its noise (a ``noise`` field); a cell without one carries the
            noise model's default, which ``identify --cell`` does not take for the tracker's noise.
        q_lower, q_upper: joint bounds of the design (rad).
        robot_capsules: robot capsules (link frames).
        obstacles: obstacle capsules (cell frame).
        half_spaces: half-spaces (cell frame).
        skip_pairs: user pairs of names never checked against each other.
        beam_radius_m: radius of the laser-beam capsule (m).
        beam_skip: names the beam is not checked against.
        incidence_max_deg: largest incidence angle of the beam on the reflector (deg).
        clearance_m: required clearance of every capsule pair (m), margins included.
        clearance_margin_m: the part of ``clearance_m`` the design added on top of the cell file's
            (``design --clearance-margin``; 0 for the cell as read).
        q_work: working configurations (t, n) rad.
        measurements: default number of measurement configurations.
        max_random_tries: rejection-sampling budget of the heuristic design.
        environment: the environment files' objects.
        paths: the working paths (:class:`~pin_kpi_oed.cell.paths.WorkingPath`: samples solved by IK).
        orientation_length_m: the length L weighting the tool's orientation in the 6-D KPI (position + L x
            rotation, "orientation at L"), m.
        camera: the cell's camera and board (:class:`~pin_kpi_oed.cell.camera_setup.CameraSetup`) when a camera
            measures instead of the tracker (then ``W_T_tracker`` is the device frame, the board or the camera, and
            ``reflector_m`` the tool-mounted part's origin), else None.
    """

    name: str
    source: str
    robot: Robot
    W_T_base: pin.SE3
    W_T_tracker: pin.SE3
    reflector_m: np.ndarray
    tcp_m: np.ndarray
    noise: NoiseModel
    q_lower: np.ndarray
    q_upper: np.ndarray
    robot_capsules: list[CapsuleSpec]
    obstacles: list[CapsuleSpec] = field(default_factory=list)
    half_spaces: list[HalfSpace] = field(default_factory=list)
    skip_pairs: list[tuple[str, str]] = field(default_factory=list)
    beam_radius_m: float = DEFAULT_BEAM_RADIUS_M
    beam_skip: list[str] = field(default_factory=list)
    incidence_max_deg: float = DEFAULT_INCIDENCE_MAX_DEG
    clearance_m: float = 0.0
    q_work: np.ndarray = field(default_factory=lambda: np.zeros((0, 6)))
    measurements: int = 60
    max_random_tries: int = 200_000
    environment: list = field(default_factory=list)
    clearance_margin_m: float = 0.0
    paths: list = field(default_factory=list)
    orientation_length_m: float = 0.2
    noise_stated: bool = True
    hidden_work: dict = field(default_factory=dict)
    nests_m: np.ndarray | None = None
    camera: CameraSetup | None = None

    @property
    def q_path(self) -> np.ndarray:
        """Every working path's samples stacked, (S, n) rad (none without paths): the path KPI's configurations."""
        if not self.paths:
            return np.zeros((0, self.robot.nq))
        return np.vstack([p.Q for p in self.paths])

    @property
    def environment_capsule_names(self) -> set[str]:
        """Names of the obstacle capsules fitted to environment files (the check uses the meshes instead)."""
        return {c.name for e in self.environment for c in e.capsules}

    # ------------------------------------------------------------------ derived
    @property
    def tracker_T_base(self) -> pin.SE3:
        """Pose of the robot base in the tracker frame, (W_T_tracker)⁻¹ W_T_base."""
        return self.W_T_tracker.inverse() * self.W_T_base

    @property
    def tracker_in_base(self) -> np.ndarray:
        """Tracker origin (beam start) in the robot base frame (m)."""
        return (self.W_T_base.inverse() * self.W_T_tracker).translation.copy()

    def tool_spec(self, source: str = "") -> ToolSpec:
        """What the cell states about the tool: robot URDF, tool frame, reflector, TCP, working configurations, and
        its reflector nests when it lists several.

        Args:
            source: where the fields come from, for messages (default: ``cell <file or name>``).

        Returns:
            The :class:`~pin_kpi_oed.data.tool_header.ToolSpec` (SI units).
        """
        q_work = np.asarray(self.q_work, float) if self.q_work is not None and np.size(self.q_work) else None
        nests = None if self.nests_m is None or len(self.nests_m) < 2 else np.array(self.nests_m, float)
        return ToolSpec(robot=str(self.robot.urdf_path), tool_frame=self.robot.tool_frame,
                        reflector_m=self.reflector_m.copy(), tcp_m=self.tcp_m.copy(), q_work=q_work, nests_m=nests,
                        source=source or f"cell {self.source or self.name}")

    def tracker_model(self) -> TrackerModel:
        """The measurement model of the cell (nominal parameters; robot bounds replaced by the cell's), with the
        cell's tool (TCP, working configurations: :meth:`tool_spec`) that a calibrated model keeps."""
        return TrackerModel(self.robot, tracker_T_base=self.tracker_T_base, reflector_m=self.reflector_m.copy(),
                            tcp_m=self.tcp_m.copy(), noise=self.noise, tool=self.tool_spec(),
                            nests_m=None if self.nests_m is None else np.array(self.nests_m, float))

    def measurement_model(self) -> MeasurementModel:
        """The cell's measuring device's model (nominal parameters): the camera's when the cell has one
        (:mod:`pin_kpi_oed.cell.camera_setup`), else the tracker's (:meth:`tracker_model`)."""
        if self.camera is not None:
            return self.camera.model(self.robot, self.W_T_base, self.tcp_m)
        return self.tracker_model()

    def to_dict(self) -> dict:
        """The cell in plain numbers (SI units, cell frame for obstacles)."""
        return {
            "name": self.name,
            "source": self.source,
            "robot": {"name": self.robot.name, "urdf_path": self.robot.urdf_path, "tool_frame": self.robot.tool_frame},
            "W_T_base": self.W_T_base.homogeneous.tolist(),
            "W_T_tracker": self.W_T_tracker.homogeneous.tolist(),
            "tracker_T_base": self.tracker_T_base.homogeneous.tolist(),
            "reflector_m": self.reflector_m.tolist(),
            **({} if self.nests_m is None else {"nests_m": np.asarray(self.nests_m).tolist()}),
            "tcp_m": self.tcp_m.tolist(),
            "noise": self.noise.to_dict(),
            "joint_names": list(self.robot.joint_names),
            "q_lower_rad": self.q_lower.tolist(),
            "q_upper_rad": self.q_upper.tolist(),
            "robot_capsules": [c.to_dict() for c in self.robot_capsules],
            "obstacles": {"capsules": [c.to_dict() for c in self.obstacles],
                          "half_spaces": [h.to_dict() for h in self.half_spaces]},
            "skip_pairs": [list(p) for p in self.skip_pairs],
            "beam": {"radius_m": self.beam_radius_m, "skip": list(self.beam_skip)},
            "incidence_max_deg": self.incidence_max_deg,
            "clearance_m": self.clearance_m,
            "q_work": self.q_work.tolist(),
            "measurements": self.measurements,
            "max_random_tries": self.max_random_tries,
            "environment": [e.to_dict() for e in self.environment],
            "paths": [p.to_dict() for p in self.paths],
            "orientation_length_m": self.orientation_length_m,
            **(self.camera.to_dict() if self.camera is not None else {}),
        }

    def summary(self) -> str:
        """Short readable description (the working configurations out of the tracker's sight named), then the robot
        loader's notes (:attr:`Robot.notes`), one ``note:`` line each."""
        hidden = ", ".join(f"{i} (beam blocked by {b})" for i, b in self.hidden_work.items())
        return (f"cell {self.name}: robot {self.robot.name} ({self.robot.tool_frame}), "
                f"{len(self.robot_capsules)} robot capsules, {len(self.obstacles)} obstacle capsules, "
                f"{len(self.half_spaces)} half-spaces, "
                + (f"{len(self.environment)} environment file(s), " if self.environment else "")
                + f"{self.q_work.shape[0]} working configuration(s), "
                + (f"{len(self.paths)} working path(s) ({len(self.q_path)} samples), " if self.paths else "")
                + f"incidence <= {self.incidence_max_deg:g} deg"
                + (f"; working configuration(s) {hidden} out of the tracker's sight (where the robot works, not where "
                   "it is measured)" if hidden else "")
                + "".join(f"\nnote: {n}" for n in self.robot.notes))
