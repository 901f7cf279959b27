"""Stage 5 of the blockwise build on the workers: the elder-rule union-find decided in
a tree of block groups, so that no process holds the whole cell graph.

The blocks are grouped by halving the block grid along its longest axis, down to single
blocks. Each group sweeps its part of the cell graph from the highest saddle down
(`_block_kernels.decide`): the edges of its blocks' spanning forests (at a leaf), or
what its two halves could not decide (above). A cell is *open* in a group when it may
have edges the group does not see: it lies on, or just outside, a face of the group
that is not the volume's boundary (`faces`). A component with no open cell is the
whole graph's component at that level, so

- an edge joining two closed components is an event of the whole graph, decided here;
- an edge joining a closed component to a higher open one is an event too: the closed
  side's highest maximum dies. Only its elder (the highest maximum of the open side at
  that level, which may lie outside) is asked of the group above, by a query;
- anything else (two open components, or a closed one above an open one) goes up, with
  each end replaced by its representative: the highest cell of a closed component, or
  the open cell whose component absorbed it. The group above then sees the same
  components at every level, with the same highest maxima.

The root has no open cell, so every event is decided somewhere, exactly as the
in-memory sweep decides it (same young, elder, target, source and saddle: the tests
compare them for every chunking). What a group passes up is what touches its faces,
so it scales with the groups' surfaces, not their volumes; the decided events leave
each group as they are found.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import _block_kernels as kernels
from ._edges import _saddle_order

__all__ = []

#: Bits of a query's handle below its group's number.
_HANDLE_BITS = 32


@dataclass
class _Items:
    """A group's undecided work: edges (``y >= 0``) between the nodes `x` and `y` (cells),
    with their original pair (a < b), saddle and saddle value, and elder queries
    (``y < 0``: at node `x`, keyed by their event's edge, named by `handle`)."""

    a: np.ndarray
    b: np.ndarray
    saddle: np.ndarray
    value: np.ndarray
    x: np.ndarray
    y: np.ndarray
    handle: np.ndarray

    @classmethod
    def joined(cls, parts) -> _Items:
        return cls(*(np.concatenate([getattr(p, name) for p in parts])
                     for name in ("a", "b", "saddle", "value", "x", "y", "handle")))

    def taken(self, index) -> _Items:
        return _Items(self.a[index], self.b[index], self.saddle[index], self.value[index],
                      self.x[index], self.y[index], self.handle[index])

    @property
    def nbytes(self) -> int:
        return sum(getattr(self, n).nbytes for n in ("a", "b", "saddle", "value", "x", "y",
                                                     "handle"))


@dataclass
class _Group:
    """What a group passes to the group above: its undecided items and its six faces'
    cells (axis 0 low, axis 0 high, axis 1 low, ...; empty on the volume's boundary)."""

    items: _Items
    faces: tuple


def forest_items(a, b, saddle, value) -> _Items:
    """A block's forest edges as a leaf group's items."""
    nothing = np.full(len(a), -1, dtype=np.int64)
    return _Items(a, b, saddle.astype(np.int64), value, a.copy(), b.copy(), nothing)


def leaf(block, group_id: int):
    """(decided, group) of one block: `block` is the pairs stage's result, its forest
    (a, b, saddle, value) and its six faces' cells."""
    a, b, saddle, value, *faces = block
    return decide(forest_items(a, b, saddle, value), tuple(faces), group_id)


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
    """The group's sweep (`_block_kernels.decide`): (the events it decides, the answers
    to queries from below, as a tuple of arrays; the `_Group` for the group above)."""
    order = _saddle_order(items.value, items.saddle, items.a, items.b)
    items = items.taken(order)
    is_query = items.y < 0
    nodes = np.unique(np.concatenate([items.x, items.y[~is_query]]))
    x = np.searchsorted(nodes, items.x)
    y = np.where(is_query, -1, np.searchsorted(nodes, items.y))
    open_cells = np.unique(np.concatenate(faces)) if faces else np.zeros(0, nodes.dtype)
    where = np.minimum(np.searchsorted(open_cells, nodes), max(len(open_cells) - 1, 0))
    node_open = (open_cells[where] == nodes) if len(open_cells) else np.zeros(len(nodes), bool)
    n = len(items.a)
    ev_item, res_item, up_item = (np.empty(n, np.int64) for _ in range(3))
    ev_young, ev_elder, res_elder, up_x, up_y = (np.empty(n, nodes.dtype) for _ in range(5))
    ev_x_elder = np.empty(n, bool)
    up_kind = np.empty(n, np.int8)
    n_ev, n_res, n_up = kernels.decide(x, y, nodes, node_open, ev_item, ev_young, ev_elder,
                                       ev_x_elder, res_item, res_elder, up_item, up_kind,
                                       up_x, up_y)
    ev_item, ev_young, ev_elder, ev_x_elder = (v[:n_ev] for v in (ev_item, ev_young, ev_elder,
                                                                   ev_x_elder))
    up_item, up_kind, up_x, up_y = (v[:n_up] for v in (up_item, up_kind, up_x, up_y))
    # A query for each event whose elder is asked above, in the events' order.
    new = up_kind == 2
    handles = (np.int64(group_id) << _HANDLE_BITS) + np.arange(int(new.sum()), dtype=np.int64)
    ev_handle = np.full(n_ev, -1, dtype=np.int64)
    ev_handle[ev_elder < 0] = handles
    decided = (ev_young, ev_elder,
               np.where(ev_x_elder, items.a[ev_item], items.b[ev_item]),      # target
               np.where(ev_x_elder, items.b[ev_item], items.a[ev_item]),      # source
               items.saddle[ev_item], items.value[ev_item], ev_handle,
               items.handle[res_item[:n_res]], res_elder[:n_res].copy())
    up = items.taken(up_item[::-1])                       # increasing key again
    up.x = nodes[up_x[::-1]]
    up.y = np.where(up_kind[::-1] == 0, nodes[np.maximum(up_y[::-1], 0)], -1).astype(nodes.dtype)
    handle = up.handle.copy()
    handle[new[::-1]] = handles[::-1]
    up.handle = handle
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


def assembled(decided: list) -> tuple:
    """The whole graph's events from every group's, in the in-memory sweep order
    (decreasing saddle, pair), each elder asked above filled in from its answer:
    (young, elder, target, source, saddle, saddle value)."""
    young, elder, target, source, saddle, value, handle = (
        np.concatenate([d[k] for d in decided]) for k in range(7))
    asked = np.concatenate([d[7] for d in decided])
    answer = np.concatenate([d[8] for d in decided])
    pending = np.flatnonzero(elder < 0)
    by_handle = np.argsort(asked)
    where = np.searchsorted(asked[by_handle], handle[pending])
    if len(pending) and not np.array_equal(asked[by_handle][where], handle[pending]):
        raise RuntimeError("blockwise Morse: an elder was asked and never answered (a bug)")
    elder[pending] = answer[by_handle][where]
    order = _saddle_order(value, saddle, np.minimum(target, source), np.maximum(target, source))
    order = order[::-1]
    cast = [x[order].astype(np.int32) for x in (young, elder, target, source)]
    return (*cast, saddle[order].astype(np.int64), value[order])
