"""Synthetic board images for the camera tests: a chessboard or ChArUco board drawn at a known scale and warped by a
known homography (cv2.warpPerspective), with the true corner pixels."""

from __future__ import annotations

import numpy as np

#: pixels per square and the white margin of the flat board image
SQUARE_PX, MARGIN_PX = 60, 60


def flat_board(kind: str, rows: int, cols: int, dictionary: str = "DICT_5X5_100") -> np.ndarray:
    """The board of rows x cols squares drawn flat (8 bit grey), SQUARE_PX per square, MARGIN_PX white around."""
    import cv2

    w, h = cols * SQUARE_PX + 2 * MARGIN_PX, rows * SQUARE_PX + 2 * MARGIN_PX
    if kind == "charuco":
        d = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, dictionary))
        board = cv2.aruco.CharucoBoard((cols, rows), 0.03, 0.022, d)
        return board.generateImage((w, h), marginSize=MARGIN_PX)
    img = np.full((h, w), 255, np.uint8)
    for r in range(rows):
        for c in range(cols):
            if (r + c) % 2 == 0:
                y, x = MARGIN_PX + r * SQUARE_PX, MARGIN_PX + c * SQUARE_PX
                img[y:y + SQUARE_PX, x:x + SQUARE_PX] = 0
    return img


def flat_corners(rows: int, cols: int) -> np.ndarray:
    """The inner corners' pixels in the flat image, (rows-1)(cols-1) x 2, row by row (pixel centres at whole
    numbers: a square's edge lies half a pixel before its first pixel)."""
    r, c = np.divmod(np.arange((rows - 1) * (cols - 1)), cols - 1)
    return np.stack([MARGIN_PX + (c + 1) * SQUARE_PX - 0.5, MARGIN_PX + (r + 1) * SQUARE_PX - 0.5], axis=1)


def warped(flat: np.ndarray, H: np.ndarray, size=(1280, 1024)) -> np.ndarray:
    """The flat board seen through the homography H (flat px -> image px), white outside."""
    import cv2

    return cv2.warpPerspective(flat, H, size, flags=cv2.INTER_LINEAR, borderValue=255)


def apply(H: np.ndarray, xy: np.ndarray) -> np.ndarray:
    """Points through a homography, (k, 2)."""
    p = np.c_[xy, np.ones(len(xy))] @ H.T
    return p[:, :2] / p[:, 2:]


def homography(seed: int, scale: float = 0.9) -> np.ndarray:
    """A seeded, moderate view: scale, a small rotation and perspective, a shift into a 1280 x 1024 image."""
    rng = np.random.default_rng(seed)
    a = rng.uniform(-0.25, 0.25)
    R = np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]]) * scale
    H = np.eye(3)
    H[:2, :2] = R
    H[:2, 2] = [150 + rng.uniform(-40, 40), 150 + rng.uniform(-40, 40)]
    H[2, :2] = rng.uniform(-1.5e-4, 1.5e-4, 2)
    return H
