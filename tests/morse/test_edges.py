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
