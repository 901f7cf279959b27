import numpy as np
from hypothesis import given
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from volseg._distinct import distinct


@given(arrays(st.sampled_from([np.int32, np.int64, np.uint8]), st.integers(0, 3).map(
    lambda d: (4,) * d), elements=st.integers(0, 5)))
def test_distinct_is_np_unique_on_ids(values):
    out = distinct(values)
    expected = np.unique(values)
    assert out.dtype == expected.dtype
    np.testing.assert_array_equal(out, expected)


def test_distinct_does_not_change_its_input():
    values = np.array([[3, 1], [3, 2]])
    assert distinct(values).tolist() == [1, 2, 3]
    assert values.tolist() == [[3, 1], [3, 2]]
