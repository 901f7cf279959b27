"""Compiled pruning of the hierarchy by an additive measure (DESIGN.md section 12).

Carr, Snoeyink and van de Panne (2004): repeatedly take the region of least measure,
merge it across the highest saddle it shares with a neighbour, add its measure to the
neighbour's. The highest edge leaving a connected union of cells is an edge of the
cell graph's maximum spanning forest (the cut property; the sweep order is strict),
and those edges are exactly the merge events' (source, target) pairs: the pruning runs
on the events alone. Each region keeps its events in a pairing heap keyed by sweep
order (a lower event index is a higher saddle); an event whose two ends already share
a region is dropped when it reaches the top.

The measures are non-negative, so the pruned measures never decrease: pruned to the
end once, the order and the measure at each merge (its *extinction*) hold every cut,
a count k as a prefix of the order, a threshold t as the events whose extinction is
below t.
"""

import heapq

import numba
import numpy as np

from .._union_find import find_root


@numba.njit(cache=True, nogil=True, inline="always")
def _meld(a, b, child, sibling):
    """The root of two pairing heaps of event entries (entry // 2 is its key)."""
    if a < 0:
        return b
    if b < 0:
        return a
    if b // 2 < a // 2:
        a, b = b, a
    sibling[b] = child[a]
    child[a] = b
    return a


@numba.njit(cache=True, nogil=True)
def _pop(root, child, sibling, stack):
    """The heap without its root: the two-pass pairing of the root's children."""
    c = child[root]
    n = 0
    while c >= 0:
        second = sibling[c]
        sibling[c] = -1
        if second < 0:
            stack[n] = c
            c = -1
        else:
            rest = sibling[second]
            sibling[second] = -1
            stack[n] = _meld(c, second, child, sibling)
            c = rest
        n += 1
    out = -1
    for i in range(n - 1, -1, -1):
        out = _meld(out, stack[i], child, sibling)
    return out


@numba.njit(cache=True, nogil=True)
def prune(source, target, n_max, base, order, extinction):
    """Prune to the end: order[i] is the i-th event merged, extinction[e] the measure
    of the region pruned across event e. `base` (n_max,) is each cell's measure.

    Ties of measure: the region whose highest maximum is lower (larger id) first,
    the rest of the Morse stage's order. Returns the number of merges (every event).
    """
    n_ev = len(source)
    child = np.full(2 * n_ev, -1, dtype=np.int64)
    sibling = np.full(2 * n_ev, -1, dtype=np.int64)
    stack = np.empty(2 * n_ev + 1, dtype=np.int64)
    heap_of = np.full(n_max, -1, dtype=np.int64)
    for e in range(n_ev):             # entry 2e at the source's end, 2e + 1 the target's
        heap_of[source[e]] = _meld(heap_of[source[e]], 2 * e, child, sibling)
        heap_of[target[e]] = _meld(heap_of[target[e]], 2 * e + 1, child, sibling)
    parent = np.arange(n_max)
    measure = base.copy()
    version = np.zeros(n_max, dtype=np.int64)
    queue = [(measure[m], -m, np.int64(0)) for m in range(n_max) if heap_of[m] >= 0]
    heapq.heapify(queue)
    n_merged = 0
    while len(queue):
        value, neg, seen = heapq.heappop(queue)
        r = -neg
        if parent[r] != r or version[r] != seen:
            continue                                    # merged since, or grown since
        h = heap_of[r]
        while h >= 0 and find_root(parent, source[h // 2]) == find_root(parent, target[h // 2]):
            h = _pop(h, child, sibling, stack)          # an edge inside the region
        heap_of[r] = h
        if h < 0:
            continue                                    # a whole component: nothing left
        e = h // 2
        other = find_root(parent, source[e])
        if other == r:
            other = find_root(parent, target[e])
        order[n_merged] = e
        extinction[e] = value
        n_merged += 1
        keep, gone = min(r, other), max(r, other)
        parent[gone] = keep
        measure[keep] = value + measure[other]
        heap_of[keep] = _meld(heap_of[r], heap_of[other], child, sibling)
        version[keep] += 1
        version[gone] += 1
        heapq.heappush(queue, (measure[keep], -keep, version[keep]))
    return n_merged


@numba.njit(cache=True, nogil=True)
def cell_sums(cells, terms, out):
    """out[c] += the int64 terms of cell c's vertices (cells < 0: outside the mask)."""
    for i in range(len(cells)):
        c = cells[i]
        if c >= 0:
            out[c] += terms[i]
