"""A cell's camera and calibration board: the ``camera:`` and ``board:`` fields of the cell file (SI units, px).

Schema (a camera cell needs no ``tracker`` nor ``reflector_m``)::

    camera:
      mount: eye_in_hand             # or eye_to_hand
      pose: {xyz_m: [...], rpy_deg: [...]}   # eye_in_hand: the camera in the tool frame (tool_T_camera);
                                             # eye_to_hand: the camera in the cell frame (W_T_camera)
      intrinsics: {fx: 1200, fy: 1200, cx: 640, cy: 512,      # px
                   distortion: [k1, k2, p1, p2, k3],           # dimensionless, OpenCV's order (default zeros)
                   image_size_px: [1280, 1024]}                # width, height
      sigma_px: 0.2                  # corner noise per image coordinate (px)
      intrinsics_sigma: {fx: 5.0, fy: 5.0, cx: 5.0, cy: 5.0}   # optional: estimate these intrinsics (module text)
      view:                          # what the camera needs to see the board (design and pool; all optional)
        margin_px: 20.0              # every corner at least this far inside the image (px, >= 0)
        max_angle_rad: 1.0472        # largest angle between the board's normal and the ray to the camera (rad,
                                     # in (0, pi/2); 60 deg)
        near_m: 0.15                 # depth of field: every outer corner's depth within [near_m, far_m] (m)
        far_m: 2.0
    board:
      type: chessboard               # or charuco
      rows: 7                        # squares along the board's y axis
      columns: 9                     # squares along its x axis
      square_m: 0.025
      marker_m: 0.018                # charuco only: the ArUco marker's side (m)
      dictionary: DICT_5X5_100       # charuco only: cv2.aruco's predefined dictionary
      pose: {xyz_m: [...], rpy_deg: [...]}   # eye_in_hand: the board in the cell frame (W_T_board);
                                             # eye_to_hand: the board in the tool frame (tool_T_board)

``intrinsics_sigma`` (optional) asks the calibration to estimate the named intrinsics with the robot: a mapping from
an intrinsic's name (fx, fy, cx, cy in px; k1, k2, p1, p2, k3 dimensionless) to the σ of its Gaussian prior around
the nominal value in ``intrinsics`` (the σ of a separate intrinsic calibration, or a generous bound on what is
known). The intrinsics it does not name are held at their nominal values; without the field all are. Every σ is
positive and finite.

The board frame has its origin at the first inner corner, x along a row of squares, z out of the printed side; the
(rows − 1) × (columns − 1) inner corners are numbered row by row (id = row · (columns − 1) + column), OpenCV's
order for a chessboard and ChArUco's corner ids. A chessboard's corners are ordered by OpenCV from the image alone
(a board seen upside down is numbered from the other end); a ChArUco board's ids are printed on it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pinocchio as pin

from pin_kpi_oed.cell.fields import read_pose, read_vec, where
from pin_kpi_oed.errors import InputError
from pin_kpi_oed.model.camera import CAMERA_MODES, INTRINSIC_NAMES, Board, CameraModel, Intrinsics
from pin_kpi_oed.model.robot import Robot

__all__ = ["CameraSetup", "read_camera_setup", "read_board", "read_view", "read_intrinsics_sigma", "BOARD_TYPES",
           "VIEW_DEFAULTS"]

#: the calibration boards the package reads
BOARD_TYPES = ("chessboard", "charuco")
_CAMERA_KEYS = {"mount", "pose", "intrinsics", "sigma_px", "view", "intrinsics_sigma"}
_VIEW_KEYS = {"margin_px", "max_angle_rad", "near_m", "far_m"}
#: the view limits a camera block without ``view`` (or a ``view`` without a field) states: margin (px), largest
#: viewing angle (rad, 60 deg), depth of field near and far (m)
VIEW_DEFAULTS = {"margin_px": 20.0, "max_angle_rad": math.radians(60.0), "near_m": 0.15, "far_m": 2.0}
_INTRINSIC_KEYS = {"fx", "fy", "cx", "cy", "distortion", "image_size_px"}
_BOARD_KEYS = {"type", "rows", "columns", "square_m", "marker_m", "dictionary", "pose"}


@dataclass
class CameraSetup:
    """A camera and its board as the cell file states them (nominal values).

    Attributes:
        mode: ``eye_in_hand`` or ``eye_to_hand``.
        intrinsics: the camera's intrinsics (px; distortion dimensionless).
        board: the board's inner corners (:class:`~pin_kpi_oed.model.camera.Board`).
        camera_pose: tool_T_camera (eye-in-hand) or W_T_camera (eye-to-hand), m / rad.
        board_pose: W_T_board (eye-in-hand) or tool_T_board (eye-to-hand), m / rad.
        sigma_px: corner noise per image coordinate (px).
        board_type: ``chessboard`` or ``charuco``; marker_m: a ChArUco marker's side (m); dictionary: its name.
        view: what the camera needs to see the board (``margin_px`` px, ``max_angle_rad`` rad, ``near_m`` and
            ``far_m`` m; :data:`VIEW_DEFAULTS` where the file says nothing), read by
            :func:`~pin_kpi_oed.cell.camera_view.cell_view_limits`.
        intrinsics_sigma: the prior σ of the intrinsics the calibration estimates, by name (px; distortion
            dimensionless), or None: the intrinsics are known.
    """

    mode: str
    intrinsics: Intrinsics
    board: Board
    camera_pose: pin.SE3
    board_pose: pin.SE3
    sigma_px: float = 0.2
    board_type: str = "chessboard"
    marker_m: float | None = None
    dictionary: str | None = None
    view: dict = field(default_factory=lambda: dict(VIEW_DEFAULTS))
    intrinsics_sigma: dict[str, float] | None = None

    @property
    def eye_in_hand(self) -> bool:
        """The camera rides on the tool."""
        return self.mode == "eye_in_hand"

    def device_in_cell(self) -> pin.SE3:
        """The fixed device frame in the cell frame: the board (eye-in-hand) or the camera (eye-to-hand)."""
        return self.board_pose if self.eye_in_hand else self.camera_pose

    def tool_mounted(self) -> pin.SE3:
        """What rides on the tool, in the tool frame: the camera (eye-in-hand) or the board (eye-to-hand)."""
        return self.camera_pose if self.eye_in_hand else self.board_pose

    def model(self, robot: Robot, W_T_base: pin.SE3, tcp_m: np.ndarray) -> CameraModel:
        """The camera's measurement model with the robot base at ``W_T_base`` (cell frame) and the TCP (tool frame, m).

        Returns:
            The nominal :class:`~pin_kpi_oed.model.camera.CameraModel` (board_T_base or camera_T_base from the
            cell-frame poses); with ``intrinsics_sigma`` it estimates the named intrinsics with their prior (group
            ``intrinsics``), the others fixed at nominal.
        """
        fixed_T_base = self.device_in_cell().inverse() * W_T_base
        cam, brd = (self.camera_pose, fixed_T_base) if self.eye_in_hand else (fixed_T_base, self.board_pose)
        model = CameraModel(robot, self.intrinsics, self.board, mode=self.mode, camera_pose=cam, board_pose=brd,
                            tcp_m=np.asarray(tcp_m, float), sigma_px=self.sigma_px,
                            estimate_intrinsics=bool(self.intrinsics_sigma))
        if self.intrinsics_sigma:
            L = model.layout
            assert L is not None
            for name in INTRINSIC_NAMES:
                if name in self.intrinsics_sigma:
                    L.set_prior(f"intrinsics.{name}", self.intrinsics_sigma[name])
                else:
                    L.fix(f"intrinsics.{name}")
        return model

    def to_dict(self) -> dict:
        """The ``camera`` and ``board`` fields (the cell file's syntax, rad), for a design or model file."""
        def pose(T: pin.SE3) -> dict:
            return {"xyz_m": T.translation.tolist(), "rpy_rad": pin.rpy.matrixToRpy(T.rotation).tolist()}

        k = self.intrinsics
        extra = {"intrinsics_sigma": dict(self.intrinsics_sigma)} if self.intrinsics_sigma else {}
        board = {"type": self.board_type, "rows": self.board.rows + 1, "columns": self.board.cols + 1,
                 "square_m": self.board.square_m, "pose": pose(self.board_pose)}
        if self.board_type == "charuco":
            board.update(marker_m=self.marker_m, dictionary=self.dictionary)
        return {"camera": {"mount": self.mode, "pose": pose(self.camera_pose), "sigma_px": self.sigma_px,
                           "view": dict(self.view),
                           "intrinsics": {"fx": k.fx, "fy": k.fy, "cx": k.cx, "cy": k.cy,
                                          "distortion": k.dist.tolist(), "image_size_px": [k.width, k.height]},
                           **extra},
                "board": board}


def _mapping(d: Any, keys: set[str], what: str) -> dict:
    if not isinstance(d, dict):
        raise InputError(f"{what}: expected a mapping, got {d!r}")
    unknown = set(d) - keys
    if unknown:
        raise InputError(f"{what}: unknown field(s) {', '.join(sorted(unknown))} (expected {', '.join(sorted(keys))})")
    return d


def _positive(d: dict, key: str, what: str, limit: float | None = None, unit: str = "",
              hint: str = "the value looks like mm; give it in m") -> float:
    v = d.get(key)
    if v is None:
        raise InputError(f"{what}.{key}: missing field")
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v <= 0:
        raise InputError(f"{what}.{key}: expected a positive number{unit}, got {v!r}")
    if limit is not None and v > limit:
        raise InputError(f"{what}.{key}: {v:g} is more than {limit:g}{unit}: {hint}")
    return float(v)


#: the smallest focal length (px) a camera file may state: below, a field of view near 180 deg over a 1000 px
#: image; a focal length in mm (the lens's) is what such a value usually is
FOCAL_MIN_PX = 50.0


def _count(d: dict, key: str, what: str) -> int:
    v = d.get(key)
    if isinstance(v, bool) or not isinstance(v, int) or v < 3:
        raise InputError(f"{what}.{key}: expected a whole number of squares >= 3, got {v!r}")
    return v


def _intrinsics(d: Any, what: str) -> Intrinsics:
    d = _mapping(d, _INTRINSIC_KEYS, what)
    f = {k: _positive(d, k, what, unit=" px") for k in ("fx", "fy", "cx", "cy")}
    for k in ("fx", "fy"):
        if f[k] < FOCAL_MIN_PX:
            raise InputError(f"{what}.{k}: {f[k]:g} px is less than {FOCAL_MIN_PX:g} px: a focal length in px (the "
                             "lens's in mm divided by the pixel pitch in mm, e.g. 8 mm / 0.0055 mm = 1455 px), not mm")
    dist = read_vec(d.get("distortion", [0.0] * 5), 5, f"{what}.distortion (k1, k2, p1, p2, k3)")
    size = d.get("image_size_px")
    if (not isinstance(size, list) or len(size) != 2
            or not all(isinstance(s, int) and not isinstance(s, bool) and s > 0 for s in size)):
        raise InputError(f"{what}.image_size_px: expected [width, height], two positive whole numbers (px), "
                         f"got {size!r}")
    if not (f["cx"] < size[0] and f["cy"] < size[1]):
        raise InputError(f"{what}: the principal point ({f['cx']:g}, {f['cy']:g}) px lies outside the image "
                         f"{size[0]} x {size[1]} px")
    return Intrinsics(f["fx"], f["fy"], f["cx"], f["cy"], dist, size[0], size[1])


def read_board(d: Any, what: str) -> tuple[Board, str, float | None, str | None, pin.SE3]:
    """The ``board`` fields (module docstring): (the board's inner corners, type, marker side (m) or None,
    dictionary or None, pose (identity when not given)).

    Raises:
        InputError: an unknown or missing field or a bad value, naming ``what`` and the field.
    """
    d = _mapping(d, _BOARD_KEYS, what)
    kind = d.get("type", "chessboard")
    if kind not in BOARD_TYPES:
        raise InputError(f"{what}.type: '{kind}' is not one of {', '.join(BOARD_TYPES)}")
    rows, cols = _count(d, "rows", what), _count(d, "columns", what)
    square = _positive(d, "square_m", what, limit=0.5, unit=" m")
    marker, dictionary = None, None
    if kind == "charuco":
        marker = _positive(d, "marker_m", what, limit=0.5, unit=" m")
        if marker >= square:
            raise InputError(f"{what}.marker_m: {marker:g} m must be smaller than square_m {square:g} m")
        dictionary = d.get("dictionary")
        import cv2

        if not isinstance(dictionary, str) or not dictionary.startswith("DICT_") or not hasattr(cv2.aruco,
                                                                                              dictionary):
            raise InputError(f"{what}.dictionary: {dictionary!r} is not a cv2.aruco dictionary (e.g. DICT_5X5_100)")
    else:
        for key in ("marker_m", "dictionary"):
            if key in d:
                raise InputError(f"{what}.{key}: only a charuco board has it (type is {kind})")
    return Board(rows - 1, cols - 1, square), kind, marker, dictionary, read_pose(d.get("pose"), f"{what}.pose")


def read_camera_setup(d: dict, source: str = "") -> CameraSetup | None:
    """The ``camera`` and ``board`` fields of a cell mapping (module docstring), or None without a camera.

    Args:
        d: the parsed cell mapping; source: the file, for messages.

    Returns:
        The :class:`CameraSetup`, or None when the mapping has neither field.

    Raises:
        InputError: one of the two fields without the other, an unknown or missing field or a bad value, named with
            the file and the field.
    """
    if "camera" not in d and "board" not in d:
        return None
    for key, other in (("camera", "board"), ("board", "camera")):
        if key not in d:
            raise InputError(f"{where(source, key)}: missing field (a cell with a {other} needs its {key})")
    what = where(source, "camera")
    cam = _mapping(d["camera"], _CAMERA_KEYS, what)
    mode = cam.get("mount")
    if mode not in CAMERA_MODES:
        raise InputError(f"{what}.mount: {mode!r} is not one of {', '.join(CAMERA_MODES)}")
    if "pose" not in cam:
        raise InputError(f"{what}.pose: missing field (the camera in the "
                         f"{'tool' if mode == 'eye_in_hand' else 'cell'} frame: xyz_m, rpy_deg)")
    pose = read_pose(cam["pose"], f"{what}.pose")
    sigma = (_positive(cam, "sigma_px", what, limit=50.0, unit=" px",
                       hint="a corner's detection noise is a fraction of a pixel (e.g. 0.2)")
             if "sigma_px" in cam else 0.2)
    intr = _intrinsics(cam.get("intrinsics"), f"{what}.intrinsics")
    bwhat = where(source, "board")
    if "pose" not in (d["board"] or {}):
        raise InputError(f"{bwhat}.pose: missing field (the board in the "
                         f"{'cell' if mode == 'eye_in_hand' else 'tool'} frame: xyz_m, rpy_deg)")
    board, kind, marker, dictionary, bpose = read_board(d["board"], bwhat)
    view = read_view(cam.get("view", {}), f"{what}.view")
    isig = read_intrinsics_sigma(cam["intrinsics_sigma"], f"{what}.intrinsics_sigma") if (
        "intrinsics_sigma" in cam) else None
    return CameraSetup(mode, intr, board, pose, bpose, sigma, kind, marker, dictionary, view, isig)


def read_intrinsics_sigma(d: Any, what: str) -> dict[str, float]:
    """The camera's ``intrinsics_sigma`` (module docstring): the prior σ of the intrinsics to estimate, by name.

    Args:
        d: the mapping {name: σ} (fx, fy, cx, cy in px; k1, k2, p1, p2, k3 dimensionless); what: the file and field.

    Returns:
        {name: σ} in the model's intrinsic order.

    Raises:
        InputError: not a mapping (e.g. a list), empty, an unknown name, or a σ that is not a positive finite number.
    """
    if not isinstance(d, dict):
        raise InputError(f"{what}: expected a mapping from intrinsic name to prior sigma (e.g. {{fx: 5.0, cx: 5.0}}; "
                         f"names {', '.join(INTRINSIC_NAMES)}), got {d!r}")
    if not d:
        raise InputError(f"{what}: empty; name the intrinsics to estimate ({', '.join(INTRINSIC_NAMES)}) or leave "
                         "the field out")
    d = _mapping(d, set(INTRINSIC_NAMES), what)
    for key, v in d.items():
        unit = " px" if key in ("fx", "fy", "cx", "cy") else " (dimensionless)"
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v <= 0:
            raise InputError(f"{what}.{key}: expected a positive finite prior sigma{unit}, got {v!r} (leave the "
                             "intrinsic out to hold it at its nominal value)")
    return {k: float(d[k]) for k in INTRINSIC_NAMES if k in d}


def read_view(d: Any, what: str) -> dict:
    """The camera's ``view`` fields (module docstring), :data:`VIEW_DEFAULTS` for those not given.

    Args:
        d: the ``view`` mapping; what: the file and field, for messages.

    Returns:
        ``{margin_px: px, max_angle_rad: rad, near_m: m, far_m: m}``.

    Raises:
        InputError: an unknown field, a value that is not a number, a negative margin, an angle outside
            (0, pi/2) rad (one in degrees named as such), a depth of field not 0 < near_m < far_m or beyond 50 m.
    """
    d = _mapping(d if d is not None else {}, _VIEW_KEYS, what)
    out = dict(VIEW_DEFAULTS)
    for key, v in d.items():
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            raise InputError(f"{what}.{key}: expected a number, got {v!r}")
        out[key] = float(v)
    if out["margin_px"] < 0:
        raise InputError(f"{what}.margin_px: must be >= 0 px, got {out['margin_px']:g}")
    a = out["max_angle_rad"]
    if not 0.0 < a < math.pi / 2:
        hint = " (it looks like degrees: give it in rad)" if 1.0 <= a < 90.0 else ""
        raise InputError(f"{what}.max_angle_rad: must be in (0, {math.pi / 2:.4f}) rad, got {a:g}{hint}")
    near, far = out["near_m"], out["far_m"]
    if not 0.0 < near < far:
        raise InputError(f"{what}: need 0 < near_m < far_m (m), got near_m {near:g}, far_m {far:g}")
    if far > 50.0:
        raise InputError(f"{what}.far_m: {far:g} is more than 50 m: the value looks like mm; give it in m")
    return out
