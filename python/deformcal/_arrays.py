"""Input arrays as OpenCV takes them, checked and normalised; the board and each
corner's identity inferred from the object points.

Everything here is about the caller's arrays (shapes, dtypes, finiteness, the
grid they lie on); no calibration step is done in Python.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ._errors import InputError

#: Out-of-plane tolerance of object points, relative to the board's extent:
#: well above float32 rounding (6e-8), far below any real non-planar rig.
PLANAR_TOLERANCE = 1e-5
#: Largest distance of an object point from its grid position, in spacings:
#: float32 rounding is 1e-7 of it, a point on the wrong corner 0.5 or more.
GRID_TOLERANCE = 0.05


def _points(a, dims: int, what: str) -> np.ndarray:
    """One view's (N, dims) or (N, 1, dims) float32/float64 array as (N, dims) float64."""
    if not isinstance(a, np.ndarray):
        raise InputError(
            f"{what}: expected a numpy array of shape (N, {dims}) or (N, 1, {dims}), "
            f"got {type(a).__name__}"
        )
    if a.dtype not in (np.float32, np.float64):
        raise InputError(
            f"{what}: dtype {a.dtype}; expected float32 or float64 (as OpenCV), "
            f"e.g. {what.split('[')[0]}[i].astype(np.float64)"
        )
    if a.ndim == 3 and a.shape[1] == 1 and a.shape[2] == dims:
        a = a[:, 0, :]
    elif not (a.ndim == 2 and a.shape[1] == dims):
        raise InputError(
            f"{what}: shape {a.shape}; expected (N, {dims}) or (N, 1, {dims})"
        )
    if a.shape[0] == 0:
        raise InputError(f"{what}: no points")
    finite = np.isfinite(a).all(axis=1)
    if not finite.all():
        row = int(np.argmin(finite))
        raise InputError(f"{what}: point {row} is not finite ({a[row].tolist()})")
    return np.ascontiguousarray(a, dtype=np.float64)


def _view_list(a, what: str) -> list:
    """A list of per-view arrays (a list, a tuple, or a (V, N, d) array)."""
    if isinstance(a, np.ndarray):
        if a.ndim == 3 and a.shape[1] > 1:
            return list(a)
        raise InputError(
            f"{what}: expected a list with one array per view (as cv2.calibrateCamera "
            f"takes), got one array of shape {a.shape}"
        )
    if not isinstance(a, (list, tuple)):
        raise InputError(
            f"{what}: expected a list with one array per view, got {type(a).__name__}"
        )
    return list(a)


def views(object_points, image_points, what: str = "") -> list:
    """Pairs (object (N, 3), image (N, 2)) per view, float64; ``None`` for a view
    given as ``None`` in both lists (a camera of a rig that did not see the board).
    An object-point array of float32 is marked by a third element, True."""
    obj = _view_list(object_points, f"{what}object_points")
    img = _view_list(image_points, f"{what}image_points")
    if len(obj) != len(img):
        raise InputError(
            f"{what}object_points has {len(obj)} views but {what}image_points has {len(img)}"
        )
    out = []
    for i, (o, p) in enumerate(zip(obj, img)):
        if o is None and p is None:
            out.append(None)
            continue
        single = isinstance(o, np.ndarray) and o.dtype == np.float32
        o = _points(o, 3, f"{what}object_points[{i}]")
        p = _points(p, 2, f"{what}image_points[{i}]")
        if len(o) != len(p):
            raise InputError(
                f"{what}view {i}: {len(o)} object points but {len(p)} image points"
            )
        out.append((o, p, single))
    return out


@dataclass(frozen=True)
class Board:
    """The chessboard the object points describe: ``rows`` × ``cols`` inner
    corners ``spacing`` apart (the object points' unit, metres for deformcal),
    corner ``row * cols + col`` at ``origin + (col, row, 0) * spacing``."""

    rows: int
    cols: int
    spacing: float
    origin: np.ndarray

    @property
    def centre(self) -> np.ndarray:
        """The board centre in object-point coordinates: deformcal's board origin."""
        return self.origin + np.array(
            [(self.cols - 1) / 2 * self.spacing, (self.rows - 1) / 2 * self.spacing, 0.0]
        )


def _nearest_distances(xy: np.ndarray) -> np.ndarray:
    """Each point's distance to its nearest other point (in blocks: O(N) memory per row)."""
    out = np.empty(len(xy))
    for start in range(0, len(xy), 512):
        block = xy[start : start + 512]
        d = np.sqrt(((block[:, None, :] - xy[None, :, :]) ** 2).sum(axis=2))
        for k in range(len(block)):
            d[k, start + k] = np.inf
        out[start : start + len(block)] = d.min(axis=1)
    return out


