"""One edge per pair of adjacent cells with its highest saddle, and the order the
elder-rule union-find takes them in (shared by the in-memory and blockwise builds)."""

from __future__ import annotations

import numpy as np

from . import _kernels

__all__ = []


#: Vertices per chunk of the cross-edge pass (a chunk is a run of cells).
_CHUNK_VERTICES = 1 << 20

#: The pass walks each edge once (and merges the pairs found from both sides) when
#: there are fewer cells than this per vertex; else every neighbour of every vertex.
_ONE_SIDED_BELOW = 0.01


def _cross_edges(graph, cell, n_cells, *, cells_mark_vertices=False, one_sided=None):
    """(a, b, saddle) of every pair of adjacent cells, a < b, with its highest saddle.
    `cells_mark_vertices`: the vertices are exactly the nodes whose cell is not -1 (in
    memory; a block's halo nodes have cells too), so the grouping reads `cell` alone
    and the vertex list is freed before it (4 bytes a voxel off the build's peak).
    `one_sided`: walk each edge once (True) or every neighbour (False); None chooses
    by the cells per vertex (below).

    The vertices are grouped by cell (a counting sort), then each cell's edges to
    cells with a larger id are reduced to one per partner: exactly one edge per pair,
    which is all the elder-rule union-find needs (a lower edge of a pair can never
    join two components). Cells are walked tile by tile (`_visit_order`: the
    vertices reached stay in cache), in chunks of about `_CHUNK_VERTICES` vertices run
    in parallel; each chunk gets room for 10 pairs per cell plus one per 16 vertices
    (quantized fields need about 8 per cell), and the chunks that overflow are rerun
    with exact room. The grouping is freed before the pieces are joined, so the peak
    stays near the field's own arrays (about 24 bytes per voxel in all at 256^3).

    That walk reads every edge twice, once from each end. With few cells (fewer than
    `_ONE_SIDED_BELOW` per vertex: a smooth field, the value field, the curvature of
    most of the five datasets) it walks each edge once, from its lower-index end,
    keeps every partner cell and merges the pairs found from both sides
    (`_kernels.two_sided`, room for twice the entries): the same pairs, the pass
    1.34x faster at 256^3 on a smooth field (11 794 cells: 0.79 -> 0.59 s). With many
    cells the merge's random reads cost more than the walk saves (0.95x on the
    synthetic curvature field, 389 020 cells at 256^3). On the small real volumes the
    one-sided walk also won above the threshold (tooth's curvature, 0.018 cells a
    vertex: 40 -> 30 ms), where the merge stays in cache; the threshold is kept low
    for the large ones. Blocks pass False (`blocks._build._pairs_of_block`).
    """
    flat, grid, offsets, indptr, indices = (graph.values, graph.grid, graph.offsets,
                                            graph.indptr, graph.indices)
    n_real, index = len(graph.vertices), graph.vertices.dtype
    starts = np.empty(n_cells + 1, dtype=np.int64)
    # members will hold every vertex: the list is let go (4 bytes per voxel less at the
    # peak), before they are made when the cells mark the vertices.
    vertices, graph.vertices = (None if cells_mark_vertices else graph.vertices), None
    members = np.empty(n_real, dtype=index)
    if vertices is None:
        _kernels.group_by_cell_of_nodes(cell, n_cells, starts, members)
    else:
        _kernels.group_by_cell(vertices, cell, n_cells, starts, members)
    del vertices
    # (A cell may have no vertex: the blockwise pass's cells seen only in a block's halo.)
    visit = _visit_order(members[np.minimum(starts[:-1], n_real - 1)], graph)
    counts_in_order = np.diff(starts)[visit]
    n_chunks = max(1, min(256, -(-n_real // _CHUNK_VERTICES)))
    bounds = np.searchsorted(np.cumsum(counts_in_order),
                             np.linspace(0, n_real, n_chunks + 1)[1:], side="left") + 1
    bounds = np.minimum(np.concatenate([[0], bounds]), n_cells).astype(np.int64)
    bounds[-1] = n_cells
    chunks = np.arange(n_chunks, dtype=np.int64)
    cells_in = np.diff(bounds)
    vertices_in = _per_chunk(np.add, counts_in_order, bounds)
    if one_sided is None:
        one_sided = n_cells < _ONE_SIDED_BELOW * n_real
    if one_sided:
        capacity = 20 * cells_in + vertices_in // 8 + 1024
        if grid:                    # forward edges only: the other half walked from there
            offsets = np.ascontiguousarray(offsets[offsets > 0])
    else:
        capacity = 10 * cells_in + vertices_in // 16 + 1024
    degree = len(offsets) if grid else int(np.diff(indptr).max(initial=0))
    # Partner table per chunk: twice the largest partner bound of its cells, a power of 2.
    sizes = np.minimum(degree * counts_in_order, n_cells)
    largest = _per_chunk(np.maximum, sizes, bounds)
    table_sizes = np.maximum(16, 2 ** np.ceil(np.log2(np.maximum(2 * largest, 1)))).astype(np.int64)
    args = (flat, members, starts, visit, bounds, grid, offsets, indptr, indices, cell, degree,
            one_sided, table_sizes)
    out, out_starts, counts = _pair_pass(args, chunks, capacity)
    over = np.flatnonzero(counts > capacity)
    if len(over):
        room, room_starts, _ = _pair_pass(args, over, counts[over])
    del args, members, starts, visit
    pieces = []
    for c in range(n_chunks):
        if counts[c] <= capacity[c]:
            pieces.append([arr[out_starts[c]:out_starts[c] + counts[c]] for arr in out])
        else:
            k = int(np.searchsorted(over, c))
            pieces.append([arr[room_starts[k]:room_starts[k] + counts[c]] for arr in room])
    a, b, v = (np.concatenate([p[k] for p in pieces]) for k in range(3))
    if not one_sided:
        return a, b, v
    del pieces, out
    if len(over):
        del room
    keep = _kernels.two_sided(a, b, v, flat, n_cells)
    return a[keep], b[keep], v[keep]


#: A grid's cells are walked tile by tile: cubes of this many nodes a side.
_TILE = 32


def _visit_order(first, graph):
    """The order the pass walks the cells in, given each cell's first vertex: on a
    grid by the `_TILE`-cube of the padded grid that vertex lies in, then by the
    vertex; on a graph by the vertex. The pass is bound by reaching each cell's
    vertices and their neighbours in memory: by tile, what a chunk is walking at once
    is about (32 + 8)^3 nodes (0.8 MB of values and cells, within a core's 2 MB L2),
    where in node order it spanned whole planes (several MB at 256^3; an estimate, not
    counted). Pairs pass 1.4x faster at 256^3 (389 020 cells: 0.71-0.77 s against
    1.01-1.18; smooth field, 11 794 cells: 0.26-0.33 s against 0.37-0.42; tiles of 16
    and 64 about the same), the same pairs: their order is not the result's,
    `_saddle_order` sorts by value, vertex and pair. A 128^3 block of the blockwise
    build gained nothing measurable (512^3 end to end: 99.1 s against 97.6)."""
    first = first.astype(np.int64)
    if not graph.grid:
        return np.argsort(first, kind="stable")
    coords = np.unravel_index(first, graph.padded_shape)
    tiles = tuple(-(-n // _TILE) for n in graph.padded_shape)
    tile = np.ravel_multi_index(tuple(c // _TILE for c in coords), tiles).astype(np.int64)
    return np.argsort(tile * len(graph.values) + first, kind="stable")


def _per_chunk(ufunc, values, bounds):
    """`ufunc` reduced over each chunk's cells values[bounds[c]:bounds[c + 1]], 0 for
    an empty chunk. ``ufunc.reduceat`` is given the non-empty chunks' starts only: with
    every start (clipped to the last cell), a chunk followed by empty ones at the end
    lost its last cell, and its partner table could be too small for that cell."""
    out = np.zeros(len(bounds) - 1, dtype=values.dtype)
    full = bounds[:-1] < bounds[1:]
    if full.any():
        out[full] = ufunc.reduceat(values, bounds[:-1][full])
    return out


def _pair_pass(args, chunks, capacity):
    (flat, members, starts, visit, bounds, grid, offsets, indptr, indices, cell, degree,
     one_sided, sizes) = args
    out_starts = np.concatenate([[0], np.cumsum(capacity)[:-1]]).astype(np.int64)
    counts = np.zeros(len(chunks), dtype=np.int64)
    total = int(capacity.sum())
    out = [np.empty(total, dtype=cell.dtype), np.empty(total, dtype=cell.dtype),
           np.empty(total, dtype=members.dtype)]
    _kernels.cell_pairs(flat, members, starts, visit, bounds, chunks, grid, offsets, indptr,
                       indices, cell, degree, one_sided, sizes, *out, out_starts,
                       capacity.astype(np.int64), counts)
    return out, out_starts, counts


def _saddle_order(keys, saddle, edge_a, edge_b, edges=None):
    """Argsort of edges by (saddle value `keys`, saddle vertex, cell pair): the
    simulation of simplicity order, with the pair deciding between edges that share a
    saddle (also the blockwise build's, per block and on the client). Given `edges`
    (indices), those edges in that order."""
    order, place, _ = _sorted_columns(keys, saddle, edge_a, edge_b, edges)
    return order[place]


def _sorted_columns(keys, saddle, edge_a, edge_b, edges=None):
    """The `_saddle_order` in two steps: (order: the edges (all, or `edges`) by value
    alone; place: the permutation of 0..len(order)-1 that breaks their ties, so that
    order[place] is the saddle order; (a, b): their cells in `order`'s order, for a
    Kruskal that reads them through `place`).

    An unstable value sort, then a compiled pass that orders each short run of equal
    values, and np.lexsort each run of more than 32 (quantized fields have plateaus):
    2x faster than one np.lexsort at 256^3. The pass and the Kruskal after it read
    copies of the columns in value order, nearly in sequence (`place` moves an edge
    only within its run), where reading them through the order was a random read per
    edge into arrays of every edge: at 256^3 (1.17 M edges sorted of 3.19 M) the ties
    0.063 -> 0.011 s and the Kruskal 0.070 -> 0.016 s, for 0.034 s of copies.
    """
    if edges is None:
        by = np.argsort(keys)
        value, order = keys[by], by
    else:
        value = keys[edges]
        by = np.argsort(value)
        value, order = value[by], edges[by]
    a, b, vertex = edge_a[order], edge_b[order], saddle[order]
    place = np.arange(len(order))
    for start, stop in _kernels.break_ties(place, value, vertex, a, b):
        run = place[start:stop]
        place[start:stop] = run[np.lexsort((b[run], a[run], vertex[run]))]
    return order, place, (a, b)


def _kruskal_batch(keys, saddle, edge_a, edge_b, edges, parent):
    """`edges` (all when None) in the `_saddle_order`, and whether each joined two
    components of `parent` (updated) in Kruskal from the highest down."""
    order, place, (a, b) = _sorted_columns(keys, saddle, edge_a, edge_b, edges)
    taken = np.zeros(len(order), dtype=bool)
    _kernels.spanning_edges(a, b, place, parent, taken)
    return order[place], taken[place]


#: `spanning_forest` sorts first the highest (this many x cells) edges.
_FIRST_EDGES_PER_CELL = 3


def spanning_forest(keys, saddle, edge_a, edge_b, n_cells, *, ordered=False):
    """keep[e]: whether edge e is in the maximum spanning forest of cells
    0..n_cells-1 in the `_saddle_order` (Kruskal from the highest edge down). With
    `ordered`: the forest's edges (indices) in the `_saddle_order` instead, which is
    the order Kruskal met them in (no second sort: 0.05 s of the build at 256^3).

    A filter-Kruskal: the highest 3 x n_cells edges are sorted and taken first; of
    the rest, only the edges between two components still apart are sorted and taken
    after them (an edge inside a component is refused whenever it comes: components
    only grow). The same forest as one sort of every edge, 1.7x faster on a 128^3
    block of a quantized field (7 edges per cell; 40 000 of 650 000 lower edges
    survive the filter). Every low edge's key is at most the pivot and every high
    one's above it, so the low batch's forest edges, then the high batch's, each in
    its own sorted order, are the forest in the `_saddle_order`.
    """
    parent = np.arange(n_cells, dtype=np.int64)
    first = _FIRST_EDGES_PER_CELL * n_cells
    if first >= len(keys):                  # few edges: one sort
        batches = [_kruskal_batch(keys, saddle, edge_a, edge_b, None, parent)]
    else:
        pivot = np.partition(keys, len(keys) - first)[len(keys) - first]
        high = _kruskal_batch(keys, saddle, edge_a, edge_b, np.flatnonzero(keys > pivot),
                              parent)
        low = _kernels.apart(edge_a, edge_b, np.flatnonzero(keys <= pivot), parent)
        batches = [_kruskal_batch(keys, saddle, edge_a, edge_b, low, parent), high]
    forest = [order[taken] for order, taken in batches]
    if ordered:
        return np.concatenate(forest)
    keep = np.zeros(len(edge_a), dtype=bool)
    for edges in forest:
        keep[edges] = True
    return keep
