import networkx as nx
import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from volseg.morse._edges import _FIRST_EDGES_PER_CELL, _saddle_order, spanning_forest


def _graph(seed, n_cells, n_edges, n_values):
    """Random cell-graph edges (a < b, one per pair as `_cross_edges` gives), their
    saddle values quantized to `n_values` levels (plateaus) and saddle vertices shared
    by several edges."""
    rng = np.random.default_rng(seed)
    pairs = rng.integers(0, n_cells, size=(n_edges, 2))
    pairs = np.unique(np.sort(pairs[pairs[:, 0] != pairs[:, 1]], axis=1), axis=0)
    rng.shuffle(pairs)
    saddle = rng.integers(0, max(1, len(pairs) // 3), size=len(pairs))
    keys = rng.integers(0, n_values, size=len(pairs)).astype(np.float64)[saddle]
    return keys, saddle, pairs[:, 0].copy(), pairs[:, 1].copy()


@settings(max_examples=60, deadline=None)
@given(st.integers(0, 2**32 - 1), st.integers(1, 40), st.integers(0, 400), st.integers(1, 6))
def test_the_forest_is_networkx_maximum_spanning_forest_in_the_strict_order(
        seed, n_cells, n_edges, n_values):
    keys, saddle, a, b = _graph(seed, n_cells, n_edges, n_values)
    keep = spanning_forest(keys, saddle, a, b, n_cells)
    # The strict order (value, saddle vertex, a, b) as distinct integer weights.
    rank = np.empty(len(keys), dtype=np.int64)
    rank[np.lexsort((b, a, saddle, keys))] = np.arange(len(keys))
    graph = nx.Graph()
    graph.add_nodes_from(range(n_cells))
    graph.add_weighted_edges_from(zip(a.tolist(), b.tolist(), rank.tolist(), strict=True))
    expected = {tuple(sorted(e)) for e in nx.maximum_spanning_edges(graph, data=False)}
    assert {(int(x), int(y)) for x, y in zip(a[keep], b[keep], strict=True)} == expected


def test_the_filter_runs_and_drops_edges_on_a_dense_graph():
    """More than 3 edges per cell: the low edges go through the filter, and the
    forest still spans each component with one edge fewer than its cells."""
    keys, saddle, a, b = _graph(7, 30, 600, 4)
    assert len(keys) > _FIRST_EDGES_PER_CELL * 30
    keep = spanning_forest(keys, saddle, a, b, 30)
    graph = nx.Graph(zip(a.tolist(), b.tolist(), strict=True))
    graph.add_nodes_from(range(30))
    assert keep.sum() == 30 - nx.number_connected_components(graph)


@settings(max_examples=60, deadline=None)
@given(st.integers(0, 2**32 - 1), st.integers(1, 40), st.integers(0, 600), st.integers(1, 6))
def test_the_ordered_forest_is_the_forest_in_the_saddle_order(seed, n_cells, n_edges,
                                                               n_values):
    """`ordered=True` gives the kept edges in the `_saddle_order` without sorting them
    again, with few edges (one sort) and with many (the filter's two batches), on
    plateaus and shared saddles."""
    keys, saddle, a, b = _graph(seed, n_cells, n_edges, n_values)
    keep = spanning_forest(keys, saddle, a, b, n_cells)
    ordered = spanning_forest(keys, saddle, a, b, n_cells, ordered=True)
    expected = _saddle_order(keys, saddle, a, b, np.flatnonzero(keep))
    assert ordered.tolist() == expected.tolist()


def test_the_ordered_forest_takes_both_batches():
    """A dense graph where cell 0 hangs on its lowest edges: the filter's low batch
    keeps edges too, and they come first."""
    keys, saddle, a, b = _graph(11, 30, 900, 50)
    keys[(a == 0) | (b == 0)] = -1.0
    assert len(keys) > _FIRST_EDGES_PER_CELL * 30
    keep = spanning_forest(keys, saddle, a, b, 30)
    ordered = spanning_forest(keys, saddle, a, b, 30, ordered=True)
    pivot = np.partition(keys, len(keys) - 90)[len(keys) - 90]
    assert (keys[ordered] <= pivot).any() and (keys[ordered] > pivot).any()
    assert ordered.tolist() == _saddle_order(keys, saddle, a, b, np.flatnonzero(keep)).tolist()


def test_no_edges_no_forest():
    empty = np.zeros(0, dtype=np.int64)
    assert spanning_forest(np.zeros(0), empty, empty, empty, 3).tolist() == []


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 2**32 - 1), st.integers(2, 300), st.integers(0, 3000), st.integers(1, 40))
def test_the_saddle_order_is_the_strict_order(seed, n_cells, n_edges, n_values):
    """Runs of equal values both short (sorted in the kernel) and longer than 32
    (sorted by numpy afterwards): the order is (value, saddle vertex, a, b) exactly,
    for the whole edge list and for a subset."""
    keys, saddle, a, b = _graph(seed, n_cells, n_edges, n_values)
    assert _saddle_order(keys, saddle, a, b).tolist() == np.lexsort((b, a, saddle, keys)).tolist()
    some = np.flatnonzero(np.random.default_rng(seed).random(len(keys)) < 0.5)
    expected = some[np.lexsort((b[some], a[some], saddle[some], keys[some]))]
    assert _saddle_order(keys, saddle, a, b, some).tolist() == expected.tolist()


