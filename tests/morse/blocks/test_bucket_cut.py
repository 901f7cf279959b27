"""A cut where the blockwise hierarchy's buckets of maximum ids are (issue 30): labels
and report exactly those of the cut in memory, for every kind of cut (persistence,
size, hypervolume), chunking, tie and mask, with no task joining every maximum."""

import warnings

import dask
import dask.array as da
import numpy as np
import pytest

from volseg import descending_complex
from volseg.morse import _kernels, cut_of
from volseg.morse._prune_groups import GroupState
from volseg.morse.blocks import _bucket_cut, _bucket_prune, _buckets
from volseg.morse.blocks._cut import in_buckets
from volseg.segment import CutRequest

from ...conftest import smooth_random_field
from .test_block_groups import _arrays, recording

CUTS = [dict(n_regions="auto"), dict(n_regions=5), dict(n_regions=1),
        dict(min_persistence=0.0), dict(min_persistence=1.0), dict(min_persistence=np.inf)]


@pytest.fixture(autouse=True)
def _synchronous():
    with dask.config.set(scheduler="synchronous"):
        yield


@pytest.fixture
def never_joined(monkeypatch):
    """The whole hierarchy must not be joined in one task: `_buckets.joined` fails."""
    def joined(*args):
        raise AssertionError("the events were joined in one task")
    monkeypatch.setattr(_buckets, "joined", joined)


def assert_same_report(report, expected):
    assert report.n_regions == expected.n_regions and report.record == expected.record
    for name in ("top_maxima", "top_values", "top_persistence", "largest_persistences"):
        assert np.array_equal(getattr(report, name), getattr(expected, name)), name
    assert (report.n_maxima, report.n_components, report.n_events) == \
        (expected.n_maxima, expected.n_components, expected.n_events)
    for name in ("values", "ranks"):
        assert np.array_equal(getattr(report.curve, name), getattr(expected.curve, name))
    assert (report.curve.n_positive, report.curve.n_components) == \
        (expected.curve.n_positive, expected.curve.n_components)


def _both(field, chunks, mask=None, connectivity="kuhn"):
    """(the blockwise hierarchy kept on the workers, the in-memory one)."""
    return (descending_complex(da.from_array(field, chunks=chunks), mask=mask,
                               connectivity=connectivity, on_workers=True),
            descending_complex(field, mask=mask, connectivity=connectivity))


def _cut_both(both, cut):
    lazy, whole = both
    assert in_buckets(lazy, cut)
    labels, report = cut_of(lazy, cut)
    expected, expected_report = cut_of(whole, cut)
    assert np.array_equal(np.asarray(labels), expected)
    assert_same_report(report, expected_report)
    return report


@pytest.mark.parametrize("asked", CUTS)
@pytest.mark.parametrize("chunks", [(2, 3, 2), (5, 7, 4)])
def test_every_persistence_cut_equals_the_one_in_memory(asked, chunks, never_joined):
    field = np.round(smooth_random_field((14, 12, 10), np.random.default_rng(9), sigma=0.5)
                     * 20)                                   # plateaus and tied saddles
    report = _cut_both(_both(field, chunks), CutRequest.checked(measure="persistence", **asked))
    assert report.n_maxima > 100


@pytest.fixture
def small_leaves(monkeypatch):
    """Leaves of 3^3 voxels: the pruning's tree of groups has many levels."""
    monkeypatch.setattr(_bucket_prune, "MIN_LEAF_EDGE", 3)


MEASURE_CUTS = [dict(n_regions="auto"), dict(n_regions=5), dict(n_regions=1),
                dict(threshold=0.0), dict(threshold=25.0), dict(threshold=np.inf)]


