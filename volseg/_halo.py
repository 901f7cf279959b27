"""A 1-voxel halo around every block of a Dask array, without pinning whole blocks.

`dask.array.overlap.overlap` cuts each neighbour's faces, edges and corners as
views of that neighbour's block: until the last block that needs one of them has
run, the whole neighbour stays in memory. On the blockwise Morse stage that kept
most of the volume's float64 and int64 blocks alive at once (4.3 GB at 512^3, and a
worker of a 27-block run held more bytes than the whole volume). Here, axis by axis,
each block's first and last layers are copied out (a layer per block, small), shifted
by one block, and joined to the block: once its two layers are copied and its joined
block is made, a block is free. The joined blocks are what `overlap(x, depth=1,
boundary=value)` gives, value for value (tested through the Morse stage).
"""

from __future__ import annotations

import numpy as np

__all__ = ["with_halo", "block_starts"]


def block_starts(chunks) -> list:
    """Per axis, the index of the first voxel of each block of a Dask array's `chunks`."""
    return [np.concatenate([[0], np.cumsum(c)[:-1]]).astype(np.int64) for c in chunks]


def _layer(block, end, axis):
    index = [slice(None)] * block.ndim
    index[axis] = slice(end, end + 1) if end >= 0 else slice(end, None)
    return block[tuple(index)].copy()


def _join(before, block, after, axis):
    return np.concatenate([before, block, after], axis=axis)


def _halo_axis(x, axis: int, value):
    import dask.array as da

    n = x.numblocks[axis]
    thin = tuple((1,) * n if d == axis else c for d, c in enumerate(x.chunks))
    first = x.map_blocks(_layer, 0, axis, chunks=thin, dtype=x.dtype)
    last = x.map_blocks(_layer, -1, axis, chunks=thin, dtype=x.dtype)
    fill_shape = tuple(1 if d == axis else s for d, s in enumerate(x.shape))
    fill_chunks = tuple((1,) if d == axis else c for d, c in enumerate(x.chunks))
    fill = da.full(fill_shape, value, dtype=x.dtype, chunks=fill_chunks)
    cut = [slice(None)] * x.ndim
    cut[axis] = slice(0, n)
    before = da.concatenate([fill, last], axis=axis)[tuple(cut)]      # block k: last of k-1
    cut[axis] = slice(1, n + 1)
    after = da.concatenate([first, fill], axis=axis)[tuple(cut)]      # block k: first of k+1
    grown = tuple(tuple(s + 2 for s in c) if d == axis else c for d, c in enumerate(x.chunks))
    return da.map_blocks(_join, before, x, after, axis=axis, chunks=grown, dtype=x.dtype,
                         meta=np.empty((0,) * x.ndim, dtype=x.dtype))


def with_halo(x, value):
    """`x` (a Dask array) with every block grown by one voxel on each side: its
    neighbours' voxels, and `value` outside the array (as `overlap(x, depth=1,
    boundary=value)`)."""
    for axis in range(x.ndim):
        x = _halo_axis(x, axis, value)
    return x
