"""Descending Morse complex of a vertex field, simplified hierarchically by persistence.

Stands alone: of volseg it imports only its compiled kernels
(`volseg._morse_kernels`) and the Kuhn leaf module (`volseg._kuhn`, the grid
neighbourhood); otherwise numpy, scipy and numba, networkx only for graph input and
`region_adjacency`. DESIGN.md section 5 is the contract:

- order: simulation of simplicity, u is higher than v when (f(u), u) > (f(v), v),
  so every result is deterministic and plateaus need no special case;
- maxima: vertices higher than all their neighbours;
- descending cells: each vertex belongs to the maximum its steepest ascent (always
  to the highest neighbour) reaches;
- persistence (0-dimensional, superlevel sets, elder rule): sweeping from high to
  low, when two components meet at vertex v the one with the lower maximum m dies,
  ``persistence(m) = f(m) - f(v)``; a component's highest maximum has infinite
  persistence. The saddle of an edge (u, v) is ``min(f(u), f(v))``;
- simplification at threshold t: every maximum with persistence < t merges, with
  its whole cell, across the saddle edge where it died into the cell on the other
  side (transitively). Merging across the saddle edge, rather than into the
  component's oldest maximum, keeps every region connected; the region count is
  still ``1 + #{non-global maxima with persistence >= t}`` (per connected
  component of the graph).

Examples
--------
>>> import numpy as np
>>> field = np.array([0.0, 3.0, 1.0, 2.0, 0.5])  # two peaks, at 1 and 3
>>> hierarchy = descending_complex(field)
>>> hierarchy.maxima.tolist(), hierarchy.persistence.tolist()
([1, 3], [inf, 1.0])
>>> hierarchy.segment().tolist(), hierarchy.segment(n_regions=1).tolist()
([0, 0, 0, 1, 1], [0, 0, 0, 0, 0])
"""

from __future__ import annotations

import itertools
import time
import warnings
from dataclasses import dataclass
from dataclasses import field as dataclass_field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from . import _kuhn

__all__ = ["descending_complex", "MorseHierarchy", "grid_offsets", "check_cut"]


def check_cut(min_persistence=None, n_regions=None) -> tuple:
    """The checked cut of a hierarchy, ``(min_persistence, n_regions)``, at most one given.

    `n_regions` must be a positive integer (not a float or a bool); `min_persistence`
    a non-negative number (``inf`` merges everything).
    """
    import numbers

    if min_persistence is not None and n_regions is not None:
        raise ValueError("give `min_persistence` or `n_regions`, not both")
    if n_regions is not None:
        if isinstance(n_regions, bool) or not isinstance(n_regions, numbers.Integral):
            raise ValueError(f"`n_regions` must be an integer, got {n_regions!r}")
        if n_regions < 1:
            raise ValueError(f"`n_regions` must be at least 1, got {n_regions}")
        n_regions = int(n_regions)
    if min_persistence is not None:
        try:
            value = float(min_persistence)
        except (TypeError, ValueError):
            raise ValueError(f"`min_persistence` must be a number, got {min_persistence!r}") from None
        if not value >= 0:  # NaN too
            raise ValueError(f"`min_persistence` must be a non-negative number, got {min_persistence!r}")
        min_persistence = value
    return min_persistence, n_regions


def grid_offsets(ndim: int, connectivity="kuhn") -> NDArray[np.intp]:
    """(m, ndim) neighbour offsets of a grid connectivity.

    ``'kuhn'``: the edges of the Kuhn triangulation (3-D: 14 neighbours,
    +-(1,0,0), +-(0,1,0), +-(0,0,1), +-(1,1,0), +-(0,1,1), +-(1,0,1), +-(1,1,1);
    2-D: 6, +-(1,0), +-(0,1), +-(1,1); 1-D: 2). Integers: 6, 18, 26 (3-D), 4, 8
    (2-D), 2 (1-D): face, edge and corner neighbours.
    """
    if connectivity == "kuhn":
        return _kuhn.neighbour_offsets(ndim)
    allowed = {1: {2: 1}, 2: {4: 1, 8: 2}, 3: {6: 1, 18: 2, 26: 3}}.get(ndim, {})
    if connectivity not in allowed:
        choices = ", ".join(map(str, ["'kuhn'", *allowed]))
        raise ValueError(
            f"`connectivity` {connectivity!r} is not available in {ndim}-D; choose {choices}"
        )
    steps = [np.array(s) for s in itertools.product((-1, 0, 1), repeat=ndim) if any(s)]
    chosen = [s for s in steps if np.abs(s).sum() <= allowed[connectivity]]
    return np.array(chosen, dtype=np.intp).reshape(-1, ndim)


