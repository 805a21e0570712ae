"""The Python result is the command line's: the same observations through
``deformcal calibrate --config`` give the same calibration.json to 1e-9, and
``save`` writes the same set of files."""

import json
import subprocess

import numpy as np
import pytest

import deformcal
from conftest import COLS, ROWS, SIZE, SPACING, synthetic_views


def write_csv_and_config(tmp, obj, img, model, method, extra=""):
    rows = ["camera,frame,corner,u,v"]
    for f, (o, p) in enumerate(zip(obj, img)):
        ids = np.rint(o[:, 1] / SPACING).astype(int) * COLS + np.rint(o[:, 0] / SPACING).astype(int)
        for c, (u, v) in zip(ids, p.astype(np.float64)):
            rows.append(f"cam0,{f},{c},{float(u)!r},{float(v)!r}")
    (tmp / "observations.csv").write_text("\n".join(rows) + "\n")
    config = tmp / "config.toml"
    config.write_text(
        f"[target]\nrows = {ROWS}\ncols = {COLS}\nspacing = {SPACING!r}\n"
        f'[[cameras]]\nname = "cam0"\nwidth = {SIZE[0]}\nheight = {SIZE[1]}\nmodel = "{model}"\n'
        '[data]\nobservations = "observations.csv"\n'
        f'[calibration]\nmethod = "{method}"\n{extra}'
        '[output]\ndir = "out"\n'
    )
    return config


def numbers(x, path=""):
    """Every number in a JSON value, keyed by its path (timings left out)."""
    if isinstance(x, dict):
        out = {}
        for k, v in x.items():
            if k in ("seconds",):
                continue
            out.update(numbers(v, f"{path}.{k}"))
        return out
    if isinstance(x, list):
        out = {}
        for i, v in enumerate(x):
            out.update(numbers(v, f"{path}[{i}]"))
        return out
    if isinstance(x, bool) or not isinstance(x, (int, float)):
        return {path: x}
    return {path: float(x)}


@pytest.mark.parametrize("model,method", [("opencv5", "full"), ("kb4", "standard")])
def test_equals_cli(cli, tmp_path, model, method):
    obj, img = synthetic_views(model, views=12, seed=3)
    # The board: corner (row, col) at (col, row) * spacing, which the CSV's ids follow.
    config = write_csv_and_config(tmp_path, obj, img, model, method, 'threads = 1\n')
    run = subprocess.run([cli, "calibrate", "--config", str(config)], capture_output=True, text=True)
    assert run.returncode == 0, run.stderr
    cli_json = json.loads((tmp_path / "out" / "calibration.json").read_text())
    r = deformcal.calibrate_camera(obj, img, SIZE, model=model, method=method, threads=1)
    saved = r.save(tmp_path / "py")
    assert saved == tmp_path / "py" / "calibration.json"
    ours, theirs = numbers(json.loads(saved.read_text())), numbers(cli_json)
    assert ours.keys() == theirs.keys()
    for key, a in theirs.items():
        b = ours[key]
        if isinstance(a, float):
            assert abs(a - b) <= 1e-9 * max(1.0, abs(a)), f"{key}: CLI {a} Python {b}"
        else:
            assert a == b, f"{key}: CLI {a!r} Python {b!r}"
    assert numbers(r.json).keys() == theirs.keys()
    cli_files = {p.name for p in (tmp_path / "out").iterdir()} - {"observations.csv"}
    assert {p.name for p in (tmp_path / "py").iterdir()} == cli_files
    # The CLI's poses are in deformcal's board frame (origin at the board centre).
    for f, rvec, tvec in zip(cli_json["frames"], r.rvecs, r.tvecs):
        np.testing.assert_allclose(np.ravel(rvec), f["rotation"], atol=1e-12)
        R = deformcal._camera._rotation_matrix(np.array(f["rotation"]))
        np.testing.assert_allclose(
            np.ravel(tvec) + R @ r.board.centre, f["translation"], atol=1e-12
        )
    if method == "full":
        assert r.static_correction.shape == (ROWS * COLS, 3)
        assert all(b is not None and set("abc") <= b.keys() for b in r.bends)
        assert r.uncertainty["cameras"]["cam0"]["expected_mapping_error_px"] > 0
