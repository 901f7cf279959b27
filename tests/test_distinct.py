import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from volseg._distinct import distinct, index_type, is_in, places, positions


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


@settings(deadline=None)     # the first call of each dtype loads its compiled kernel
@given(st.sampled_from([np.int8, np.int32, np.int64, np.uint16]).flatmap(lambda dtype: arrays(
    dtype, st.integers(0, 3).map(lambda d: (5,) * d),
    elements=st.integers(0 if np.dtype(dtype).kind == "u" else -3, 100))))
def test_places_is_np_unique_with_its_inverse(values):
    ids, where = places(values)
    expected, inverse = np.unique(values, return_inverse=True)
    assert ids.dtype == expected.dtype
    np.testing.assert_array_equal(ids, expected)
    np.testing.assert_array_equal(where, inverse.reshape(values.shape))


def test_places_grows_its_table_past_a_thousand_ids_far_apart():
    rng = np.random.default_rng(3)
    values = rng.integers(-2**62, 2**62, size=50_000)
    values = np.repeat(values, rng.integers(1, 4, size=len(values)))    # runs of one id
    ids, where = places(values)
    expected, inverse = np.unique(values, return_inverse=True)
    np.testing.assert_array_equal(ids, expected)
    np.testing.assert_array_equal(where, inverse)


def test_places_refuses_floats():
    with pytest.raises(TypeError, match="integers"):
        places(np.array([1.0, 2.0]))


@settings(deadline=None)
@given(st.lists(st.integers(-2**40, 2**40), unique=True, max_size=40).map(np.array),
       st.sampled_from([np.int32, np.int64]), st.data())
def test_positions_is_searchsorted_on_present_queries_and_minus_one_elsewhere(values, dtype,
                                                                           data):
    values = np.sort(values).astype(np.int64)
    present = data.draw(st.lists(st.sampled_from(values.tolist()), max_size=30)
                        if len(values) else st.just([]))
    absent = data.draw(st.lists(st.integers(-2**31, 2**31 - 1).filter(
        lambda q: q not in set(values.tolist())), max_size=5))
    queries = np.array(present + absent, dtype=np.int64)
    queries = queries[np.abs(queries) < 2**31].astype(dtype)      # what `dtype` holds
    out = positions(values, queries)
    expected = np.where(np.isin(queries, values), np.searchsorted(values, queries), -1)
    assert out.dtype == np.int64 and out.shape == queries.shape
    np.testing.assert_array_equal(out, expected)


def test_positions_numbers_unsorted_values_by_their_index_past_a_grown_table():
    rng = np.random.default_rng(5)
    values = rng.permutation(rng.choice(2**50, size=100_000, replace=False))
    at = rng.integers(0, len(values), size=(300, 7))
    np.testing.assert_array_equal(positions(values, values[at]), at)


def test_positions_of_required_queries_refuse_a_missing_one():
    values = np.array([7, 3, 11])
    np.testing.assert_array_equal(positions(values, [11, 7], required="lost"), [2, 0])
    assert positions(values, np.zeros(0, np.int64), required="lost").size == 0
    with pytest.raises(RuntimeError, match="an id went missing"):
        positions(values, [3, 5], required="an id went missing")


@given(arrays(np.int64, st.integers(0, 12), elements=st.integers(-4, 6)),
       arrays(st.sampled_from([np.int32, np.int64]), st.integers(0, 12),
              elements=st.integers(-4, 6)))
def test_is_in_is_np_isin(values, ids):
    np.testing.assert_array_equal(is_in(values, ids), np.isin(values, ids))


def test_index_type_is_int32_up_to_its_largest_value_then_int64():
    top = np.iinfo(np.int32).max
    assert index_type(0) is np.int32 and index_type(top) is np.int32
    assert index_type(top + 1) is np.int64 and index_type(2 ** 40) is np.int64
    # Every value up to the largest fits the type chosen, -1 too.
    for largest in (0, 7, top, top + 1):
        info = np.iinfo(index_type(largest))
        assert info.min <= -1 and largest <= info.max


def test_counts_in_chunks_are_bincounts(monkeypatch):
    """`counts` chunk by chunk equals ``np.bincount`` for every id type and chunk
    length, with ids above `minlength` in a later chunk than the first."""
    from volseg import _distinct

    rng = np.random.default_rng(4)
    ids = rng.integers(0, 9, (5, 4, 3))
    ids[-1, -1, -1] = 30
    for chunk in (1, 7, 60, 1000):
        monkeypatch.setattr(_distinct, "COUNT_CHUNK", chunk)
        for dtype in (np.uint8, np.uint16, np.int32, np.int64):
            for minlength in (0, 12, 40):
                got = _distinct.counts(ids.astype(dtype), minlength)
                want = np.bincount(ids.ravel(), minlength=minlength)
                assert got.dtype == np.int64
                np.testing.assert_array_equal(got, want)
