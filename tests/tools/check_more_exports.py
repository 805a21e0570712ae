"""Reads deformcal's ROS, Kalibr and COLMAP exports back as their consumers do and
projects points through them.

Usage: check_more_exports.py DIR < request.json
request.json: {"points": {"<camera>": [[x, y, z], ...]}} in each camera's frame.

Prints JSON with, per camera name present in the request:
- "ros": the camera_info yaml loaded with PyYAML (the loader ROS's
  camera_calibration_parsers uses), projected with cv2.projectPoints
  (plumb_bob, rational_polynomial) or cv2.fisheye.projectPoints (equidistant), as
  image_geometry does; plus its R, P, distortion_model; null when absent;
- "kalibr": the camchain camera whose comment names it, checked like Kalibr's
  ConfigReader (models, coefficient counts, floats) and projected with a
  reimplementation of aslam_cv's PinholeProjection + RadialTangentialDistortion /
  EquidistantDistortion and DoubleSphereProjection; plus T_cn_cnm1; null when absent;
- "colmap": cameras.txt projected by pycolmap (COLMAP itself) when it imports, and
  by a reimplementation of COLMAP's PINHOLE / OPENCV / FULL_OPENCV / OPENCV_FISHEYE models
  in any case, both shifted back by COLMAP's 0.5 px pixel-centre offset.
And "stereo_rectify": cv2.stereoRectify (CALIB_ZERO_DISPARITY, alpha=-1) on the
first two cameras of calibration.json, when there are exactly two pinhole-like ones.
"""
import json
import math
import os
import re
import sys

import cv2
import numpy as np
import yaml

try:
    import pycolmap
except ImportError:
    pycolmap = None


def ros_entry(path, points):
    if not os.path.exists(path):
        return None
    with open(path) as f:
        d = yaml.safe_load(f)
    k = np.array(d["camera_matrix"]["data"], dtype=np.float64).reshape(3, 3)
    dist = np.array(d["distortion_coefficients"]["data"], dtype=np.float64)
    assert d["distortion_coefficients"]["cols"] == dist.size
    model = d["distortion_model"]
    if model == "equidistant":
        uv, _ = cv2.fisheye.projectPoints(points.reshape(-1, 1, 3), np.zeros(3), np.zeros(3), k, dist)
    elif model in ("plumb_bob", "rational_polynomial"):
        uv, _ = cv2.projectPoints(points, np.zeros(3), np.zeros(3), k, dist)
    else:
        raise ValueError("unknown distortion_model " + model)
    return {
        "uv": uv.reshape(-1, 2).tolist(),
        "distortion_model": model,
        "coefficients": int(dist.size),
        "width": d["image_width"],
        "height": d["image_height"],
        "camera_name": d["camera_name"],
        "R": d["rectification_matrix"]["data"],
        "P": d["projection_matrix"]["data"],
    }


def kalibr_check(cam):
    """The checks of Kalibr's ConfigReader on one camera of a camchain."""
    n_intr = {"pinhole": 4, "ds": 6}[cam["camera_model"]]
    assert len(cam["intrinsics"]) == n_intr
    assert all(isinstance(v, float) for v in cam["intrinsics"])
    n_dist = {"radtan": 4, "equidistant": 4, "none": 0}[cam["distortion_model"]]
    assert len(cam["distortion_coeffs"]) == n_dist
    assert all(isinstance(v, int) for v in cam["resolution"])
    if cam["camera_model"] == "ds":
        assert 0 <= cam["intrinsics"][1] < 1, "Kalibr needs 0 <= alpha < 1"
    assert isinstance(cam["rostopic"], str)


