#!/usr/bin/python3
"""Side-by-side benchmark: deformcal against OpenCV and mrcal (Debian's python3-opencv
and python3-mrcal) on identical 25-image subsets of the built-in t2 preset.

    cargo build --release && bench/compare.py [--subsets 10] [--repeats 3]

For every subset it times deformcal's four methods and `auto` (and `standard` without the
robust loss, which must reproduce calibrateCamera's intrinsics), OpenCV's calibrateCamera
(k1, k2, k3) and calibrateCameraRO (Strobl's static method), and mrcal's optimiser
without and with its board warp (seeding included), then prints each tool's median
wall time, its ratio to calibrateCamera, and its mapping error to the true
intrinsics (20 px grid, SPEC 3), so speed and accuracy are read together.
deformcal's time is the calibration itself (initialisation included), as reported
in calibration.json; the others are timed around the library call.
"""
import argparse
import csv
import json
import os
import random
import statistics
import subprocess
import sys
import tempfile
import time

import cv2
import mrcal
import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def load(folder):
    views = {}
    with open(os.path.join(folder, "observations.csv"), newline="") as f:
        for r in csv.DictReader(f):
            # calibrateCamera takes float32 pixels: every tool gets the same rounded values.
            u, v = (float(np.float32(r[k])) for k in ("u", "v"))
            views.setdefault(int(r["frame"]), {})[int(r["corner"])] = (u, v)
    with open(os.path.join(folder, "truth.json")) as f:
        truth = json.load(f)
    return views, truth


def grid(width, height, step=20):
    u, v = np.meshgrid(np.arange(0, width, step, dtype=np.float64), np.arange(0, height, step, dtype=np.float64))
    return np.stack([u.ravel(), v.ravel()], axis=1)


def as_opencv(k):
    """A radial3 intrinsics dict as OpenCV's camera matrix and distortion vector."""
    K = np.array([[k["fx"], 0, k["cx"]], [0, k["fy"], k["cy"]], [0, 0, 1.0]])
    return K, np.array([k["k1"], k["k2"], 0, 0, k["k3"]])


def truth_rays(k, width, height):
    """Normalised rays of a 20 px pixel grid under the radial3 intrinsics k."""
    px = grid(width, height)
    K, dist = as_opencv(k)
    crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-14)
    n = cv2.undistortPointsIter(px.reshape(-1, 1, 2), K, dist, None, None, crit).reshape(-1, 2)
    return px, np.concatenate([n, np.ones((len(n), 1))], axis=1)


def opencv_intrinsics(K, dist):
    """OpenCV's camera matrix and distortion as the radial3 dict truth.json uses."""
    d = np.ravel(dist)
    return dict(fx=K[0, 0], fy=K[1, 1], cx=K[0, 2], cy=K[1, 2], k1=d[0], k2=d[1], k3=d[4])


def mapping_error_opencv(px, rays, K, dist):
    p, _ = cv2.projectPoints(rays, np.zeros(3), np.zeros(3), K, dist)
    return float(np.sqrt(np.mean(np.sum((p.reshape(-1, 2) - px) ** 2, axis=1))))


def mapping_error_mrcal(px, rays, lensmodel, intrinsics):
    p = mrcal.project(rays, lensmodel, intrinsics)
    return float(np.sqrt(np.mean(np.sum((p - px) ** 2, axis=1))))


# --whole-process: time the whole deformcal process (start, reading, calibration,
# covariance, every output file) instead of the calibration call.
WHOLE_PROCESS = False

TIGHT = "function_tolerance = 1e-15\nparameter_tolerance = 1e-15\ngradient_tolerance = 1e-15\nmax_iterations = 500\n"


def run_deformcal(binary, folder, method, rows, cols, spacing, width, height, loss="cauchy", extra=""):
    cfg = os.path.join(folder, "c.toml")
    with open(cfg, "w") as f:
        f.write(f"[target]\nrows = {rows}\ncols = {cols}\nspacing = {spacing}\n")
        f.write(f'[[cameras]]\nname = "cam0"\nwidth = {width}\nheight = {height}\n')
        f.write('[data]\nobservations = "subset.csv"\n[output]\ndir = "out"\n')
        f.write(f'[calibration]\nloss = "{loss}"\n{extra}')
    start = time.perf_counter()
    subprocess.run([binary, "--config", cfg, "--method", method], check=True, stdout=subprocess.DEVNULL)
    process = time.perf_counter() - start
    with open(os.path.join(folder, "out", "calibration.json")) as f:
        j = json.load(f)
    return (process if WHOLE_PROCESS else j["seconds"]), j["cameras"][0]["intrinsics"]


