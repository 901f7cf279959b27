"""Stage 2 of the blockwise build on the workers: the paths that leave their block,
resolved to the maxima they reach, by pointer jumping in the tree of block groups
(`_group_tree.block_tree`), so that no process holds every block's outer layer.

A block's ascent ends each of its outer layer's voxels at one of its maxima (by id,
`_ranks`) or at an exit: the first voxel outside the block on its path, on a
neighbouring block's outer layer. Going up the tree, a group joins its two halves'
maps and jumps every pointer that lands inside it (the paths rise strictly, so they
end); it keeps for the group above only the voxels on its own faces (the only ones a
path from outside can land on) and the exits it could not resolve, which lie outside
it. Going down, each group answers its halves' unresolved exits from its own map and
its parent's answers. A block ends with the id of every maximum its paths reach: its
table for the cells pass.
"""

from __future__ import annotations

import numpy as np

from ..._distinct import distinct

__all__ = []


def _resolved(keys, ends):
    """Pointer jumping inside a group: each end that is an exit onto a voxel of `keys`
    replaced by that voxel's end, until none is (`keys` sorted)."""
    for _ in range(len(keys) + 1):
        out = np.flatnonzero(ends < 0)
        if not len(out) or not len(keys):
            return ends
        target = -1 - ends[out]
        where = np.minimum(np.searchsorted(keys, target), len(keys) - 1)
        found = keys[where] == target
        if not found.any():
            return ends
        ends[out[found]] = ends[where[found]]
    raise RuntimeError("blockwise Morse: path ends did not resolve (a bug)")


def _on_faces(keys, box, shape):
    """The voxels of `keys` on a face of the box ``(lo, hi)`` that is not the volume's."""
    index = np.unravel_index(keys, tuple(int(s) for s in shape))
    on = np.zeros(len(keys), dtype=bool)
    for axis in range(3):
        lo, hi = box[0][axis], box[1][axis]
        if lo > 0:
            on |= index[axis] == lo
        if hi < shape[axis]:
            on |= index[axis] == hi - 1
    return on


def _up(keys, ends, box, shape):
    order = np.argsort(keys)
    keys, ends = keys[order], ends[order]
    ends = _resolved(keys, ends)
    refs = distinct(-1 - ends[ends < 0])
    face = _on_faces(keys, box, shape)
    return (keys[face], ends[face]), refs, (keys, ends)


def _lookup(keys, ends, wanted):
    """The ends of the `wanted` voxels in a map; -1 - voxel for those not in it."""
    if not len(keys):
        return -1 - wanted
    where = np.minimum(np.searchsorted(keys, wanted), len(keys) - 1)
    return np.where(keys[where] == wanted, ends[where], -1 - wanted)


def leaf_up(summary, ranks, box, shape):
    """A block going up: (its face map, its exits); its own maxima's gids replaced by
    their ids first. (The group above reads the face map; the exits are also read on
    the way down, so they are apart.)"""
    layer, ends = summary[2], summary[3].copy()
    gids, ids = ranks
    own = ends >= 0
    ends[own] = ids[np.searchsorted(gids, ends[own])]
    up, refs, _ = _up(layer, ends, box, shape)
    return up, refs


def group_up(low_map, low_refs, high_map, high_refs, box, shape):
    """A group going up from its halves' face maps and exits: (its face map, its exits,
    its answers to each half's exits: an id, or -1 - an exit outside the group; the
    halves' exits)."""
    keys = np.concatenate([low_map[0], high_map[0]])
    ends = np.concatenate([low_map[1], high_map[1]])
    up, refs, (keys, ends) = _up(keys, ends, box, shape)
    return (up, refs, (_lookup(keys, ends, low_refs), _lookup(keys, ends, high_refs)),
            (low_refs, high_refs))


def answers_down(down, halves_refs, answers, half: int):
    """(a half's exits, their ids), from the group's answers to them (`down`) and the
    parent's `answers` (exits, ids) to the group's own exits."""
    ends = down[half]
    out = ends.copy()
    outside = ends < 0
    if outside.any():
        refs, ids = answers
        wanted = -1 - ends[outside]
        where = np.searchsorted(refs, wanted)
        if not len(refs) or not np.array_equal(refs[np.minimum(where, len(refs) - 1)], wanted):
            raise RuntimeError("blockwise Morse: an exit was left unresolved (a bug)")
        out[outside] = ids[where]
    return halves_refs[half], out


def table(ranks, answers):
    """A block's table for the cells pass: (gids of its maxima and of its exits, sorted;
    the id of the maximum each reaches)."""
    gids, ids = ranks
    refs, reached = answers
    keys = np.concatenate([gids, refs])
    values = np.concatenate([ids, reached])
    order = np.argsort(keys)
    return keys[order], values[order]
