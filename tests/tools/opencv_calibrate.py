"""Independent reference: OpenCV's calibrateCamera on a deformcal observations CSV.

Usage: opencv_calibrate.py OBSERVATIONS.csv ROWS COLS SPACING WIDTH HEIGHT
Prints JSON: fx fy cx cy k1 k2 k3 rms.  Board points follow SPEC 1 (origin at
the board centre, z = 0); the lens model is OpenCV's with p1 = p2 = 0.
"""
import csv
import json
import sys

import cv2
import numpy as np


def main():
    path, rows, cols, spacing, width, height = sys.argv[1:7]
    rows, cols, spacing = int(rows), int(cols), float(spacing)
    width, height = int(width), int(height)
    views = {}
    with open(path, newline="") as f:
        for r in csv.DictReader(f):
            views.setdefault(int(r["frame"]), []).append((int(r["corner"]), float(r["u"]), float(r["v"])))
    obj, img = [], []
    for frame in sorted(views):
        pts = sorted(views[frame])
        o = [((c % cols - (cols - 1) / 2) * spacing, (c // cols - (rows - 1) / 2) * spacing, 0.0) for c, _, _ in pts]
        obj.append(np.array(o, dtype=np.float32))
        img.append(np.array([(u, v) for _, u, v in pts], dtype=np.float32))
    flags = cv2.CALIB_ZERO_TANGENT_DIST
    criteria = (cv2.TERM_CRITERIA_COUNT + cv2.TERM_CRITERIA_EPS, 1000, 1e-16)
    rms, k, dist, _, _ = cv2.calibrateCamera(obj, img, (width, height), None, None, flags=flags, criteria=criteria)
    d = dist.ravel()
    print(json.dumps({"fx": k[0, 0], "fy": k[1, 1], "cx": k[0, 2], "cy": k[1, 2],
                      "k1": d[0], "k2": d[1], "k3": d[4], "rms": rms}))


if __name__ == "__main__":
    main()
