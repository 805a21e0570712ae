"""``detect`` is the command line's detector; on OpenCV's sample photos (9 × 6)
it finds OpenCV's corners (findChessboardCorners + cornerSubPix) under the same ids."""

from pathlib import Path

import numpy as np
import pytest

import deformcal
from conftest import cv2

PHOTOS = sorted(Path("/usr/share/doc/opencv-doc/examples/data").glob("left[0-9]*.jpg"))
ROWS, COLS = 6, 9


def opencv_corners(path):
    gray = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
    found, corners = cv2.findChessboardCorners(gray, (COLS, ROWS))
    if not found:
        return None
    criteria = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 30, 0.001)
    return cv2.cornerSubPix(gray, corners, (11, 11), (-1, -1), criteria).reshape(-1, 2)


@pytest.mark.skipif(not PHOTOS, reason="opencv-doc's sample photos are not installed")
def test_sample_photos_against_opencv():
    distances = []
    for path in PHOTOS:
        corners, ids = deformcal.detect(path, ROWS, COLS)
        assert corners.shape == (len(ids), 2) and corners.dtype == np.float64
        assert ids.dtype == np.int64 and len(np.unique(ids)) == len(ids)
        # OpenCV's JPEG decoder and the detector's differ in the last bits of some
        # pixels: cv2.imread's image gives the same board within a hundredth of a pixel.
        c2, i2 = deformcal.detect(cv2.imread(str(path)), ROWS, COLS)
        np.testing.assert_array_equal(i2, ids)
        np.testing.assert_allclose(c2, corners, atol=0.01)
        cv = opencv_corners(path)
        if cv is None:
            continue
        # OpenCV's i-th corner is ours with id i (row-major from the same corner),
        # or, for a board OpenCV reads turned by 180°, id rows*cols-1-i.
        d = np.linalg.norm(cv[ids] - corners, axis=1)
        flipped = np.linalg.norm(cv[ROWS * COLS - 1 - ids] - corners, axis=1)
        distances.append((path.name, float(np.median(np.minimum(d, flipped))), len(ids)))
    print(distances)
    assert len(distances) >= 10
    close = [d for d in distances if d[1] < 0.2]
    assert len(close) >= len(distances) - 2, distances


def test_an_array_is_the_same_image_as_its_file(tmp_path):
    """A lossless file of cv2.imread's BGR array: the same corners, bit for bit."""
    if not PHOTOS:
        pytest.skip("opencv-doc's sample photos are not installed")
    bgr = cv2.imread(str(PHOTOS[0]))
    png = tmp_path / "left.png"
    cv2.imwrite(str(png), bgr)
    c1, i1 = deformcal.detect(png, ROWS, COLS)
    for image in (bgr, cv2.cvtColor(bgr, cv2.COLOR_BGR2GRAY)[:, :, None]):
        c2, i2 = deformcal.detect(image, ROWS, COLS)
        np.testing.assert_array_equal(i2, i1)
        tol = 0.0 if image.shape[2] == 3 else 0.05  # grey: OpenCV's own grey weights
        np.testing.assert_allclose(c2, c1, atol=tol, rtol=0)


def test_refusals(tmp_path):
    with pytest.raises(deformcal.FileError, match="missing.png"):
        deformcal.detect(tmp_path / "missing.png", 6, 9)
    (tmp_path / "junk.png").write_bytes(b"not an image")
    with pytest.raises(deformcal.FileError, match="junk.png"):
        deformcal.detect(tmp_path / "junk.png", 6, 9)
    with pytest.raises(deformcal.DetectionError):
        deformcal.detect(np.full((240, 320), 128, np.uint8), 6, 9)
    with pytest.raises(deformcal.InputError, match="uint8"):
        deformcal.detect(np.zeros((240, 320), np.float32), 6, 9)
    with pytest.raises(deformcal.InputError, match=r"\(H, W\)"):
        deformcal.detect(np.zeros((240, 320, 4), np.uint8), 6, 9)
    with pytest.raises(deformcal.InputError, match="rows"):
        deformcal.detect(np.zeros((240, 320), np.uint8), 1, 9)
