"""Loads deformcal's exports with the real tools and projects points through them.

Usage: check_exports.py DIR CAMERA [CAMERA ...] < points.json
points.json: {"points": [[x, y, z], ...]} in each camera's own frame.
Prints JSON: per camera the OpenCV and mrcal projections (null where that export is
absent), the OpenCV distortion_model and coefficient count, OpenCV's R and T, mrcal's
lensmodel, rt_cam_ref and imagersize.  A camera whose yaml says
distortion_model "fisheye" is projected with cv2.fisheye.projectPoints, any other
with cv2.projectPoints, as an OpenCV user would.
"""
import json
import os
import sys

import cv2
import mrcal
import numpy as np


def opencv_entry(fs, p, points):
    if fs is None or fs.getNode(p + "camera_matrix").empty():
        return {"opencv": None}
    k = fs.getNode(p + "camera_matrix").mat()
    dist = fs.getNode(p + "distortion_coefficients").mat()
    model = fs.getNode(p + "distortion_model").string()
    if model == "fisheye":
        cv, _ = cv2.fisheye.projectPoints(points.reshape(-1, 1, 3), np.zeros(3), np.zeros(3), k, dist)
    else:
        cv, _ = cv2.projectPoints(points, np.zeros(3), np.zeros(3), k, dist)
    entry = {
        "opencv": cv.reshape(-1, 2).tolist(),
        "distortion_model": model,
        "coefficients": int(dist.size),
        "width": fs.getNode(p + "image_width").real(),
        "rms": fs.getNode(p + "avg_reprojection_error").real(),
    }
    if not fs.getNode(p + "R").empty():
        entry["R"] = fs.getNode(p + "R").mat().tolist()
        entry["T"] = fs.getNode(p + "T").mat().ravel().tolist()
    return entry


def mrcal_entry(path, points):
    if not os.path.exists(path):
        return {"mrcal": None}
    model = mrcal.cameramodel(path)
    lensmodel, intrinsics = model.intrinsics()
    return {
        "mrcal": mrcal.project(points, lensmodel, intrinsics).tolist(),
        "lensmodel": lensmodel,
        "rt_cam_ref": model.extrinsics_rt_fromref().tolist(),
        "imagersize": model.imagersize().tolist(),
    }


def main():
    folder, cameras = sys.argv[1], sys.argv[2:]
    points = np.array(json.load(sys.stdin)["points"], dtype=np.float64)
    yaml = folder + "/opencv.yaml"
    fs = cv2.FileStorage(yaml, cv2.FILE_STORAGE_READ) if os.path.exists(yaml) else None
    prefix = (lambda c: "") if len(cameras) == 1 else (lambda c: c + "_")
    out = {}
    for c in cameras:
        entry = opencv_entry(fs, prefix(c), points)
        entry.update(mrcal_entry(folder + "/" + c + ".cameramodel", points))
        out[c] = entry
    print(json.dumps(out))


if __name__ == "__main__":
    main()
