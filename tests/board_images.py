"""Synthetic board images for the camera tests: a chessboard or ChArUco board drawn at a known scale and warped by a
known homography (cv2.warpPerspective), with the true corner pixels."""

from __future__ import annotations

import numpy as np

#: pixels per square and the white margin of the flat board image
SQUARE_PX, MARGIN_PX = 60, 60


def flat_board(kind: str, rows: int, cols: int, dictionary: str = "DICT_5X5_100", px: float = 1.0) -> np.ndarray:
    """The board of rows x cols squares drawn flat (8 bit grey), px · SQUARE_PX per square, px · MARGIN_PX white
    around (px: the resolution against the default one)."""
    import cv2

    sq, mg = round(px * SQUARE_PX), round(px * MARGIN_PX)
    w, h = cols * sq + 2 * mg, rows * sq + 2 * mg
    if kind == "charuco":
        d = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, dictionary))
        board = cv2.aruco.CharucoBoard((cols, rows), 0.03, 0.022, d)
        return board.generateImage((w, h), marginSize=mg)
    img = np.full((h, w), 255, np.uint8)
    for r in range(rows):
        for c in range(cols):
            if (r + c) % 2 == 0:
                y, x = mg + r * sq, mg + c * sq
                img[y:y + sq, x:x + sq] = 0
    return img


def flat_corners(rows: int, cols: int, px: float = 1.0) -> np.ndarray:
    """The inner corners' pixels in the flat image of :func:`flat_board` at resolution px, (rows-1)(cols-1) x 2,
    row by row (pixel centres at whole numbers: a square's edge lies half a pixel before its first pixel)."""
    sq, mg = round(px * SQUARE_PX), round(px * MARGIN_PX)
    r, c = np.divmod(np.arange((rows - 1) * (cols - 1)), cols - 1)
    return np.stack([mg + (c + 1) * sq - 0.5, mg + (r + 1) * sq - 0.5], axis=1)


def warped(flat: np.ndarray, H: np.ndarray, size=(1280, 1024)) -> np.ndarray:
    """The flat board seen through the homography H (flat px -> image px), white outside."""
    import cv2

    return cv2.warpPerspective(flat, H, size, flags=cv2.INTER_LINEAR, borderValue=255)


def apply(H: np.ndarray, xy: np.ndarray) -> np.ndarray:
    """Points through a homography, (k, 2)."""
    p = np.c_[xy, np.ones(len(xy))] @ H.T
    return p[:, :2] / p[:, 2:]


def homography(seed: int, scale: float = 0.9, px: float = 1.0) -> np.ndarray:
    """A seeded, moderate view: scale, a small rotation and perspective, a shift into a 1280 x 1024 image; at
    resolution px the same view of the board of :func:`flat_board` at px into a px · (1280 x 1024) image."""
    rng = np.random.default_rng(seed)
    a = rng.uniform(-0.25, 0.25)
    R = np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]]) * scale
    H = np.eye(3)
    H[:2, :2] = R
    H[:2, 2] = [150 + rng.uniform(-40, 40), 150 + rng.uniform(-40, 40)]
    H[2, :2] = rng.uniform(-1.5e-4, 1.5e-4, 2)
    return np.diag([px, px, 1.0]) @ H @ np.diag([1.0 / px, 1.0 / px, 1.0])
