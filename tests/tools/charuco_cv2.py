"""OpenCV's ChArUco detection (cv2.aruco, OpenCV 4.6's API) on the test's images.

stdin: {"rows", "cols" (squares), "square", "marker" (metres), "dictionary"
(OpenCV's name), "images": [png paths]}. stdout: {"corners": [{id: [u, v]}
per image]} with OpenCV's ChArUco corner ids, and {"layout": {id: [x, y]}}, the
board's corner positions as OpenCV places them (origin at the outer corner).
"""
import json
import sys

import cv2

spec = json.load(sys.stdin)
aruco = cv2.aruco
dictionary = aruco.getPredefinedDictionary(getattr(aruco, spec["dictionary"]))
board = aruco.CharucoBoard_create(
    spec["cols"], spec["rows"], spec["square"], spec["marker"], dictionary
)
params = aruco.DetectorParameters_create()
out = []
for path in spec["images"]:
    img = cv2.imread(path, cv2.IMREAD_GRAYSCALE)
    corners, ids, _ = aruco.detectMarkers(img, dictionary, parameters=params)
    found = {}
    if ids is not None and len(ids) > 0:
        n, cc, cids = aruco.interpolateCornersCharuco(corners, ids, img, board)
        if n and cids is not None:
            for c, i in zip(cc.reshape(-1, 2), cids.reshape(-1)):
                found[str(int(i))] = [float(c[0]), float(c[1])]
    out.append(found)
layout = {
    str(i): [float(p[0]), float(p[1])] for i, p in enumerate(board.chessboardCorners)
}
json.dump({"corners": out, "layout": layout}, sys.stdout)
