"""``calibrate_camera`` and ``calibrate_rig``: OpenCV's inputs in, the command
line's calibration out. The arrays are checked and the board inferred here
(``_arrays``); the options become the config's ``[calibration]`` keys and the
calibration runs in the library exactly as ``deformcal calibrate`` runs it."""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np

from . import _arrays, _deformcal
from ._camera import Camera, _rotation_matrix
from ._errors import CalibrationFailed, InputError


class Calibration:
    """The result of ``calibrate_camera`` / ``calibrate_rig``.

    Attributes, as OpenCV returns them where OpenCV has them:

    - ``rms``: the RMS reprojection error, px (``calibration.json``'s ``rmse_px``).
    - ``K`` (3, 3) and ``dist`` (OpenCV's order and shape for the model) of the
      first camera; every camera in ``cameras`` (``Camera`` objects).
    - ``rvecs``, ``tvecs``: per view, (3, 1) float64 each, the board's pose in
      the first camera in the object points' own frame (``None`` for a view the
      calibration could not use).
    - ``bends``: per view, the board's bend (``{"a", "b", "c"}`` of the
      paraboloid z = a x² + b y² + c x y in metres, plus ``higher_bend`` and
      ``max_out_of_plane_m`` where the method has them), or ``None``.
    - ``static_correction``: (rows·cols, 3) metres, each corner's fixed offset
      from the ideal board (``static`` and ``full``), or ``None``.
    - ``uncertainty``: the noise, bias ratio and G-AIC, and per camera the σ of
      each lens parameter and the expected mapping error (px).
    - ``method`` and ``method_reason``: the method that ran and why.
    - ``board``: the board inferred from the object points (rows, cols, spacing,
      origin); corner id ``row * cols + col``.
    - ``warnings``, ``converged``, ``json`` (calibration.json as a dict).
    """

    def __init__(self, native, board: _arrays.Board, frames: int):
        self._native = native
        self.json: dict = json.loads(native.json())
        self.board = board
        self.cameras = [Camera(self.json, k) for k in range(len(self.json["cameras"]))]
        self.rms: float = float(self.json["rmse_px"])
        self.method: str = self.json["method"]
        reason = native.reason()
        self.method_reason: str = reason or f'method "{self.method}" was asked for'
        self.warnings: list = list(self.json.get("warnings", []))
        self.converged: bool = bool(self.json["converged"])
        by_frame = {f["frame"]: f for f in self.json["frames"]}
        self._frames = [by_frame.get(i) for i in range(frames)]

    def __repr__(self) -> str:
        return f"Calibration(method={self.method!r}, rms={self.rms:.4f} px, cameras={self.cameras})"

    @property
    def K(self) -> np.ndarray:
        return self.cameras[0].K

    @property
    def dist(self):
        return self.cameras[0].dist

    @property
    def camera(self) -> Camera:
        """The first camera."""
        return self.cameras[0]

    def _pose(self, f):
        """A frame's (rvec, tvec) in the object points' frame: deformcal's board
        frame has its origin at the board centre."""
        if f is None:
            return None, None
        r = np.asarray(f["rotation"], dtype=np.float64)
        t = np.asarray(f["translation"], dtype=np.float64)
        t = t - _rotation_matrix(r) @ self.board.centre
        return r.reshape(3, 1), t.reshape(3, 1)

    @property
    def rvecs(self) -> tuple:
        return tuple(self._pose(f)[0] for f in self._frames)

    @property
    def tvecs(self) -> tuple:
        return tuple(self._pose(f)[1] for f in self._frames)

    @property
    def bends(self) -> list:
        out = []
        for f in self._frames:
            if f is None or f.get("deformation") is None:
                out.append(None)
                continue
            bend = dict(f["deformation"])
            for key in ("higher_bend", "max_out_of_plane_m"):
                if f.get(key) is not None:
                    bend[key] = f[key]
            out.append(bend)
        return out

    @property
    def static_correction(self):
        c = self.json.get("static_correction")
        return None if c is None else np.asarray(c, dtype=np.float64)

    @property
    def uncertainty(self) -> dict:
        keys = ("noise_px", "noise_source", "bias_ratio", "g_aic", "parameters", "uncertainty_note")
        out = {k: self.json[k] for k in keys if self.json.get(k) is not None}
        out["cameras"] = {c.name: c.uncertainty for c in self.cameras}
        return out

    def save(self, directory) -> Path:
        """Writes the command line's files (calibration.json, the exports,
        outliers.csv, board.json, the uncertainty maps, report.html) into
        ``directory`` as one set, replacing a previous calibration's; returns
        the path of calibration.json. Warnings of exports a lens model could not
        be written to are added to ``warnings``."""
        directory = Path(os.fspath(directory))
        for w in self._native.save(directory):
            if w not in self.warnings:
                self.warnings.append(w)
        failed = self._native.failure() is not None
        return directory / ("FAILED-calibration.json" if failed else "calibration.json")