@pytest.mark.parametrize("measure", ["size", "hypervolume"])
@pytest.mark.parametrize("asked", MEASURE_CUTS)
@pytest.mark.parametrize("chunks", [(2, 3, 2), (5, 7, 4)])
def test_every_size_measure_cut_equals_the_one_in_memory(measure, asked, chunks, never_joined,
                                                         small_leaves):
    field = np.round(smooth_random_field((14, 12, 10), np.random.default_rng(9), sigma=0.5)
                     * 20)                                   # plateaus and tied saddles
    both = _both(field, chunks)
    edge, grid = _bucket_prune.leaf_grid(field.shape, len(both[0].buckets))
    assert edge <= 6 and np.prod(grid) >= 8           # a tree of several levels
    report = _cut_both(both, CutRequest.checked(measure=measure, **asked))
    assert report.n_maxima > 100


@pytest.mark.parametrize("connectivity", [6, pytest.param(26, marks=pytest.mark.slow)])
@pytest.mark.parametrize("measure", ["size", "hypervolume"])
def test_size_measure_cuts_with_ties_and_dropped_components(measure, connectivity,
                                                            never_joined, small_leaves):
    rng = np.random.default_rng(4)
    field = rng.integers(0, 4, size=(12, 11, 10)).astype(float)     # ties everywhere
    mask = np.zeros(field.shape, bool)
    mask[1:5, 1:9, 2:8] = True
    mask[7:11, 2:10, 1:9] = True
    mask[6, 0:3, 9] = True
    both = _both(field, (2, 3, 2), mask, connectivity)
    for asked, share in [(dict(n_regions=4), 0.0), (dict(n_regions="auto"), 0.05),
                         (dict(threshold=3.0), 0.45), (dict(n_regions=300), 0.05)]:
        cut = CutRequest.checked(measure=measure, min_component=share, **asked)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")         # more regions than maxima
            report = _cut_both(both, cut)
        components = 3 if connectivity == 6 else 2             # a diagonal touch
        assert report.curve.n_components == {0.0: components, 0.05: 2, 0.45: 1}[share]


def test_the_merges_ids_are_the_sequential_prunings(small_leaves):
    """Each merge's two region ids, decided in groups, are those the sequential pruning
    gives them (a group's own union-find would name the other side by whatever its
    children merged into it first)."""
    field = smooth_random_field((16, 14, 12), np.random.default_rng(5), sigma=0.5)
    lazy, whole = _both(field, (4, 5, 6))
    for measure in ("size", "hypervolume"):
        merges = dask.compute(*lazy.pruned_in_buckets(measure))
        target = np.concatenate([m.target for m in merges])
        order, extinction, _ = whole._pruning(measure)
        parent, expected = np.arange(len(whole.maxima)), np.full(len(whole.maxima), -1)
        for e in order:                               # the sequential pruning's ids
            a, b = (_kernels_root(parent, c) for c in (whole.source[e], whole.target[e]))
            parent[max(a, b)] = expected[max(a, b)] = min(a, b)
        assert np.array_equal(target, expected)
        extinction_of = np.concatenate([m.extinction() for m in merges])
        gone = expected >= 0
        assert np.array_equal(np.sort(extinction_of[gone]), np.sort(extinction))


def _kernels_root(parent, x):
    while parent[x] != x:
        x = parent[x]
    return x


def test_a_groups_edge_ends_by_hash_are_those_of_a_binary_search():
    """`_with_local` places each edge's ends among the group's regions by a hash
    table: the places `GroupState.pruned` finds by binary search without it, -1 for an
    end outside the group, ids far apart and none."""
    rng = np.random.default_rng(17)
    for n in (0, 1, 7, 1000):
        rid = np.unique(rng.integers(0, 10**12, n))
        m = 3 * len(rid)
        a = rng.choice(rid, m) if len(rid) else np.zeros(0, np.int64)
        b = np.where(rng.random(m) < 0.3, -1, rng.choice(rid, m) if len(rid) else -1)
        state = GroupState(rid, np.zeros(len(rid), np.int64), np.arange(m), a, b,
                           np.zeros(m, np.int64), np.full(m, -1))
        u, v = _bucket_prune._with_local(state).local
        assert u.tolist() == np.searchsorted(rid, a).tolist()
        assert v.tolist() == np.where(b >= 0, np.searchsorted(rid, np.maximum(b, 0)),
                                      -1).tolist()
        assert (v == -1).sum() == (b == -1).sum()


