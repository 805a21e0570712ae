"""A calibrated camera: its intrinsics in deformcal's and OpenCV's terms, its
projection and unprojection over arrays of any leading shape, and its export to
each format the command line writes. The mathematics and the file formats are
the library's (the native module); this layer handles shapes and files."""

from __future__ import annotations

import json
import os
import re
from pathlib import Path

import numpy as np

from . import _deformcal
from ._errors import InputError

#: OpenCV's distortion vector of each lens model: (its coefficients, the shape
#: OpenCV returns them in). radial3 is OpenCV's plumb_bob with p1 = p2 = 0.
OPENCV_DIST = {
    "radial3": (("k1", "k2", None, None, "k3"), (1, 5)),
    "opencv5": (("k1", "k2", "p1", "p2", "k3"), (1, 5)),
    "opencv8": (("k1", "k2", "p1", "p2", "k3", "k4", "k5", "k6"), (1, 8)),
    "kb4": (("k1", "k2", "k3", "k4"), (4, 1)),
}
#: opencv.yaml's distortion_model for each lens model it can hold.
OPENCV_MODELS = {"plumb_bob": "opencv5", "rational_polynomial": "opencv8", "fisheye": "kb4"}
#: The export formats (``Camera.export``) and their usual file names.
EXPORT_FORMATS = {
    "json": "calibration.json",
    "opencv": "opencv.yaml",
    "mrcal": "<camera>.cameramodel",
    "ros": "<camera>_camera_info.yaml",
    "kalibr": "camchain.yaml",
    "colmap": "cameras.txt",
}


def _minimal_json(camera: dict, rmse: float) -> dict:
    """A calibration.json holding one camera and nothing of a solve."""
    return {
        "method": "standard",
        "rmse_px": rmse,
        "observations": 0,
        "converged": True,
        "iterations": 0,
        "seconds": 0.0,
        "cameras": [camera],
        "frames": [],
        "gauge_corners": [],
        "frozen_corners": [],
        "initial_intrinsics": [],
        "stages": [],
        "warnings": [],
    }


