"""`descending_complex` of a 3-D Dask array: the in-memory build, block by block
(docs/design.md section 10).

1. Per block, with a 1-voxel halo (-inf outside the volume; `volseg._halo`, which
   frees each block once its halo layers are copied): steepest ascent and path
   compression inside the block (`_block_kernels.ascend`). A path ends at a
   maximum of the block or leaves it; a path that leaves lands on a neighbouring
   block's outer layer. Each block returns its maxima and the ends of its outer
   layer's paths, a few percent of its voxels.
2. On the workers (one graph, the client waits): the maxima numbered by decreasing
   (value, index) as in memory, by a sample sort (`_ranks`); the outer-layer ends
   resolved to those ids by pointer jumping in a tree of block groups (`_exits`), so
   each block gets its own table. The tables stay on the workers (`hooks.persist`).
3. Per block again: cells = maximum id of each voxel, from the path ends the ascent
   kept on disk (the hooks' `scratch` folder: the blockwise work folder), or, without
   one, by climbing again (so no block-sized intermediate outlives its task).
4. Per block, cells and values with a halo: the in-memory cross-edge pass on the
   block (every edge between two cells, seen from its smaller cell's voxel, with its
   lower end as saddle, reduced to the highest saddle per pair of cells), then the
   block's maximum spanning forest in the sweep order (value, saddle index, pair):
   the only edges that can merge components, about one per cell.
5. On the workers: the elder-rule union-find decided in the same tree of block
   groups (`_group_tree`): each group decides the events its faces cannot change and
   passes the rest up. The decided events go to the sample sort's buckets of maximum
   ids, each to its young maximum's (`_buckets`): the same maxima, events and
   persistence as in memory, for any chunking (tested), and no task holds them all.

`dask_hierarchy` returns the buckets kept where they were computed
(`HierarchyOnWorkers`), its `cells` a lazy Dask array; a persistence cut runs where
the buckets are, any other cut beside one task that joins them (on a cluster, one
worker's memory), and the client receives the maxima's count and the cut's small
result (`volseg.cuts`), nothing per maximum or per voxel (tested).
`dask_descending_complex` fetches the joined hierarchy whole (about 64 B per maximum).
"""

from __future__ import annotations

import math
import operator
import os
import shutil
from dataclasses import dataclass

import numpy as np

from ... import _atomic
from ..._block_hooks import BlockHooks
from ..._distinct import index_type, places
from ..._halo import block_starts, with_halo, with_halos
from ..._task_graph import TaskGraph, _one_object
from .. import _group_tree, _measures
from .._edges import _cross_edges, spanning_forest
from .._graph import _Neighbourhood, grid_offsets
from .._phases import _Phases
from . import _buckets, _exits, _ranks
from . import _kernels as kernels
from ._cells import lookup, table_cells
from ._objects import only, per_block
from ._on_workers import HierarchyOnWorkers

__all__ = ["dask_descending_complex", "dask_hierarchy"]


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
    """The field inside the mask, -inf outside it (docs/design.md section 9: no edge has an
    end outside); NaN or infinite values inside the mask are refused."""
    values = np.asarray(field, dtype=np.float64)
    if not np.isfinite(values[mask]).all():
        raise ValueError("`field` holds NaN or infinite values inside the mask")
    return np.where(mask, values, -np.inf)