def test_leaves_double_until_about_two_per_bucket():
    assert _bucket_prune.leaf_grid((1024,) * 3, 32) == (256, (4, 4, 4))
    assert _bucket_prune.leaf_grid((4096,) * 3, 256) == (512, (8, 8, 8))
    assert _bucket_prune.leaf_grid((100, 30, 20), 1) == (64, (2, 1, 1))
    # Never fewer than allowed by `MIN_LEAVES` (64), however few the buckets.
    assert _bucket_prune.leaf_grid((1024,) * 3, 8) == (256, (4, 4, 4))
    assert _bucket_prune.leaf_grid((10, 10, 10), 4, 2) == (4, (3, 3, 3))
    assert _bucket_prune.leaf_grid((9, 9, 9), 1, 2) == (4, (3, 3, 3))
    assert _bucket_prune.leaf_grid((9, 9, 9), 63, 2) == (2, (5, 5, 5))      # 125 <= 126


def test_the_keys_come_down_the_tree_or_it_is_an_error():
    """A leaf looks up every one of its events' keys in what came down the tree
    (`_bucket_prune._keys_down`); one missing is a bug, never a silent key."""
    decided = (np.array([5, 2]), np.array([20, 10]), np.array([5, 2]))
    known = (np.array([7]), np.array([30]), np.array([7]))
    keys = _bucket_prune._known_keys(decided, known)
    ext, tie = _bucket_prune._looked_up(keys, np.array([7, 2, 5]))
    assert ext.tolist() == [30, 10, 20] and tie.tolist() == [7, 2, 5]
    for missing in ([3], [8], [0, 2]):
        with pytest.raises(RuntimeError, match="lost the key"):
            _bucket_prune._looked_up(keys, np.array(missing))
    low, high = _bucket_prune._keys_down(decided, (np.array([2, 7]), np.array([5])), known)
    assert [c.tolist() for c in low] == [[2, 7], [10, 30], [2, 7]]
    assert [c.tolist() for c in high] == [[5], [20], [5]]


@pytest.mark.parametrize("connectivity", [6, pytest.param(26, marks=pytest.mark.slow)])
def test_ties_everywhere_and_a_mask_of_several_components(connectivity, never_joined):
    rng = np.random.default_rng(4)
    field = rng.integers(0, 4, size=(12, 11, 10)).astype(float)
    mask = np.zeros(field.shape, bool)
    mask[1:5, 1:9, 2:8] = True                 # three components, one a voxel thick
    mask[7:11, 2:10, 1:9] = True
    mask[6, 0:3, 9] = True
    both = _both(field, (2, 3, 2), mask, connectivity)
    # None dropped, the thin one, all but the largest; counts below and above them all.
    cases = [(asked, share) for asked in (dict(n_regions=4), dict(n_regions="auto"),
                                          dict(min_persistence=1.0))
             for share in (0.0, 0.05, 0.45)] + [(dict(n_regions=1), 0.45),
                                                (dict(n_regions=300), 0.05)]
    for asked, share in cases:
        cut = CutRequest.checked(measure="persistence", min_component=share, **asked)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")         # fewer components than asked
            report = _cut_both(both, cut)
        assert report.n_components == (3 if connectivity == 6 else 2)   # diagonal touch
        assert report.curve.n_components == {0.0: report.n_components, 0.05: 2,
                                             0.45: 1}[share]


def test_counts_that_cannot_be_met_warn_as_in_memory(never_joined):
    field = np.round(smooth_random_field((12, 12, 12), np.random.default_rng(2), sigma=1.0)
                     * 10)
    mask = np.ones(field.shape, bool)
    mask[:, 6, :] = False                       # two components
    both = _both(field, 5, mask)
    for n_regions, words in ((10**5, "only"), (1, "connected components")):
        cut = CutRequest.checked(n_regions=n_regions, measure="persistence")
        with pytest.warns(UserWarning, match=words):
            _cut_both(both, cut)


