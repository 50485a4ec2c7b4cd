"""CLI subcommand ``import-images`` of ``pin-kpi-oed``: a folder of board images + the joint values -> the camera
measurement CSV (one row per detected corner, :mod:`pin_kpi_oed.data.corner_measurements`).

Example::

    pin-kpi-oed import-images shots/ --board board.yaml --joints joints.csv --out meas.csv

``board.yaml`` holds the board's fields (``type``, ``rows``, ``columns``, ``square_m``; a ChArUco board's
``marker_m`` and ``dictionary``: :mod:`pin_kpi_oed.cell.camera_setup`), or is a cell file with a ``board``.
``joints.csv`` has an ``image`` column (the image's file name, with or without its suffix) and one column per joint
(rad, named as in the URDF). An image whose board is not found is named and skipped, never guessed.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

__all__ = ["register", "run", "IMAGE_SUFFIXES"]

#: the image files read from the folder
IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff")


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``import-images`` subcommand."""
    p = subparsers.add_parser("import-images", help="detect a calibration board in images: the camera measurement CSV",
                              description="Detect the board's corners (OpenCV) in every image of a folder and join "
                                          "them with the robot's joint values by image name; write one CSV row per "
                                          "detected corner (pose, corner, u_px, v_px, joints in rad).")
    p.add_argument("images", help="folder of the images (" + ", ".join(IMAGE_SUFFIXES) + ")")
    p.add_argument("--board", required=True, help="YAML with the board's fields, or a cell file with a board")
    p.add_argument("--joints", required=True, help="CSV: image + one column per joint (rad)")
    p.add_argument("--out", required=True, help="write the camera measurement CSV here")
    p.add_argument("--quiet", action="store_true", help="print nothing but errors")
    p.set_defaults(func=run)


def _board(path: str):
    import yaml

    from pin_kpi_oed.cell.camera_setup import read_board
    from pin_kpi_oed.data.table import read_text_file
    from pin_kpi_oed.errors import InputError

    try:
        d = yaml.safe_load(read_text_file(path, path, "board file"))
    except yaml.YAMLError as exc:
        raise InputError(f"{path}: invalid YAML ({str(exc).strip().splitlines()[0]})") from None
    if isinstance(d, dict) and "board" in d:
        return read_board(d["board"], f"{path}: board")
    return read_board(d, f"{path}: board")


def _joints(path: str) -> tuple[list[str], dict[str, list[float]]]:
    """(joint names, image stem -> joint values (rad)) of the joints CSV."""
    from pin_kpi_oed.data.table import read_text_table
    from pin_kpi_oed.errors import InputError

    header, _, rows, lines = read_text_table(path, path, "joints file")
    if "image" not in header:
        raise InputError(f"{path}: missing column 'image' (the image's file name) beside the joint columns")
    names = [h for h in header if h != "image"]
    if not names or not rows:
        raise InputError(f"{path}: needs one column per joint (rad) and one row per image")
    out: dict[str, list[float]] = {}
    for line, row in zip(lines, rows):
        if len(row) != len(header):
            raise InputError(f"{path}: line {line}: {len(row)} cells, the header has {len(header)}")
        cells = dict(zip(header, row))
        stem = Path(cells["image"].strip()).stem
        if stem in out:
            raise InputError(f"{path}: line {line}: image '{stem}' is listed twice")
        try:
            q = [float(cells[n]) for n in names]
        except ValueError:
            raise InputError(f"{path}: line {line}: a joint value is not a number") from None
        bad = [n for n, v in zip(names, q) if not math.isfinite(v) or abs(v) > 4 * math.pi]
        if bad:
            raise InputError(f"{path}: line {line}, column '{bad[0]}': {cells[bad[0]]} is not finite or beyond ±4π "
                             "rad: the joint values look like degrees; give them in rad")
        out[stem] = q
    return names, out


def run(args: argparse.Namespace) -> int:
    """Handler of ``pin-kpi-oed import-images`` (module docstring).

    Raises:
        InputError: a missing folder, an unreadable image, a joints row without its image, a bad board or joints
            file, or no image with the board found.
    """
    import cv2
    import numpy as np

    from pin_kpi_oed.data.corner_measurements import CornerSet, write_corners
    from pin_kpi_oed.errors import InputError
    from pin_kpi_oed.model.board_detection import detect_corners
    from pin_kpi_oed.validation.paths import check_outputs

    folder = Path(args.images)
    if not folder.is_dir():
        raise InputError(f"images folder '{folder}' does not exist or is not a folder")
    check_outputs([("--out", args.out)], [("--joints", args.joints), ("--board", args.board), ("images", folder)])
    board, kind, marker, dictionary, _ = _board(args.board)
    names, joints = _joints(args.joints)
    images = {p.stem: p for p in sorted(folder.iterdir()) if p.suffix.lower() in IMAGE_SUFFIXES}
    missing = [s for s in joints if s not in images]
    if missing:
        raise InputError(f"{args.joints}: image '{missing[0]}' is not in {folder}"
                         + (f" ({len(missing) - 1} more)" if len(missing) > 1 else ""))
    labels, Q, uv, skipped = [], [], [], []
    for stem in joints:
        img = cv2.imread(str(images[stem]), cv2.IMREAD_GRAYSCALE)
        if img is None:
            raise InputError(f"{images[stem]}: cannot read the image")
        ids, pix = detect_corners(img, board, kind, marker, dictionary)
        if len(ids) == 0:
            skipped.append(images[stem].name)
            continue
        row = np.full(2 * board.n, np.nan)
        row.reshape(-1, 2)[ids] = pix
        labels.append(stem)
        Q.append(joints[stem])
        uv.append(row)
    if not labels:
        raise InputError(f"{folder}: the board ({kind}, {board.rows + 1} x {board.cols + 1} squares) was found in "
                         f"none of the {len(joints)} images")
    cs = CornerSet.from_arrays(labels, np.array(Q), np.array(uv), names)
    write_corners(cs, args.out)
    if not args.quiet:
        for name in skipped:
            print(f"{name}: board not found, skipped")
        extra = sorted(set(images) - set(joints))
        if extra:
            print(f"{len(extra)} image(s) without joint values ignored: {', '.join(extra[:5])}")
        print(f"{len(labels)} of {len(joints)} images with the board, {len(cs)} corners -> {args.out} (px, rad)")
    return 0
