"""What ``calibrate_camera`` accepts (OpenCV's shapes and dtypes, partial views)
and what it refuses, each with a ``deformcal.Error`` whose message says what is
wrong; never a crash."""

import numpy as np
import pytest

import deformcal
from conftest import EXACT, SIZE, synthetic_views

OBJ, IMG = synthetic_views("opencv5", views=8, seed=7)


def calibrate(obj=OBJ, img=IMG, size=SIZE, **kw):
    kw.setdefault("method", "standard")
    return deformcal.calibrate_camera(obj, img, size, **{**EXACT, **kw})


def test_every_shape_and_dtype_opencv_takes_gives_the_same_camera():
    base = calibrate()
    variants = {
        "(N,1,3)/(N,1,2)": ([o.reshape(-1, 1, 3) for o in OBJ], [i.reshape(-1, 1, 2) for i in IMG]),
        "float64": ([o.astype(np.float64) for o in OBJ], [i.astype(np.float64) for i in IMG]),
        "tuples": (tuple(OBJ), tuple(IMG)),
        "non-contiguous views": (
            [np.repeat(o, 2, axis=0)[::2] for o in OBJ],
            [np.asfortranarray(i) for i in IMG],
        ),
        "stacked (V,N,3) arrays": (np.stack(OBJ), np.stack(IMG)),
    }
    for name, (obj, img) in variants.items():
        r = calibrate(obj, img)
        # float64 object points differ from float32 ones by float32's rounding.
        np.testing.assert_allclose(r.K, base.K, rtol=1e-6, err_msg=name)
        np.testing.assert_allclose(r.dist, base.dist, atol=1e-6, err_msg=name)


def test_corner_order_does_not_matter():
    rng = np.random.default_rng(0)
    perms = [rng.permutation(len(o)) for o in OBJ]
    r = calibrate([o[p] for o, p in zip(OBJ, perms)], [i[p] for i, p in zip(IMG, perms)])
    np.testing.assert_allclose(r.K, calibrate().K, rtol=1e-9)


def test_board_units_and_origin_follow_the_object_points():
    """A board whose first corner is not at the origin: the same camera, and
    OpenCV's poses in the caller's frame."""
    shift = np.array([0.5, -0.2, 0.0], np.float32)
    r = calibrate([o + shift for o in OBJ], IMG)
    base = calibrate()
    np.testing.assert_allclose(r.K, base.K, rtol=1e-6)
    for t0, t1, rv in zip(base.tvecs, r.tvecs, r.rvecs):
        R = deformcal._camera._rotation_matrix(rv.ravel())
        np.testing.assert_allclose(t1.ravel() + R @ shift, t0.ravel(), atol=1e-6)


def bad(message, *args, error=deformcal.InputError, **kw):
    with pytest.raises(error) as e:
        calibrate(*args, **kw)
    assert message in str(e.value), str(e.value)
    assert isinstance(e.value, deformcal.Error)
    return e.value


def test_refused_with_clear_messages():
    o, i = list(OBJ), list(IMG)
    bad("shape (70, 2); expected (N, 3) or (N, 1, 3)", [x[:, :2] for x in o], i)
    bad("image_points[1]: shape (70, 3)", o, [i[0], np.zeros((70, 3), np.float32)] + i[2:])
    bad("dtype int64; expected float32 or float64", [x.astype(np.int64) for x in o], i)
    nan = [x.copy() for x in i]
    nan[2][5, 0] = np.nan
    bad("image_points[2]: point 5 is not finite", o, nan)
    bad("object_points has 8 views but image_points has 7", o, i[:7])
    bad("view 3: 70 object points but 69 image points", o, i[:3] + [i[3][:69]] + i[4:])
    lifted = [x.copy() for x in o]
    lifted[4][10, 2] = 0.05
    bad("object_points[4]: point 10 has z = 0.05: the object is not a planar board", lifted, i)
    off = [x.copy() for x in o]
    off[0][3, 0] += 0.011
    bad("spacings off the square grid", off, i)
    bad("expected a list with one array per view", OBJ[0], IMG[0])
    bad("image_size: expected (width, height)", size=(1280,))
    bad("no views", [], [])


def test_too_few_views_is_a_data_error():
    e = bad("", OBJ[:2], IMG[:2], error=deformcal.DataError)
    assert "3" in str(e) and "image" in str(e), str(e)


def test_options_are_the_configs_keys():
    e = bad("los", loss_function="none", error=deformcal.OptionError)
    assert "loss_function" in str(e)
    bad("outlier_k", outlier_k=1.0, error=deformcal.OptionError)
    bad("method", method="bendy", error=deformcal.OptionError)
    bad("model", model="pinhole9", error=deformcal.OptionError)
    bad("which no option takes", loss=object(), error=deformcal.OptionError)
    assert issubclass(deformcal.OptionError, ValueError)


def test_millimetres_are_refused_with_the_unit_named():
    e = bad("millimetres must be converted", [o * 1000 for o in OBJ], IMG)
    assert "spacing" in str(e)