class Camera:
    """One calibrated camera.

    Attributes: ``name``, ``model`` (deformcal's lens model name), ``image_size``
    (width, height), ``params`` (the lens parameters by name, in the model's
    order), ``K`` (3, 3), ``dist`` (OpenCV's coefficients and shape for the model;
    ``None`` for ``ds``, which OpenCV lacks), ``R`` (3, 3) and ``T`` (3,): this
    camera from the rig's first camera, x_k = R x_0 + T (identity and zero for
    the first), ``uncertainty`` (dict or ``None``).
    """

    def __init__(self, calibration_json: dict, index: int = 0):
        cams = calibration_json["cameras"]
        cam = cams[index]
        self.name: str = cam["name"]
        self.model: str = cam["model"]
        self.image_size: tuple = (int(cam["width"]), int(cam["height"]))
        names = _deformcal.lens_models()[self.model]
        self.params: dict = {n: float(cam["intrinsics"][n]) for n in names}
        self._values = np.array([self.params[n] for n in names], dtype=np.float64)
        self.R = _rotation_matrix(np.asarray(cam["rotation"], dtype=np.float64))
        self.T = np.asarray(cam["translation"], dtype=np.float64)
        self.uncertainty = cam.get("uncertainty")
        rmse = cam.get("rmse_px", calibration_json.get("rmse_px"))
        self.rmse_px = float("nan") if rmse is None else float(rmse)
        one = dict(calibration_json)
        one["cameras"] = [cam]
        if index != 0:
            one["frames"] = []
        self._json = one

    def __repr__(self) -> str:
        return f"Camera({self.name!r}, {self.model}, {self.image_size[0]}x{self.image_size[1]})"

    @property
    def K(self) -> np.ndarray:
        """The camera matrix, (3, 3) float64."""
        p = self.params
        return np.array([[p["fx"], 0.0, p["cx"]], [0.0, p["fy"], p["cy"]], [0.0, 0.0, 1.0]])

    @property
    def dist(self):
        """OpenCV's distortion coefficients: (1, 5) for radial3 and opencv5, (1, 8)
        for opencv8 (``cv2.calibrateCamera``), (4, 1) for kb4 (``cv2.fisheye``);
        ``None`` for ds."""
        if self.model not in OPENCV_DIST:
            return None
        keys, shape = OPENCV_DIST[self.model]
        return np.array([0.0 if k is None else self.params[k] for k in keys]).reshape(shape)

    def project(self, points) -> np.ndarray:
        """Pixels (..., 2) of camera-frame points (..., 3), any leading shape;
        NaN where the lens has no image of a point (behind a pinhole camera)."""
        pts = _float_array(points, 3, "points")
        out = _deformcal.project(self.model, self._values, pts.reshape(-1, 3))
        return out.reshape(pts.shape[:-1] + (2,))

    def unproject(self, pixels) -> np.ndarray:
        """Unit rays (..., 3) in the camera frame of pixels (..., 2), any leading
        shape; NaN where no ray maps to a pixel (beyond a distortion's fold)."""
        px = _float_array(pixels, 2, "pixels")
        out = _deformcal.unproject(self.model, self._values, px.reshape(-1, 2))
        return out.reshape(px.shape[:-1] + (3,))

    def export(self, fmt: str, path) -> Path:
        """Writes this camera in format ``fmt`` to the file ``path`` (atomically):
        ``json`` (calibration.json), ``opencv`` (opencv.yaml), ``mrcal``
        (.cameramodel), ``ros`` (camera_info YAML), ``kalibr`` (camchain.yaml) or
        ``colmap`` (cameras.txt). Raises ``ExportError`` where the format cannot
        hold the lens model exactly."""
        path = Path(os.fspath(path))
        _deformcal.export(json.dumps(self._json), str(fmt), path)
        return path

    @classmethod
    def load(cls, path, camera=None) -> "Camera":
        """A camera from a ``calibration.json`` (checked as ``deformcal export``
        checks it) or an ``opencv.yaml`` (``.yaml``/``.yml``); ``camera`` names one
        camera of a rig (default: the first)."""
        path = Path(os.fspath(path))
        if path.suffix.lower() in (".yaml", ".yml"):
            return cls._from_opencv_yaml(path, camera)
        data = json.loads(_deformcal.check_calibration_json(path))
        names = [c["name"] for c in data["cameras"]]
        if camera is None:
            return cls(data, 0)
        if camera not in names:
            raise InputError(f"{path}: no camera {camera!r} (it has {', '.join(names)})")
        return cls(data, names.index(camera))

    @classmethod
    def _from_opencv_yaml(cls, path: Path, camera=None) -> "Camera":
        try:
            text = path.read_text()
        except OSError as e:
            from ._errors import FileError

            raise FileError(f"{path}: {e.strerror or e}") from e
        prefix = "" if camera is None else f"{camera}_"
        model_name = _yaml_scalar(text, prefix + "distortion_model", path)
        model = OPENCV_MODELS.get(model_name.strip('"'))
        if model is None:
            raise InputError(f"{path}: distortion_model {model_name} is none of {', '.join(OPENCV_MODELS)}")
        k = _yaml_matrix(text, prefix + "camera_matrix", path)
        d = _yaml_matrix(text, prefix + "distortion_coefficients", path)
        keys = [x for x in OPENCV_DIST[model][0] if x is not None]
        if len(k) != 9 or len(d) != len(keys):
            raise InputError(
                f"{path}: camera_matrix needs 9 values and {model_name} {len(keys)} "
                f"distortion coefficients (got {len(k)} and {len(d)})"
            )
        intrinsics = {"fx": k[0], "fy": k[4], "cx": k[2], "cy": k[5]}
        intrinsics.update(zip(keys, d))
        cam = {
            "name": camera or path.stem,
            "model": model,
            "width": int(_yaml_scalar(text, prefix + "image_width", path)),
            "height": int(_yaml_scalar(text, prefix + "image_height", path)),
            "intrinsics": intrinsics,
            "rotation": [0.0, 0.0, 0.0],
            "translation": [0.0, 0.0, 0.0],
        }
        try:
            rmse = float(_yaml_scalar(text, prefix + "avg_reprojection_error", path))
        except InputError:
            rmse = 0.0
        checked = _deformcal.check_calibration_json(path, json.dumps(_minimal_json(cam, rmse)))
        return cls(json.loads(checked), 0)


def _yaml_scalar(text: str, key: str, path: Path) -> str:
    m = re.search(rf"^{re.escape(key)}:[ \t]*(\S+)[ \t]*$", text, re.MULTILINE)
    if m is None:
        raise InputError(f"{path}: no `{key}` (is this an OpenCV FileStorage YAML?)")
    return m.group(1)


def _yaml_matrix(text: str, key: str, path: Path) -> list:
    m = re.search(
        rf"^{re.escape(key)}:\s*!!opencv-matrix.*?data:\s*\[([^\]]*)\]",
        text,
        re.MULTILINE | re.DOTALL,
    )
    if m is None:
        raise InputError(f"{path}: no matrix `{key}`")
    try:
        return [float(v) for v in m.group(1).replace("\n", " ").split(",") if v.strip()]
    except ValueError as e:
        raise InputError(f"{path}: `{key}`: {e}") from e


def _float_array(a, dims: int, what: str) -> np.ndarray:
    arr = np.asarray(a)
    if arr.dtype.kind not in "fiu":
        raise InputError(f"{what}: dtype {arr.dtype}; expected numbers")
    if arr.ndim == 0 or arr.shape[-1] != dims:
        raise InputError(f"{what}: shape {arr.shape}; expected (..., {dims})")
    return np.ascontiguousarray(arr, dtype=np.float64)


def _rotation_matrix(rvec: np.ndarray) -> np.ndarray:
    """The rotation of an axis-angle vector (Rodrigues' formula, as cv2.Rodrigues)."""
    theta = float(np.linalg.norm(rvec))
    if theta < 1e-300:
        return np.eye(3)
    k = rvec / theta
    kx = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + np.sin(theta) * kx + (1.0 - np.cos(theta)) * (kx @ kx)
