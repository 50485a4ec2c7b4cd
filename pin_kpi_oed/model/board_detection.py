"""What a camera measures in an image: the calibration board's corners, detected with OpenCV (px).

* a chessboard: ``cv2.findChessboardCornersSB`` (the sector-based detector, sub-pixel by itself), else
  ``cv2.findChessboardCorners`` refined by ``cv2.cornerSubPix``; every inner corner or none, numbered row by row
  from the end nearest the image's top left (OpenCV numbers a symmetric board from either end; the image alone
  cannot tell them apart: keep the board within a quarter turn of upright in the images, or use ChArUco);
* a ChArUco board: ``cv2.aruco.CharucoDetector`` on the board ``cv2.aruco.CharucoBoard((columns, rows), square,
  marker, dictionary)``; the corners whose neighbouring markers are seen, with their printed ids (a partly seen
  board still counts), refined by ``cv2.cornerSubPix`` (5 x 5 px window).

The ids are those of :class:`~pin_kpi_oed.model.camera.Board` (row · (columns − 1) + column) and the pixels
OpenCV's (pixel centres at whole numbers), what :func:`~pin_kpi_oed.model.camera.project` predicts.
"""

from __future__ import annotations

import numpy as np

from pin_kpi_oed.errors import InputError
from pin_kpi_oed.model.camera import Board

__all__ = ["detect_corners", "charuco_board"]


def charuco_board(board: Board, marker_m: float, dictionary: str):
    """The ``cv2.aruco.CharucoBoard`` of a board of (cols + 1) × (rows + 1) squares.

    Raises:
        InputError: an unknown dictionary name.
    """
    import cv2

    if not hasattr(cv2.aruco, str(dictionary)):
        raise InputError(f"board dictionary '{dictionary}' is not a cv2.aruco dictionary (e.g. DICT_5X5_100)")
    d = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, dictionary))
    return cv2.aruco.CharucoBoard((board.cols + 1, board.rows + 1), board.square_m, marker_m, d)


def detect_corners(image: np.ndarray, board: Board, kind: str = "chessboard", marker_m: float | None = None,
                   dictionary: str | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The board's corners detected in an image (module docstring).

    Args:
        image: the image, grey (h, w) or BGR (h, w, 3), 8 bit.
        board: the board's inner corners and square size; kind: ``chessboard`` or ``charuco``.
        marker_m, dictionary: a ChArUco board's marker side (m) and ``cv2.aruco`` dictionary name.

    Returns:
        (ids (k,) int, uv (k, 2) px); both empty when the board is not found.

    Raises:
        InputError: an unknown board kind, or a ChArUco board without its marker size or dictionary.
    """
    import cv2

    gray = image if image.ndim == 2 else cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
    none = (np.zeros(0, int), np.zeros((0, 2)))
    if kind == "chessboard":
        size = (board.cols, board.rows)
        found, corners = cv2.findChessboardCornersSB(gray, size, flags=cv2.CALIB_CB_EXHAUSTIVE | cv2.CALIB_CB_ACCURACY)
        if not found:
            found, corners = cv2.findChessboardCorners(gray, size, flags=cv2.CALIB_CB_ADAPTIVE_THRESH
                                                       | cv2.CALIB_CB_NORMALIZE_IMAGE)
            if not found:
                return none
            crit = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 50, 1e-3)
            corners = cv2.cornerSubPix(gray, corners, (5, 5), (-1, -1), crit)
        uv = corners.reshape(-1, 2).astype(float)
        if (uv[-1] - uv[0]).sum() < 0:  # numbered from the far end: corner 0 nearest the top left
            uv = uv[::-1].copy()
        return np.arange(board.n), uv
    if kind != "charuco":
        raise InputError(f"board type '{kind}': one of chessboard, charuco")
    if marker_m is None or dictionary is None:
        raise InputError("a charuco board needs its marker size (marker_m) and dictionary")
    detector = cv2.aruco.CharucoDetector(charuco_board(board, marker_m, dictionary))
    corners, ids, _, _ = detector.detectBoard(gray)
    if ids is None or len(ids) == 0:
        return none
    crit = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 100, 1e-4)
    corners = cv2.cornerSubPix(gray, corners.astype(np.float32), (5, 5), (-1, -1), crit)
    return ids.reshape(-1).astype(int), corners.reshape(-1, 2).astype(float)
