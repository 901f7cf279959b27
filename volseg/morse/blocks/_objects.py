"""Per-block results as Dask object arrays of the block grid: one graph of one task per
block (no per-block copy of it, which `to_delayed` would make), whose reads of its
input arrays Dask fuses into it, so a block's inputs are read where it runs."""

from __future__ import annotations

import numpy as np

__all__ = []


def per_block(function, *arrays, **kwargs):
    """Run `function(*blocks, block_id=..., **kwargs)` on every block of `arrays` (the
    same block grid, matched by block index: an array of this function's results
    passes its objects) and return its results, one object per block, as an (object)
    array of the block grid, through `map_blocks`. `kwargs` may hold Delayed objects
    (one shared task each)."""
    import dask.array as da

    def wrapped(*blocks, block_id=None, **given):
        out = np.empty((1,) * blocks[0].ndim, dtype=object)
        out[(0,) * blocks[0].ndim] = function(*blocks, block_id=block_id, **given)
        return out
    return da.map_blocks(wrapped, *arrays, dtype=object,
                         chunks=tuple((1,) * len(c) for c in arrays[0].chunks),
                         meta=np.empty((0,) * arrays[0].ndim, object), **kwargs)


def only(block):
    """The one element of a 1x1x1 object block (`per_block`'s result)."""
    return block.flat[0]
