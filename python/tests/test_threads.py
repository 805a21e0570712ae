"""Four Python threads calibrate at once (the GIL is released during the solve)
and each gets the serial result, bit for bit."""

from concurrent.futures import ThreadPoolExecutor

import numpy as np

import deformcal
from conftest import SIZE, synthetic_views


def test_four_threads_calibrate_in_parallel():
    data = [synthetic_views("opencv5", views=10, seed=s) for s in range(4)]

    def run(k):
        obj, img = data[k]
        return deformcal.calibrate_camera(obj, img, SIZE, method="full", threads=1)

    serial = [run(k) for k in range(4)]
    with ThreadPoolExecutor(4) as pool:
        parallel = list(pool.map(run, range(4)))
    for a, b in zip(serial, parallel):
        np.testing.assert_array_equal(a.K, b.K)
        np.testing.assert_array_equal(a.dist, b.dist)
        assert a.rms == b.rms
    # Different data, different cameras: the threads did not share a result.
    assert len({r.rms for r in parallel}) == 4