@settings(max_examples=30, deadline=None)
@given(st.integers(0, 2**31), st.integers(1, 40), st.integers(1, 400))
def test_grouping_read_off_the_cells_is_the_grouping_by_the_vertex_list(seed, n_cells, n):
    """The in-memory build groups vertices by cell from `cell` alone (its vertices are
    the nodes with a cell), after freeing the vertex list: the same starts and members
    as the grouping that walks the list."""
    from volseg.morse import _kernels

    rng = np.random.default_rng(seed)
    cell = np.full(n, -1, dtype=np.int32)
    vertices = np.flatnonzero(rng.random(n) < 0.7).astype(np.int32)
    cell[vertices] = rng.integers(0, n_cells, len(vertices))
    expected = [np.empty(n_cells + 1, np.int64), np.empty(len(vertices), np.int32)]
    _kernels.group_by_cell(vertices, cell, n_cells, *expected)
    got = [np.empty(n_cells + 1, np.int64), np.empty(len(vertices), np.int32)]
    _kernels.group_by_cell_of_nodes(cell, n_cells, *got)
    for one, other in zip(expected, got, strict=True):
        np.testing.assert_array_equal(one, other)


def _pairs_by_definition(graph, cell):
    """{(a, b): saddle} of every pair of cells a < b joined by an edge, the saddle the
    highest lower end of their edges (by value, then index), walking every neighbour
    of every vertex: the definition `_cross_edges` must meet."""
    best = {}
    for v in graph.vertices:
        ends = (v + graph.offsets if graph.grid
                else graph.indices[graph.indptr[v]:graph.indptr[v + 1]])
        for u in ends:
            a, b = cell[v], cell[u]
            if b < 0 or a == b:
                continue
            low = min((graph.values[v], v), (graph.values[u], u))
            key = (min(a, b), max(a, b))
            best[key] = max(best.get(key, low), low)
    return {key: int(saddle) for key, (_, saddle) in best.items()}


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 2**31), st.integers(1, 30), st.sampled_from(["kuhn", 6, 26, "graph"]),
       st.sampled_from([1 << 20, 7, 1]), st.sampled_from([0.0, np.inf]))
