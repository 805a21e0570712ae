"""``Camera``: project/unproject round trips to 1e-9 px over the image and
broadcast over any leading shape; loaded from calibration.json and opencv.yaml
as it was saved; every export format written and read back by its consumer."""

import json

import numpy as np
import pytest

import deformcal
from conftest import SIZE, TRUE_DIST, TRUE_K, cv2, pixel_grid, synthetic_views

MODELS = ["radial3", "opencv5", "opencv8", "kb4", "ds"]


SEEN = {}


@pytest.fixture(scope="module")
def calibrations():
    out = {}
    for model in MODELS:
        data_model = "kb4" if model == "ds" else model
        obj, img = synthetic_views(data_model, views=10, seed=2)
        SEEN[model] = img
        out[model] = deformcal.calibrate_camera(obj, img, SIZE, model=model, method="standard")
    return out


@pytest.mark.parametrize("model", MODELS)
def test_round_trip_over_the_image(calibrations, model):
    cam = calibrations[model].camera
    px = pixel_grid(step=16)
    rays = cam.unproject(px)
    ok = np.isfinite(rays).all(axis=1)
    # A fitted rational model may fold beyond the corners it saw (opencv8 here:
    # 2.4 % of the image, in its corners); inside them every pixel has a ray.
    seen = np.concatenate(SEEN[model])
    inside = (px >= seen.min(axis=0)).all(axis=1) & (px <= seen.max(axis=0)).all(axis=1)
    assert ok[inside].all() and ok.mean() > 0.95, f"{model}: pixels without a ray"
    rays, px = rays[ok], px[ok]
    np.testing.assert_allclose(np.linalg.norm(rays, axis=1), 1.0, atol=1e-12)
    back = cam.project(rays)
    err = np.abs(back - px).max()
    assert err <= 1e-9, f"{model}: round trip {err} px"
    # Scaling a ray does not move its pixel.
    np.testing.assert_allclose(cam.project(rays * 3.7), back, atol=1e-9)


def test_broadcasting(calibrations):
    cam = calibrations["opencv5"].camera
    px = pixel_grid(step=64)[:24].reshape(2, 3, 4, 2)
    rays = cam.unproject(px)
    assert rays.shape == (2, 3, 4, 3)
    np.testing.assert_allclose(cam.project(rays), px, atol=1e-9)
    assert cam.project(np.array([0.0, 0.0, 1.0])).shape == (2,)
    one = cam.project(rays.reshape(-1, 3))
    np.testing.assert_array_equal(one.reshape(2, 3, 4, 2), cam.project(rays))
    assert np.isnan(cam.project([0.0, 0.0, -1.0])).all(), "behind a pinhole camera"
    with pytest.raises(deformcal.InputError, match=r"expected \(\.\.\., 3\)"):
        cam.project(np.zeros((4, 2)))
    with pytest.raises(deformcal.InputError, match=r"expected \(\.\.\., 2\)"):
        cam.unproject(np.zeros((4, 3)))


def test_project_agrees_with_opencv(calibrations):
    """Independent check of the projection: OpenCV's projectPoints with the K and
    dist the result gives."""
    for model in ("radial3", "opencv5", "opencv8", "kb4"):
        cam = calibrations[model].camera
        pts = np.random.default_rng(1).uniform([-0.3, -0.2, 0.5], [0.3, 0.2, 1.0], (50, 3))
        if model == "kb4":
            cv, _ = cv2.fisheye.projectPoints(pts.reshape(-1, 1, 3), np.zeros(3), np.zeros(3), cam.K, cam.dist)
        else:
            cv, _ = cv2.projectPoints(pts, np.zeros(3), np.zeros(3), cam.K, cam.dist)
        np.testing.assert_allclose(cam.project(pts), cv.reshape(-1, 2), atol=1e-6, err_msg=model)


