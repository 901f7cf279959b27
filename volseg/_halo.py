"""A 1-voxel halo around every block of a Dask array, without pinning whole blocks.

`dask.array.overlap.overlap` cuts each neighbour's faces, edges and corners as
views of that neighbour's block: until the last block that needs one of them has
run, the whole neighbour stays in memory (on the blockwise Morse stage that kept most
of the volume's blocks alive at once). Here each block's outer layers are copied out
first (its "shell": two layers per axis, a few percent of the block), and each block
with halo is assembled in one task from the block itself and its neighbours' shells,
right before the task that reads it. The result is what `overlap(x, depth=1,
boundary=value)` gives, value for value (tested).

With ``fresh=True`` the blocks assembled are recomputed (a clone of `x`'s graph)
rather than kept from the shell pass: for a store-backed array this rereads a block
when its halo is needed, so a block is in memory only while a shell is cut from it
or while the task that reads its halo runs; without it, a block waits in memory from
its shell's pass to its own assembly, as the scheduler orders them.
"""

from __future__ import annotations

import itertools

import numpy as np

__all__ = ["with_halo", "block_starts"]


def block_starts(chunks) -> list:
    """Per axis, the index of the first voxel of each block of a Dask array's `chunks`."""
    return [np.concatenate([[0], np.cumsum(c)[:-1]]).astype(np.int64) for c in chunks]


def _shell(block):
    """Copies of the block's first and last layer along each axis."""
    layers = []
    for axis in range(block.ndim):
        for end in (0, -1):
            index = [slice(None)] * block.ndim
            index[axis] = slice(end, end + 1) if end >= 0 else slice(end, None)
            layers.append(block[tuple(index)].copy())
    return layers


def _piece(shell, offset):
    """The part of a neighbour's block next to a block at `offset` from it (-1: the
    neighbour is before along that axis, so its last layer; +1: its first)."""
    axis = next(d for d, o in enumerate(offset) if o)
    piece = shell[2 * axis + (1 if offset[axis] < 0 else 0)]
    index = tuple(slice(None) if o == 0 or d == axis
                  else (slice(-1, None) if o < 0 else slice(0, 1)) for d, o in enumerate(offset))
    return piece[index]


def _assemble(block, shells, offsets, value):
    out = np.full(tuple(s + 2 for s in block.shape), value, dtype=block.dtype)
    out[(slice(1, -1),) * block.ndim] = block
    for offset, shell in zip(offsets, shells, strict=True):
        if shell is not None:
            where = tuple(slice(0, 1) if o < 0 else slice(-1, None) if o > 0 else slice(1, -1)
                          for o in offset)
            out[where] = _piece(shell, offset)
    return out


def with_halo(x, value, fresh: bool = False):
    """`x` (a Dask array) with every block grown by one voxel on each side: its
    neighbours' voxels, and `value` outside the array (as `overlap(x, depth=1,
    boundary=value)`). `fresh`: assemble from a recomputed copy of each block (see
    the module docstring)."""
    import dask.array as da
    from dask.base import tokenize
    from dask.graph_manipulation import clone
    from dask.highlevelgraph import HighLevelGraph

    token = tokenize(x, value, fresh)
    shells = f"halo-shell-{token}"
    name = f"halo-{token}"
    own = clone(x) if fresh else x
    grid = list(itertools.product(*(range(n) for n in x.numblocks)))
    offsets = [o for o in itertools.product((-1, 0, 1), repeat=x.ndim) if any(o)]
    graph = {(shells, *index): (_shell, (x.name, *index)) for index in grid}
    for index in grid:
        around = [tuple(i + o for i, o in zip(index, offset, strict=True)) for offset in offsets]
        keys = [(shells, *n) if all(0 <= i < b for i, b in zip(n, x.numblocks, strict=True))
                else None for n in around]
        graph[(name, *index)] = (_assemble, (own.name, *index), keys, offsets, value)
    layers = HighLevelGraph.from_collections(name, graph, dependencies=[x, own])
    grown = tuple(tuple(s + 2 for s in c) for c in x.chunks)
    return da.Array(layers, name, chunks=grown, dtype=x.dtype,
                    meta=np.empty((0,) * x.ndim, dtype=x.dtype))