def kalibr_project(cam, p):
    """aslam_cv's projections, formula by formula."""
    x, y, z = p
    if cam["camera_model"] == "ds":
        xi, alpha, fu, fv, cu, cv = cam["intrinsics"]
        r2 = x * x + y * y
        d1 = math.sqrt(r2 + z * z)
        k = xi * d1 + z
        d2 = math.sqrt(r2 + k * k)
        norm_inv = 1.0 / (alpha * d2 + (1 - alpha) * k)
        return [fu * (x * norm_inv) + cu, fv * (y * norm_inv) + cv]
    fu, fv, cu, cv = cam["intrinsics"]
    assert z > 0, "Kalibr's pinhole projection needs z > 0"
    rz = 1.0 / z
    m = [x * rz, y * rz]
    if cam["distortion_model"] == "radtan":
        k1, k2, p1, p2 = cam["distortion_coeffs"]
        mx2, my2, mxy = m[0] * m[0], m[1] * m[1], m[0] * m[1]
        rho2 = mx2 + my2
        rad = k1 * rho2 + k2 * rho2 * rho2
        m = [m[0] + m[0] * rad + 2.0 * p1 * mxy + p2 * (rho2 + 2.0 * mx2),
             m[1] + m[1] * rad + 2.0 * p2 * mxy + p1 * (rho2 + 2.0 * my2)]
    elif cam["distortion_model"] == "equidistant":
        k1, k2, k3, k4 = cam["distortion_coeffs"]
        r = math.sqrt(m[0] * m[0] + m[1] * m[1])
        th = math.atan(r)
        t2 = th * th
        t4 = t2 * t2
        thd = th * (1 + k1 * t2 + k2 * t4 + k3 * t4 * t2 + k4 * t4 * t4)
        s = thd / r if r > 1e-8 else 1.0
        m = [m[0] * s, m[1] * s]
    return [fu * m[0] + cu, fv * m[1] + cv]


def kalibr_entries(path):
    """camchain cameras by deformcal name (from the comments), in chain order."""
    if not os.path.exists(path):
        return {}
    text = open(path).read()
    chain = yaml.safe_load(text)
    assert all(re.fullmatch(r"cam\d+", k) for k in chain), "Kalibr counts every key as a camera"
    names = dict(re.findall(r"^# (cam\d+): deformcal camera `([^`]*)`", text, re.M))
    out = {}
    for key in sorted(chain, key=lambda k: int(k[3:])):
        cam = chain[key]
        kalibr_check(cam)
        if key != "cam0":
            assert np.array(cam["T_cn_cnm1"]).shape == (4, 4)
        out[names[key]] = (key, cam)
    return out


def colmap_reimpl(model, params, p):
    """COLMAP's ImgFromCam for the four models: normalise, distort, scale."""
    x, y, z = p
    u, v = x / z, y / z
    f1, f2, c1, c2 = params[:4]
    e = params[4:]
    if model == "PINHOLE":
        du = dv = 0.0
    elif model == "OPENCV_FISHEYE":
        k1, k2, k3, k4 = e
        r = math.sqrt(u * u + v * v)
        if r > np.finfo(np.float64).eps:
            th = math.atan(r)
            t2 = th * th
            t4 = t2 * t2
            thd = th * (1 + k1 * t2 + k2 * t4 + k3 * t2 * t4 + k4 * t4 * t4)
            du, dv = u * thd / r - u, v * thd / r - v
        else:
            du = dv = 0.0
    else:
        k1, k2, p1, p2 = e[:4]
        k3, k4, k5, k6 = e[4:] if model == "FULL_OPENCV" else (0.0, 0.0, 0.0, 0.0)
        u2, uv, v2 = u * u, u * v, v * v
        r2 = u2 + v2
        r4 = r2 * r2
        r6 = r4 * r2
        radial = (1 + k1 * r2 + k2 * r4 + k3 * r6) / (1 + k4 * r2 + k5 * r4 + k6 * r6)
        du = u * radial + 2 * p1 * uv + p2 * (r2 + 2 * u2) - u
        dv = v * radial + 2 * p2 * uv + p1 * (r2 + 2 * v2) - v
    return [f1 * (u + du) + c1, f2 * (v + dv) + c2]


