"""The in-memory build of the descending complex: steepest ascent and path
compression to cells, one edge per pair of adjacent cells with its highest saddle,
then the elder-rule union-find (docs/design.md section 5)."""

from __future__ import annotations

from contextlib import nullcontext
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._buffers import room_to_pad
from .._distinct import index_type
from . import _kernels as kernels
from ._edges import _cross_edges, spanning_forest
from ._graph import PaddedInPlace, _Neighbourhood, _neighbourhood, _validate_field
from ._hierarchy import MorseHierarchy
from ._phases import _Phases

__all__ = ["descending_complex"]


def _descending_cells(graph: _Neighbourhood, phases: _Phases):
    """(cell per node, -1 off the vertices; maxima nodes by decreasing value): cell[v] is
    the id of the maximum v's steepest ascent reaches."""
    index = index_type(len(graph.values) + 1)
    # One node-sized array, `up`, becomes the cells in place (4-8 bytes a voxel less
    # than a second one): -1 off the vertices, the ascent's step, the root, the id.
    up = np.full(len(graph.values), -1, dtype=index)
    steps, fixed = kernels.unrolled(graph.offsets)
    if graph.grid and fixed:
        kernels.steepest_ascent_unrolled(graph.values, graph.vertices, steps, up)
    else:
        kernels.steepest_ascent(graph.values, graph.vertices, graph.grid, graph.offsets,
                                graph.indptr, graph.indices, up)
    phases.done("steepest ascent")
    kernels.resolve_cells(graph.vertices, up, up)     # up[v] = its root, compressed
    phases.done("path compression")
    maxima = kernels.roots(graph.vertices, up)
    # Maximum ids by decreasing value (simulation of simplicity: then by index).
    maxima = maxima[np.lexsort((maxima, graph.values[maxima]))[::-1]]
    kernels.relabel_roots(graph.vertices, up, maxima)
    phases.done("maxima order and relabel")
    return up, maxima


@dataclass
class _MergeEvents:
    """Elder-rule merges, in sweep order: `young` dies into `elder`'s component at the
    saddle node `saddle`; `target` and `source` are the cells of the saddle edge on the
    elder's and on the young's side."""

    young: NDArray[np.int32]
    elder: NDArray[np.int32]
    target: NDArray[np.int32]
    source: NDArray[np.int32]
    saddle: NDArray[np.int64]


def _merge_events(graph: _Neighbourhood, cell, n_maxima,
                  phases: _Phases) -> _MergeEvents:
    """One edge per pair of adjacent cells (its highest saddle); the maximum spanning
    forest of them in the order (saddle value, saddle vertex, pair), then one Kruskal
    over its edges from the highest saddle down."""
    edge_a, edge_b, edge_v = _cross_edges(graph, cell, n_maxima, cells_mark_vertices=True)
    phases.done("cross-cell edges")
    # Only the cell graph's maximum spanning forest can merge two components.
    keys = graph.values[edge_v]
    order = spanning_forest(keys, edge_v, edge_a, edge_b, n_maxima, ordered=True)
    del keys
    phases.done("saddle order (spanning forest, sort, ties)")
    sorted_edges = [np.empty(len(order), dtype=e.dtype) for e in (edge_a, edge_b, edge_v)]
    kernels.gather(order, edge_a, edge_b, edge_v, *sorted_edges)
    del order, edge_a, edge_b, edge_v
    out = [np.empty(max(n_maxima - 1, 0), dtype=t)
           for t in (np.int32, np.int32, np.int32, np.int32, np.int64)]
    n_events = kernels.kruskal(*sorted_edges, n_maxima, *out)
    phases.done("union-find")
    return _MergeEvents(*(a[:n_events].copy() for a in out))


