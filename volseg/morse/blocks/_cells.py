"""Each block's own cells, so that no block's task needs an array of every maximum.

A blockwise cut reads two arrays as long as the maxima: the cells' saddles (for their
hypervolume) and the regions of the cut (for the labels). Sent whole to every worker
that sums or labels a block, each would cost every such worker 4-8 bytes per maximum
of the volume (35 GB at 4096^3). Instead (issue 30):

- `block_cells`: each block's distinct cells (sorted ids), one task per block, kept
  on the workers (`block_counts`: their vertex counts, aligned); `table_cells` finds
  the same from the blocks' tables of the cells pass, without reading a voxel;
- `gathered`: a per-maximum array's entries for each block's cells, one task per block
  where the array is (the hierarchy's worker): it receives the block's ids and sends
  back as many values;
- `looked_up`: a per-block array of values by cell, read through the block's ids.

The traffic is a few bytes per (block, cell) pair (a cell that several blocks share
counts once in each), whatever the workers' count.
"""

from __future__ import annotations

import numba
import numpy as np

from ..._distinct import distinct
from .. import _prune
from ._objects import per_block

__all__ = []


def block_cells(cells):
    """Lazy (object array of the block grid): each block's sorted distinct cell ids,
    cells < 0 (outside the mask) left out."""
    return per_block(_cells_of_block, cells)


def table_cells(tables, id_type):
    """Lazy, as `block_cells`, from each block's table of the cells pass
    (`_exits.table`: its path ends and the maximum id each reaches): the distinct ids
    of the table are the block's cells. Every voxel's cell is the id of its path end
    in the table; every id is some voxel's cell (a maximum of the block is its own
    path end, an exit is in the table because a voxel's path leaves by it). A table
    is about 6 % of its block's voxels, the cells 4 bytes per voxel to read again
    (1024^3: 58 s on two workers)."""
    return per_block(_cells_of_table, tables, id_type=np.dtype(id_type))


def _cells_of_table(table, block_id, id_type):
    return distinct(table.flat[0][1]).astype(id_type)


def block_counts(cells):
    """Lazy, as `block_cells`: the vertex count of each block's cells, aligned with
    their ids (what a size measure sums)."""
    return per_block(_counts_of_block, cells)


def _sorted_cells(cells) -> tuple:
    """(a block's distinct cells >= 0, sorted; their vertex counts), one hashed pass."""
    ids, counts = _prune.block_sums(cells.ravel(), np.zeros(0), np.zeros(0), 1.0, False)
    order = np.argsort(ids)
    return ids[order], counts[order]


def _cells_of_block(cells, block_id):
    return _sorted_cells(cells)[0].astype(cells.dtype)


def _counts_of_block(cells, block_id):
    return _sorted_cells(cells)[1]


def gathered(ids, array):
    """Lazy: ``array[ids]`` of each block (`array` a Delayed of a per-maximum array)."""
    return ids.map_blocks(_gather, array, dtype=object,
                          meta=np.empty((0,) * ids.ndim, object))


def _gather(ids, array):
    out = np.empty(ids.shape, dtype=object)
    out.flat[0] = array[ids.flat[0]]
    return out


def looked_up(cells, ids, values, dtype, default=0):
    """Lazy array of `cells`' chunks: each voxel's value from its block's `values`
    (aligned with its `ids`), `default` outside the mask (cells < 0)."""
    def block(c, i, v):
        out = np.empty(c.shape, dtype=dtype)
        lookup(np.ascontiguousarray(c), i.flat[0], v.flat[0], dtype(default), out)
        return out
    return cells.map_blocks(block, ids, values, dtype=dtype,
                            meta=np.empty((0,) * cells.ndim, dtype))


@numba.njit(cache=True, nogil=True)
def lookup(cells, ids, values, default, out):
    """out[v] = values[position of cells[v] in ids] for a 3-D block, `default` where
    cells < 0 (or any sorted keys: the gids a block's paths end at,
    `_build._cells_of_ends`). A voxel in the cell of the voxel before it in its row,
    in the row before or in the plane before reuses that voxel's position (kept for
    one plane); only the others search `ids`: a cell spans a few voxels along each
    axis, and a search per run along the rows alone was 3 % of a 512^3 blockwise
    run's CPU time."""
    planes, rows, width = cells.shape
    at_of = np.empty((rows, width), dtype=np.int64)     # the last plane's positions
    for z in range(planes):
        for y in range(rows):
            last, at = -1, 0
            for x in range(width):
                c = cells[z, y, x]
                if c < 0:
                    out[z, y, x] = default
                    last = -1
                    continue
                if c != last:
                    if y > 0 and cells[z, y - 1, x] == c:
                        at = at_of[y - 1, x]            # this plane's row before
                    elif z > 0 and cells[z - 1, y, x] == c:
                        at = at_of[y, x]                # not yet overwritten: the plane before
                    else:
                        at = np.searchsorted(ids, c)
                    last = c
                at_of[y, x] = at
                out[z, y, x] = values[at]
