"""The measure pruning's merges with the region ids the sequential pruning gives them,
decided in groups (`_bucket_prune`, step 4; issue 30).

The groups of `_prune_groups` find every merge's extinction and pruned region
exactly, but not the id the other region has at that moment in the sequential order:
a group may merge a frozen neighbour's region only later, or its child may have merged
into it a region the sequential order merges later. A cut needs those ids (the larger
of the two is never a region again, so following it to the smaller over the merges a
cut makes gives each maximum its region).

Once every merge's key is known, the sequential pruning is Kruskal's algorithm on the
merge edges in the order of their keys (extinction, then the larger pruned id first:
a strict order, a region pruned again with its id has a larger key), each component
named by its lowest id. A group knows, for each region, the keys of its edges to the
outside; a union of its regions under the edges before key k is the sequential one
when no edge to the outside comes before k (*exact*). A merge whose two sides are
exact is decided: its two ids are the sides' lowest. The others go up, their ends
named by the decided unions, as do the edges to the outside; every edge passed up
comes after every merge decided inside the unions it touches, so the group above
starts from those unions. The root has no outside and decides every merge.
"""

from __future__ import annotations

import numba
import numpy as np

from ..._distinct import distinct, positions
from ..._union_find import find_root
from .._prune_groups import GroupState

__all__ = []

_NONE = np.iinfo(np.int64).max


@numba.njit(cache=True, nogil=True, inline="always")
def _before(ext_a, tie_a, ext_b, tie_b):
    """Key a comes before key b: a lower extinction, ties the larger pruned id first."""
    return ext_a < ext_b or (ext_a == ext_b and tie_a > tie_b)


@numba.njit(cache=True, nogil=True)
def decide(u, v, ext, tie, n_nodes):
    """Kruskal in a group (module docstring): edges (u, v) in the order of their keys
    (ext, tie), v = -1 for an edge to the outside. Returns (decided (E,) bool, gone and
    keep (E,): the local nodes whose unions a decided merge joins, the larger index
    first; each node's decided union (its lowest node))."""
    n_ev = len(u)
    every = np.arange(n_nodes)
    union = np.arange(n_nodes)
    out_ext = np.full(n_nodes, _NONE, dtype=np.int64)
    out_tie = np.full(n_nodes, -1, dtype=np.int64)
    for e in range(n_ev):
        if v[e] < 0 and _before(ext[e], tie[e], out_ext[u[e]], out_tie[u[e]]):
            out_ext[u[e]], out_tie[u[e]] = ext[e], tie[e]
    decided = np.zeros(n_ev, dtype=np.bool_)
    gone = np.full(n_ev, -1, dtype=np.int64)
    keep = np.full(n_ev, -1, dtype=np.int64)
    for e in range(n_ev):
        if v[e] < 0:
            continue
        a, b = find_root(every, u[e]), find_root(every, v[e])
        if not (_before(out_ext[a], out_tie[a], ext[e], tie[e])
                or _before(out_ext[b], out_tie[b], ext[e], tie[e])):
            ra, rb = find_root(union, u[e]), find_root(union, v[e])
            keep[e], gone[e] = min(ra, rb), max(ra, rb)
            union[gone[e]] = keep[e]
            decided[e] = True
        low, high = min(a, b), max(a, b)
        every[high] = low
        if _before(out_ext[high], out_tie[high], out_ext[low], out_tie[low]):
            out_ext[low], out_tie[low] = out_ext[high], out_tie[high]
    root = np.empty(n_nodes, dtype=np.int64)
    for m in range(n_nodes):
        root[m] = find_root(union, m)
    return decided, gone, keep, root


def state(rid, young, near, far, ext, tie) -> GroupState:
    """A group's edges as a `GroupState` (`GroupState.joined` joins them): the nodes
    `rid` (increasing), each edge (`young`: its identity) from `near` to `far` (-1:
    outside), in the order of their keys, given as the sweep (-ext, tie): decreasing."""
    zeros = np.zeros(len(young), np.int64)
    return GroupState(rid, np.zeros(len(rid), np.int64), young, near, far, zeros, zeros - 1,
                      (-ext, tie))


def local_ends(group: GroupState) -> tuple:
    """(u, v): each edge's ends as places among the group's regions, by one hash table
    (`positions`) for both; v is -1 where b is -1 (outside): region ids are never
    negative, so -1 is never among them."""
    u, v = positions(group.rid, np.stack([group.a, group.b]))
    return u, v


def decided(group: GroupState) -> tuple:
    """(the merges it decides, as (larger id, smaller id, extinction, pruned id); the
    `GroupState` it passes up: its undecided edges, ends named by the decided unions)."""
    rid = group.rid.astype(np.int64)
    u, v = local_ends(group)
    ext, tie = -group.sweep[0], group.sweep[1]
    done, gone, keep, root = decide(u, v, ext, tie, len(rid))
    rest = ~done
    a = rid[root[u[rest]]]
    b = np.where(v[rest] >= 0, rid[root[np.maximum(v[rest], 0)]], -1)
    up = state(distinct(np.concatenate([a, b[b >= 0]])), group.event[rest], a, b,
               ext[rest], tie[rest])
    return (rid[gone[done]], rid[keep[done]], ext[done], tie[done]), up
