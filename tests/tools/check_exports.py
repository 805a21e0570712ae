"""Loads deformcal's exports with the real tools and projects points through them.

Usage: check_exports.py DIR CAMERA [CAMERA ...] < points.json
points.json: {"points": [[x, y, z], ...]} in each camera's own frame.
Prints JSON: per camera the OpenCV and mrcal projections, OpenCV's R and T, mrcal's
rt_cam_ref and imagersize.
"""
import json
import sys

import cv2
import mrcal
import numpy as np


def main():
    folder, cameras = sys.argv[1], sys.argv[2:]
    points = np.array(json.load(sys.stdin)["points"], dtype=np.float64)
    fs = cv2.FileStorage(folder + "/opencv.yaml", cv2.FILE_STORAGE_READ)
    prefix = (lambda c: "") if len(cameras) == 1 else (lambda c: c + "_")
    out = {}
    for c in cameras:
        p = prefix(c)
        k = fs.getNode(p + "camera_matrix").mat()
        dist = fs.getNode(p + "distortion_coefficients").mat()
        cv, _ = cv2.projectPoints(points, np.zeros(3), np.zeros(3), k, dist)
        model = mrcal.cameramodel(folder + "/" + c + ".cameramodel")
        mr = mrcal.project(points, *model.intrinsics())
        entry = {
            "opencv": cv.reshape(-1, 2).tolist(),
            "mrcal": mr.tolist(),
            "rt_cam_ref": model.extrinsics_rt_fromref().tolist(),
            "imagersize": model.imagersize().tolist(),
            "width": fs.getNode(p + "image_width").real(),
            "rms": fs.getNode(p + "avg_reprojection_error").real(),
        }
        if len(cameras) > 1:
            entry["R"] = fs.getNode(p + "R").mat().tolist()
            entry["T"] = fs.getNode(p + "T").mat().ravel().tolist()
        out[c] = entry
    print(json.dumps(out))


if __name__ == "__main__":
    main()