def run_mrcal(obs, width, height, spacing, warp):
    """mrcal's own recipe: stereographic seed, the core first, then everything."""
    start = time.perf_counter()
    n = len(obs)
    indices_fc = np.array([[i, 0] for i in range(n)], dtype=np.int32)
    intr, extr, frames = mrcal.seed_stereographic(imagersizes=np.array([[width, height]]), focal_estimate=2900.0,
                                                  indices_frame_camera=indices_fc, observations=obs, object_spacing=spacing)
    intrinsics = np.zeros((1, 9))
    intrinsics[:, :4] = intr
    inputs = dict(
        intrinsics=intrinsics, extrinsics_rt_fromref=np.zeros((0, 6)), frames_rt_toref=frames, points=None,
        observations_board=obs, indices_frame_camintrinsics_camextrinsics=np.array([[i, 0, -1] for i in range(n)], dtype=np.int32),
        observations_point=None, indices_point_camintrinsics_camextrinsics=None, lensmodel="LENSMODEL_OPENCV5",
        imagersizes=np.array([[width, height]], dtype=np.int32), calobject_warp=np.zeros(2) if warp else None,
        do_optimize_intrinsics_core=True, do_optimize_intrinsics_distortions=False, do_optimize_extrinsics=False,
        do_optimize_frames=True, do_optimize_calobject_warp=False, calibration_object_spacing=spacing,
        do_apply_outlier_rejection=False, do_apply_regularization=True, verbose=False)
    mrcal.optimize(**inputs)
    inputs["do_optimize_intrinsics_distortions"] = True
    inputs["do_optimize_calobject_warp"] = warp
    stats = mrcal.optimize(**inputs)
    if os.environ.get("BENCH_DEBUG"):
        print("mrcal rms", stats["rms_reproj_error__pixels"], inputs["intrinsics"][0], file=sys.stderr)
    return time.perf_counter() - start, inputs["intrinsics"][0]


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--subsets", type=int, default=10)
    ap.add_argument("--images", type=int, default=25)
    ap.add_argument("--repeats", type=int, default=3, help="timed runs per subset and tool (median taken)")
    ap.add_argument("--seed", type=int, default=7)
    ap.add_argument("--skip-ro", action="store_true", help="skip calibrateCameraRO (about 13 s per subset)")
    ap.add_argument("--deformcal", default=os.path.join(ROOT, "target", "release", "deformcal"))
    ap.add_argument("--whole-process", action="store_true", help="time the whole deformcal process, not its calibration call")
    a = ap.parse_args()
    global WHOLE_PROCESS
    WHOLE_PROCESS = a.whole_process
    if not os.path.exists(a.deformcal):
        sys.exit(f"{a.deformcal} not found: run cargo build --release first")
    work = tempfile.mkdtemp(prefix="deformcal-bench-")
    subprocess.run([a.deformcal, "generate", "--preset", "t2", "--seed", str(a.seed), "--out", work], check=True, stdout=subprocess.DEVNULL)
    views, truth = load(work)
    t = truth["target"]
    rows, cols, spacing = t["rows"], t["cols"], t["spacing"]
    width, height = 1936, 1216
    ncorners = rows * cols
    # calibrateCameraRO needs every corner in every view: use the complete views.
    complete = sorted(f for f, v in views.items() if len(v) == ncorners)
    rng = random.Random(a.seed)
    subsets = [sorted(rng.sample(complete, a.images)) for _ in range(a.subsets)]
    px, rays = truth_rays(truth["intrinsics"][0], width, height)
    board = np.array([((c % cols - (cols - 1) / 2) * spacing, (c // cols - (rows - 1) / 2) * spacing, 0.0) for c in range(ncorners)], dtype=np.float32)
    times, errors = {}, {}
    agreement, agreement_tight = [], []

    def record(name, seconds, error):
        times.setdefault(name, []).append(seconds)
        errors.setdefault(name, []).append(error)

    for si, frames in enumerate(subsets):
        folder = os.path.join(work, f"s{si}")
        os.makedirs(folder, exist_ok=True)
        with open(os.path.join(folder, "subset.csv"), "w") as f:
            f.write("camera,frame,corner,u,v\n")
            for fr in frames:
                for c in range(ncorners):
                    u, v = views[fr][c]
                    f.write(f"cam0,{fr},{c},{u!r},{v!r}\n")
        for m, loss in [("standard", "cauchy"), ("standard", "none"), ("static", "cauchy"), ("dynamic", "cauchy"), ("full", "cauchy"), ("auto", "cauchy")]:
            runs = [run_deformcal(a.deformcal, folder, m, rows, cols, spacing, width, height, loss) for _ in range(a.repeats)]
            k = runs[-1][1]
            name = f"deformcal {m}" + (", no loss" if loss == "none" else "")
            record(name, statistics.median(r[0] for r in runs), mapping_error_opencv(px, rays, *as_opencv(k)))
            if loss == "none":
                unrobust = k
                tight = run_deformcal(a.deformcal, folder, m, rows, cols, spacing, width, height, loss, TIGHT)[1]
        obj = [board.copy() for _ in frames]
        img = [np.array([views[fr][c] for c in range(ncorners)], dtype=np.float32) for fr in frames]
        flags = cv2.CALIB_ZERO_TANGENT_DIST
        runs = []
        for _ in range(a.repeats):
            start = time.perf_counter()
            _, K, dist, _, _ = cv2.calibrateCamera(obj, img, (width, height), None, None, flags=flags)
            runs.append(time.perf_counter() - start)
        record("OpenCV calibrateCamera", statistics.median(runs), mapping_error_opencv(px, rays, K, dist))
        # The same model and cost as calibrateCamera: the intrinsics must agree.
        cv_px, cv_rays = truth_rays(opencv_intrinsics(K, dist), width, height)
        agreement.append(mapping_error_opencv(cv_px, cv_rays, *as_opencv(unrobust)))
        agreement_tight.append(mapping_error_opencv(cv_px, cv_rays, *as_opencv(tight)))
        if not a.skip_ro:
            start = time.perf_counter()
            _, K, dist, _, _, _ = cv2.calibrateCameraRO(obj, img, (width, height), cols - 1, None, None, flags=flags)
            record("OpenCV calibrateCameraRO", time.perf_counter() - start, mapping_error_opencv(px, rays, K, dist))
        obs = np.ones((len(frames), rows, cols, 3))
        for i, fr in enumerate(frames):
            for c in range(ncorners):
                obs[i, c // cols, c % cols, :2] = views[fr][c]
        for warp in (False, True):
            runs = [run_mrcal(obs.copy(), width, height, spacing, warp) for _ in range(a.repeats)]
            name = "mrcal with board warp" if warp else "mrcal rigid"
            record(name, statistics.median(r[0] for r in runs), mapping_error_mrcal(px, rays, "LENSMODEL_OPENCV5", runs[-1][1]))
        print(f"subset {si + 1}/{len(subsets)} done", file=sys.stderr)

    base = statistics.median(times["OpenCV calibrateCamera"])
    print(f"t2 preset, {a.subsets} subsets x {a.images} complete views ({ncorners} corners), median of {a.repeats} runs each, 1 process")
    print(f"{'method':28} {'median ms':>10} {'vs calibrateCamera':>19} {'mapping error to truth (px)':>30}")
    for name, ts in times.items():
        med = statistics.median(ts)
        e = errors[name]
        print(f"{name:28} {med * 1e3:10.1f} {med / base:18.2f}x {statistics.mean(e):15.3f} ± {statistics.pstdev(e):.3f}")
    print("deformcal standard, no loss, against calibrateCamera's intrinsics (mapping error, mean / max):")
    print(f"  default tolerances          {statistics.mean(agreement):.2e} / {max(agreement):.2e} px")
    print(f"  tolerances 1e-15 (untimed)  {statistics.mean(agreement_tight):.2e} / {max(agreement_tight):.2e} px")


if __name__ == "__main__":
    main()
