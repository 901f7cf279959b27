"""The measure pruning (`_prune`) decided in groups of regions, so that no process
needs every maximum: a group prunes what its outside cannot change and passes the
rest up a tree of groups, as the union-find's block groups do (`_group_tree`).

Why a group may decide alone. The sequential pruning pops the region least in the
order (measure, then the larger id first) and merges it across its highest edge. Keys
only grow: a merge gives the union a key (sum) no less than either part's and the
smaller id, so it comes after both parts. Hence a region r that comes before every
region adjacent to it (a *local minimum*) stays so until the sequential pruning pops
it: nothing merges into r first (only an adjacent region coming before r could), its
highest edge stays its highest, and it is pruned with its own key across that edge.
Two local minima are never adjacent, so their merges commute and each stays a local
minimum after the other's: every order of local-minimum merges makes the same merges
with the same extinctions (the diamond lemma), the sequential order among them.

A group knows its regions' keys exactly and, for a region just outside it, a lower
bound of its key in that order (the outside maximum's own cell: any region holding it
weighs at least that much and its id is no larger). Popping its regions in order, a
region is merged when it comes before every outside neighbour's bound and its
highest edge stays inside; otherwise it is *frozen*, and so is every region found
adjacent to a frozen one when its turn comes (the frozen one came before it). Frozen
regions and the edges between them go up, unchanged: nothing inside the group merges
into a frozen region, so its key stays exact. The root has no outside and freezes
nothing. The sequential pops come in strictly increasing (key, -id), so the merge
order is the decided merges sorted by (extinction, -id of the region pruned).

Keys are int64 (the measures' fixed point, `_measures`): sums in any order are exact,
where float sums in another order could differ in the last bit and swap two merges.
"""

from __future__ import annotations

import numba
import numpy as np

from .._distinct import index_type
from .._sizes import SizedByArrays
from .._union_find import find_root
from ._group_tree import block_tree
from ._kernels import counting_sort
from ._prune import _before, _joined, _meld, _rekeyed, _remove, region_heap

__all__ = []

_NONE = np.iinfo(np.int64).max


@numba.njit(cache=True, nogil=True)
def prune_group(key, rid, u, v, out_key, out_id):
    """Prune a group as far as its outside allows (module docstring).

    key, rid (R,) int64: its regions' keys and ids (increasing ids); u, v (E,): the
    local ends of its edges in sweep order (highest saddle first; their integer type
    is the links' and region indices': int32 needs 2 max(E, R) + 1 < 2^31), v = -1
    where the other end is outside the group, with the lower bound (out_key, out_id)
    of the region there. Returns (decided (E,) bool, extinction (E,) int64 and pruned (E,)
    int64: the key and id of the region pruned across each decided edge; root (R,):
    each region's region after the merges, frozen (R,) bool, the regions' keys after
    the merges (the roots' exact), and the decided edges in the order decided, which
    is increasing (extinction, -pruned)).
    """
    n_reg, n_ev = len(key), len(u)
    key = key.copy()
    child, sibling, prev, stack, heap_of, low_key, low_id = _edge_heaps(
        n_reg, u, v, out_key, out_id)
    parent = np.arange(n_reg).astype(u.dtype)
    frozen = np.zeros(n_reg, dtype=np.bool_)
    blocked = np.zeros(n_reg, dtype=np.bool_)
    decided = np.zeros(n_ev, dtype=np.bool_)
    extinction = np.zeros(n_ev, dtype=np.int64)
    pruned = np.full(n_ev, -1, dtype=np.int64)
    sequence = np.empty(n_ev, dtype=np.int64)
    n_decided = 0
    hkey, region, pos, n = region_heap(key, heap_of, heap_of)
    while n:
        r = region[0]
        h = heap_of[r]                # the highest edge leaving r
        e = h // 2
        if (blocked[r] or (h % 2 == 0 and v[e] < 0)
                or not _before(key[r], rid[r], low_key[r], low_id[r])):
            frozen[r] = True
            n = _remove(r, hkey, region, n, pos)
            _block_neighbours(h, u, v, child, sibling, parent, blocked, stack)
            continue
        other = find_root(parent, v[e] if h % 2 == 0 else u[e])
        decided[e], extinction[e], pruned[e] = True, key[r], rid[r]
        sequence[n_decided] = e
        n_decided += 1
        total = key[r] + key[other]
        keep, gone = _joined(r, other, h, parent, heap_of, child, sibling, prev, stack)
        key[keep] = total
        blocked[keep] = blocked[other]
        if _before(low_key[gone], low_id[gone], low_key[keep], low_id[keep]):
            low_key[keep], low_id[keep] = low_key[gone], low_id[gone]
        n = _rekeyed(keep, gone, total, heap_of, hkey, region, n, pos)
    root = np.empty(n_reg, dtype=np.int64)
    for m in range(n_reg):
        root[m] = find_root(parent, m)
    return decided, extinction, pruned, root, frozen, key, sequence[:n_decided]


