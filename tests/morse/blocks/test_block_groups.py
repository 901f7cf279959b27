"""The blockwise build's global part on the workers (issue 30): the maxima's ids by a
sample sort, the exits by pointer jumping in the tree of block groups, the union-find
decided in the same tree. Exactly the in-memory hierarchy for every chunking (tiny
blocks, so that the tree is deep and most cells touch a face), connectivity, ties and
mask; and the tree decides most events below its root."""

import dask
import dask.array as da
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from volseg import descending_complex
from volseg.morse import _group_tree
from volseg.morse.blocks import _build as _blocks
from volseg.morse.blocks import _ranks

from ...blockwise.test_blockwise import assert_same_hierarchy
from ...conftest import smooth_random_field


@pytest.fixture(autouse=True)
def _synchronous():
    with dask.config.set(scheduler="synchronous"):
        yield


@pytest.mark.parametrize("connectivity", ["kuhn", 6, 18, 26])
@pytest.mark.parametrize("chunks", [(2, 2, 2), (3, 2, 5), (1, 7, 3)])
def test_tiny_blocks_give_the_in_memory_hierarchy(connectivity, chunks):
    rng = np.random.default_rng(3)
    field = rng.integers(0, 4, size=(9, 8, 10)).astype(float)       # ties everywhere
    eager = descending_complex(field, connectivity=connectivity)
    lazy = descending_complex(da.from_array(field, chunks=chunks), connectivity=connectivity)
    assert_same_hierarchy(lazy, eager)
    for k in (1, 3, len(eager.maxima)):
        assert np.array_equal(lazy.segment(n_regions=k).compute(), eager.segment(n_regions=k))


@pytest.mark.parametrize("connectivity", ["kuhn", 26])
def test_tiny_blocks_with_a_mask_of_several_components(connectivity):
    rng = np.random.default_rng(4)
    field = np.round(smooth_random_field((12, 11, 10), rng, sigma=1.0), 1)
    mask = np.zeros(field.shape, bool)
    mask[1:5, 1:9, 2:8] = True          # three components, one only a voxel thick
    mask[7:11, 2:10, 1:9] = True
    mask[6, 0:3, 9] = True
    field[~mask] = np.nan
    eager = descending_complex(field, connectivity=connectivity, mask=mask)
    for chunks in [(2, 3, 2), (5, 11, 1)]:
        lazy = descending_complex(da.from_array(field, chunks=chunks),
                                  connectivity=connectivity, mask=mask)
        assert_same_hierarchy(lazy, eager)
        assert np.array_equal(lazy.segment(n_regions=4).compute(), eager.segment(n_regions=4))


@pytest.mark.parametrize("one_sided_below", [0.2, np.inf])
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_blocks_of_few_and_many_cells_give_the_in_memory_hierarchy(monkeypatch, seed,
                                                                   one_sided_below):
    """A smooth half (few cells a block) beside a noisy one (many), with the in-memory
    pass walking each edge once wherever cells are few (`_ONE_SIDED_BELOW` raised so
    that tiny blocks qualify): the blocks still give the in-memory hierarchy. Each
    block walks every neighbour; had each chosen by its own cells, an edge over a face
    between the two kinds of block could be found by neither (with 0.2, every seed here
    lost a saddle that way)."""
    from volseg.morse import _edges

    monkeypatch.setattr(_edges, "_ONE_SIDED_BELOW", one_sided_below)
    rng = np.random.default_rng(seed)
    field = smooth_random_field((16, 12, 12), rng, sigma=3.0)
    field[8:] = rng.random((8, 12, 12))
    eager = descending_complex(field)
    for chunks in [(4, 4, 4), (5, 6, 3)]:
        lazy = descending_complex(da.from_array(field, chunks=chunks))
        assert_same_hierarchy(lazy, eager)


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(shape=st.tuples(*(st.integers(1, 7),) * 3), levels=st.integers(1, 6),
       connectivity=st.sampled_from(["kuhn", 6, 26]), seed=st.integers(0, 2**16),
       data=st.data())
def test_any_chunking_gives_the_in_memory_hierarchy(shape, levels, connectivity, seed, data):
    field = np.random.default_rng(seed).integers(0, levels, size=shape).astype(float)
    chunks = tuple(data.draw(st.integers(1, s)) for s in shape)
    eager = descending_complex(field, connectivity=connectivity)
    lazy = descending_complex(da.from_array(field, chunks=chunks), connectivity=connectivity)
    assert_same_hierarchy(lazy, eager)


