"""A block's per-voxel lookup of its cells' values (`volseg.morse.blocks._cells`)."""

import numpy as np
import pytest

from volseg.morse.blocks._cells import looked_up, lookup


def _reference(cells, ids, values, default):
    at = np.searchsorted(ids, np.maximum(cells, 0))
    return np.where(cells < 0, default, values[np.minimum(at, len(ids) - 1)])


def _cells(rng, shape, coarse):
    """Cells that span a few voxels along each axis (as a block's do), with cells
    seen once, runs broken by another cell, and voxels outside the mask (-1)."""
    grid = rng.integers(0, 10 * coarse ** 3 + 1, size=[-(-s // coarse) for s in shape])
    cells = grid.repeat(coarse, 0).repeat(coarse, 1).repeat(coarse, 2)
    cells = cells[tuple(slice(0, s) for s in shape)].copy()
    noise = rng.random(shape)
    cells[noise < 0.1] = rng.integers(0, 10 * coarse ** 3 + 1, size=int((noise < 0.1).sum()))
    cells[noise > 0.95] = -1
    return cells


@pytest.mark.parametrize("shape", [(7, 6, 5), (1, 1, 9), (9, 1, 1), (1, 8, 1), (3, 4, 1),
                                   (1, 1, 1), (12, 11, 13)])
@pytest.mark.parametrize("coarse", [1, 2, 3])
def test_lookup_is_a_search_of_every_voxel(shape, coarse):
    """Reusing the position of the voxel before in the row, the row or the plane gives
    what a search of every voxel gives, at the block's edges and past a voxel outside
    the mask (whose stale position must not be reused)."""
    rng = np.random.default_rng(sum(shape) * 10 + coarse)
    cells = _cells(rng, shape, coarse)
    ids = np.unique(cells[cells >= 0])
    values = rng.permutation(len(ids)).astype(np.int64) + 1
    out = np.empty(shape, dtype=np.int32)
    lookup(cells, ids, values, np.int32(0), out)
    assert np.array_equal(out, _reference(cells, ids, values, 0))


def test_looked_up_over_blocks_equals_a_search_of_every_voxel():
    """The lazy lookup over a Dask array of cells, each block with its own ids and
    values (one object per block, as the build's tables are)."""
    import dask.array as da

    cells = _cells(np.random.default_rng(5), (14, 9, 11), 3)
    lazy = da.from_array(cells, chunks=(5, 4, 6))
    ids = np.empty(lazy.numblocks, dtype=object)
    values = np.empty(lazy.numblocks, dtype=object)
    for index in np.ndindex(*lazy.numblocks):
        own = np.unique(lazy.blocks[index].compute())
        ids[index] = own[own >= 0]
        values[index] = ids[index] * 7 + 1
    got = looked_up(lazy, da.from_array(ids, chunks=1), da.from_array(values, chunks=1),
                    np.int64, default=-5)
    assert np.array_equal(got.compute(), np.where(cells < 0, -5, cells * 7 + 1))
