"""Independent reference: OpenCV's own calibration on a deformcal observations CSV.

Usage: opencv_calibrate.py OBSERVATIONS.csv ROWS COLS SPACING WIDTH HEIGHT [MODEL]
MODEL is deformcal's lens model name (default radial3) and picks the OpenCV call:
  radial3  calibrateCamera, CALIB_ZERO_TANGENT_DIST (p1 = p2 = 0)
  opencv5  calibrateCamera, default flags
  opencv8  calibrateCamera, CALIB_RATIONAL_MODEL
  kb4      fisheye.calibrate, CALIB_FIX_SKEW | CALIB_RECOMPUTE_EXTRINSIC
Prints JSON: the model's parameters under deformcal's names (fx fy cx cy k1 ...),
"rms" (OpenCV's per-point RMS) and "flags". Board points follow docs/conventions.md §1 (origin at the
board centre, z = 0).
"""
import csv
import json
import sys

import cv2
import numpy as np

# Parameter names of OpenCV's distortion vector, in OpenCV's order.
PINHOLE = {
    "radial3": (cv2.CALIB_ZERO_TANGENT_DIST, ["k1", "k2", "p1", "p2", "k3"], ["k1", "k2", "k3"]),
    "opencv5": (0, ["k1", "k2", "p1", "p2", "k3"], ["k1", "k2", "p1", "p2", "k3"]),
    "opencv8": (cv2.CALIB_RATIONAL_MODEL, ["k1", "k2", "p1", "p2", "k3", "k4", "k5", "k6"],
                ["k1", "k2", "p1", "p2", "k3", "k4", "k5", "k6"]),
}


def read_views(path, rows, cols, spacing):
    views = {}
    with open(path, newline="") as f:
        for r in csv.DictReader(f):
            views.setdefault(int(r["frame"]), []).append((int(r["corner"]), float(r["u"]), float(r["v"])))
    obj, img = [], []
    for frame in sorted(views):
        pts = sorted(views[frame])
        obj.append([((c % cols - (cols - 1) / 2) * spacing, (c // cols - (rows - 1) / 2) * spacing, 0.0)
                    for c, _, _ in pts])
        img.append([(u, v) for _, u, v in pts])
    return obj, img


def main():
    path, rows, cols, spacing, width, height = sys.argv[1:7]
    model = sys.argv[7] if len(sys.argv) > 7 else "radial3"
    rows, cols, spacing = int(rows), int(cols), float(spacing)
    width, height = int(width), int(height)
    obj, img = read_views(path, rows, cols, spacing)
    out = {}
    if model in PINHOLE:
        flags, names, keep = PINHOLE[model]
        # calibrateCamera takes float32 points; the caller's pixels are float32-exact.
        obj = [np.array(o, dtype=np.float32) for o in obj]
        img = [np.array(i, dtype=np.float32) for i in img]
        criteria = (cv2.TERM_CRITERIA_COUNT + cv2.TERM_CRITERIA_EPS, 1000, 1e-16)
        rms, k, dist, _, _ = cv2.calibrateCamera(obj, img, (width, height), None, None,
                                                 flags=flags, criteria=criteria)
        d = dist.ravel()
    elif model == "kb4":
        flags = cv2.fisheye.CALIB_FIX_SKEW | cv2.fisheye.CALIB_RECOMPUTE_EXTRINSIC
        names = keep = ["k1", "k2", "k3", "k4"]
        # cv2.fisheye wants (N, 1, 3) and (N, 1, 2) arrays, float64.
        obj = [np.array(o, dtype=np.float64).reshape(-1, 1, 3) for o in obj]
        img = [np.array(i, dtype=np.float64).reshape(-1, 1, 2) for i in img]
        # No initial guess: OpenCV starts from f = max(w, h) / pi and the image centre.
        criteria = (cv2.TERM_CRITERIA_COUNT + cv2.TERM_CRITERIA_EPS, 1000, 1e-16)
        rms, k, dist, _, _ = cv2.fisheye.calibrate(obj, img, (width, height), None, None,
                                                   flags=flags, criteria=criteria)
        d = dist.ravel()
    else:
        sys.exit(f"opencv_calibrate.py: OpenCV has no calibration for lens model {model!r}")
    out.update({"fx": k[0, 0], "fy": k[1, 1], "cx": k[0, 2], "cy": k[1, 2]})
    for i, n in enumerate(names):
        if n in keep:
            out[n] = float(d[i])
    out["skew"] = float(k[0, 1])
    out["rms"] = float(rms)
    out["flags"] = int(flags)
    print(json.dumps(out))


if __name__ == "__main__":
    main()