def descending_complex(field: ArrayLike, *, adjacency=None, connectivity="kuhn",
                       mask=None, block_hooks=None, on_workers=False,
                       overwrite_field=False) -> "MorseHierarchy":
    """Descending Morse complex of `field` and its persistence hierarchy.

    Parameters
    ----------
    field : ndarray of real, or 3-D Dask array
        On a grid: an N-d array (1-D, 2-D or 3-D), neighbours by `connectivity`.
        On a graph: a 1-D array, one value per vertex, with `adjacency`. A Dask
        array is built block by block (docs/design.md section 10), the same result.
    adjacency : scipy sparse matrix, (E, 2) int array or networkx graph, optional
        Vertex adjacency (symmetrised; self-loops ignored). Structure, not weight:
        any stored nonzero of a sparse matrix is an edge, whatever its value or
        sign. For a networkx graph, ``field[i]`` is the value of the i-th node of
        ``list(graph.nodes)``.
    connectivity : {'kuhn', 4, 8, 6, 18, 26, 2}
        Grid neighbourhood (see `grid_offsets`); ignored with `adjacency`.
    mask : bool ndarray (or Dask array) of the field's shape, optional
        The vertices that take part (docs/design.md section 9): the graph is restricted
        to them (an edge only between two masked vertices), so maxima, cells,
        saddles and persistence are those of the foreground, exactly as with the
        explicit restricted adjacency; values outside the mask are ignored (they may
        be NaN). Cuts label unmasked vertices 0 and regions 1..k.
    block_hooks : volseg._block_hooks.BlockHooks, optional
        For a Dask `field`: how its blocks are kept and computed (the blockwise
        pipeline's work folder and progress); default plain Dask.
    on_workers : bool
        For a Dask `field`: return the `HierarchyOnWorkers` (its per-maximum arrays
        kept where they were assembled, cut there) rather than fetching it whole to
        this process; anything of `MorseHierarchy` read from it fetches it.
    overwrite_field : bool
        Let the build use the field's own memory as its padded work array (8 bytes a
        voxel less at the peak), when it can: a 3-D float64 C-ordered numpy field at
        the start of a buffer with room for it padded by one voxel on every side, as
        `volseg.curvature` leaves its result. The field holds its own values again,
        bit for bit, when the call returns or raises; no other thread may read it
        meanwhile. The result is the same.

    Returns
    -------
    MorseHierarchy
        Cut it with ``segment(min_persistence=...)`` or ``segment(n_regions=...)``,
        by any measure of `volseg.morse.MEASURE_REGISTRY`, without recomputation.

    See Also
    --------
    MorseHierarchy.segment : labels of a cut.
    volseg.segment_volume : the whole pipeline on a volume.
    skimage.segmentation.watershed : flooding from markers (h-maxima), a relative.
    higra.watershed_hierarchy_by_dynamics : the same hierarchy up to ties.

    Notes
    -----
    Each vertex joins the cell of the maximum its steepest ascent reaches; the cells'
    merge events follow the elder rule over the highest saddle between adjacent cells
    (Edelsbrunner et al. [1]_), ties broken by vertex index (simulation of simplicity);
    a cut by size or hypervolume prunes them as Carr et al. [2]_.

    References
    ----------
    .. [1] H. Edelsbrunner, D. Letscher, A. Zomorodian, "Topological persistence and
           simplification", Discrete & Computational Geometry 28, 2002.
    .. [2] H. Carr, J. Snoeyink, M. van de Panne, "Simplifying flexible isosurfaces
           using local geometric measures", IEEE Visualization 2004.

    Examples
    --------
    >>> import numpy as np
    >>> from volseg.morse import descending_complex
    >>> field = np.array([0.0, 3.0, 1.0, 2.0, 0.5])     # peaks at 1 and 3
    >>> hierarchy = descending_complex(field)
    >>> hierarchy.persistence.tolist()
    [inf, 1.0]
    >>> hierarchy.segment(n_regions=2).tolist(), hierarchy.segment(min_persistence=1.5).tolist()
    ([1, 1, 1, 2, 2], [1, 1, 1, 1, 1])

    Raises
    ------
    ValueError
        NaN or infinite values (inside the mask), a non-numeric field, adjacency of
        the wrong size or with out-of-range vertices, an unknown connectivity, a
        mask of the wrong shape or type, or one that selects nothing.
    """
    if type(field).__module__.startswith("dask."):
        if adjacency is not None:
            raise ValueError("a Dask `field` is segmented on its grid; compute it (numpy) "
                             "to use `adjacency`")
        from .blocks import dask_hierarchy  # the distributed build, on Dask input only

        hierarchy = dask_hierarchy(field, connectivity, mask=mask, hooks=block_hooks)
        return hierarchy if on_workers else hierarchy.fetch()
    phases = _Phases()
    values, mask = _validate_field(field, mask, adjacency)
    buffer = room_to_pad(values) if overwrite_field and adjacency is None else None
    if buffer is None:
        built = nullcontext(_neighbourhood(values, mask, adjacency, connectivity))
    else:       # the field's values back in place as the block ends, however it ends
        built = PaddedInPlace(values, buffer, mask, connectivity)
    with built as graph:
        phases.done("checks and neighbourhood")
        cell, maxima = _descending_cells(graph, phases)
        events = _merge_events(graph, cell, len(maxima), phases)
        maxima_values, saddle_values = graph.values[maxima], graph.values[events.saddle]
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
        values=maxima_values,
        young=events.young,
        elder=events.elder,
        target=events.target,
        source=events.source,
        saddle=saddles,
        saddle_value=saddle_values,
        mask=mask,
        _field=values,
        _adjacency=None if graph.grid else (graph.indptr, graph.indices),
        _connectivity=connectivity if graph.grid else None,
        timings=phases.times,
    )
