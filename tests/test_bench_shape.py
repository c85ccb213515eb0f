"""bench/shape.py's yardstick for the shape estimate: the local error it reports is zero for
an estimate that is the truth turned, scaled and moved, and large where one part of the
estimate has the wrong scale (what a hinged part looked like before the length prior), and
a shift of the whole estimate changes nothing."""
import math
import sys
from pathlib import Path

import numpy as np
from hypothesis import given, settings, strategies as st

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench.shape import local_errors  # noqa: E402


def _lattice(n: int, d: float = 0.9) -> np.ndarray:
    return np.array([[i * d + (k % 2) * d / 2, k * d * math.sqrt(3) / 2]
                     for k in range(n) for i in range(n)])


@settings(max_examples=30, deadline=None)
@given(angle=st.floats(-math.pi, math.pi), scale=st.floats(0.2, 5.0),
       dx=st.floats(-10, 10), dy=st.floats(-10, 10), n=st.integers(2, 7))
def test_a_similar_copy_has_no_local_error(angle, scale, dx, dy, n):
    T = _lattice(n)
    c, s = math.cos(angle), math.sin(angle)
    E = scale * T @ np.array([[c, -s], [s, c]]).T + [dx, dy]
    err, k = local_errors(E, T, 2.5)
    assert err.max() < 1e-9
    assert abs(k * scale - 1.0) < 1e-9        # the fit undoes the scale


def test_a_part_at_the_wrong_scale_is_found_and_a_drift_is_not():
    T = _lattice(6)
    E = T.copy()
    far = T[:, 0] > 3.5                       # the right-hand part, hinged at x = 3.5
    E[far] = [3.5, 0.0] + 2.0 * (T[far] - [3.5, 0.0])
    err, _ = local_errors(E, T, 2.5)
    # the one similarity fitted to the whole compromises between the two scales, so both
    # parts show: more than half the robots over 0.2 (bench/shape.py's "off"), the
    # stretched part's worst over 1
    assert (err > 0.2).mean() > 0.5
    assert err[far].max() > 1.0
    # the same estimate shifted as a whole: the same local errors
    err2, _ = local_errors(E + [7.0, -3.0], T, 2.5)
    assert np.allclose(err, err2)