@numba.njit(cache=True, nogil=True)
def _edge_heaps(n_reg, u, v, out_key, out_id):
    """Each region's pairing heap of its edges (entry 2e at u's end, 2e + 1 at v's)
    and the least lower bound (low_key, low_id) of the regions outside it touches."""
    n_ev = len(u)
    child = np.full(2 * n_ev, -1, dtype=u.dtype)
    sibling = np.full(2 * n_ev, -1, dtype=u.dtype)
    prev = np.full(2 * n_ev, -1, dtype=u.dtype)
    stack = np.empty(2 * n_ev + 1, dtype=u.dtype)
    heap_of = np.full(n_reg, -1, dtype=u.dtype)
    low_key = np.full(n_reg, _NONE, dtype=np.int64)
    low_id = np.full(n_reg, -1, dtype=np.int64)
    for e in range(n_ev):
        heap_of[u[e]] = _meld(heap_of[u[e]], 2 * e, child, sibling, prev)
        if v[e] >= 0:
            heap_of[v[e]] = _meld(heap_of[v[e]], 2 * e + 1, child, sibling, prev)
        elif _before(out_key[e], out_id[e], low_key[u[e]], low_id[u[e]]):
            low_key[u[e]], low_id[u[e]] = out_key[e], out_id[e]
    return child, sibling, prev, stack, heap_of, low_key, low_id


@numba.njit(cache=True, nogil=True)
def _block_neighbours(top, u, v, child, sibling, parent, blocked, stack):
    """Mark blocked every region across an edge of the pairing heap rooted at `top`
    (a frozen region's edges; outside ends skipped)."""
    n = 0
    stack[n] = top
    n += 1
    while n:
        n -= 1
        x = stack[n]
        e = x // 2
        far = v[e] if x % 2 == 0 else u[e]
        if far >= 0:
            blocked[find_root(parent, far)] = True
        c = child[x]
        while c >= 0:
            stack[n] = c
            n += 1
            c = sibling[c]


class GroupState(SizedByArrays):
    """What a group holds, or passes up: its regions (ids `rid` increasing, exact
    `key`s) and its edges in sweep order (`event`: the event's identity; `a` the region
    holding one end, `b` the other's, or -1 outside with the lower bound (`out_key`,
    `out_id`) of the region there). `sweep`: None when `event` is the event's index in
    sweep order, else the sweep key's columns, decreasing in sweep order (the saddle
    value, saddle, lower end and higher end of `_group_tree.assembled`; `_merge_groups`
    orders its edges by another key)."""

    __slots__ = ("rid", "key", "event", "a", "b", "out_key", "out_id", "sweep", "local")

    def __init__(self, rid, key, event, a, b, out_key, out_id, sweep=None, local=None):
        self.rid, self.key = rid, key
        self.event, self.a, self.b, self.out_key, self.out_id = event, a, b, out_key, out_id
        self.sweep = sweep
        self.local = local      # (u, v) in `rid` of a and b, when known (a leaf's)

    @property
    def nbytes(self) -> int:
        return sum(getattr(self, c).nbytes for c in _COLUMNS) + sum(
            c.nbytes for c in self.sweep or ())

    @classmethod
    def joined(cls, parts) -> GroupState:
        """The union of sibling groups' states: an edge between two of them, passed
        up by both, is inside now (its ends the two holders)."""
        rid = np.concatenate([p.rid for p in parts])
        order = np.argsort(rid, kind="stable")
        event, a, b, out_key, out_id, sweep = _in_sweep_order(parts)
        twin = np.flatnonzero(event[1:] == event[:-1])      # seen from both sides
        b[twin] = a[twin + 1]
        out_key[twin], out_id[twin] = 0, -1
        keep = np.ones(len(event), dtype=bool)
        keep[twin + 1] = False
        return cls(rid[order], np.concatenate([p.key for p in parts])[order], event[keep],
                   a[keep], b[keep], out_key[keep], out_id[keep],
                   None if sweep is None else tuple(c[keep] for c in sweep))

    def pruned(self) -> tuple:
        """(decided, rest): the merges this group decides, as (event, extinction, id of
        the region pruned) in the order decided, and the state it passes up
        (`prune_group`)."""
        u, v = self.local or (np.searchsorted(self.rid, self.a), np.where(
            self.b >= 0, np.searchsorted(self.rid, np.maximum(self.b, 0)), -1))
        # int32 links and region indices where they fit: 25 % faster on a leaf of
        # 130 000 regions (less memory to walk); one signature per index type.
        index = index_type(2 * max(len(u), len(self.rid)) + 1)
        decided, extinction, pruned, root, frozen, key, sequence = prune_group(
            self.key, self.rid.astype(np.int64), u.astype(index, copy=False),
            v.astype(index, copy=False), self.out_key, self.out_id.astype(np.int64))
        rest = ~decided
        ru, rv = root[u[rest]], root[np.maximum(v[rest], 0)]
        stays = np.flatnonzero(frozen)
        up = GroupState(self.rid[stays], key[stays], self.event[rest], self.rid[ru],
                        np.where(v[rest] >= 0, self.rid[rv], -1), self.out_key[rest],
                        self.out_id[rest],
                        None if self.sweep is None else tuple(c[rest] for c in self.sweep))
        return (self.event[sequence], extinction[sequence], pruned[sequence]), up