def _csr_adjacency(adjacency, n_vertices):
    """Symmetric CSR (indptr, indices) without self-loops from sparse, (E, 2) or networkx.

    Adjacency is structure, not weight: every stored nonzero of a sparse matrix is an
    edge, whatever its value or sign (duplicates that would sum to zero included).
    """
    from scipy import sparse

    if hasattr(adjacency, "nodes") and hasattr(adjacency, "edges"):  # networkx graph
        import networkx as nx

        adjacency = nx.to_scipy_sparse_array(adjacency, nodelist=list(adjacency.nodes),
                                             weight=None)
    if sparse.issparse(adjacency):
        if adjacency.shape != (n_vertices, n_vertices):
            raise ValueError(
                f"`adjacency` is {adjacency.shape[0]} x {adjacency.shape[1]} but the field has "
                f"{n_vertices} vertices"
            )
        coo = sparse.coo_array(adjacency)  # keeps duplicates and explicit entries as stored
        stored = coo.data != 0
        rows, cols = coo.row[stored], coo.col[stored]
    else:
        edges = np.asarray(adjacency)
        if edges.ndim == 2 and edges.shape[0] == edges.shape[1] == n_vertices:
            raise ValueError(
                f"`adjacency` is a dense {n_vertices} x {n_vertices} array: pass an adjacency "
                "matrix as scipy.sparse.csr_array(matrix), or edges as an (E, 2) array"
            )
        if edges.ndim != 2 or edges.shape[1] != 2:
            raise ValueError(
                f"`adjacency` must be a sparse matrix, an (E, 2) edge array or a networkx "
                f"graph, got an array of shape {edges.shape}"
            )
        if edges.size and not np.issubdtype(edges.dtype, np.integer):
            raise ValueError(f"`adjacency` edges must be integer indices, got {edges.dtype}")
        if edges.size and (edges.min() < 0 or edges.max() >= n_vertices):
            raise ValueError(
                f"`adjacency` refers to vertices outside the field (indices must be in "
                f"[0, {n_vertices - 1}], got [{edges.min()}, {edges.max()}])"
            )
        rows, cols = edges[:, 0], edges[:, 1]
    rows = rows.astype(np.int64, copy=False)
    cols = cols.astype(np.int64, copy=False)
    keep = rows != cols
    key = np.unique(np.concatenate([rows[keep] * n_vertices + cols[keep],
                                    cols[keep] * n_vertices + rows[keep]]))
    indptr = np.zeros(n_vertices + 1, dtype=np.int64)
    np.cumsum(np.bincount(key // n_vertices, minlength=n_vertices), out=indptr[1:])
    return indptr, key % n_vertices


#: Vertices per chunk of the cross-edge pass (a chunk is a run of cells).
_CHUNK_VERTICES = 1 << 20


def _cross_edges(kernels, graph, cell, n_cells):
    """(a, b, saddle) of every pair of adjacent cells, a < b, with its highest saddle.

    The vertices are grouped by cell (a counting sort), then each cell's edges to
    cells with a larger id are reduced to one per partner: exactly one edge per pair,
    which is all the elder-rule union-find needs (a lower edge of a pair can never
    join two components). Cells are walked in the order of their first vertex (so
    the walk moves through memory), in chunks of about `_CHUNK_VERTICES` vertices run
    in parallel; each chunk gets room for 10 pairs per cell plus one per 16 vertices
    (quantized fields need about 8 per cell), and the chunks that overflow are rerun
    with exact room. The grouping is freed before the pieces are joined, so the peak
    stays near the field's own arrays (about 24 bytes per voxel in all at 256^3).
    """
    flat, grid, offsets, indptr, indices = (graph.values, graph.grid, graph.offsets,
                                            graph.indptr, graph.indices)
    n_real = len(graph.vertices)
    starts = np.empty(n_cells + 1, dtype=np.int64)
    members = np.empty(n_real, dtype=graph.vertices.dtype)
    kernels.group_by_cell(graph.vertices, cell, n_cells, starts, members)
    graph.vertices = None  # members hold every vertex now: 4 bytes per voxel less at the peak
    # Cells in the order of their first vertex, so that the walk moves through memory.
    # (A cell may have no vertex: the blockwise pass's cells seen only in a block's halo.)
    visit = np.argsort(members[np.minimum(starts[:-1], n_real - 1)], kind="stable").astype(np.int64)
    counts_in_order = np.diff(starts)[visit]
    n_chunks = max(1, min(256, -(-n_real // _CHUNK_VERTICES)))
    bounds = np.searchsorted(np.cumsum(counts_in_order),
                             np.linspace(0, n_real, n_chunks + 1)[1:], side="left") + 1
    bounds = np.minimum(np.concatenate([[0], bounds]), n_cells).astype(np.int64)
    bounds[-1] = n_cells
    chunks = np.arange(n_chunks, dtype=np.int64)
    cells_in = np.diff(bounds)
    vertices_in = np.add.reduceat(counts_in_order, np.minimum(bounds[:-1], n_cells - 1))
    vertices_in[cells_in == 0] = 0
    capacity = 10 * cells_in + vertices_in // 16 + 1024
    degree = len(offsets) if grid else int(np.diff(indptr).max(initial=0))
    # Partner table per chunk: twice the largest partner bound of its cells, a power of 2.
    sizes = np.minimum(degree * counts_in_order, n_cells)
    largest = np.maximum.reduceat(sizes, np.minimum(bounds[:-1], n_cells - 1))
    largest[cells_in == 0] = 0  # empty chunks (reduceat gives them a neighbour's)
    table_sizes = np.maximum(16, 2 ** np.ceil(np.log2(np.maximum(2 * largest, 1)))).astype(np.int64)
    args = (flat, members, starts, visit, bounds, grid, offsets, indptr, indices, cell, degree,
            table_sizes)
    out, out_starts, counts = _pair_pass(kernels, args, chunks, capacity)
    over = np.flatnonzero(counts > capacity)
    if len(over):
        room, room_starts, _ = _pair_pass(kernels, args, over, counts[over])
    del args, members, starts, visit
    pieces = []
    for c in range(n_chunks):
        if counts[c] <= capacity[c]:
            pieces.append([arr[out_starts[c]:out_starts[c] + counts[c]] for arr in out])
        else:
            k = int(np.searchsorted(over, c))
            pieces.append([arr[room_starts[k]:room_starts[k] + counts[c]] for arr in room])
    return tuple(np.concatenate([p[k] for p in pieces]) for k in range(3))


def _pair_pass(kernels, args, chunks, capacity):
    flat, members, starts, visit, bounds, grid, offsets, indptr, indices, cell, degree, sizes = args
    out_starts = np.concatenate([[0], np.cumsum(capacity)[:-1]]).astype(np.int64)
    counts = np.zeros(len(chunks), dtype=np.int64)
    total = int(capacity.sum())
    out = [np.empty(total, dtype=cell.dtype), np.empty(total, dtype=cell.dtype),
           np.empty(total, dtype=members.dtype)]
    kernels.cell_pairs(flat, members, starts, visit, bounds, chunks, grid, offsets, indptr,
                       indices, cell, degree, sizes, *out, out_starts,
                       capacity.astype(np.int64), counts)
    return out, out_starts, counts


def _saddle_order(keys, saddle, edge_a, edge_b):
    """Argsort of edges by (saddle value `keys`, saddle vertex, cell pair): the
    simulation of simplicity order, with the pair deciding between edges that share a
    saddle (also the blockwise build's, per block and on the client).

    An unstable value sort, then a compiled pass that orders each run of equal values
    (curvature fields have plateaus): 2x faster than np.lexsort at 256^3.
    """
    from . import _morse_kernels as kernels

    order = np.argsort(keys)
    kernels.break_ties(order, keys, saddle, edge_a, edge_b)
    return order


class _Phases:
    """Wall time per phase of the build, in the order they ran (`MorseHierarchy.timings`)."""

    def __init__(self):
        self.times = {}
        self._last = time.perf_counter()

    def done(self, name):
        now = time.perf_counter()
        self.times[name] = self.times.get(name, 0.0) + now - self._last
        self._last = now


@dataclass
class _Neighbourhood:
    """The graph the compiled passes walk, in one index space ("node" ids).

    On a grid, nodes are flat indices into the field padded by one layer of -inf
    (so no neighbour test needs a bounds check, and -inf is never higher than a
    vertex); voxels outside a mask hold -inf too, which removes their edges. On a
    graph, nodes are vertex indices and neighbours come from CSR arrays.

    values : flat float64 values per node; vertices : the nodes that take part
    (in increasing order, so ties break by field index in both spaces); offsets :
    flat neighbour offsets (grid) or empty; indptr, indices : CSR (graph) or dummies;
    to_field : node -> flat field index, for results.
    """

    values: NDArray[np.float64]
    vertices: NDArray
    grid: bool
    offsets: NDArray[np.int64]
    indptr: NDArray[np.int64]
    indices: NDArray[np.int64]
    padded_shape: tuple | None

    def to_field(self, nodes, shape) -> NDArray[np.int64]:
        if not self.grid:
            return np.asarray(nodes, dtype=np.int64)
        coords = np.unravel_index(nodes, self.padded_shape)
        return np.ravel_multi_index(tuple(c - 1 for c in coords), shape)


def _validate_field(field, mask, adjacency) -> tuple:
    """(float64 values, bool mask or None), checked."""
    field = np.asarray(field)
    if field.dtype.kind not in "biuf":
        raise ValueError(f"`field` must hold real numbers, got dtype {field.dtype}")
    if field.size == 0:
        raise ValueError("`field` is empty")
    values = np.ascontiguousarray(field, dtype=np.float64)  # flat indices are C order
    if mask is not None:
        mask = np.asarray(mask)
        if mask.dtype != bool or mask.shape != field.shape:
            raise ValueError(f"`mask` must be a boolean array of the field's shape {field.shape}, "
                             f"got {mask.dtype} {mask.shape}")
        if not mask.any():
            raise ValueError("`mask` selects no vertex")
    finite = np.isfinite(values) if mask is None else np.isfinite(values) | ~mask
    if not finite.all():
        bad = np.argwhere(~finite)[0].tolist()
        raise ValueError(f"`field` holds {int((~finite).sum())} NaN or infinite values "
                         f"(first at index {bad})")
    if adjacency is not None and field.ndim != 1:
        raise ValueError(f"with `adjacency`, `field` must be 1-D (one value per vertex), "
                         f"got shape {field.shape}")
    if adjacency is None and field.ndim > 3:
        raise ValueError(f"grid fields must be 1-D, 2-D or 3-D, got shape {field.shape}")
    return values, mask


def _neighbourhood(values, mask, adjacency, connectivity) -> _Neighbourhood:
    empty = np.zeros(0, dtype=np.int64)
    if adjacency is not None:
        indptr, indices = _csr_adjacency(adjacency, values.size)
        if mask is not None:  # drop every edge with an end outside the mask
            values = np.where(mask, values, -np.inf)
        vertices = np.arange(values.size, dtype=np.int64) if mask is None else np.flatnonzero(mask)
        return _Neighbourhood(values, vertices, False, empty, indptr, indices, None)
    steps = grid_offsets(values.ndim, connectivity)
    padded = np.pad(values if mask is None else np.where(mask, values, -np.inf), 1,
                    constant_values=-np.inf)
    strides = np.array([s // padded.itemsize for s in padded.strides], dtype=np.int64)
    index_type = np.int32 if padded.size < 2**31 - 1 else np.int64
    node = np.zeros((1,) * values.ndim, dtype=index_type)
    for axis, (size, stride) in enumerate(zip(values.shape, strides, strict=True)):
        step = ((np.arange(size) + 1) * stride).astype(index_type)
        node = node + step.reshape([-1 if a == axis else 1 for a in range(values.ndim)])
    vertices = node.ravel() if mask is None else node[mask]
    dummy = np.zeros(1, dtype=np.int64)
    return _Neighbourhood(padded.ravel(), vertices, True, (steps @ strides).astype(np.int64),
                          dummy, dummy, padded.shape)


def _descending_cells(kernels, graph: _Neighbourhood, phases: _Phases):
    """(cell per node, -1 off the vertices; maxima nodes by decreasing value): cell[v] is
    the id of the maximum v's steepest ascent reaches."""
    index_type = np.int32 if len(graph.values) < 2**31 - 1 else np.int64
    up = np.empty(len(graph.values), dtype=index_type)
    kernels.steepest_ascent(graph.values, graph.vertices, graph.grid, graph.offsets,
                            graph.indptr, graph.indices, up)
    phases.done("steepest ascent")
    cell = np.full(len(graph.values), -1, dtype=index_type)
    kernels.resolve_cells(graph.vertices, up, cell)
    phases.done("path compression")
    maxima = kernels.roots(graph.vertices, up)
    # Maximum ids by decreasing value (simulation of simplicity: then by index).
    maxima = maxima[np.lexsort((maxima, graph.values[maxima]))[::-1]]
    up[maxima] = np.arange(len(maxima), dtype=index_type)  # up is free now: root -> id
    kernels.relabel(graph.vertices, cell, up)
    phases.done("maxima order and relabel")
    return cell, maxima


@dataclass
class _MergeEvents:
    """Elder-rule merges, in sweep order: `young` dies into `elder`'s component at the
    saddle node `saddle`; `target` is the cell across the saddle edge."""

    young: NDArray[np.int32]
    elder: NDArray[np.int32]
    target: NDArray[np.int32]
    saddle: NDArray[np.int64]


def _merge_events(kernels, graph: _Neighbourhood, cell, n_maxima,
                  phases: _Phases) -> _MergeEvents:
    """One edge per pair of adjacent cells (its highest saddle), sorted by (saddle value,
    saddle vertex, pair), then one Kruskal over them from the highest saddle down."""
    edge_a, edge_b, edge_v = _cross_edges(kernels, graph, cell, n_maxima)
    phases.done("cross-cell edges")
    order = _saddle_order(graph.values[edge_v], edge_v, edge_a, edge_b)
    phases.done("saddle order (sort, ties)")
    sorted_edges = [np.empty_like(edge_a), np.empty_like(edge_b), np.empty_like(edge_v)]
    kernels.gather(order, edge_a, edge_b, edge_v, *sorted_edges)
    del order, edge_a, edge_b, edge_v
    out = [np.empty(max(n_maxima - 1, 0), dtype=t) for t in (np.int32, np.int32, np.int32, np.int64)]
    n_events = kernels.kruskal(*sorted_edges, n_maxima, *out)
    phases.done("union-find")
    return _MergeEvents(*(a[:n_events].copy() for a in out))


def descending_complex(field: ArrayLike, *, adjacency=None, connectivity="kuhn",
                       mask=None) -> "MorseHierarchy":
    """Descending Morse complex of `field` and its persistence hierarchy.

    Parameters
    ----------
    field : ndarray of real, or 3-D Dask array
        On a grid: an N-d array (1-D, 2-D or 3-D), neighbours by `connectivity`.
        On a graph: a 1-D array, one value per vertex, with `adjacency`. A Dask
        array is built block by block (DESIGN.md section 10), the same result.
    adjacency : scipy sparse matrix, (E, 2) int array or networkx graph, optional
        Vertex adjacency (symmetrised; self-loops ignored). Structure, not weight:
        any stored nonzero of a sparse matrix is an edge, whatever its value or
        sign. For a networkx graph, ``field[i]`` is the value of the i-th node of
        ``list(graph.nodes)``.
    connectivity : {'kuhn', 4, 8, 6, 18, 26, 2}
        Grid neighbourhood (see `grid_offsets`); ignored with `adjacency`.
    mask : bool ndarray (or Dask array) of the field's shape, optional
        The vertices that take part (DESIGN.md section 9): the graph is restricted
        to them (an edge only between two masked vertices), so maxima, cells,
        saddles and persistence are those of the foreground, exactly as with the
        explicit restricted adjacency; values outside the mask are ignored (they may
        be NaN). Cuts label unmasked vertices 0 and regions 1..k.

    Returns
    -------
    MorseHierarchy

    Raises
    ------
    ValueError
        NaN or infinite values (inside the mask), a non-numeric field, adjacency of
        the wrong size or with out-of-range vertices, an unknown connectivity, a
        mask of the wrong shape or type, or one that selects nothing.
    """
    from . import _morse_kernels as kernels

    if type(field).__module__.startswith("dask."):
        if adjacency is not None:
            raise ValueError("a Dask `field` is segmented on its grid; compute it (numpy) "
                             "to use `adjacency`")
        from ._morse_blocks import dask_descending_complex

        return dask_descending_complex(field, connectivity, mask=mask)
    phases = _Phases()
    values, mask = _validate_field(field, mask, adjacency)
    graph = _neighbourhood(values, mask, adjacency, connectivity)
    phases.done("checks and neighbourhood")
    cell, maxima = _descending_cells(kernels, graph, phases)
    events = _merge_events(kernels, graph, cell, len(maxima), phases)
    shape = values.shape
    if graph.grid:
        cells = cell.reshape(graph.padded_shape)[(slice(1, -1),) * values.ndim].astype(np.int32)
    else:
        cells = cell.astype(np.int32, copy=False)
    del cell
    maxima = graph.to_field(maxima, shape)
    saddles = graph.to_field(events.saddle, shape)
    phases.done("cells and indices out")
    return MorseHierarchy(
        shape=shape,
        cells=cells,
        maxima=maxima,
        values=values.ravel()[maxima],
        young=events.young,
        elder=events.elder,
        target=events.target,
        saddle=saddles,
        saddle_value=values.ravel()[saddles],
        mask=mask,
        _field=values,
        _adjacency=None if graph.grid else (graph.indptr, graph.indices),
        _connectivity=connectivity if graph.grid else None,
        timings=phases.times,
    )


@dataclass(eq=False)
class MorseHierarchy:
    """The descending Morse complex of a field and its merge hierarchy.

    Attributes
    ----------
    shape : tuple
        The field's shape; labels have it.
    cells : ndarray of int32, `shape`
        The unsimplified descending cells: the id of each vertex's maximum.
    maxima : (M,) ndarray of int
        Flat vertex index of each maximum, by decreasing value (id = position).
    values : (M,) ndarray of float
        Field value at each maximum.
    young, elder, target : (E,) ndarray of int32
        Merge events, in sweep order (decreasing saddle value): maximum ``young``
        dies into the component of ``elder`` (elder rule); its cell joins the cell
        ``target`` across the saddle edge when simplified.
    saddle : (E,) ndarray of int
        Flat vertex index of each event's saddle (the lower end of the highest edge
        crossing between the two components).
    saddle_value : (E,) ndarray of float
    mask : bool ndarray of `shape`, or None
        The vertices that took part; cuts label the others 0 and regions 1..k.
        Without a mask, regions are 0..k-1.
    timings : dict
        Seconds per phase of the build (steepest ascent, path compression, ...).
    """

    shape: tuple
    cells: NDArray[np.int32]
    maxima: NDArray[np.int64]
    values: NDArray[np.float64]
    young: NDArray[np.int32]
    elder: NDArray[np.int32]
    target: NDArray[np.int32]
    saddle: NDArray[np.int64]
    saddle_value: NDArray[np.float64]
    mask: NDArray[np.bool_] | None
    _field: NDArray[np.float64]
    _adjacency: tuple | None = None
    _connectivity: object = None
    timings: dict = dataclass_field(default_factory=dict, repr=False)

    @property
    def persistence(self) -> NDArray[np.float64]:
        """(M,) persistence of each maximum, aligned with `maxima`; inf for survivors."""
        out = np.full(len(self.maxima), np.inf)
        out[self.young] = self.values[self.young] - self.saddle_value
        return out

    @property
    def event_persistence(self) -> NDArray[np.float64]:
        """(E,) persistence of each merge event."""
        return self.values[self.young] - self.saddle_value

    @property
    def n_components(self) -> int:
        """Connected components of the graph (regions that can never merge)."""
        return len(self.maxima) - len(self.young)

    def threshold_for(self, n_regions: int) -> float:
        """A persistence threshold whose cut has `n_regions` regions, if ties allow.

        The midpoint between the persistences of the last kept and the first merged
        event; `segment(n_regions=k)` is exact even where ties make no threshold so.
        """
        _, n_regions = check_cut(n_regions=n_regions)
        p = np.sort(self.event_persistence)[::-1]
        keep = n_regions - self.n_components
        if keep <= 0:
            return float(p[0]) + 1.0 if len(p) else 0.0
        if keep >= len(p):
            return 0.0
        return 0.5 * float(p[keep - 1] + p[keep])

    def regions_at(self, thresholds) -> NDArray[np.int64]:
        """Region count of the cut at each persistence threshold (the persistence curve)."""
        p = np.sort(self.event_persistence)
        return self.n_components + len(p) - np.searchsorted(p, np.asarray(thresholds), side="left")

    def largest_gap(self, region_range=(20, 40)) -> int:
        """The region count k in `region_range` (inclusive) whose cut sits in the widest
        gap between consecutive persistences, on a log scale: the most clearly
        separated simplification. Falls back to the range's ends when the hierarchy
        has fewer maxima."""
        lo, hi = (int(r) for r in region_range)
        p = np.sort(self.event_persistence)[::-1]
        best, best_gap = None, -np.inf
        for k in range(max(lo, self.n_components), hi + 1):
            keep = k - self.n_components
            if keep < 1 or keep >= len(p):
                continue
            gap = np.log(p[keep - 1]) - np.log(p[keep]) if p[keep] > 0 else np.inf
            if gap > best_gap:
                best, best_gap = k, gap
        if best is None:
            return max(min(hi, len(self.maxima)), 1)
        return best

    def _merged_events(self, min_persistence, n_regions):
        p = self.event_persistence
        min_persistence, n_regions = check_cut(min_persistence, n_regions)
        if n_regions is not None:
            if n_regions > len(self.maxima):
                warnings.warn(
                    f"asked for {n_regions} regions but the field has only "
                    f"{len(self.maxima)} maxima; returning all of them", stacklevel=3)
            elif n_regions < self.n_components:
                warnings.warn(
                    f"asked for {n_regions} regions but the graph has {self.n_components} "
                    "connected components; returning one region per component", stacklevel=3)
            return _all_but_most_persistent(p, self.young, max(n_regions - self.n_components, 0))
        return p < (0.0 if min_persistence is None else min_persistence)

    def region_of_maximum(self, min_persistence=None, n_regions=None) -> NDArray[np.int32]:
        """(M,) region label of each maximum for a cut (see `segment`): the maxima
        joined by the merged events, regions numbered by their highest maximum (a
        compiled union-find: 8 M maxima take a few hundred ms and a few bytes each)."""
        from . import _morse_kernels

        merged = self._merged_events(min_persistence, n_regions)
        region = np.empty(len(self.maxima), dtype=np.int32)
        _morse_kernels.regions_of_cut(self.young, self.target, merged, region)
        return region

    def segment(self, min_persistence: float | None = None, n_regions: int | None = None):
        """Labels of a cut of the hierarchy: no recomputation, one gather per vertex.

        Parameters
        ----------
        min_persistence : float, optional
            Merge every maximum with persistence below it (default 0: the
            unsimplified complex).
        n_regions : int, optional
            Instead, exactly this many regions: the ``n_regions - 1`` most
            persistent non-global maxima stay (ties broken by maximum value). Fewer
            maxima than asked: all of them, with a warning.

        Returns
        -------
        ndarray of int32, `shape`
            Consecutive labels 0..k-1, ordered by decreasing maximum value; with a
            mask, 0 outside it and regions 1..k.
        """
        return self.relabel(self.region_of_maximum(min_persistence, n_regions))

    def relabel(self, region):
        """Labels of every vertex from the region of each maximum (the result of
        `region_of_maximum`): what `segment` returns, for a caller that needs the
        regions too."""
        if type(self.cells).__module__.startswith("dask."):   # blockwise: relabel per block
            import dask

            # The table as one shared task: a distributed scheduler sends it to each
            # worker once, not inside every block's task.
            table = dask.delayed(_with_outside(region, self.mask), pure=True)
            return self.cells.map_blocks(lambda cells, table: table[cells], table,
                                         dtype=region.dtype,
                                         meta=np.empty((0,) * self.cells.ndim, region.dtype))
        return _with_outside(region, self.mask)[self.cells]

    def region_adjacency(self, labels=None, **cut):
        """The regions of a cut as a networkx graph.

        Nodes are region labels with ``size``, ``maximum`` (flat vertex index) and
        ``value``; edges join adjacent regions with ``saddle`` (the highest value
        min(f(u), f(v)) over edges (u, v) crossing between them). `labels`
        defaults to ``segment(**cut)``. With a mask, label 0 (outside it) is not
        a region: it has no node and no edges.
        """
        import networkx as nx

        if labels is None:
            labels = self.segment(**cut)
        labels = np.asarray(labels)
        if labels.shape != tuple(self.shape):
            raise ValueError(f"`labels` must have the field's shape {tuple(self.shape)}, "
                             f"got {labels.shape}")
        if labels.dtype.kind not in "biu" or (labels.size and labels.min() < 0):
            raise ValueError("`labels` must hold non-negative integer labels")
        f = self._field
        pairs, saddles = [], []
        if self._adjacency is None:
            for step in grid_offsets(len(self.shape), self._connectivity):
                if tuple(step) <= (0,) * len(step):
                    continue
                src = tuple(slice(max(-s, 0), n - max(s, 0)) for s, n in zip(step, self.shape, strict=True))
                dst = tuple(slice(max(s, 0), n - max(-s, 0)) for s, n in zip(step, self.shape, strict=True))
                a, b = labels[src].ravel(), labels[dst].ravel()
                cross = a != b
                pairs.append(np.sort(np.stack([a[cross], b[cross]], 1), axis=1))
                saddles.append(np.minimum(f[src].ravel()[cross], f[dst].ravel()[cross]))
        else:
            indptr, indices = self._adjacency
            u = np.repeat(np.arange(len(indptr) - 1), np.diff(indptr))
            a, b = labels[u], labels[indices]
            cross = a < b
            pairs.append(np.stack([a[cross], b[cross]], 1))
            saddles.append(np.minimum(f[u[cross]], f[indices[cross]]))
        pairs = np.concatenate(pairs) if pairs else np.zeros((0, 2), int)
        saddles = np.concatenate(saddles) if saddles else np.zeros(0)
        first = 0
        if self.mask is not None:  # label 0 is outside the mask: no edges, no node
            inside = pairs[:, 0] > 0
            pairs, saddles, first = pairs[inside], saddles[inside], 1
        graph = nx.Graph()
        flat_labels = labels.ravel()
        flat_field = f.ravel()
        sizes = np.bincount(flat_labels)
        # Highest vertex per region under simulation of simplicity: the last write wins.
        order = np.lexsort((np.arange(flat_field.size), flat_field))
        top = np.full(len(sizes), -1)
        top[flat_labels[order]] = order
        for region in range(first, len(sizes)):
            graph.add_node(region, size=int(sizes[region]), maximum=int(top[region]),
                           value=float(flat_field[top[region]]))
        if len(pairs):
            key = pairs[:, 0].astype(np.int64) * len(sizes) + pairs[:, 1]
            order = np.lexsort((saddles, key))
            last = np.r_[key[order][1:] != key[order][:-1], True]
            for k, s in zip(key[order][last], saddles[order][last], strict=True):
                graph.add_edge(int(k // len(sizes)), int(k % len(sizes)), saddle=float(s))
        return graph


def _all_but_most_persistent(p, young, keep):
    """True for every event but the `keep` most persistent; ties: the older (lower id)
    young maximum first. The order of ``np.lexsort((young, -p))[:keep]``, in linear
    time: the keep-th largest persistence by a partition, then only its ties sorted
    (a full sort of 8 M events took 3 s per cut at 512^3)."""
    merged = np.ones(len(p), dtype=bool)
    if keep <= 0:
        return merged
    if keep >= len(p):
        return ~merged
    kth = np.partition(p, len(p) - keep)[len(p) - keep]      # the keep-th largest
    above = p > kth
    ties = np.flatnonzero(p == kth)
    chosen = ties[np.argsort(young[ties], kind="stable")[:keep - int(above.sum())]]
    merged[above] = False
    merged[chosen] = False
    return merged


def _with_outside(region, mask):
    """The relabelling table of a cut: `region` without a mask; with one, regions
    1..k and a last entry 0 for the cells of -1 (outside the mask)."""
    if mask is None:
        return region
    return np.concatenate([region + 1, np.zeros(1, dtype=region.dtype)])