def test_most_events_are_decided_below_the_root(monkeypatch):
    # A noisy 8-bit-like field: its maxima die young, inside their blocks, and what
    # goes up is only what touches the faces.
    field = np.round(smooth_random_field((64, 64, 64), np.random.default_rng(5), sigma=0.7)
                     * 40)
    swept = {}
    decide = _group_tree.decide

    def recorded(items, faces, group_id):
        decided, group = decide(items, faces, group_id)
        swept[group_id] = (len(items.a), len(decided[0]), len(group.items.a))
        return decided, group

    monkeypatch.setattr(_group_tree, "decide", recorded)
    lazy = descending_complex(da.from_array(field, chunks=32))
    groups = _group_tree.block_tree((2, 2, 2))
    assert sorted(swept) == list(range(len(groups))) and len(groups) == 15
    edges, decided, up = (np.array([swept[g][i] for g in range(len(groups))]) for i in range(3))
    leaves = np.array([g[2] is None for g in groups])
    assert decided.sum() == len(lazy.young) > 5000
    assert decided[leaves].sum() > 0.6 * decided.sum()     # most die inside their block
    assert up[leaves].sum() < 0.4 * edges[leaves].sum()    # what goes up is the faces'
    assert edges[-1] < 0.15 * edges[leaves].sum()          # the root sees few edges
    assert up[-1] == 0
    assert_same_hierarchy(lazy, descending_complex(field))


def test_block_tree_halves_the_longest_axis():
    groups = _group_tree.block_tree((4, 1, 2))
    leaves = [g for g in groups if g[2] is None]
    assert sorted(g[0] for g in leaves) == [(i, 0, k) for i in range(4) for k in range(2)]
    root = groups[-1]
    assert root[:3] == ((0, 0, 0), (4, 1, 2), 0)
    for lo, hi, axis, low, high in groups:
        if axis is not None:     # the halves tile the group along `axis`
            assert groups[low][0] == lo and groups[high][1] == hi
            assert groups[low][1][axis] == groups[high][0][axis]


def test_the_sample_sort_gives_the_in_memory_ids():
    rng = np.random.default_rng(6)
    parts = []
    for size in (0, 5, 300, 1, 57, 0, 900):
        gids = rng.choice(10**6, size=size, replace=False)
        parts.append((gids, rng.integers(0, 7, size=size).astype(float)))   # many ties
    gids = np.concatenate([p[0] for p in parts])
    values = np.concatenate([p[1] for p in parts])
    expected = np.empty(len(gids), np.int64)
    expected[np.lexsort((gids, values))[::-1]] = np.arange(len(gids))
    for buckets in (1, 3, 32):
        from volseg._task_graph import TaskGraph

        graph = TaskGraph("test-ranks")
        keys = [graph(tuple, [p[0], p[1]]) for p in parts]
        per_block, total, maxima = _ranks.ranks_of(graph, keys, buckets)
        results = dask.compute(*graph.delayed([*per_block, total, *maxima]))
        assert results[len(parts)] == len(gids)
        got = dict(zip(np.concatenate([r[0] for r in results[:len(parts)]]).tolist(),
                       np.concatenate([r[1] for r in results[:len(parts)]]).tolist(),
                       strict=True))
        assert [got[g] for g in gids.tolist()] == expected.tolist()
        sorted_gids = np.concatenate([m[0] for m in results[len(parts) + 1:]])
        assert np.array_equal(sorted_gids, gids[np.argsort(expected)])


def test_the_client_holds_no_outer_layer(monkeypatch):
    # What the build's computes bring back to the client: the hierarchy, fetched (the
    # maxima and the events), never the blocks' outer layers or their forests.
    field = smooth_random_field((40, 40, 40), np.random.default_rng(9), sigma=1.0)
    received = []
    lazy = _blocks.dask_descending_complex(da.from_array(field, chunks=10), "kuhn",
                                           hooks=recording(received))
    total = sum(_nbytes(r) for r in received)
    per_maximum = total / len(lazy.maxima)
    assert per_maximum < 65            # 16 B for the maxima + 48 B for the events
    assert_same_hierarchy(lazy, descending_complex(field))