def test_the_cuts_that_need_the_whole_hierarchy_still_join_it():
    field = smooth_random_field((16, 16, 16), np.random.default_rng(3), sigma=1.0)
    mask = field > np.quantile(field, 0.1)
    lazy = descending_complex(da.from_array(field, chunks=8), mask=mask, on_workers=True)
    for measure in ("persistence", "size", "hypervolume"):
        assert in_buckets(lazy, CutRequest.checked(n_regions=10**5, measure=measure))
        assert not in_buckets(lazy, CutRequest.checked(n_regions=10**5 + 1, measure=measure))
    cut = CutRequest.checked(n_regions=10**6, measure="size")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")         # more regions than maxima
        labels, report = cut_of(lazy, cut)
        whole = descending_complex(field, mask=mask)
        expected, expected_report = cut_of(whole, cut)
    assert np.array_equal(np.asarray(labels), expected)
    assert_same_report(report, expected_report)
    # The hierarchy joined for that cut is the one a caller reads (`fetch`).
    assert lazy._joined is not None and np.array_equal(lazy.maxima, whole.maxima)
    assert np.array_equal(lazy.young, whole.young)


def _chain_buckets(n, sizes, rng):
    """Buckets of `sizes` over n maxima, each maximum i > 0 dying into a random higher
    maximum (a forest whose every tree has its lowest id as root), persistence random."""
    target = np.array([-1] + [int(rng.integers(0, i)) for i in range(1, n)])
    values = np.sort(rng.random(n))[::-1] + 1.0
    saddle_value = values - rng.random(n)
    firsts = np.concatenate([[0], np.cumsum(sizes)])
    buckets = []
    for j in range(len(sizes)):
        s = slice(firsts[j], firsts[j + 1])
        buckets.append(_buckets.Bucket(int(firsts[j]), np.arange(n)[s], values[s], target[s],
                                       target[s], np.arange(n)[s], saddle_value[s]))
    return buckets, firsts, target, values - saddle_value


@pytest.mark.parametrize("threshold", [0.0, 0.3, 0.9, 2.0])
def test_pointer_jumping_across_buckets_gives_the_union_find_regions(threshold):
    # Long chains that cross buckets back and forth: several rounds, each maximum's
    # region that of the compiled union-find on the merged events.
    rng = np.random.default_rng(11)
    n = 400
    buckets, firsts, target, persistence = _chain_buckets(n, [1, 0, 57, 3, 200, 139], rng)
    delayed = [dask.delayed(b) for b in buckets]
    rounds = []
    hooks = _hooks(rounds)
    states = _bucket_cut.regions(delayed, dask.delayed(firsts), ("below", threshold), hooks)
    got = np.concatenate([s.compute().pointer for s in states])
    young = np.arange(1, n)
    expected = np.empty(n, np.int32)
    _kernels.regions_of_cut(young, target[1:], persistence[1:] < threshold, expected)
    assert np.array_equal(got, expected)
    if threshold == 2.0:                       # everything merged: one region, and
        assert got.max() == 0 and len(rounds) >= 3     # chains crossed buckets


def _hooks(rounds):
    from volseg._block_hooks import BlockHooks

    def persist(*collections, stage, hierarchy=False):
        if "round" in stage:
            rounds.append(stage)
        return dask.persist(*collections)
    return BlockHooks(persist=persist)


def test_no_bucket_holds_most_of_the_maxima(never_joined):
    # The sample sort's buckets share the maxima: with many blocks, none holds a
    # quarter of them, and nothing the client receives is that long but the curve.
    field = smooth_random_field((40, 40, 40), np.random.default_rng(9), sigma=1.0)
    received = []
    lazy = descending_complex(da.from_array(field, chunks=10), on_workers=True,
                              block_hooks=recording(received))
    buckets = dask.compute(*lazy.buckets)
    assert len(buckets) == 32 and sum(len(b) for b in buckets) == lazy.n_maxima > 1000
    assert max(len(b) for b in buckets) < lazy.n_maxima / 4
    cut = CutRequest.checked(n_regions="auto", measure="persistence")
    labels, report = cut_of(lazy, cut)
    arrays = [a for a in _arrays(received) if len(a) != len(report.curve)]
    assert max(len(a) for a in arrays) < lazy.n_maxima / 4
    expected, expected_report = cut_of(descending_complex(field), cut)
    assert np.array_equal(np.asarray(labels), expected)
    assert_same_report(report, expected_report)         # the head shorter than the events



