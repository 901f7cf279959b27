"""The stencil kernels' angle (`volseg.curvature._atan`) against numpy's arctan2."""

import numba
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from volseg.curvature._atan import _SMALL, angle_times_root, atan2_upper


@numba.njit
def _atan2_all(y, x):
    out = np.empty(len(y))
    for i in range(len(y)):
        out[i] = atan2_upper(y[i], x[i])
    return out


@numba.njit
def _scaled_all(s2, c, a2):
    out = np.empty(len(s2))
    for i in range(len(s2)):
        out[i] = angle_times_root(s2[i], c[i], a2[i])
    return out


def _ulps(got, want):
    return np.abs(got - want) / np.spacing(np.maximum(np.abs(want), np.finfo(float).tiny))


@pytest.mark.parametrize("scale", [1e-300, 1e-8, 1.0, 1e8, 1e300])
def test_atan2_upper_is_within_2_ulp_of_numpy(scale, rng):
    y = np.abs(rng.standard_cauchy(200_000)) * scale
    x = rng.standard_cauchy(200_000) * scale
    assert _ulps(_atan2_all(y, x), np.arctan2(y, x)).max() <= 2


def test_atan2_upper_at_the_axes_octant_edges_and_infinities():
    y = np.array([0.0, 0.0, 0.0, 0.0, 1.0, 1.0, 1.0, 1.0, _SMALL, _SMALL, np.inf, 1.0, 1.0])
    x = np.array([1.0, -1.0, 0.0, -0.0, 0.0, -0.0, 1.0, -1.0, 1.0, -1.0, 1.0, np.inf, -np.inf])
    got = _atan2_all(y, x)
    assert _ulps(got, np.arctan2(y, x)).max() <= 1
    assert got[0] == 0.0 and got[2] == 0.0      # flat: exactly 0


_SIZE = st.one_of(st.just(0.0), st.floats(1e-100, 1e100))


@settings(deadline=None)     # the first example compiles the kernel
@given(st.lists(st.tuples(_SIZE, st.one_of(_SIZE, _SIZE.map(lambda v: -v)), _SIZE),
                min_size=1, max_size=50))
def test_angle_times_root_is_atan2_times_sqrt(values):
    s2, c, a2 = (np.array(column) for column in zip(*values, strict=True))
    want = np.arctan2(np.sqrt(s2), c) * np.sqrt(a2)
    got = _scaled_all(s2, c, a2)
    assert np.all(np.abs(got - want) <= 6 * np.spacing(np.abs(want)) + 1e-300)


def test_angle_times_root_on_both_sides_of_the_small_angle_bound(rng):
    # r = sqrt(s2) / c just below and above 0.66: the branchless rational and the
    # reduced one meet without a step.
    c = rng.uniform(0.5, 2.0, 100_000)
    r = _SMALL * (1 + rng.uniform(-1e-6, 1e-6, len(c)))
    s2, a2 = (r * c) ** 2, rng.uniform(0.0, 4.0, len(c))
    want = np.arctan2(np.sqrt(s2), c) * np.sqrt(a2)
    assert _ulps(_scaled_all(s2, c, a2), want).max() <= 4
    assert np.all(_scaled_all(np.zeros(3), np.array([1.0, 2.0, 0.5]), np.ones(3)) == 0.0)
