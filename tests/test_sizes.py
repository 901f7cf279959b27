"""The Morse stage's task results report their arrays to dask's `sizeof` (which the
workers' memory accounting and the scheduler's transfer costs read)."""

import numpy as np
from dask.sizeof import sizeof

from volseg._sizes import SizedByArrays, held_bytes
from volseg.morse._prune_groups import GroupState
from volseg.morse.blocks._buckets import Bucket


def test_a_bucket_and_a_group_count_their_arrays():
    n = 100_000
    bucket = Bucket(7, *(np.zeros(n, dtype) for dtype in
                         (np.int64, np.float64, np.int32, np.int32, np.int64, np.float64)))
    arrays = n * (8 + 8 + 4 + 4 + 8 + 8)
    assert arrays <= sizeof(bucket) < arrays + 4096
    columns = [np.zeros(n, np.int64) for _ in range(7)]
    state = GroupState(*columns, sweep=(np.zeros(n), np.zeros(n, np.int64)),
                       local=(np.zeros(n, np.int32), np.zeros(n, np.int32)))
    arrays = n * (7 * 8 + 16 + 8)
    assert arrays <= sizeof(state) < arrays + 4096


def test_nested_objects_and_containers_count_what_they_hold():
    class Inner(SizedByArrays):
        def __init__(self):
            self.a = np.zeros(1000)

    class Outer(SizedByArrays):
        __slots__ = ("parts", "table", "unset")

        def __init__(self):
            self.parts = [Inner(), (np.zeros(500, np.int32), "name")]
            self.table = {"x": np.zeros(250)}

    assert held_bytes(np.zeros(3)) == 24
    assert 8000 + 2000 + 2000 <= sizeof(Outer()) < 8000 + 2000 + 2000 + 2048
