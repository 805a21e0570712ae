# Type stubs of the deformcal package (shapes in the comments: N corners, V views).
from os import PathLike
from pathlib import Path
from typing import Any, Dict, List, Optional, Sequence, Tuple, Union

import numpy as np
import numpy.typing as npt

__version__: str
LENS_MODELS: Dict[str, List[str]]
EXPORT_FORMATS: Dict[str, str]

_Path = Union[str, PathLike]
_Float = npt.NDArray[np.floating]

class Error(Exception): ...
class InputError(Error, ValueError): ...
class OptionError(InputError): ...
class DataError(Error): ...
class SolverError(Error): ...
class DetectionError(Error): ...
class ExportError(Error): ...
class FileError(Error, OSError): ...

class CalibrationFailed(Error):
    reasons: List[str]
    hints: List[str]
    result: Optional[Calibration]

class Board:
    rows: int
    cols: int
    spacing: float
    origin: npt.NDArray[np.float64]  # (3,)
    @property
    def centre(self) -> npt.NDArray[np.float64]: ...  # (3,)

class Camera:
    name: str
    model: str
    image_size: Tuple[int, int]  # (width, height)
    params: Dict[str, float]
    R: npt.NDArray[np.float64]  # (3, 3): this camera from the first, x_k = R x_0 + T
    T: npt.NDArray[np.float64]  # (3,)
    rmse_px: float
    uncertainty: Optional[Dict[str, Any]]
    @property
    def K(self) -> npt.NDArray[np.float64]: ...  # (3, 3)
    @property
    def dist(self) -> Optional[npt.NDArray[np.float64]]: ...  # (1, 5), (1, 8) or (4, 1)
    def project(self, points: npt.ArrayLike) -> npt.NDArray[np.float64]: ...  # (..., 3) -> (..., 2)
    def unproject(self, pixels: npt.ArrayLike) -> npt.NDArray[np.float64]: ...  # (..., 2) -> (..., 3)
    def export(self, fmt: str, path: _Path) -> Path: ...
    @classmethod
    def load(cls, path: _Path, camera: Optional[str] = ...) -> Camera: ...

class Calibration:
    rms: float
    method: str
    method_reason: str
    warnings: List[str]
    converged: bool
    json: Dict[str, Any]
    board: Board
    cameras: List[Camera]
    @property
    def camera(self) -> Camera: ...
    @property
    def K(self) -> npt.NDArray[np.float64]: ...  # (3, 3)
    @property
    def dist(self) -> Optional[npt.NDArray[np.float64]]: ...
    @property
    def rvecs(self) -> Tuple[Optional[npt.NDArray[np.float64]], ...]: ...  # V × (3, 1)
    @property
    def tvecs(self) -> Tuple[Optional[npt.NDArray[np.float64]], ...]: ...  # V × (3, 1)
    @property
    def bends(self) -> List[Optional[Dict[str, Any]]]: ...
    @property
    def static_correction(self) -> Optional[npt.NDArray[np.float64]]: ...  # (rows*cols, 3)
    @property
    def uncertainty(self) -> Dict[str, Any]: ...
    def save(self, directory: _Path) -> Path: ...

def calibrate_camera(
    object_points: Sequence[_Float],  # V × (N, 3) or (N, 1, 3)
    image_points: Sequence[_Float],  # V × (N, 2) or (N, 1, 2)
    image_size: Tuple[int, int],  # (width, height)
    *,
    model: str = ...,
    method: str = ...,
    name: str = ...,
    fix: Sequence[str] = ...,
    **options: Any,
) -> Calibration: ...
def calibrate_rig(
    object_points: Sequence[Sequence[Optional[_Float]]],  # cameras × V × (N, 3)
    image_points: Sequence[Sequence[Optional[_Float]]],  # cameras × V × (N, 2)
    image_sizes: Sequence[Tuple[int, int]],
    *,
    models: Union[str, Sequence[str]] = ...,
    method: str = ...,
    names: Optional[Sequence[str]] = ...,
    fix: Optional[Sequence[Any]] = ...,
    **options: Any,
) -> Calibration: ...
def detect(
    image_or_path: Union[_Path, npt.NDArray[np.uint8]],  # (H, W) or (H, W, 3) BGR
    rows: int,
    cols: int,
) -> Tuple[npt.NDArray[np.float64], npt.NDArray[np.int64]]: ...  # (N, 2), (N,)
