"""``detect``: the command line's chessboard detector on an image file or array."""

from __future__ import annotations

import os

import numpy as np

from . import _deformcal
from ._errors import InputError


def detect(image_or_path, rows: int, cols: int):
    """Finds a chessboard of ``rows`` × ``cols`` inner corners, as
    ``deformcal detect`` does.

    ``image_or_path``: an image file (PNG, JPEG, TIFF) or an 8-bit numpy image,
    (H, W) grey or (H, W, 3) in OpenCV's BGR order (what ``cv2.imread`` gives).
    ``rows`` × ``cols`` are OpenCV's pattern size read the other way round:
    ``cv2.findChessboardCorners(img, (cols, rows))``.

    Returns ``(corners, ids)``: corners (N, 2) float64 pixels (OpenCV's
    pixel-centre convention), ids (N,) int64, ``row * cols + col``; a partial
    view gives only the corners it sees. Raises ``DetectionError`` when no
    board is found, ``FileError`` for an unreadable file, ``InputError`` for an
    image of another shape or dtype. The GIL is released while it runs.
    """
    rows, cols = _count(rows, "rows"), _count(cols, "cols")
    if isinstance(image_or_path, (str, bytes, os.PathLike)):
        corners, ids, _, _ = _deformcal.detect_file(os.fsdecode(image_or_path), rows, cols)
        return corners, ids
    img = image_or_path
    if not isinstance(img, np.ndarray):
        raise InputError(f"image: expected a path or a numpy array, got {type(img).__name__}")
    if img.dtype != np.uint8:
        raise InputError(f"image: dtype {img.dtype}; expected uint8 (8-bit)")
    if img.ndim == 3 and img.shape[2] == 1:
        img = img[:, :, 0]
    if img.ndim == 3 and img.shape[2] == 3:
        img = img[:, :, ::-1]  # BGR to RGB
    elif img.ndim != 2:
        raise InputError(f"image: shape {img.shape}; expected (H, W) or (H, W, 3)")
    if min(img.shape[:2]) == 0:
        raise InputError(f"image: shape {img.shape} has no pixels")
    corners, ids, _, _ = _deformcal.detect_array(np.ascontiguousarray(img), rows, cols)
    return corners, ids


def _count(v, what: str) -> int:
    if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 2:
        raise InputError(f"{what}: expected an integer >= 2 (inner corners), got {v!r}")
    return int(v)