_COLUMNS = ("rid", "key", "event", "a", "b", "out_key", "out_id")


def _in_sweep_order(parts) -> tuple:
    """The parts' edges (event, a, b, out_key, out_id, sweep) joined in sweep order: by
    `event`, or by decreasing sweep key; an edge seen by two parts comes twice, side
    by side."""
    columns = [np.concatenate([getattr(p, c) for p in parts])
               for c in ("event", "a", "b", "out_key", "out_id")]
    if parts[0].sweep is None:
        by, sweep = np.argsort(columns[0], kind="stable"), None
    else:
        sweep = [np.concatenate([p.sweep[k] for p in parts]) for k in range(len(parts[0].sweep))]
        by = np.lexsort(sweep[::-1])[::-1]
        sweep = tuple(c[by] for c in sweep)
    return (*(c[by] for c in columns), sweep)


def leaves(source, target, base, leaf_of, n_leaves) -> list:
    """Each leaf's `GroupState`, in leaf order: its maxima (`leaf_of` (M,): each
    maximum's leaf) and the events touching them, bucketed in one compiled pass each
    (`_bucketed`). Indices are int32 where they fit: about 28 bytes per event and end
    outside its leaf."""
    index = index_type(max(len(source), len(leaf_of), n_leaves))
    leaf_of = leaf_of.astype(index, copy=False)
    by_leaf = np.empty(len(leaf_of), dtype=index)     # maxima by leaf, ids increasing
    max_at = counting_sort(leaf_of, n_leaves, by_leaf)
    event, near, far, at = _bucketed(source, target, leaf_of, n_leaves)
    local = np.empty(len(leaf_of), dtype=index)       # each maximum's place in its leaf
    local[by_leaf] = np.arange(len(leaf_of), dtype=index) - max_at[leaf_of[by_leaf]]
    out = []
    for g in range(n_leaves):
        m = by_leaf[max_at[g]:max_at[g + 1]]
        e = slice(at[g], at[g + 1])
        far_in = leaf_of[far[e]] == g
        b = np.where(far_in, far[e], -1)
        out.append(GroupState(m, base[m], event[e], near[e], b,
                              np.where(far_in, 0, base[far[e]]), np.where(far_in, -1, far[e]),
                              local=(local[near[e]], np.where(far_in, local[far[e]], -1))))
    return out


@numba.njit(cache=True, nogil=True)
def _bucketed(source, target, leaf_of, n_leaves):
    """Every event at the leaf of each end (once if both are in one leaf), events
    increasing in each leaf: (event, near end, far end, each leaf's start (L + 1,))."""
    at = np.zeros(n_leaves + 1, dtype=np.int64)
    for e in range(len(source)):
        at[leaf_of[source[e]] + 1] += 1
        if leaf_of[target[e]] != leaf_of[source[e]]:
            at[leaf_of[target[e]] + 1] += 1
    at = np.cumsum(at)
    fill = at[:-1].copy()
    event = np.empty(at[-1], dtype=leaf_of.dtype)
    near = np.empty(at[-1], dtype=leaf_of.dtype)
    far = np.empty(at[-1], dtype=leaf_of.dtype)
    for e in range(len(source)):
        s, t = source[e], target[e]
        for a, b in ((s, t), (t, s)):
            g = leaf_of[a]
            if a == t and g == leaf_of[s]:
                break
            event[fill[g]], near[fill[g]], far[fill[g]] = e, a, b
            fill[g] += 1
    return event, near, far, at


#: A leaf group's edge on a grid, in voxels: 64^3 measured fastest at 256^3 (2.5 s
#: against 2.9 s for 128^3, 7.9 s for 32^3, the sequential pruning 3.7 s).
LEAF_EDGE = 64


