"""A 1-voxel halo around every block of a Dask array, without pinning whole blocks.

`dask.array.overlap.overlap` cuts each neighbour's faces, edges and corners as
views of that neighbour's block: until the last block that needs one of them has
run, the whole neighbour stays in memory (on the blockwise Morse stage that kept most
of the volume's blocks alive at once). Here each block's outer layers are copied out
first (its "shell": two layers per axis, a few percent of the block), and each block
with halo is assembled in one task from the block itself and its neighbours' shells,
right before the task that reads it. The result is what `overlap(x, depth=1,
boundary=value)` gives, value for value (tested).

With ``fresh=True`` the blocks assembled are recomputed (`fresh_copy`: a clone of `x`'s graph)
rather than kept from the shell pass: for a store-backed array this rereads a block
when its halo is needed, so a block is in memory only while a shell is cut from it
or while the task that reads its halo runs; without it, a block waits in memory from
its shell's pass to its own assembly, as the scheduler orders them.
"""

from __future__ import annotations

import itertools

import numpy as np

__all__ = ["with_halo", "with_halos", "fresh_copy", "block_starts"]


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


def fresh_copy(x):
    """`x` (a Dask array) computed again from its sources: `dask.graph_manipulation.clone`,
    which leaves the keys inside dask's `Task` objects in materialized layers
    (slicing, transposing, rechunking) as they were, so that its copy failed to fuse
    ("Cannot fuse tasks with multiple outputs", dask issue 12455) or read the
    original's tasks after all; here those keys are renamed too."""
    import dask.array as da
    from dask._task_spec import GraphNode
    from dask.base import clone_key, tokenize
    from dask.graph_manipulation import clone
    from dask.highlevelgraph import HighLevelGraph, MaterializedLayer

    seed = tokenize(x, "fresh")
    copy = clone(x, seed=seed)
    graph = copy.__dask_graph__()
    layers, names = dict(graph.layers), None
    for name, layer in graph.layers.items():
        if isinstance(layer, MaterializedLayer) and any(
                isinstance(v, GraphNode) for v in layer.values()):
            names = names or {k: clone_key(k, seed) for k in x.__dask_graph__()}
            layers[name] = MaterializedLayer({
                k: v.substitute(names, key=k) if isinstance(v, GraphNode) else v
                for k, v in layer.items()})
    return da.Array(HighLevelGraph(layers, graph.dependencies), copy.name,
                    chunks=x.chunks, dtype=x.dtype, meta=x._meta)


def _halo_tasks(x, value, fresh: bool):
    """(the shells' graph, the collections it reads, {block index: the arguments of
    `_assemble` for that block}) of `x`'s halo."""
    from dask.base import tokenize

    shells = f"halo-shell-{tokenize(x, value, fresh)}"
    own = fresh_copy(x) if fresh else x
    grid = list(itertools.product(*(range(n) for n in x.numblocks)))
    offsets = [o for o in itertools.product((-1, 0, 1), repeat=x.ndim) if any(o)]
    graph = {(shells, *index): (_shell, (x.name, *index)) for index in grid}
    arguments = {}
    for index in grid:
        around = [tuple(i + o for i, o in zip(index, offset, strict=True)) for offset in offsets]
        keys = [(shells, *n) if all(0 <= i < b for i, b in zip(n, x.numblocks, strict=True))
                else None for n in around]
        arguments[index] = [(own.name, *index), keys, offsets, value]
    return graph, [x, own], arguments


def with_halo(x, value, fresh: bool = False):
    """`x` (a Dask array) with every block grown by one voxel on each side: its
    neighbours' voxels, and `value` outside the array (as `overlap(x, depth=1,
    boundary=value)`). `fresh`: assemble from a recomputed copy of each block (see
    the module docstring)."""
    import dask.array as da
    from dask.base import tokenize
    from dask.highlevelgraph import HighLevelGraph

    name = f"halo-{tokenize(x, value, fresh)}"
    graph, dependencies, arguments = _halo_tasks(x, value, fresh)
    for index, args in arguments.items():
        graph[(name, *index)] = (_assemble, *args)
    layers = HighLevelGraph.from_collections(name, graph, dependencies=dependencies)
    grown = tuple(tuple(s + 2 for s in c) for c in x.chunks)
    return da.Array(layers, name, chunks=grown, dtype=x.dtype,
                    meta=np.empty((0,) * x.ndim, dtype=x.dtype))


def _assembled_together(*arguments):
    """The halos of one block of several arrays, as one object (a 1x..x1 object
    block holding their tuple)."""
    from ._task_graph import _one_object

    halos = tuple(_assemble(*args) for args in arguments)
    return _one_object(halos, halos[0].ndim)


def with_halos(arrays, values, fresh):
    """The halos (`with_halo`, `fresh` per array) of several arrays of the same block
    grid, each block's made in one task: an object array of the block grid (chunks of
    one), each block holding the tuple of that block's halos. A task that reads two
    halos of one block then waits for one task, not for two that the scheduler may
    run far apart (on a cluster, each halo held, then moved, until its partner is
    made)."""
    import dask.array as da
    from dask.base import tokenize
    from dask.highlevelgraph import HighLevelGraph

    name = f"halos-{tokenize(*arrays, *values, *fresh)}"
    graph, dependencies, arguments = {}, [], []
    for x, value, new in zip(arrays, values, fresh, strict=True):
        shells, reads, args = _halo_tasks(x, value, new)
        graph.update(shells)
        dependencies += reads
        arguments.append(args)
    for index in arguments[0]:
        graph[(name, *index)] = (_assembled_together, *(args[index] for args in arguments))
    layers = HighLevelGraph.from_collections(name, graph, dependencies=dependencies)
    ndim = arrays[0].ndim
    return da.Array(layers, name, chunks=tuple((1,) * n for n in arrays[0].numblocks),
                    dtype=object, meta=np.empty((0,) * ndim, dtype=object))
