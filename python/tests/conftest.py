"""Shared fixtures: synthetic views of a rigid board with a known camera, made
with OpenCV's own projection (an independent model of each lens), and the
command-line binary for comparisons.

The package under test is the one on ``sys.path`` (tests/python.rs puts the
freshly built module first); ``DEFORMCAL_BIN`` names the command line built
with it.
"""

import os
import shutil
from pathlib import Path

import numpy as np
import pytest

cv2 = pytest.importorskip("cv2")

ROOT = Path(__file__).resolve().parents[2]
ROWS, COLS, SPACING = 7, 10, 0.03
SIZE = (1280, 960)
#: The true camera of each lens model, in OpenCV's terms (K, dist).
TRUE_K = np.array([[900.0, 0.0, 645.0], [0.0, 905.0, 470.0], [0.0, 0.0, 1.0]])
TRUE_DIST = {
    "radial3": np.array([-0.28, 0.11, 0.0, 0.0, -0.02]),
    "opencv5": np.array([-0.28, 0.11, 0.0011, -0.0007, -0.02]),
    "opencv8": np.array([0.35, -0.2, 0.0011, -0.0007, 0.02, 0.62, -0.25, 0.08]),
    "kb4": np.array([0.05, -0.02, 0.01, -0.003]),
}
#: OpenCV's calibration of each model: calibrateCamera's flags, or fisheye.
CV_FLAGS = {"radial3": cv2.CALIB_ZERO_TANGENT_DIST, "opencv5": 0, "opencv8": cv2.CALIB_RATIONAL_MODEL}
#: Options that make deformcal solve OpenCV's exact problem: least squares, no
#: rejection, no prior, tight tolerances.
EXACT = dict(
    loss="none",
    outlier_k=0,
    lens_prior="none",
    function_tolerance=1e-15,
    gradient_tolerance=1e-15,
    parameter_tolerance=1e-15,
    max_iterations=500,
)


def board_points(dtype=np.float64):
    """OpenCV's usual object points: corner (row, col) at (col, row, 0) * spacing."""
    objp = np.zeros((ROWS * COLS, 3), dtype)
    objp[:, :2] = np.mgrid[0:COLS, 0:ROWS].T.reshape(-1, 2) * SPACING
    return objp


def project(model, pts, rvec, tvec, K=TRUE_K, dist=None):
    dist = TRUE_DIST[model] if dist is None else dist
    if model == "kb4":
        uv, _ = cv2.fisheye.projectPoints(pts.reshape(-1, 1, 3), rvec, tvec, K, dist)
    else:
        uv, _ = cv2.projectPoints(pts, rvec, tvec, K, dist)
    return uv.reshape(-1, 2)


def synthetic_views(model, views=20, seed=1, noise=0.2, partial=False):
    """Views of a rigid board in front of the true camera: (object_points,
    image_points) lists as cv2.calibrateCamera takes them, pixels rounded to
    float32 as OpenCV works in float32 (both tools then see the same numbers)."""
    rng = np.random.default_rng(seed)
    objp = board_points()
    centre = objp.mean(axis=0)
    obj, img = [], []
    while len(obj) < views:
        angles = rng.uniform(-0.6, 0.6, 3) * np.array([1, 1, 0.5])
        rvec = angles.reshape(3, 1)
        R, _ = cv2.Rodrigues(rvec)
        depth = rng.uniform(0.35, 0.6)
        shift = rng.uniform(-0.12, 0.12, 2)
        tvec = (np.array([shift[0], shift[1], depth]) - R @ centre).reshape(3, 1)
        uv = project(model, objp, rvec, tvec)
        uv = uv + rng.normal(0.0, noise, uv.shape)
        inside = (uv[:, 0] > 0) & (uv[:, 0] < SIZE[0] - 1) & (uv[:, 1] > 0) & (uv[:, 1] < SIZE[1] - 1)
        keep = inside if partial else np.ones(len(uv), bool)
        if partial and len(obj) % 3 == 0:
            keep &= np.arange(len(uv)) % COLS < COLS - 3  # a board cut at the right
        if not partial and not inside.all():
            continue
        obj.append(objp[keep].astype(np.float32))
        img.append(uv[keep].astype(np.float32))
    return obj, img


def opencv_calibrate(model, obj, img):
    """OpenCV's calibration of the views: (rms, K, dist, rvecs, tvecs)."""
    criteria = (cv2.TERM_CRITERIA_COUNT + cv2.TERM_CRITERIA_EPS, 1000, 1e-16)
    if model == "kb4":
        flags = cv2.fisheye.CALIB_FIX_SKEW | cv2.fisheye.CALIB_RECOMPUTE_EXTRINSIC
        o = [x.astype(np.float64).reshape(-1, 1, 3) for x in obj]
        i = [x.astype(np.float64).reshape(-1, 1, 2) for x in img]
        return cv2.fisheye.calibrate(o, i, SIZE, None, None, flags=flags, criteria=criteria)
    return cv2.calibrateCamera(obj, img, SIZE, None, None, flags=CV_FLAGS[model], criteria=criteria)


def pixel_grid(step=40):
    u, v = np.meshgrid(np.arange(0, SIZE[0], step, dtype=float), np.arange(0, SIZE[1], step, dtype=float))
    return np.stack([u.ravel(), v.ravel()], axis=1)


@pytest.fixture(scope="session")
def cli():
    """The deformcal command line built with the module under test."""
    path = os.environ.get("DEFORMCAL_BIN") or shutil.which("deformcal")
    if not path:
        built = ROOT / "target" / "release" / "deformcal"
        path = str(built) if built.exists() else None
    if not path:
        pytest.skip("no deformcal binary (set DEFORMCAL_BIN)")
    return path
