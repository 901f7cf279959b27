"""Stage 5 of the blockwise build on the workers: the elder-rule union-find decided in
a tree of block groups, so that no process holds the whole cell graph.

The blocks are grouped by halving the block grid along its longest axis, down to single
blocks. Each group sweeps its part of the cell graph from the highest saddle down
(`_block_kernels.decide`): the edges of its blocks' spanning forests (at a leaf), or
what its two halves could not decide (above). A cell is *open* in a group when it may
have edges the group does not see: it lies on, or just outside, a face of the group
that is not the volume's boundary (`faces`). A component with no open cell is the
whole graph's component at that level, so

- an edge whose lower side is a closed component is an event of the whole graph: that
  component's highest maximum dies there, into the other side (closed or open: the
  other side's component may be larger outside, but then only higher);
- any other edge (the lower side open) goes up, with each end replaced by its
  representative: the highest cell of a closed component, or the open cell whose
  component absorbed it. The group above then sees the same components at every
  level, with the same highest maxima.

The root has no open cell, so every event is decided somewhere, exactly as the
in-memory sweep decides it (same young, target, source and saddle: the tests compare
them for every chunking). An event's elder, the other side's highest maximum at that
level, may lie outside the group that decides it; it follows from the events in
sweep order (`assembled`, `_kernels.elders`). What a group passes up is what touches
its faces, so it scales with the groups' surfaces, not their volumes; the decided
events leave each group as they are found.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._distinct import is_in, places
from .._sizes import SizedByArrays
from . import _group_kernels as kernels
from . import _kernels
from ._edges import _saddle_order

__all__ = []

@dataclass
class _Items(SizedByArrays):
    """A group's undecided edges: between the nodes `x` and `y` (cells, or their
    representatives), with their original pair (a < b), saddle and saddle value."""

    a: np.ndarray
    b: np.ndarray
    saddle: np.ndarray
    value: np.ndarray
    x: np.ndarray
    y: np.ndarray

    @classmethod
    def joined(cls, parts) -> _Items:
        return cls(*(np.concatenate([getattr(p, name) for p in parts]) for name in _FIELDS))

    def taken(self, index) -> _Items:
        return _Items(*(getattr(self, name)[index] for name in _FIELDS))

    @property
    def nbytes(self) -> int:
        return sum(getattr(self, name).nbytes for name in _FIELDS)


_FIELDS = ("a", "b", "saddle", "value", "x", "y")


@dataclass
class _Group(SizedByArrays):
    """What a group passes to the group above: its undecided edges and its six faces'
    cells (axis 0 low, axis 0 high, axis 1 low, ...; empty on the volume's boundary)."""

    items: _Items
    faces: tuple


def leaf(block, group_id: int):
    """(decided, group) of one block: `block` is the pairs stage's result, its forest
    (a, b, saddle, value) and its six faces' cells."""
    a, b, saddle, value, *faces = block
    return decide(_Items(a, b, saddle.astype(np.int64), value, a, b), tuple(faces), group_id)


def merged(low: _Group, high: _Group, axis: int, group_id: int):
    """(decided, group) of the union of two neighbouring groups, `low` below `high`
    along `axis`: their shared face is inside now."""
    faces = []
    for face in range(6):
        if face == 2 * axis:
            faces.append(low.faces[face])
        elif face == 2 * axis + 1:
            faces.append(high.faces[face])
        else:
            faces.append(np.union1d(low.faces[face], high.faces[face]))
    return decide(_Items.joined([low.items, high.items]), tuple(faces), group_id)


def decide(items: _Items, faces: tuple, group_id: int):
    """The group's sweep (`_block_kernels.decide`): (the events it decides, as (young,
    target, source, saddle, saddle value); the `_Group` for the group above).
    `group_id`: the group's place in `block_tree` (what a report of the tree names)."""
    order = _saddle_order(items.value, items.saddle, items.a, items.b)
    items = items.taken(order)
    # The distinct nodes and each end's place among them, by a hash table (`places`:
    # no binary search per end).
    nodes, ends = places(np.concatenate([items.x, items.y]))
    x, y = ends[:len(items.x)], ends[len(items.x):]
    node_open = is_in(nodes, np.concatenate(faces))
    n = len(items.a)
    ev_item, up_item = np.empty(n, np.int64), np.empty(n, np.int64)
    ev_young, up_x, up_y = (np.empty(n, nodes.dtype) for _ in range(3))
    ev_x_elder = np.empty(n, bool)
    n_ev, n_up = kernels.decide(x, y, nodes, node_open, ev_item, ev_young, ev_x_elder,
                                up_item, up_x, up_y)
    ev_item, ev_young, ev_x_elder = ev_item[:n_ev], ev_young[:n_ev], ev_x_elder[:n_ev]
    decided = (ev_young,
               np.where(ev_x_elder, items.a[ev_item], items.b[ev_item]),      # target
               np.where(ev_x_elder, items.b[ev_item], items.a[ev_item]),      # source
               items.saddle[ev_item], items.value[ev_item])
    up = items.taken(up_item[:n_up][::-1])                # increasing key again
    up.x, up.y = nodes[up_x[:n_up][::-1]], nodes[up_y[:n_up][::-1]]
    return decided, _Group(up, faces)


def block_tree(block_grid) -> list:
    """The groups of a block grid, children before parents: (lo, hi, axis, low child,
    high child) in block coordinates, children as indices into the list (None for a
    block); the last is the root. Halving the longest axis keeps the groups compact, so
    their faces (what they pass up) stay small."""
    groups = []

    def build(lo, hi):
        extent = [b - a for a, b in zip(lo, hi, strict=True)]
        if max(extent) == 1:
            groups.append((tuple(lo), tuple(hi), None, None, None))
            return len(groups) - 1
        axis = int(np.argmax(extent))
        middle = lo[axis] + extent[axis] // 2
        low = build(lo, [middle if d == axis else h for d, h in enumerate(hi)])
        high = build([middle if d == axis else a for d, a in enumerate(lo)], hi)
        groups.append((tuple(lo), tuple(hi), axis, low, high))
        return len(groups) - 1

    build([0, 0, 0], list(block_grid))
    return groups


def assembled(decided: list, n_maxima: int) -> tuple:
    """The whole graph's events from every group's (`decided`, emptied as they are
    joined), in the in-memory sweep order (decreasing saddle, pair), with their
    elders: (young, elder, target, source, saddle, saddle value)."""
    # One column at a time, each group's copy dropped as it is joined: the peak is a
    # column more than the events, not twice them (the joining worker's, issue 30).
    columns = []
    for k in range(5):
        columns.append(np.concatenate([d[k] for d in decided]))
        for i, d in enumerate(decided):
            decided[i] = (*d[:k], None, *d[k + 1:])
    young, target, source, saddle, value = columns
    del columns
    order = _saddle_order(value, saddle, np.minimum(target, source), np.maximum(target, source))
    order = order[::-1]
    young, target, source = (v[order].astype(np.int32) for v in (young, target, source))
    saddle, value = saddle[order].astype(np.int64), value[order]
    del order
    elder = np.empty_like(young)
    _kernels.elders(young, target, n_maxima, elder)
    return young, elder, target, source, saddle, value
