"""The graph the Morse passes walk: grid connectivities, CSR adjacency from any
graph input, the checked field and its neighbourhood in one index space."""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from .. import _kuhn
from .._buffers import padded_size
from .._distinct import distinct, index_type

__all__ = ["grid_offsets"]


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
    key = distinct(np.concatenate([rows[keep] * n_vertices + cols[keep],
                                    cols[keep] * n_vertices + rows[keep]]))
    indptr = np.zeros(n_vertices + 1, dtype=np.int64)
    np.cumsum(np.bincount(key // n_vertices, minlength=n_vertices), out=indptr[1:])
    return indptr, key % n_vertices

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


#: The largest integer magnitude float64 holds exactly (every integer up to it).
EXACT_INTEGER = 2**53


def _exactly_float(field) -> None:
    """Refuse 64-bit integers that float64 would round: two maxima 1 apart above 2^53
    would become one plateau and one maximum, silently."""
    if field.dtype.kind in "iu" and field.dtype.itemsize >= 8 and field.size:
        low, high = int(field.min()), int(field.max())
        if max(abs(low), abs(high)) > EXACT_INTEGER:
            raise ValueError(f"`field` holds {field.dtype} values up to {max(abs(low), high)}, "
                             f"beyond 2^53, where float64 (the Morse stage's order) "
                             "rounds distinct integers together; subtract an offset or "
                             "give their ranks (e.g. scipy.stats.rankdata)")


def _validate_field(field, mask, adjacency) -> tuple:
    """(float64 values, bool mask or None), checked."""
    field = np.asarray(field)
    if field.dtype.kind not in "biuf":
        raise ValueError(f"`field` must hold real numbers, got dtype {field.dtype}")
    if field.size == 0:
        raise ValueError("`field` is empty")
    if field.ndim == 0:
        raise ValueError("`field` is a single number; give an array (one value per vertex)")
    _exactly_float(field)
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
    # -inf around the grid and, with a mask, at every vertex outside it: written into
    # the padded array directly, no full-size temporary on the way.
    padded = np.full(tuple(n + 2 for n in values.shape), -np.inf)
    np.copyto(padded[(slice(1, -1),) * values.ndim], values,
              where=True if mask is None else mask)
    return _grid_graph(padded, mask, connectivity)


def _grid_graph(padded, mask, connectivity) -> _Neighbourhood:
    """The grid neighbourhood of `padded` (the field with its -inf layer and -inf
    outside `mask`)."""
    ndim = padded.ndim
    steps = grid_offsets(ndim, connectivity)
    strides = np.array([s // padded.itemsize for s in padded.strides], dtype=np.int64)
    index = index_type(padded.size + 1)
    node = np.zeros((1,) * ndim, dtype=index)
    for axis, (size, stride) in enumerate(zip(padded.shape, strides, strict=True)):
        step = ((np.arange(size - 2) + 1) * stride).astype(index)
        node = node + step.reshape([-1 if a == axis else 1 for a in range(ndim)])
    vertices = node.ravel() if mask is None else node[mask]
    dummy = np.zeros(1, dtype=np.int64)
    return _Neighbourhood(padded.ravel(), vertices, True, (steps @ strides).astype(np.int64),
                          dummy, dummy, padded.shape)


class PaddedInPlace:
    """The grid neighbourhood of a 3-D float64 field built in the field's own buffer
    (`volseg._buffers.room_to_pad`): no 8-byte-a-voxel padded copy. Entering moves the
    values to their padded places slab by slab (each to a higher address, last first),
    writes -inf around them and outside the mask (those values kept aside); leaving
    moves back the slabs moved (first first) and restores the kept values, whatever
    happened inside, an interrupt during the move included: the field holds its own
    values again, bit for bit. Nothing else may read the field meanwhile."""

    def __init__(self, values, buffer, mask, connectivity):
        self.values, self.buffer, self.mask = values, buffer, mask
        self.connectivity, self._kept = connectivity, None
        shape = values.shape
        self._padded = buffer[:padded_size(shape)].reshape(tuple(n + 2 for n in shape))
        self._flat = buffer[:values.size].reshape(shape[0], -1)
        self._moved = len(self._flat)        # slabs from here on are in padded places

    def __enter__(self) -> _Neighbourhood:
        padded = self._padded
        try:
            # Every padded slab starts above the end of its flat slab and all before it.
            for x in range(len(self._flat) - 1, -1, -1):
                self._move_up(x)
                self._moved = x
            for axis in range(3):
                edges = (slice(None),) * axis
                padded[(*edges, 0)] = padded[(*edges, -1)] = -np.inf
            if self.mask is not None:
                inner, outside = padded[1:-1, 1:-1, 1:-1], ~self.mask
                self._kept = inner[outside]
                inner[outside] = -np.inf
            return _grid_graph(padded, self.mask, self.connectivity)
        except BaseException:
            self._back()
            raise

    def __exit__(self, *exc) -> None:
        self._back()

    def _move_up(self, x: int) -> None:
        self._padded[x + 1, 1:-1, 1:-1] = self._flat[x].reshape(self.values.shape[1:])

    def _back(self) -> None:
        inner, flat = self._padded[1:-1, 1:-1, 1:-1], self._flat
        if self._kept is not None:           # gathered after the whole move
            inner[~self.mask] = self._kept
            self._kept = None
        for x in range(self._moved, len(flat)):  # every flat slab ends below its padded one
            flat[x] = inner[x].reshape(-1)
        self._moved = len(flat)