def colmap_entries(path):
    if not os.path.exists(path):
        return {}
    text = open(path).read()
    names = dict(re.findall(r"^# camera (\d+): deformcal camera `([^`]*)`", text, re.M))
    out = {}
    for line in text.splitlines():
        if not line or line.startswith("#"):
            continue
        f = line.split()
        cam_id, model, w, h = int(f[0]), f[1], int(f[2]), int(f[3])
        params = [float(v) for v in f[4:]]
        out[names[str(cam_id)]] = (cam_id, model, w, h, params)
    return out


def colmap_entry(entry, points):
    cam_id, model, w, h, params = entry
    res = {"model": model, "width": w, "height": h, "params": params,
           "reimpl": [[c - 0.5 for c in colmap_reimpl(model, params, p)] for p in points]}
    if pycolmap is not None:
        cam = pycolmap.Camera(model=model, width=w, height=h, params=params)
        assert len(cam.params) == len(params), "pycolmap expects another parameter count"
        uv = cam.img_from_cam(np.asarray(points, dtype=np.float64))
        res["pycolmap"] = (np.asarray(uv) - 0.5).tolist()
    return res


def rectify_entry(folder):
    calib = json.load(open(folder + "/calibration.json"))
    cams = calib["cameras"]
    keys = {"radial3": ["k1", "k2", "p1", "p2", "k3"], "opencv5": ["k1", "k2", "p1", "p2", "k3"],
            "opencv8": ["k1", "k2", "p1", "p2", "k3", "k4", "k5", "k6"],
            "pinhole": ["k1", "k2", "p1", "p2", "k3"]}
    if len(cams) != 2 or any(c["model"] not in keys for c in cams):
        return None
    km, ds = [], []
    for c in cams:
        i = c["intrinsics"]
        km.append(np.array([[i["fx"], 0, i["cx"]], [0, i["fy"], i["cy"]], [0, 0, 1]], dtype=np.float64))
        ds.append(np.array([i.get(k, 0.0) for k in keys[c["model"]]], dtype=np.float64))
    r, _ = cv2.Rodrigues(np.array(cams[1]["rotation"], dtype=np.float64))
    t = np.array(cams[1]["translation"], dtype=np.float64)
    size = (cams[0]["width"], cams[0]["height"])
    r1, r2, p1, p2, _, _, _ = cv2.stereoRectify(km[0], ds[0], km[1], ds[1], size, r, t,
                                                flags=cv2.CALIB_ZERO_DISPARITY, alpha=-1)
    return {"R1": r1.ravel().tolist(), "R2": r2.ravel().tolist(),
            "P1": p1.ravel().tolist(), "P2": p2.ravel().tolist()}


def main():
    folder = sys.argv[1]
    request = json.load(sys.stdin)
    kalibr = kalibr_entries(folder + "/camchain.yaml")
    colmap = colmap_entries(folder + "/cameras.txt")
    out = {"cameras": {}, "pycolmap": pycolmap is not None,
           "stereo_rectify": rectify_entry(folder)}
    for name, pts in request["points"].items():
        points = np.array(pts, dtype=np.float64)
        e = {"ros": ros_entry(folder + "/" + name + "_camera_info.yaml", points)}
        if name in kalibr:
            key, cam = kalibr[name]
            e["kalibr"] = {"key": key, "camera_model": cam["camera_model"],
                           "distortion_model": cam["distortion_model"],
                           "T_cn_cnm1": cam.get("T_cn_cnm1"),
                           "uv": [kalibr_project(cam, p) for p in points.tolist()]}
        else:
            e["kalibr"] = None
        e["colmap"] = colmap_entry(colmap[name], points.tolist()) if name in colmap else None
        out["cameras"][name] = e
    print(json.dumps(out))


if __name__ == "__main__":
    main()
