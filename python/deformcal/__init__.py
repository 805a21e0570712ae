"""deformcal: camera calibration with a chessboard that bends while it is carried.

The Python interface of the ``deformcal`` command line, with OpenCV's arrays:

- ``calibrate_camera(object_points, image_points, image_size, *, model, method, **options)``
  takes what ``cv2.calibrateCamera`` takes and returns a ``Calibration``;
- ``calibrate_rig`` the same for several cameras;
- ``detect(image_or_path, rows, cols)`` the command line's chessboard detector;
- ``Camera`` (from a result, ``calibration.json`` or ``opencv.yaml``) with
  ``project``, ``unproject`` and ``export``;
- every error is a ``deformcal.Error``.

See docs/python.md and docs/from-opencv.md.
"""

from ._deformcal import __version__
from ._errors import (
    CalibrationFailed,
    DataError,
    DetectionError,
    Error,
    ExportError,
    FileError,
    InputError,
    OptionError,
    SolverError,
)
from ._arrays import Board
from ._camera import EXPORT_FORMATS, Camera
from ._calibration import Calibration, calibrate_camera, calibrate_rig
from ._detect import detect

#: The lens models and their parameters, in calibration.json's order.
from ._deformcal import lens_models as _lens_models

LENS_MODELS = _lens_models()

__all__ = [
    "Board",
    "Calibration",
    "CalibrationFailed",
    "Camera",
    "DataError",
    "DetectionError",
    "EXPORT_FORMATS",
    "Error",
    "ExportError",
    "FileError",
    "InputError",
    "LENS_MODELS",
    "OptionError",
    "SolverError",
    "__version__",
    "calibrate_camera",
    "calibrate_rig",
    "detect",
]