def grid_leaves(maxima, shape, edge: int = LEAF_EDGE) -> tuple:
    """(leaf of each maximum (M,), the groups' tree) for maxima at flat indices of a
    grid of `shape`, in leaves of edge^3 voxels."""
    grid = tuple(max(-(-int(n) // edge), 1) for n in shape)
    leaf_of = _leaf_of(np.asarray(maxima), np.array(shape, np.int64), np.array(grid, np.int64),
                       edge)
    return leaf_of, block_tree(grid)


@numba.njit(cache=True, nogil=True)
def _leaf_of(maxima, shape, grid, edge):
    out = np.empty(len(maxima), dtype=np.int64)
    for i in range(len(maxima)):
        rest, leaf, stride = maxima[i], 0, 1
        for d in range(2, -1, -1):
            leaf += (rest % shape[d]) // edge * stride
            rest //= shape[d]
            stride *= grid[d]
        out[i] = leaf
    return out


def grouped_prune(source, target, base, leaf_of, tree) -> tuple:
    """The sequential pruning (`_prune.prune`) of the events (source, target) with
    int64 `base` keys, decided in the groups of `tree` (`_group_tree.block_tree`,
    children before parents; a leaf's place in the block grid is its index in
    `leaf_of`'s numbering, C order): (order, extinction (E,) int64)."""
    grid = tuple(tree[-1][1])
    leaf_states = dict(enumerate(leaves(source, target, base, leaf_of, int(np.prod(grid)))))
    passed, decided = {}, []
    for i, (lo, _, _, low, high) in enumerate(tree):
        if low is None:
            state = leaf_states.pop(int(np.ravel_multi_index(lo, grid)))
        else:
            state = GroupState.joined([passed.pop(low), passed.pop(high)])
        found, passed[i] = state.pruned()
        decided.append(found)
    if len(passed.pop(len(tree) - 1).event):     # the root has no outside: a bug
        raise RuntimeError("the root group of the pruning left events undecided")
    starts = np.cumsum([0] + [len(d[0]) for d in decided])
    event, extinction, pruned = (np.concatenate([d[k] for d in decided]) for k in range(3))
    out = np.empty(len(source), dtype=np.int64)
    out[event] = extinction
    return merge_order(event, extinction, pruned, starts), out


def merge_order(event, extinction, pruned, starts) -> np.ndarray:
    """The sequential pruning's order of the decided merges, by extinction, ties the
    larger pruned id first (module docstring): the groups' lists, each in that order
    already (from `starts`, (k + 1,)), merged."""
    index, ids = index_type(len(event)), index_type(int(pruned.max(initial=0)))
    return event[_merged_runs(extinction.copy(), pruned.astype(ids),
                              np.arange(len(event), dtype=index), np.asarray(starts, np.int64))]


@numba.njit(cache=True, nogil=True)
def _merged_runs(ext, pr, pos, starts):
    """The positions of k sorted runs (from `starts`) merged: neighbouring runs merged
    pairwise, pass after pass, each pass a streaming read of the keys inline (a heap
    of the k heads missed the cache on every step). `ext`, `pr` and `pos` (the
    positions, 0..n-1) are overwritten."""
    ext2, pr2, pos2 = np.empty_like(ext), np.empty_like(pr), np.empty_like(pos)
    bounds = starts.copy()
    while len(bounds) > 2:
        k = len(bounds) - 1
        out_bounds = np.empty((k + 1) // 2 + 1, dtype=np.int64)
        for j in range(0, k, 2):
            lo, mid = bounds[j], bounds[j + 1]
            hi = bounds[j + 2] if j + 2 <= k else mid
            i, m, t = lo, mid, lo
            while i < mid and m < hi:
                if ext[m] < ext[i] or (ext[m] == ext[i] and pr[m] > pr[i]):
                    ext2[t], pr2[t], pos2[t] = ext[m], pr[m], pos[m]
                    m += 1
                else:
                    ext2[t], pr2[t], pos2[t] = ext[i], pr[i], pos[i]
                    i += 1
                t += 1
            for a in range(i, mid):
                ext2[t], pr2[t], pos2[t] = ext[a], pr[a], pos[a]
                t += 1
            for a in range(m, hi):
                ext2[t], pr2[t], pos2[t] = ext[a], pr[a], pos[a]
                t += 1
            out_bounds[j // 2] = lo
        out_bounds[-1] = bounds[-1]
        bounds = out_bounds
        ext, ext2, pr, pr2, pos, pos2 = ext2, ext, pr2, pr, pos2, pos
    return pos