def test_load_what_save_wrote(calibrations, tmp_path):
    r = calibrations["opencv8"]
    r.save(tmp_path)
    for loaded in (
        deformcal.Camera.load(tmp_path / "calibration.json"),
        deformcal.Camera.load(tmp_path / "opencv.yaml"),
    ):
        assert loaded.model == "opencv8" and loaded.image_size == SIZE
        np.testing.assert_allclose(loaded.K, r.K, rtol=1e-12)
        np.testing.assert_allclose(loaded.dist, r.dist, rtol=1e-12, atol=1e-15)
    with pytest.raises(deformcal.InputError, match="no camera 'left'"):
        deformcal.Camera.load(tmp_path / "calibration.json", camera="left")
    (tmp_path / "broken.json").write_text('{"method": 1}')
    with pytest.raises(deformcal.InputError, match="broken.json"):
        deformcal.Camera.load(tmp_path / "broken.json")
    with pytest.raises(deformcal.FileError):
        deformcal.Camera.load(tmp_path / "missing.json")


def read_back(fmt, path, cam):
    """The export read by its consumer: the camera matrix it holds."""
    text = path.read_text()
    if fmt == "json":
        return deformcal.Camera.load(path).K
    if fmt == "opencv":
        fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_READ)
        K = fs.getNode("camera_matrix").mat()
        d = fs.getNode("distortion_coefficients").mat().ravel()
        np.testing.assert_allclose(d, cam.dist.ravel(), rtol=1e-12, atol=1e-15)
        return K
    if fmt == "mrcal":
        mrcal = pytest.importorskip("mrcal")
        lens, intr = mrcal.cameramodel(str(path)).intrinsics()
        return np.array([[intr[0], 0, intr[2]], [0, intr[1], intr[3]], [0, 0, 1]])
    yaml = pytest.importorskip("yaml")
    if fmt == "ros":
        data = yaml.safe_load(text)
        return np.array(data["camera_matrix"]["data"]).reshape(3, 3)
    if fmt == "kalibr":
        data = yaml.safe_load(text)
        fx, fy, cx, cy = data["cam0"]["intrinsics"]
        return np.array([[fx, 0, cx], [0, fy, cy], [0, 0, 1]])
    if fmt == "colmap":
        line = [l for l in text.splitlines() if l and not l.startswith("#")][0].split()
        fx, fy, cx, cy = map(float, line[4:8])
        # COLMAP puts the centre of the first pixel at 0.5, OpenCV at 0.
        return np.array([[fx, 0, cx - 0.5], [0, fy, cy - 0.5], [0, 0, 1]])
    raise AssertionError(fmt)


@pytest.mark.parametrize("fmt", sorted(deformcal.EXPORT_FORMATS))
def test_every_export_is_readable(calibrations, tmp_path, fmt):
    # Kalibr's radtan has no k3: its export is tested on the fisheye camera.
    cam = calibrations["kb4" if fmt == "kalibr" else "opencv5"].camera
    path = cam.export(fmt, tmp_path / f"camera.{fmt}")
    np.testing.assert_allclose(read_back(fmt, path, cam), cam.K, rtol=1e-12)


def test_export_refuses_what_a_format_cannot_hold(calibrations, tmp_path):
    with pytest.raises(deformcal.ExportError, match="opencv"):
        calibrations["ds"].camera.export("opencv", tmp_path / "ds.yaml")
    with pytest.raises(deformcal.InputError, match="unknown export format"):
        calibrations["opencv5"].camera.export("matlab", tmp_path / "x")
    assert not (tmp_path / "ds.yaml").exists()


def test_truth_is_near(calibrations):
    """Guard against both tools failing alike: the calibrated camera is near the true one."""
    cam = calibrations["opencv5"].camera
    seen = np.concatenate(SEEN["opencv5"])
    px = pixel_grid(step=20)
    px = px[(px >= seen.min(axis=0)).all(axis=1) & (px <= seen.max(axis=0)).all(axis=1)]
    rays = cam.unproject(px)
    true, _ = cv2.projectPoints(rays, np.zeros(3), np.zeros(3), TRUE_K, TRUE_DIST["opencv5"])
    assert np.abs(true.reshape(-1, 2) - px).max() < 2.0