def _written_spacing(xy, grid, spacing: float, single: bool):
    """The spacing (and origin) the user wrote, where the points show it: the
    shortest decimal whose grid reproduces every point to the rounding of the
    points' dtype (float32's 0.03 is 0.029999999329…, and a least-squares fit
    through float32 roundings lands a float32 step away). ``None`` if none does."""
    dtype = np.float32 if single else np.float64
    # Each point's own rounding, plus that of the board's largest coordinate (the
    # median origin carries the other points' rounding into a point at zero).
    tol = 4.0 * np.spacing(np.abs(xy).astype(dtype)).astype(np.float64)
    tol += 4.0 * float(np.spacing(dtype(np.abs(xy).max())))
    for digits in range(1, 18):
        candidate = float(f"{spacing:.{digits}g}")
        if not candidate > 0.0:
            continue
        origin = np.median(xy - grid * candidate, axis=0)
        slack = tol + 4.0 * np.spacing(np.abs(origin).astype(dtype)).astype(np.float64)
        if np.all(np.abs(xy - origin - grid * candidate) <= slack):
            return candidate, origin
    return None


def infer_board(object_views: list, single: bool = False) -> tuple[Board, list]:
    """The board and each view's corner ids from the object points of every view
    (``None`` views skipped). The points must lie on z = 0 (as OpenCV requires
    without an initial camera matrix) on a square grid aligned with x and y.
    ``single``: some points were float32, whose rounding the spacing drops."""
    given = [(i, o) for i, o in enumerate(object_views) if o is not None]
    if not given:
        raise InputError("no views: object_points is empty")
    pts = np.concatenate([o for _, o in given])
    extent = max(float(np.abs(pts[:, :2]).max()), float(np.ptp(pts[:, :2], axis=0).max()))
    if extent == 0.0:
        raise InputError("object points: every point is at the origin")
    for i, o in given:
        far = np.abs(o[:, 2]) > PLANAR_TOLERANCE * extent
        if far.any():
            j = int(np.argmax(far))
            raise InputError(
                f"object_points[{i}]: point {j} has z = {o[j, 2]:g}: the object is not a "
                "planar board at z = 0 (deformcal calibrates with a chessboard, and "
                "cv2.calibrateCamera also needs z = 0 without an initial camera matrix)"
            )
    nearest = np.concatenate([_nearest_distances(o[:, :2]) for _, o in given if len(o) > 1])
    if len(nearest) == 0:
        raise InputError("object points: every view has a single point; no grid to infer")
    guess = float(np.median(nearest))
    if not guess > 0.0:
        raise InputError("object points: a view lists the same point twice")
    xy = pts[:, :2]
    grid = np.rint((xy - xy.min(axis=0)) / guess)
    rel = xy - xy.min(axis=0)
    spacing = float((grid * rel).sum() / (grid * grid).sum())
    origin = (xy - grid * spacing).mean(axis=0)
    written = _written_spacing(xy, grid, spacing, single)
    if written is not None:
        spacing, origin = written
    off = np.abs(xy - origin - grid * spacing).max(axis=1)
    if off.max() > GRID_TOLERANCE * spacing:
        k = int(np.argmax(off))
        raise InputError(
            f"object points: point {pts[k].tolist()} is {off[k] / spacing:.2f} spacings off "
            f"the square grid of spacing {spacing:g} that the others lie on (a chessboard's "
            "corners, aligned with x and y, are expected)"
        )
    cols = int(grid[:, 0].max()) + 1
    rows = int(grid[:, 1].max()) + 1
    ids = []
    start = 0
    for i, o in enumerate(object_views):
        if o is None:
            ids.append(None)
            continue
        g = grid[start : start + len(o)].astype(np.int64)
        start += len(o)
        view_ids = g[:, 1] * cols + g[:, 0]
        unique, counts = np.unique(view_ids, return_counts=True)
        if (counts > 1).any():
            twice = int(unique[np.argmax(counts > 1)])
            raise InputError(
                f"object_points[{i}]: corner (row {twice // cols}, col {twice % cols}) is "
                "listed twice"
            )
        ids.append(view_ids)
    board = Board(rows, cols, spacing, np.array([origin[0], origin[1], 0.0]))
    return board, ids


def image_size(size, what: str = "image_size") -> tuple[int, int]:
    """OpenCV's (width, height) as two positive ints."""
    try:
        w, h = (int(v) for v in size)
        ok = all(float(v) == int(v) for v in size)
    except (TypeError, ValueError):
        ok = False
    if not ok or w <= 0 or h <= 0:
        raise InputError(f"{what}: expected (width, height) in pixels as OpenCV, got {size!r}")
    return w, h
