"""`descending_complex` of a 3-D Dask array: the in-memory build, block by block
(DESIGN.md section 10).

1. Per block, with a 1-voxel halo (-inf outside the volume; `volseg._halo`, which
   frees each block once its halo layers are copied): steepest ascent and path
   compression inside the block (`_block_kernels.ascend`). A path ends at a
   maximum of the block or leaves it; a path that leaves lands on a neighbouring
   block's outer layer. Each block returns its maxima and the ends of its outer
   layer's paths, a few percent of its voxels.
2. On the client: the outer-layer ends are resolved to maxima by pointer jumping
   (the chains follow strictly rising values, so they end), and the maxima are
   numbered by decreasing (value, index), as in memory.
3. Per block again: cells = maximum id of each voxel, from the path ends the ascent
   kept on disk (the hooks' `scratch` folder: the blockwise work folder), or, without
   one, by climbing again (so no block-sized intermediate outlives its task).
4. Per block, cells and values with a halo: the in-memory cross-edge pass on the
   block (every edge between two cells, seen from its smaller cell's voxel, with its
   lower end as saddle, reduced to the highest saddle per pair of cells), then the
   block's maximum spanning forest in the sweep order (value, saddle index, pair):
   the only edges that can merge components, about one per cell.
5. On the client: the union of the blocks' forests (a pair found by two blocks stays
   twice; the lower edge closes a cycle), the in-memory sort and the same Kruskal:
   the same maxima, events and persistence as in memory, for any chunking (tested).

The returned `MorseHierarchy` holds the per-maximum data and the events in memory and
its `cells` as a lazy Dask array; `segment` relabels block by block.
"""

from __future__ import annotations

import os
import shutil
from dataclasses import dataclass

import numpy as np

from .. import _atomic
from .._block_hooks import BlockHooks
from .._halo import block_starts, with_halo
from . import _block_kernels as kernels
from . import _kernels
from ._edges import _cross_edges, _saddle_order
from ._graph import _Neighbourhood, grid_offsets
from ._hierarchy import MorseHierarchy
from ._phases import _Phases

__all__ = ["dask_descending_complex"]


def _ascend(halo, origin, shape, offsets, masked):
    result = np.empty(tuple(s - 2 for s in halo.shape), dtype=np.int64)
    values = np.ascontiguousarray(halo, dtype=np.float64)
    # The halo's -inf marks outside the volume; the block's own voxels must be finite
    # (the neighbours' are checked by their own blocks), or -inf outside a mask
    # (`_masked`, which checked the values inside it).
    inner = values[1:-1, 1:-1, 1:-1]
    if not (np.isfinite(inner) | (masked & (inner == -np.inf))).all():
        raise ValueError("`field` holds NaN or infinite values")
    kernels.ascend(values, np.asarray(origin, dtype=np.int64), np.asarray(shape, dtype=np.int64),
                   offsets, result)
    return result, values


def _outer_layer(block):
    """Flat local indices of a block's outer layer (its voxels next to other blocks)."""
    mask = np.zeros(block.shape, dtype=bool)
    for axis in range(3):
        index = [slice(None)] * 3
        for end in (0, -1):
            index[axis] = end
            mask[tuple(index)] = True
    return np.flatnonzero(mask)


def _masked(field, mask):
    """The field inside the mask, -inf outside it (DESIGN.md section 9: no edge has an
    end outside); NaN or infinite values inside the mask are refused."""
    values = np.asarray(field, dtype=np.float64)
    if not np.isfinite(values[mask]).all():
        raise ValueError("`field` holds NaN or infinite values inside the mask")
    return np.where(mask, values, -np.inf)


