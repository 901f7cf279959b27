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