def _summary_of_block(halo, origin, shape, offsets, masked, ends_file=None):
    """Stage 1: (maxima gids, their values, outer-layer gids, their path ends, the
    block's (min, max) in the mask: (inf, -inf) if it has none); the outer layer's
    voxels outside the mask are left out (no path reaches them). `ends_file`: also
    keep every voxel's path end there (for `_cells_of_ends`)."""
    result, values = _ascend(halo, origin, shape, offsets, masked)
    if ends_file is not None:
        _atomic.write_atomically(ends_file, np.save, result)
    c = result.shape[2]
    rows = _row_gids(origin, shape, result.shape)
    is_max = result == rows[:, :, None] + np.arange(c)    # a maximum's path ends at itself
    inner = values[1:-1, 1:-1, 1:-1]
    flat = result.reshape(-1)
    layer = _outer_layer(result)
    layer = layer[flat[layer] != kernels.OUTSIDE]
    # The range in the mask: -inf outside it (none without a mask: `_ascend` checked).
    high = inner.max()
    low = np.min(inner, where=inner > -np.inf, initial=np.inf) if masked else inner.min()
    return (result[is_max], inner[is_max], rows.reshape(-1)[layer // c] + layer % c,
            flat[layer], np.array([low, high]))


def _row_gids(origin, shape, block_shape) -> np.ndarray:
    """(a, b): the gid (index in the whole volume of `shape`) of the first voxel of
    each row of the (a, b, c) block at `origin`; a voxel's gid is its row's plus its
    place in the row (what `_kernels._gid` computes voxel by voxel in the kernels)."""
    a, b = block_shape[:2]
    return ((origin[0] + np.arange(a))[:, None] * shape[1] + origin[1] + np.arange(b)) \
        * shape[2] + origin[2]


def _cells_of_block(halo, origin, shape, offsets, masked, keys, ids):
    """Stage 3: the maximum id of every owned voxel, from the block's own table
    (`_exits.table`); -1 outside the mask."""
    result, _ = _ascend(halo, origin, shape, offsets, masked)
    return _cells_of_ends(result, keys, ids)


def _cells_of_ends(result, keys, ids):
    """The cells of a block from its voxels' path ends (`ascend`'s result): the gid
    each path ends at (a maximum's, or the voxel an exit enters: -1 - end) looked up in
    the block's table (`keys` sorted gids, `ids`), -1 for `OUTSIDE`."""
    ends = np.where(result >= 0, result, -1 - result)
    ends[result == kernels.OUTSIDE] = -1
    cells = np.empty(result.shape, dtype=ids.dtype)
    lookup(ends, keys, ids, ids.dtype.type(-1), cells)
    return cells


def _pairs_of_block(halo_values, halo_cells, origin, shape, offsets):
    """Stage 4: (a, b, saddle gid, saddle value) of the block's edges of the cell
    graph's maximum spanning forest (about one edge per cell), then its six faces'
    cells (`_faces`).

    The in-memory cross-edge pass (`_edges._cross_edges`) runs on the block with its
    halo as the padded field: the owned voxels in the mask are its vertices, the halo
    holds the neighbours' values (-inf outside the volume and the mask, where the
    cell stays -1: no cell, never a partner, rather than a local id that only its
    place first in the order kept out). An edge is seen from its smaller cell's
    voxel, so each edge between two blocks is found by one of them. Cells are
    renumbered in increasing order (the pairs and ties keep the in-memory order) and
    `spanning_forest` keeps the block's forest of the highest saddles per pair, in
    the in-memory order."""
    faces = _faces(halo_cells, origin, shape)
    values = np.ascontiguousarray(halo_values, dtype=np.float64)
    cells, local = places(halo_cells)
    if len(cells) and cells[0] < 0:     # no cell (outside the volume or the mask): -1
        cells = cells[1:]
        local -= 1
    strides = np.array([s // values.itemsize for s in values.strides], dtype=np.int64)
    inside = np.zeros(values.shape, dtype=bool)             # the block's voxels in the mask
    inside[1:-1, 1:-1, 1:-1] = values[1:-1, 1:-1, 1:-1] > -np.inf
    owned = np.flatnonzero(inside)
    # 4-byte voxel ids below 2^31 voxels (up to 1290^3)
    gid_type = index_type(math.prod(shape))
    if not len(owned):
        nothing = np.zeros(0, dtype=halo_cells.dtype)
        return (nothing, nothing, np.zeros(0, dtype=gid_type), np.zeros(0), *faces)
    graph = _Neighbourhood(values.ravel(), owned, True, offsets @ strides,
                           np.zeros(1, np.int64), np.zeros(1, np.int64), values.shape)
    # Every neighbour, in every block: were each block to choose the one-sided walk by
    # its own cells, an edge over a face between a one-sided block (which leaves it to
    # the edge's lower-index end) and a block walking every neighbour (which leaves it
    # to the smaller cell) could be found by neither.
    a, b, saddle = _cross_edges(graph, local.ravel(), len(cells), one_sided=False)
    keep = spanning_forest(graph.values[saddle], saddle, a, b, len(cells))
    a, b, saddle = a[keep], b[keep], saddle[keep]
    # A saddle is an edge's lower end: an owned voxel or one of the halo's.
    i, j, k = np.unravel_index(saddle, values.shape)
    gids = _row_gids(origin - 1, shape, values.shape)[i, j] + k
    return (cells[a], cells[b], gids.astype(gid_type), graph.values[saddle], *faces)


def _faces(halo_cells, origin, shape) -> list:
    """The cells on each face of a block, in its outer layer or in the halo beyond it
    (axis 0 low, axis 0 high, axis 1 low, ...): the cells that may have edges found by
    the neighbour across that face (`_group_tree`). Empty on the volume's boundary,
    where there is no neighbour."""
    faces = []
    for axis in range(3):
        for end in (0, 1):
            outer = origin[axis] == 0 if end == 0 else \
                origin[axis] + halo_cells.shape[axis] - 2 == shape[axis]
            if outer:
                faces.append(np.zeros(0, dtype=halo_cells.dtype))
                continue
            index = [slice(None)] * 3
            index[axis] = slice(0, 2) if end == 0 else slice(-2, None)
            cells = np.unique(halo_cells[tuple(index)])
            faces.append(cells[cells >= 0])
    return faces


@dataclass
class _Maxima:
    """Stage 2's result: their count and the index type of their ids on the client;
    every maximum (gid) and its value, by decreasing (value, index) (a maximum's id is
    its position), as the sample sort's buckets kept on the workers (a Delayed each:
    consecutive ids, `_buckets`); the
    field's (min, max) in the mask, from the ascent's blocks (what a hypervolume's
    fixed point needs: no pass of its own)."""

    n_maxima: int
    index_type: type
    buckets: list
    low_high: tuple


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

    def voxel(self, block) -> tuple:
        """The first voxel of the block at block coordinates `block` (or the volume's
        end past the last block)."""
        return tuple(int(self.starts[d][block[d]]) if block[d] < len(self.starts[d])
                     else int(self.shape[d]) for d in range(3))

    def ends_file(self, block_id):
        if self.scratch is None:
            return None
        return os.path.join(self.scratch, "_".join(map(str, block_id)) + ".npy")


def dask_descending_complex(field, connectivity="kuhn", mask=None, hooks=None):
    """`descending_complex` of a 3-D Dask array (see the module docstring): the
    `MorseHierarchy` of `dask_hierarchy`, fetched to the client."""
    return dask_hierarchy(field, connectivity, mask, hooks).fetch()


def dask_hierarchy(field, connectivity="kuhn", mask=None, hooks=None) -> HierarchyOnWorkers:
    """The blockwise build, its hierarchy kept where it was assembled
    (`HierarchyOnWorkers`: the client holds O(blocks)).

    `mask`: a boolean array (numpy or Dask) of the field's shape, as in memory
    (docs/design.md section 9): the blocks see -inf outside it, so no edge leaves it;
    cells are -1 there and cuts label it 0.

    `hooks` (`volseg._block_hooks.BlockHooks`, from the blockwise pipeline): ``wrap``
    keeps each finished block on disk; ``compute`` runs a stage (with progress);
    ``persist`` keeps a result on the workers; ``store`` computes the cells once into
    storage instead of in every later pass (edges, labels); ``reread``: the field's
    blocks are cheap to make again, so each is made again for its halo rather than
    kept waiting for it (the stored cells are always reread); ``scratch``: a folder
    where the ascent keeps each block's path ends (8 bytes per voxel), so that the
    cells pass reads them instead of climbing again (removed once the cells are
    stored)."""
    import dask

    hooks = hooks or BlockHooks()
    values, mask = _checked_field(field, mask)
    phases = _Phases()
    grid = _Grid(np.array(field.shape, dtype=np.int64),
                 np.ascontiguousarray(grid_offsets(3, connectivity), dtype=np.int64),
                 block_starts(values.chunks), mask is not None, hooks.scratch)
    if grid.scratch is not None:
        os.makedirs(grid.scratch, exist_ok=True)
    halo = with_halo(values, -np.inf, fresh=hooks.reread)
    ascent = per_block(hooks.wrap("ascent", lambda h, block_id: _summary_of_block(
        h, grid.origin(block_id), grid.shape, grid.offsets, grid.masked,
        grid.ends_file(block_id))), halo)
    tables, maxima = _ids_and_exits(ascent, grid, hooks)
    # Each block's distinct cells, from its table: what the cut's passes route by.
    block_ids, = hooks.persist(table_cells(tables, maxima.index_type),
                               stage="Morse: each block's cells, from its table")
    phases.done("blocks and block groups: steepest ascent, maxima ids, exits")
    cells = _cells(halo, tables, values.chunks, grid, maxima.index_type, hooks)
    del tables     # held by the cells' graph only: storing may free them
    if hooks.store is not None:
        cells = hooks.store("cells", cells)
        phases.done("blocks: cells (stored)")
        if grid.scratch is not None:    # every cell is stored: the ends are not read again
            shutil.rmtree(grid.scratch, ignore_errors=True)
    # Both halos of a block in one task: made apart, one waited (and spilled, on a
    # cluster) for the other.
    halos = with_halos([values, cells], [-np.inf, -1], [hooks.reread, hooks.store is not None])
    forests = per_block(hooks.wrap("forests", lambda both, block_id: _pairs_of_block(
        *only(both), grid.origin(block_id), grid.shape, grid.offsets)), halos)
    shape = tuple(int(s) for s in grid.shape)
    # Two steps, as the blocks' work then the join: one graph ending in the join kept
    # every block's halo in memory at once.
    decided = hooks.persist(*_group_tree_of(forests),
                            stage="Morse: cross-cell edges and union-find per block group")
    phases.done("blocks: cells, cross-cell edges, union-find in block groups")
    buckets, firsts = _buckets.bucketed(maxima.buckets, decided, maxima.index_type)
    *buckets, firsts = hooks.persist(*buckets, firsts,
                                     stage="Morse: the events, in buckets of maximum ids")
    del decided
    phases.done("buckets of maximum ids: the events by their young maximum")
    # The whole hierarchy in one task, made only when a cut needs it (`HierarchyOnWorkers`).
    core = dask.delayed(_buckets.joined, pure=True)(shape, *buckets)
    return HierarchyOnWorkers(core, maxima.n_maxima, shape, cells, mask, field, connectivity,
                              phases.times, hooks, field_range=maxima.low_high,
                              buckets=buckets, firsts=firsts, _blocks=block_ids)


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


def _ids_and_exits(ascent, grid: _Grid, hooks) -> tuple:
    """Stages 1-2 on the workers: the maxima numbered by decreasing (value, gid)
    (`_ranks`), the exits resolved in the tree of block groups (`_exits`), each block's
    table made (kept where it was computed: on a cluster's workers); returns (the tables
    as a Dask object array of the block grid, `_Maxima`)."""
    import dask.array as da

    graph = TaskGraph("morse-ids", [ascent])
    shape = ascent.numblocks
    order = list(np.ndindex(shape))
    summaries = {i: graph(only, (ascent.name, *i)) for i in order}
    ranks, total, buckets = _ranks.ranks_of(graph, [graph(_maxima_of, summaries[i])
                                                    for i in order],
                                            _bucket_count(len(order), int(np.prod(grid.shape)),
                                                          hooks.threads))
    ranks = dict(zip(order, ranks, strict=True))
    groups = _group_tree.block_tree(shape)
    face_map, exits, down, halves = [], [], {}, {}
    for index, (lo, hi, axis, low, high) in enumerate(groups):
        box = (grid.voxel(lo), grid.voxel(hi))
        if axis is None:
            up = graph(_exits.leaf_up, summaries[lo], ranks[lo], box, grid.shape)
        else:
            up = graph(_exits.group_up, face_map[low], exits[low], face_map[high], exits[high],
                       box, grid.shape)
            down[index], halves[index] = graph.item(up, 2), graph.item(up, 3)
        face_map.append(graph.item(up, 0))
        exits.append(graph.item(up, 1))
    answers = {len(groups) - 1: graph(_no_answers)}
    for index in range(len(groups) - 1, -1, -1):
        _, _, axis, low, high = groups[index]
        if axis is not None:
            for half, child in enumerate((low, high)):
                answers[child] = graph(_exits.answers_down, down[index], halves[index],
                                       answers[index], half)
    leaves = {groups[i][0]: answers[i] for i in range(len(groups)) if groups[i][2] is None}
    tables = [graph(_one_object, graph(_exits.table, ranks[i], leaves[i]), 3) for i in order]
    low_high = graph(_measures.range_of,
                     *[graph(operator.itemgetter(4), summaries[i]) for i in order])
    n_buckets = len(buckets)
    *tables, total, low_high, buckets = _split_last(hooks.persist(
        *graph.delayed([*tables, total, low_high, *buckets]),
        stage="Morse: steepest ascent, maxima ids, exits"), n_buckets)
    n_maxima, low_high = hooks.compute(total, low_high, stage="Morse: the maxima, counted")
    if not n_maxima:
        raise ValueError("`mask` selects no vertex")
    grid_of_tables = np.empty(shape, dtype=object)
    for index, table in zip(order, tables, strict=True):
        grid_of_tables[index] = da.from_delayed(table, shape=(1, 1, 1), dtype=object)
    return (da.block(grid_of_tables.tolist()),
            _Maxima(int(n_maxima), index_type(int(n_maxima) + 1), buckets,
                    low_high))


def _split_last(items, n: int) -> tuple:
    """(*items[:-n], items[-n:] as a list)."""
    return (*items[:-n], list(items[-n:]))


def _no_answers():
    return np.zeros(0, np.int64), np.zeros(0, np.int64)


def _maxima_of(summary):
    return summary[0], summary[1]


#: Voxels per bucket of maximum ids past 32 buckets: 2^28 voxels hold up to 17 M maxima
#: at an 8-bit field's 6.4 %, 0.7 GB of a bucket's events (40 B each).
VOXELS_PER_BUCKET = 2 ** 28
#: Buckets for the parallelism alone: `BUCKETS_PER_THREAD` per thread that runs tasks,
#: at most `PARALLEL_BUCKETS` (also the count when the threads are not known).
BUCKETS_PER_THREAD = 4
PARALLEL_BUCKETS = 32


def _bucket_count(n_blocks: int, n_voxels: int, threads: int | None = None) -> int:
    """Buckets of the maxima's sample sort, which then hold the hierarchy (`_buckets`):
    enough for the parallelism (`BUCKETS_PER_THREAD` per thread, at most
    `PARALLEL_BUCKETS`: few enough that the blocks x buckets pieces stay a small graph),
    and at least one per `VOXELS_PER_BUCKET` (256 at 4096^3), so that a bucket stays
    small next to a worker; never more than the blocks. Every exchange with the
    buckets is a task per piece, about 1 ms each on a cluster: on 2 threads, 8 buckets
    instead of 32 make 4x to 16x fewer."""
    parallel = (PARALLEL_BUCKETS if threads is None
                else min(PARALLEL_BUCKETS, BUCKETS_PER_THREAD * max(int(threads), 1)))
    return max(1, min(n_blocks, max(parallel, n_voxels // VOXELS_PER_BUCKET)))


def _cells(halo, tables, chunks, grid: _Grid, id_type, hooks):
    """Stage 3, lazy: the maximum id of every voxel, from the path ends kept in the
    scratch folder, or, without one, by climbing again from the halos."""
    import dask.array as da

    meta = np.empty((0, 0, 0), id_type)
    if grid.scratch is None:
        def cells_of(h, table, block_id=None):
            keys, ids = table.flat[0]
            return _cells_of_block(h, grid.origin(block_id), grid.shape, grid.offsets,
                                   grid.masked, keys, ids.astype(id_type))

        return halo.map_blocks(hooks.wrap("cells", cells_of), tables, dtype=id_type,
                               chunks=chunks, meta=meta)

    def cells_of_kept_ends(table, block_id=None):
        try:
            with _atomic.NPY_READ_LOCK:
                ends = np.load(grid.ends_file(block_id))
        except OSError:
            raise RuntimeError(f"block {block_id}'s path ends were expected in "
                               f"{grid.scratch} but are not there") from None
        keys, ids = table.flat[0]
        return _cells_of_ends(ends, keys, ids.astype(id_type))

    return da.map_blocks(hooks.wrap("cells", cells_of_kept_ends), tables, dtype=id_type,
                         chunks=chunks, meta=meta)


def _group_tree_of(forests) -> list:
    """Stage 5, lazy: the union-find decided in the tree of block groups
    (`_group_tree`), one task per group; the events each group decides, as a list of
    Delayed (the undecided part goes from task to task, never to the client)."""
    graph = TaskGraph("morse-groups", [forests])
    groups, decided = [], []
    for group_id, (lo, _, axis, low, high) in enumerate(_group_tree.block_tree(forests.numblocks)):
        if axis is None:
            node = graph(_group_tree.leaf, graph(only, (forests.name, *lo)), group_id)
        else:
            node = graph(_group_tree.merged, groups[low], groups[high], axis, group_id)
        groups.append(graph.item(node, 1))
        decided.append(graph.item(node, 0))
    return graph.delayed(decided)
