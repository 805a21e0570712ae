"""OpenCV's ChArUco detection (cv2.aruco, OpenCV 4.6's API) on the test's images.

stdin: {"rows", "cols" (squares), "square", "marker" (metres), "dictionary"
(OpenCV's name), "images": [png paths]}. stdout: {"corners": [{id: [u, v]}
per image]} with OpenCV's ChArUco corner ids, and {"layout": {id: [x, y]}}, the
board's corner positions as OpenCV places them (origin at the outer corner),
and "ms_per_image", the detection's time per image (reading excluded).

OpenCV 4.6's interpolateCornersCharuco returns its corners shifted by (+0.5,
+0.5) px from the junctions (measured on a fronto-parallel board drawn by
OpenCV itself: 0.707 px RMS, mean offset (0.499, 0.501); one cornerSubPix
pass on the same corners: 0.018 px, mean offset 0.002). The corners are
therefore refined once more with cv2.cornerSubPix, as OpenCV's ChArUco
tutorials do, in a window kept clear of the markers, so that the comparison
charges OpenCV with its detector's accuracy and not with that shift.
"""
import json
import sys
import time

import cv2
import numpy as np

spec = json.load(sys.stdin)
# One thread, as benches/detect.rs compares it with ours.
cv2.setNumThreads(1)
aruco = cv2.aruco
dictionary = aruco.getPredefinedDictionary(getattr(aruco, spec["dictionary"]))
board = aruco.CharucoBoard_create(
    spec["cols"], spec["rows"], spec["square"], spec["marker"], dictionary
)
params = aruco.DetectorParameters_create()


def refine(img, markers, cc):
    """cornerSubPix in a window that stays inside the white gap between a
    corner and its markers: (square - marker) / 2 of a square, measured in
    pixels from the markers' median side."""
    sides = [
        np.linalg.norm(m.reshape(4, 2)[k] - m.reshape(4, 2)[(k + 1) % 4])
        for m in markers
        for k in range(4)
    ]
    square_px = float(np.median(sides)) * spec["square"] / spec["marker"]
    gap_px = 0.5 * (spec["square"] - spec["marker"]) / spec["square"] * square_px
    half = int(min(5, max(1, np.floor(0.8 * gap_px))))
    crit = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 100, 0.001)
    cc = cc.astype(np.float32).copy()
    cv2.cornerSubPix(img, cc, (half, half), (-1, -1), crit)
    return cc


images = [cv2.imread(path, cv2.IMREAD_GRAYSCALE) for path in spec["images"]]
out = []
start = time.perf_counter()
for img in images:
    corners, ids, _ = aruco.detectMarkers(img, dictionary, parameters=params)
    found = {}
    if ids is not None and len(ids) > 0:
        n, cc, cids = aruco.interpolateCornersCharuco(corners, ids, img, board)
        if n and cids is not None:
            cc = refine(img, corners, cc)
            for c, i in zip(cc.reshape(-1, 2), cids.reshape(-1)):
                found[str(int(i))] = [float(c[0]), float(c[1])]
    out.append(found)
layout = {
    str(i): [float(p[0]), float(p[1])] for i, p in enumerate(board.chessboardCorners)
}
# Detection alone (reading the images excluded), for benches/detect.rs.
seconds = time.perf_counter() - start
json.dump(
    {"corners": out, "layout": layout, "ms_per_image": 1e3 * seconds / max(1, len(images))},
    sys.stdout,
)