@pytest.mark.parametrize("chunks", [(2, 3, 4), (9, 5, 3)])
def test_the_ascent_gives_the_range_a_hypervolume_cut_reads(chunks):
    # The field's range in the mask comes from the ascent's blocks (no pass of its
    # own): the extremes outside the mask, and blocks with no voxel in it, count not.
    from volseg.morse import cut_of
    from volseg.segment import CutRequest

    rng = np.random.default_rng(4)
    field = rng.integers(0, 6, (9, 8, 12)).astype(np.float32)
    mask = rng.random(field.shape) > 0.3
    field[0, 0, 0], field[-1, -1, -1] = -50, 50
    mask[0, 0, 0] = mask[-1, -1, -1] = False
    mask[:, :, 9:] = False                   # whole blocks outside it
    lazy = descending_complex(da.from_array(field, chunks=chunks), mask=mask, on_workers=True)
    assert lazy.field_range == (float(field[mask].min()), float(field[mask].max())) == (0, 5)
    cut = CutRequest.checked(n_regions=7, measure="hypervolume")
    labels, report = cut_of(lazy, cut)
    expected, expected_report = cut_of(descending_complex(field, mask=mask), cut)
    assert np.array_equal(np.asarray(labels), expected)
    assert np.array_equal(report.curve.values, expected_report.curve.values)


@pytest.mark.parametrize("measure", ["hypervolume", "size", "persistence"])
def test_a_cut_on_the_workers_sends_the_client_nothing_per_maximum(measure):
    # The pipeline's path (issue 30): the hierarchy kept where it was assembled, cut
    # there; the client receives counts, the regions' tops and a thinned curve, and
    # no array as long as the maxima. The labels are those of the cut in memory.
    from volseg.morse import cut_of
    from volseg.segment import CutRequest


    field = smooth_random_field((40, 40, 40), np.random.default_rng(9), sigma=1.0)
    mask = field > np.quantile(field, 0.2)          # several components: min_component
    received = []
    lazy = descending_complex(da.from_array(field, chunks=10), mask=mask, on_workers=True,
                              block_hooks=recording(received))
    cut = CutRequest.checked(n_regions="auto", measure=measure, min_component=0.01)
    labels, report = cut_of(lazy, cut)
    n_maxima = lazy.n_maxima
    assert n_maxima > 1000 and lazy._fetched is None        # nothing fetched
    # Nor does a block's labelling read the cut's table of every maximum: each reads
    # its own cells' share of it (`_block_cells.gathered`).
    from dask.utils import key_split
    assert {key_split(k) for k in labels.__dask_graph__()}.isdisjoint({"run", "getitem"})
    # Beside the curve (thinned: test_preview), nothing as long as a fraction of them.
    arrays = [a for a in _arrays(received) if len(a) != len(report.curve)]
    assert max(len(a) for a in arrays) < n_maxima / 4, [a.shape for a in arrays]
    assert sum(a.nbytes for a in arrays) < 16 * len(report.curve) + 16 * 1024
    whole = descending_complex(field, mask=mask)
    expected, expected_report = cut_of(whole, cut)
    assert np.array_equal(np.asarray(labels), expected)
    assert report.n_regions == expected_report.n_regions and report.record == expected_report.record
    assert np.array_equal(report.top_maxima, expected_report.top_maxima)
    assert np.array_equal(report.curve.values, expected_report.curve.values)


def recording(received: list):
    """Block hooks whose computes add what the client receives to `received`."""
    from volseg._block_hooks import BlockHooks

    def compute(*collections, stage):
        results = dask.compute(*collections)
        received.extend(results)
        return results
    return BlockHooks(compute=compute)


def _arrays(item):
    """Every ndarray inside `item` (tuples, lists, dicts, dataclasses)."""
    if isinstance(item, np.ndarray):
        yield item.ravel()
    elif isinstance(item, (tuple, list)):
        for i in item:
            yield from _arrays(i)
    elif isinstance(item, dict):
        for i in item.values():
            yield from _arrays(i)
    elif hasattr(item, "__dataclass_fields__"):
        for name in item.__dataclass_fields__:
            yield from _arrays(getattr(item, name))


def _nbytes(item):
    return sum(a.nbytes for a in _arrays(item)) + 8
