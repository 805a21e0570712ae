"""mrcal's own projection of camera-frame points for given lens parameters.

Usage: mrcal_project.py < cases.json
cases.json: {"cases": [{"lensmodel": "LENSMODEL_OPENCV8", "intrinsics": [...],
                        "points": [[x, y, z], ...]}, ...]}
Prints JSON: {"projections": [[[u, v], ...], ...]}, one list per case, from
mrcal.project with exactly the given parameters.
"""
import json
import sys

import mrcal
import numpy as np


def main():
    cases = json.load(sys.stdin)["cases"]
    out = []
    for c in cases:
        points = np.array(c["points"], dtype=np.float64)
        intrinsics = np.array(c["intrinsics"], dtype=np.float64)
        out.append(mrcal.project(points, c["lensmodel"], intrinsics).tolist())
    print(json.dumps({"projections": out}))


if __name__ == "__main__":
    main()