def _summary_of_block(halo, origin, shape, offsets, masked, ends_file=None):
    """Stage 1: (maxima gids, their values, outer-layer gids, their path ends); the
    outer layer's voxels outside the mask are left out (no path reaches them).
    `ends_file`: also keep every voxel's path end there (for `_cells_of_ends`)."""
    result, values = _ascend(halo, origin, shape, offsets, masked)
    if ends_file is not None:
        _atomic.write_atomically(ends_file, np.save, result)
    a, b, c = result.shape
    local = np.arange(result.size).reshape(result.shape)
    gids = ((origin[0] + local // (b * c)) * shape[1] + origin[1] + (local // c) % b) * shape[2] \
        + origin[2] + local % c
    flat = result.ravel()
    is_max = flat == gids.ravel()
    inner = values[1:-1, 1:-1, 1:-1].ravel()
    layer = _outer_layer(result)
    layer = layer[flat[layer] != kernels.OUTSIDE]
    return (gids.ravel()[is_max], inner[is_max], gids.ravel()[layer], flat[layer])


def _resolve(keys, ends):
    """Pointer jumping: each outer-layer voxel's end resolved to a maximum gid."""
    order = np.argsort(keys)
    keys, ends = keys[order], ends[order]      # (copies: ends is written below)
    for _ in range(64):
        leaving = ends < 0
        if not leaving.any():
            return keys, ends
        where = np.searchsorted(keys, -1 - ends[leaving])
        ends[leaving] = ends[where]
    raise RuntimeError("blockwise Morse: path ends did not resolve (a bug)")


def _cells_of_block(halo, origin, shape, offsets, masked, keys, ids):
    """Stage 3: the maximum id of every owned voxel, from the block's own table
    (`_block_tables`); -1 outside the mask."""
    result, _ = _ascend(halo, origin, shape, offsets, masked)
    return _cells_of_ends(result, keys, ids)


def _cells_of_ends(result, keys, ids):
    """The cells of a block from its voxels' path ends (`ascend`'s result)."""
    cells = np.empty(result.size, dtype=ids.dtype)
    kernels.cells_of_ends(result.ravel(), keys, ids, cells)
    return cells.reshape(result.shape)


def _block_tables(summaries, layer_keys, layer_ends, maxima_sorted, maxima_ids):
    """Per block, the maximum id of every end its paths reach: its own maxima (by gid)
    and the neighbours' outer-layer voxels its paths exit to (by their gid; a path from
    inside leaves through the block's own outer layer, so these are that layer's
    exits). Each block's task then carries its own small table, not the whole
    volume's outer layers and maxima (which every worker would otherwise hold)."""
    tables = []
    for summary in summaries:
        own, ends = summary.maxima, summary.ends
        exits = np.unique(-1 - ends[ends < 0])
        reached = layer_ends[np.searchsorted(layer_keys, exits)]
        keys = np.concatenate([own, exits])
        gids = np.concatenate([own, reached])
        order = np.argsort(keys)
        tables.append((keys[order], maxima_ids[np.searchsorted(maxima_sorted, gids[order])]))
    return tables


def _pairs_of_block(halo_values, halo_cells, origin, shape, offsets):
    """Stage 4: (a, b, saddle gid, saddle value) of the block's edges of the cell
    graph's maximum spanning forest: about one edge per cell.

    The in-memory cross-edge pass (`_edges._cross_edges`) runs on the block with its
    halo as the padded field: the owned voxels in the mask are its vertices, the halo
    holds the neighbours' values (-inf outside the volume and the mask). An edge is
    seen from its smaller cell's voxel, so each edge between two blocks is found by
    one of them. Cells are renumbered in increasing order (the pairs and ties keep the
    in-memory order), the highest saddle per pair is sorted as in memory and
    `spanning_edges` keeps the block's forest."""
    values = np.ascontiguousarray(halo_values, dtype=np.float64)
    cells, local = np.unique(halo_cells, return_inverse=True)
    strides = np.array([s // values.itemsize for s in values.strides], dtype=np.int64)
    owned = np.arange(values.size).reshape(values.shape)[1:-1, 1:-1, 1:-1].ravel()
    owned = owned[values.ravel()[owned] > -np.inf]         # the block's voxels in the mask
    # 4-byte voxel ids below 2^31 voxels (up to 1290^3): the client holds ~1 per maximum
    gid_type = np.int32 if np.prod(shape) < 2**31 else np.int64
    if not len(owned):
        nothing = np.zeros(0, dtype=halo_cells.dtype)
        return nothing, nothing, np.zeros(0, dtype=gid_type), np.zeros(0)
    graph = _Neighbourhood(values.ravel(), owned, True, offsets @ strides,
                           np.zeros(1, np.int64), np.zeros(1, np.int64), values.shape)
    a, b, saddle = _cross_edges(graph, local.ravel(), len(cells))
    order = _saddle_order(graph.values[saddle], saddle, a, b)
    keep = np.zeros(len(a), dtype=bool)
    _kernels.spanning_edges(a, b, order, len(cells), keep)
    a, b, saddle = a[keep], b[keep], saddle[keep]
    i, j, k = np.unravel_index(saddle, values.shape)
    gids = ((origin[0] + i - 1) * shape[1] + origin[1] + j - 1) * shape[2] + origin[2] + k - 1
    return cells[a], cells[b], gids.astype(gid_type), graph.values[saddle]


def _per_block(function, *arrays, **kwargs):
    """Run `function(*blocks, block_id=...)` on every block and return its results, one
    object per block, as an (object) array of the block grid, through `map_blocks` (one
    small graph: no per-block copy of it, which `to_delayed` would make)."""
    import dask.array as da

    def wrapped(*blocks, block_id=None):
        out = np.empty((1,) * blocks[0].ndim, dtype=object)
        out[(0,) * blocks[0].ndim] = function(*blocks, block_id=block_id, **kwargs)
        return out
    return da.map_blocks(wrapped, *arrays, dtype=object,
                         chunks=tuple((1,) * len(c) for c in arrays[0].chunks),
                         meta=np.empty((0,) * 3, object))


def _gather(blocks, compute, stage) -> list:
    """The per-block results of `_per_block`, in block order, each fetched as its own
    result: no task concatenates them first (on a cluster, that task's worker would
    hold every block's result at once)."""
    results = compute(*blocks.to_delayed(optimize_graph=False).ravel(), stage=stage)
    return [block.flat[0] for block in results]      # each a 1x1x1 object array


@dataclass
class _Ascent:
    """Stage 1 of one block: its maxima (gids) and their values, its outer layer's
    voxels (gids) and where their paths end (a gid, or -1 - gid of the exit voxel in a
    neighbouring block). Fields are dropped (None) once joined on the client."""

    maxima: np.ndarray | None
    values: np.ndarray | None
    layer: np.ndarray | None
    ends: np.ndarray | None


@dataclass
class _Forest:
    """Stage 4 of one block: the edges (a, b, saddle gid, saddle value) of its part of
    the cell graph's maximum spanning forest."""

    a: np.ndarray | None
    b: np.ndarray | None
    saddle: np.ndarray | None
    value: np.ndarray | None


@dataclass
class _Maxima:
    """Stage 2, on the client: every maximum (gid) and its value, by decreasing
    (value, index) (a maximum's id is its position), and the index type of the ids."""

    gids: np.ndarray
    values: np.ndarray
    index_type: type


@dataclass
class _Grid:
    """What every per-block function of a build needs: the field's shape, the grid's
    flat offsets, the blocks' first indices, the mask flag, the scratch folder."""

    shape: np.ndarray
    offsets: np.ndarray
    starts: list
    masked: bool
    scratch: str | None

    def origin(self, block_id):
        return np.array([self.starts[d][block_id[d]] for d in range(3)], dtype=np.int64)

    def ends_file(self, block_id):
        if self.scratch is None:
            return None
        return os.path.join(self.scratch, "_".join(map(str, block_id)) + ".npy")


def dask_descending_complex(field, connectivity="kuhn", mask=None, hooks=None):
    """`descending_complex` of a 3-D Dask array (see the module docstring).

    `mask`: a boolean array (numpy or Dask) of the field's shape, as in memory
    (DESIGN.md section 9): the blocks see -inf outside it, so no edge leaves it;
    cells are -1 there and cuts label it 0.

    `hooks` (`volseg._block_hooks.BlockHooks`, from the blockwise pipeline): ``wrap``
    keeps each finished block on disk; ``compute`` runs a stage (with progress);
    ``store`` computes the cells once into storage instead of in every later pass
    (edges, labels); ``reread``: the field's blocks are cheap to make again, so each
    is made again for its halo rather than kept waiting for it (the stored cells are
    always reread); ``scratch``: a folder where the ascent keeps each block's path
    ends (8 bytes per voxel), so that the cells pass reads them instead of climbing
    again (removed once the cells are stored)."""
    hooks = hooks or BlockHooks()
    values, mask = _checked_field(field, mask)
    phases = _Phases()
    grid = _Grid(np.array(field.shape, dtype=np.int64),
                 np.ascontiguousarray(grid_offsets(3, connectivity), dtype=np.int64),
                 block_starts(values.chunks), mask is not None, hooks.scratch)
    if grid.scratch is not None:
        os.makedirs(grid.scratch, exist_ok=True)
    halo = with_halo(values, -np.inf, fresh=hooks.reread)
    ascent = _per_block(hooks.wrap("ascent", lambda h, block_id: _summary_of_block(
        h, grid.origin(block_id), grid.shape, grid.offsets, grid.masked,
        grid.ends_file(block_id))), halo)
    summaries = [_Ascent(*s) for s in _gather(ascent, hooks.compute,
                                              "Morse: steepest ascent per block")]
    phases.done("blocks: steepest ascent, path compression")
    maxima, tables = _maxima_and_tables(summaries, values.chunks)
    del summaries     # the client keeps only the maxima and the blocks' small tables
    phases.done("client: exits resolved, maxima ordered")
    cells = _cells(halo, tables, values.chunks, grid, maxima.index_type, hooks)
    del tables     # held by the cells' graph only: storing may free them (about 12 B/maximum)
    if hooks.store is not None:
        cells = hooks.store("cells", cells)
        phases.done("blocks: cells (stored)")
        if grid.scratch is not None:    # every cell is stored: the ends are not read again
            shutil.rmtree(grid.scratch, ignore_errors=True)
    halo_cells = with_halo(cells, -1, fresh=hooks.store is not None)
    pairs = _per_block(hooks.wrap("pairs", lambda h, c, block_id: _pairs_of_block(
        h, c, grid.origin(block_id), grid.shape, grid.offsets)), halo, halo_cells)
    forests = [_Forest(*f) for f in _gather(
        pairs, hooks.compute, "Morse: cross-cell edges and spanning forest per block")]
    phases.done("blocks: cells and cross-cell edges")
    young, elder, target, source, saddle, saddle_values = _union_find(
        forests, len(maxima.gids), maxima.index_type)
    del forests
    phases.done("client: saddle order, union-find")
    return MorseHierarchy(
        shape=tuple(int(s) for s in grid.shape), cells=cells, maxima=maxima.gids,
        values=maxima.values, young=young, elder=elder, target=target, source=source, saddle=saddle,
        saddle_value=saddle_values, mask=mask, _field=field, _connectivity=connectivity,
        timings=phases.times)


def _checked_field(field, mask):
    """(the field as float64, -inf outside the mask; the mask as a Dask array of the
    field's chunks, or None), checked."""
    import dask.array as da

    if field.ndim != 3:
        raise ValueError(f"a Dask `field` must be 3-D, got shape {field.shape}")
    if np.dtype(field.dtype).kind not in "biuf":
        raise ValueError(f"`field` must hold real numbers, got dtype {field.dtype}")
    if field.size == 0:
        raise ValueError("`field` is empty")
    values = field.astype(np.float64)
    if mask is None:
        return values, None
    mask = da.asarray(mask)
    if mask.dtype != bool or mask.shape != field.shape:
        raise ValueError(f"`mask` must be a boolean array of the field's shape {field.shape}, "
                         f"got {mask.dtype} {mask.shape}")
    mask = mask.rechunk(field.chunks)
    return da.map_blocks(_masked, values, mask, dtype=np.float64), mask


def _maxima_and_tables(summaries: list, chunks) -> tuple:
    """Stage 2 on the client: the outer layers' path ends resolved to maxima by
    pointer jumping, the maxima numbered by decreasing (value, index) as in memory,
    and each block's own table of maximum ids (as a Dask array of the block grid)."""
    import dask.array as da

    maxima = np.concatenate([s.maxima for s in summaries])
    if not len(maxima):
        raise ValueError("`mask` selects no vertex")
    maxima_values = _joined(summaries, "values")
    layer_keys, layer_ends = _resolve(_joined(summaries, "layer"),
                                      np.concatenate([s.ends for s in summaries]))
    order = np.lexsort((maxima, maxima_values))[::-1]       # decreasing (value, index)
    maxima, maxima_values = maxima[order], maxima_values[order]
    index_type = np.int32 if len(maxima) < 2**31 - 1 else np.int64
    by_gid = np.argsort(maxima)
    maxima_sorted, maxima_ids = maxima[by_gid], by_gid.astype(index_type)
    block_grid = tuple(len(c) for c in chunks)
    tables = np.empty(block_grid, dtype=object)
    for index, table in zip(np.ndindex(block_grid), _block_tables(
            summaries, layer_keys, layer_ends, maxima_sorted, maxima_ids), strict=True):
        tables[index] = table
    return (_Maxima(maxima, maxima_values, index_type),
            da.from_array(tables, chunks=1, name=False))


def _cells(halo, tables, chunks, grid: _Grid, index_type, hooks):
    """Stage 3, lazy: the maximum id of every voxel, from the path ends kept in the
    scratch folder, or, without one, by climbing again from the halos."""
    import dask.array as da

    meta = np.empty((0, 0, 0), index_type)
    if grid.scratch is None:
        def cells_of(h, table, block_id=None):
            return _cells_of_block(h, grid.origin(block_id), grid.shape, grid.offsets,
                                   grid.masked, *table.flat[0])

        return halo.map_blocks(hooks.wrap("cells", cells_of), tables, dtype=index_type,
                               chunks=chunks, meta=meta)

    def cells_of_kept_ends(table, block_id=None):
        try:
            ends = np.load(grid.ends_file(block_id))
        except OSError:
            raise RuntimeError(f"block {block_id}'s path ends were expected in "
                               f"{grid.scratch} but are not there") from None
        return _cells_of_ends(ends, *table.flat[0])

    return da.map_blocks(hooks.wrap("cells", cells_of_kept_ends), tables, dtype=index_type,
                         chunks=chunks, meta=meta)


def _union_find(forests: list, n_maxima: int, index_type) -> tuple:
    """Stage 5 on the client: the union of the blocks' forests holds the whole graph's
    forest, so Kruskal over it in the in-memory order makes the in-memory merges (a
    pair found by two blocks: the lower edge is skipped). Joined one column at a
    time, each block's copy dropped as it goes (the peak is one column more than the
    edges, not twice the edges). Returns (young, elder, target, source, saddle, saddle
    value)."""
    edge_a, edge_b, edge_v, edge_f = (_joined(forests, k) for k in ("a", "b", "saddle", "value"))
    edge_a, edge_b = edge_a.astype(index_type, copy=False), edge_b.astype(index_type, copy=False)
    order = _saddle_order(edge_f, edge_v, edge_a, edge_b)
    edge_a = edge_a[order]      # one column at a time: one copy alive, not four
    edge_b = edge_b[order]
    edge_v = edge_v[order]
    edge_f = edge_f[order]
    del order
    out = [np.empty(max(n_maxima - 1, 0), dtype=t)
           for t in (np.int32, np.int32, np.int32, np.int32, np.int64)]
    # Kruskal records each event's edge (its index in place of a saddle): the events'
    # saddles and their values are then two gathers.
    edge = np.arange(len(edge_a), dtype=index_type if len(edge_a) < 2**31 - 1 else np.int64)
    n_events = _kernels.kruskal(edge_a, edge_b, edge, n_maxima, *out)
    del edge_a, edge_b, edge
    young, elder, target, source, event_edge = (x[:n_events].copy() for x in out)
    return young, elder, target, source, edge_v[event_edge].astype(np.int64), edge_f[event_edge]


def _joined(parts, name: str):
    """Field `name` of every block's record, concatenated; each block's copy is dropped."""
    column = np.concatenate([getattr(p, name) for p in parts])
    for p in parts:
        setattr(p, name, None)
    return column
