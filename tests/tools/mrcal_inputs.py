"""What mrcal makes of the optimization_inputs in deformcal's .cameramodel files.

Usage: mrcal_inputs.py MODEL...
Prints JSON: {"models": [{...}, ...]}, one entry per model file:
- "carried": false when the model has no optimization_inputs (then nothing else);
- "icam_intrinsics", "lensmodel": as stored;
- "intrinsics_equal", "extrinsics_equal": the problem's values of this camera are
  exactly the model's (camera 0 has no extrinsics in the problem: true);
- "rms_px": sqrt(mean over used corners of |x/w|^2), x being mrcal's residuals from
  mrcal.optimizer_callback at the stored state and w the corner's weight, so the
  pixel errors with the weights undone;
- "used", "rejected": corners with weight > 0; corners with weight < 0 that hold
  an observed pixel (mrcal marks a missing corner (-1, -1, -1));
- "cost", "cost_reoptimised": |x|^2 at the stored state and after mrcal.optimize()
  from it; "intrinsics_moved": the largest change mrcal.optimize() made to any
  camera's intrinsics;
- "uncertainty_px": mrcal.projection_uncertainty (worst direction, at infinity)
  at the centre of the image.
"""
import copy
import json
import sys

import mrcal
import numpy as np


def check(path):
    model = mrcal.cameramodel(path)
    inputs = model.optimization_inputs()
    if inputs is None:
        return {"carried": False}
    icam = model.icam_intrinsics()
    lensmodel, intrinsics = model.intrinsics()
    out = {"carried": True, "icam_intrinsics": icam, "lensmodel": inputs["lensmodel"]}
    out["intrinsics_equal"] = bool(np.array_equal(inputs["intrinsics"][icam], intrinsics))
    if icam == 0:
        out["extrinsics_equal"] = bool(np.array_equal(model.extrinsics_rt_fromref(), np.zeros(6)))
    else:
        stored = inputs["extrinsics_rt_fromref"][icam - 1]
        out["extrinsics_equal"] = bool(np.array_equal(stored, model.extrinsics_rt_fromref()))

    _, x, _, _ = mrcal.optimizer_callback(**inputs, no_jacobian=True, no_factorization=True)
    board = inputs["observations_board"]
    w = board[..., 2].ravel()
    residuals = x[: board[..., :2].size].reshape(-1, 2)
    used = w > 0
    pixels = residuals[used] / w[used, None]
    out["rms_px"] = float(np.sqrt(np.mean(np.sum(pixels * pixels, axis=1))))
    out["used"] = int(np.count_nonzero(used))
    observed = board[..., 0].ravel() != -1.0
    out["rejected"] = int(np.count_nonzero((w < 0) & observed))

    out["cost"] = float(x @ x)
    again = copy.deepcopy(inputs)
    stats = mrcal.optimize(**again)
    out["cost_reoptimised"] = float(stats["x"] @ stats["x"])
    out["intrinsics_moved"] = float(np.max(np.abs(again["intrinsics"] - inputs["intrinsics"])))

    centre = (model.imagersize() - 1) / 2.0
    ray = mrcal.unproject(centre, lensmodel, intrinsics)
    out["uncertainty_px"] = float(
        mrcal.projection_uncertainty(ray, model, atinfinity=True, what="worstdirection-stdev")
    )
    return out


def main():
    print(json.dumps({"models": [check(p) for p in sys.argv[1:]]}))


if __name__ == "__main__":
    main()