def _per_camera(value, n: int, what: str) -> list:
    if isinstance(value, (list, tuple)) and not isinstance(value, str):
        if len(value) != n:
            raise InputError(f"{what}: {len(value)} given for {n} cameras")
        return list(value)
    return [value] * n


def calibrate_rig(
    object_points,
    image_points,
    image_sizes,
    *,
    models="opencv5",
    method="auto",
    names=None,
    fix=None,
    **options,
) -> Calibration:
    """Calibrates several cameras that see the board at the same time steps.

    ``object_points[k][i]`` (N, 3) and ``image_points[k][i]`` (N, 2) are camera
    k's view of time step i (``None`` in both where camera k did not see the
    board); every camera has one entry per time step. ``image_sizes[k]`` is
    (width, height). ``models``, ``names`` and ``fix`` (lens parameters held at
    their start) are one value for every camera or a list per camera.
    ``method`` and ``**options`` are the config's ``[calibration]`` keys. See
    ``calibrate_camera`` for the arrays and the result.
    """
    obj = _arrays._view_list(object_points, "object_points")
    img = _arrays._view_list(image_points, "image_points")
    sizes = list(image_sizes)
    n = len(obj)
    if n == 0 or len(img) != n or len(sizes) != n:
        raise InputError(
            f"object_points, image_points and image_sizes need one entry per camera "
            f"(got {len(obj)}, {len(img)} and {len(sizes)})"
        )
    per_camera = [_arrays.views(obj[k], img[k], f"camera {k}: " if n > 1 else "") for k in range(n)]
    frames = len(per_camera[0])
    if any(len(v) != frames for v in per_camera):
        raise InputError(
            "every camera needs one entry per time step (None where it did not see "
            f"the board); got {[len(v) for v in per_camera]}"
        )
    flat = [v[0] if v else None for cam in per_camera for v in cam]
    single = any(v[2] for cam in per_camera for v in cam if v)
    board, flat_ids = _arrays.infer_board(flat, single)
    models = _per_camera(models, n, "models")
    names = names if names is not None else (["cam0"] if n == 1 else [f"cam{k}" for k in range(n)])
    names = _per_camera(names, n, "names")
    if fix is None or all(isinstance(p, str) for p in fix):
        fixes = [list(fix or [])] * n
    else:
        fixes = _per_camera(fix, n, "fix")
    cameras = []
    for k in range(n):
        w, h = _arrays.image_size(sizes[k], f"image_sizes[{k}]" if n > 1 else "image_size")
        cameras.append((str(names[k]), w, h, str(models[k]), [str(p) for p in fixes[k]]))
    views = []
    for k in range(n):
        for i in range(frames):
            ids = flat_ids[k * frames + i]
            if ids is not None:
                views.append((k, i, ids, per_camera[k][i][1]))
    options = {"method": method, **options}
    native = _deformcal.calibrate(views, (board.rows, board.cols, board.spacing), cameras, options)
    result = Calibration(native, board, frames)
    failure = native.failure()
    if failure is not None:
        reasons, hints = failure
        raise CalibrationFailed(
            "the calibration FAILED: " + "; ".join(reasons)
            + "".join(f"\nhint: {h}" for h in hints),
            reasons,
            hints,
            result,
        )
    return result


def calibrate_camera(
    object_points,
    image_points,
    image_size,
    *,
    model="opencv5",
    method="auto",
    name="cam0",
    fix=(),
    **options,
) -> Calibration:
    """Calibrates one camera from what ``cv2.calibrateCamera`` takes.

    ``object_points``: one array per view, (N, 3) or (N, 1, 3), float32 or
    float64: the board's corners on z = 0, a square grid (its spacing, in metres,
    and each corner's identity are inferred; views may show part of the board).
    ``image_points``: one array per view, (N, 2) or (N, 1, 2), the same corners
    in pixels. ``image_size``: (width, height).

    ``model``: radial3, opencv5 (OpenCV's default), opencv8 (OpenCV's
    ``CALIB_RATIONAL_MODEL``), kb4 (``cv2.fisheye``) or ds. ``method``:
    standard (OpenCV's rigid board), static, dynamic, full or auto (chosen by
    cross-validation). ``fix``: lens parameters held at their start (OpenCV's
    ``CALIB_FIX_*``). ``**options``: any ``[calibration]`` key of the config
    file with the same name and checks (``loss="none"``, ``outlier_k=0``,
    ``priors``, ``threads``, …); an unknown key raises ``OptionError``.

    Returns a ``Calibration``; raises a ``deformcal.Error`` subclass on bad
    input (``InputError``), data that cannot support the calibration
    (``DataError``), a failed solve (``SolverError``) or a result that fails
    the guard rails (``CalibrationFailed``). The GIL is released while it runs.
    """
    return calibrate_rig(
        [object_points],
        [image_points],
        [image_size],
        models=[model],
        method=method,
        names=[name],
        fix=[list(fix)],
        **options,
    )