def test_buckets_grow_past_2048_cubed_so_each_stays_small():
    from volseg.morse.blocks import _build as _blocks

    assert _blocks._bucket_count(5, 10**6) == 5                 # never more than blocks
    assert _blocks._bucket_count(512, 1024**3) == 32
    assert _blocks._bucket_count(4096, 2048**3) == 32
    assert _blocks._bucket_count(32768, 4096**3) == 256          # 17 M maxima at most each
    assert 4096**3 * 0.064 / 256 * 40 < 0.75 * 2**30
    # Fewer on few threads (4 per thread), never fewer than the size asks.
    assert _blocks._bucket_count(64, 1024**3, threads=2) == 8
    assert _blocks._bucket_count(64, 1024**3, threads=1) == 4
    assert _blocks._bucket_count(64, 1024**3, threads=64) == 32
    assert _blocks._bucket_count(4096, 2048**3, threads=2) == 32
    assert _blocks._bucket_count(32768, 4096**3, threads=2) == 256


@pytest.mark.parametrize("threads", [1, 2, None])
def test_the_engines_threads_set_the_buckets_not_the_cut(threads, never_joined, small_leaves):
    # The bucket count follows the engine's threads (`BlockHooks.threads`); every cut
    # stays the in-memory one.
    from volseg._block_hooks import BlockHooks

    field = np.round(smooth_random_field((14, 12, 10), np.random.default_rng(9), sigma=0.5)
                     * 20)                                   # plateaus and tied saddles
    lazy = descending_complex(da.from_array(field, chunks=(2, 3, 2)), on_workers=True,
                              block_hooks=BlockHooks(threads=threads))
    assert len(lazy.buckets) == {1: 4, 2: 8, None: 32}[threads]
    both = (lazy, descending_complex(field))
    for measure in ("persistence", "size", "hypervolume"):
        for asked in (dict(n_regions=5), dict(n_regions="auto")):
            _cut_both(both, CutRequest.checked(measure=measure, **asked))


def test_a_thinned_curve_is_sampled_at_the_same_ranks(never_joined):
    # Over `EXACT` positive persistences the curve is thinned: the buckets' sample sort
    # picks the same ranks and values as the in-memory sort.
    from volseg.morse._curve import EXACT

    field = smooth_random_field((48, 48, 48), np.random.default_rng(2), sigma=0.4)
    report = _cut_both(_both(field, 12), CutRequest.checked(min_persistence=0.01))
    assert report.curve.n_positive > EXACT and len(report.curve) < report.curve.n_positive


@pytest.mark.parametrize("chunks", [(2, 3, 2), (5, 7, 4), (14, 12, 10)])
@pytest.mark.parametrize("masked", [False, True])
def test_each_blocks_cells_from_its_table_are_those_of_its_voxels(chunks, masked):
    # The cut's passes route by each block's distinct cells, found from the cells
    # pass's tables (`_block_cells.table_cells`), not by reading the cells again.
    from volseg.morse.blocks._cells import block_cells

    field = np.round(smooth_random_field((14, 12, 10), np.random.default_rng(3), sigma=0.5)
                     * 20)                                   # plateaus
    mask = (np.random.default_rng(1).random(field.shape) > 0.2) if masked else None
    lazy = descending_complex(da.from_array(field, chunks=chunks), mask=mask, on_workers=True)
    from_tables, = dask.compute(lazy._block_cells())
    from_voxels, = dask.compute(block_cells(lazy.cells))
    assert from_tables.shape == from_voxels.shape
    for a, b in zip(from_tables.flat, from_voxels.flat, strict=True):
        assert a.dtype == b.dtype and np.array_equal(a, b)
    assert sum(len(a) for a in from_tables.flat) >= lazy.n_maxima > 50