def test_cross_edges_are_one_per_pair_with_its_highest_saddle(seed, n_cells, kind, chunk,
                                                              one_sided_below):
    """`_cross_edges`, walking every neighbour (`_ONE_SIDED_BELOW` 0) or each edge
    once from its lower-index end with the pairs found from both sides merged (inf):
    exactly the pairs of cells joined by an edge, a < b, each with the highest lower
    end of its edges; with ties in the values, a mask, cells in any layout, and chunks
    of one vertex up (so the chunks overflow and are rerun)."""
    from volseg.morse import _edges
    from volseg.morse._graph import _neighbourhood

    rng = np.random.default_rng(seed)
    shape = tuple(rng.integers(2, 7, 3))
    values = np.round(rng.random(shape) * 4) / 4                  # ties
    mask = rng.random(shape) > 0.2
    adjacency = None
    if kind == "graph":
        n = values.size
        adjacency = rng.integers(0, n, (3 * n, 2))
    graph = _neighbourhood(values.ravel() if adjacency is not None else values,
                           mask.ravel() if adjacency is not None else mask, adjacency,
                           "kuhn" if kind == "graph" else kind)
    cell = np.full(len(graph.values), -1, dtype=np.int32)
    cell[graph.vertices] = rng.integers(0, n_cells, len(graph.vertices))
    want = _pairs_by_definition(graph, cell)
    old = _edges._CHUNK_VERTICES, _edges._ONE_SIDED_BELOW
    _edges._CHUNK_VERTICES, _edges._ONE_SIDED_BELOW = chunk, one_sided_below
    try:
        a, b, saddle = _edges._cross_edges(graph, cell, n_cells)
    finally:
        _edges._CHUNK_VERTICES, _edges._ONE_SIDED_BELOW = old
    assert (a < b).all()
    assert dict(zip(zip(a.tolist(), b.tolist(), strict=True), saddle.tolist(),
                    strict=True)) == want
    assert len(a) == len(want)


@settings(max_examples=60, deadline=None)
@given(st.lists(st.integers(0, 5), min_size=1, max_size=12), st.data())
def test_per_chunk_reductions_cover_every_cell_of_every_chunk(counts, data):
    """The chunks' vertex counts and largest partner bounds are reduced over exactly
    their own cells, 0 for an empty chunk: a chunk followed by empty ones at the end
    keeps its last cell (its partner table was sized without it, and the walk wrote
    past the table: a segfault in CI)."""
    from volseg.morse._edges import _per_chunk

    values = np.array(counts, dtype=np.int64)
    inner = sorted(data.draw(st.lists(st.integers(0, len(values)), max_size=6)))
    bounds = np.array([0, *inner, len(values)], dtype=np.int64)
    for ufunc, reduce in ((np.add, sum), (np.maximum, lambda part: max(part, default=0))):
        want = [reduce(values[a:b].tolist()) for a, b in zip(bounds[:-1], bounds[1:],
                                                              strict=True)]
        assert _per_chunk(ufunc, values, bounds).tolist() == want


def test_a_large_last_cell_sharing_its_chunk_gets_a_table_of_its_size():
    """A star: 100 one-vertex cells, each joined to its own vertex of a 100-vertex cell
    visited last, in chunks of 7 vertices, so that cell shares its chunk and empty
    chunks follow: every pair comes out once (before, the chunk's partner table was
    sized without the large cell)."""
    from volseg.morse import _edges
    from volseg.morse._graph import _neighbourhood

    k = 100
    values = np.arange(2 * k, dtype=float)[::-1].copy()
    graph = _neighbourhood(values, None, np.stack([np.arange(k), k + np.arange(k)], axis=1),
                           "kuhn")
    cell = np.concatenate([1 + np.arange(k), np.zeros(k)]).astype(np.int32)
    old, _edges._CHUNK_VERTICES = _edges._CHUNK_VERTICES, 7
    try:
        a, b, saddle = _edges._cross_edges(graph, cell, k + 1)
    finally:
        _edges._CHUNK_VERTICES = old
    assert sorted(zip(a.tolist(), b.tolist(), saddle.tolist(), strict=True)) == [
        (0, i + 1, k + i) for i in range(k)]
