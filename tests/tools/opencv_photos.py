"""Independent reference on real photos: OpenCV's classic chessboard detector
(findChessboardCorners + cornerSubPix, as in OpenCV's calibration sample) and
calibrateCamera with its default model (k1 k2 p1 p2 k3 = deformcal's opencv5).

Usage: opencv_photos.py ROWS COLS SPACING IMAGE...
Prints JSON: {"found": [image names with a board], "corners": {name: [[u, v],
...] in OpenCV's order (row-major, 9 per row for 9×6)}, "fx", "fy", "cx", "cy",
"k1", "k2", "p1", "p2", "k3", "rms", "ms_per_image"} (calibration over the
images with a board; the timing is detection + refinement, one thread).
"""
import json
import os
import sys
import time

import cv2
import numpy as np


def main():
    rows, cols, spacing = int(sys.argv[1]), int(sys.argv[2]), float(sys.argv[3])
    cv2.setNumThreads(1)
    crit = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 30, 0.001)
    board = np.array([((c - (cols - 1) / 2) * spacing, (r - (rows - 1) / 2) * spacing, 0.0)
                      for r in range(rows) for c in range(cols)], np.float32)
    found, corners, obj, img, size, elapsed = [], {}, [], [], None, 0.0
    for path in sys.argv[4:]:
        gray = cv2.imread(path, cv2.IMREAD_GRAYSCALE)
        size = gray.shape[::-1]
        t = time.perf_counter()
        ok, c = cv2.findChessboardCorners(gray, (cols, rows),
                                          cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE)
        if ok:
            c = cv2.cornerSubPix(gray, c, (11, 11), (-1, -1), crit)
        elapsed += time.perf_counter() - t
        if ok:
            found.append(os.path.basename(path))
            corners[os.path.basename(path)] = c.reshape(-1, 2).tolist()
            obj.append(board)
            img.append(c)
    out = {"found": found, "corners": corners, "ms_per_image": 1e3 * elapsed / max(1, len(sys.argv) - 4)}
    if len(found) >= 3:
        criteria = (cv2.TERM_CRITERIA_COUNT + cv2.TERM_CRITERIA_EPS, 1000, 1e-15)
        rms, k, dist, _, _ = cv2.calibrateCamera(obj, img, size, None, None, criteria=criteria)
        d = dist.ravel()
        out.update({"fx": k[0, 0], "fy": k[1, 1], "cx": k[0, 2], "cy": k[1, 2], "k1": d[0],
                    "k2": d[1], "p1": d[2], "p2": d[3], "k3": d[4], "rms": rms})
    print(json.dumps(out))


if __name__ == "__main__":
    main()
