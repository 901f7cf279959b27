"""Compiled pruning of the hierarchy by an additive measure (DESIGN.md section 12),
and the one-pass sums of the cells' measures it prunes by.

Carr, Snoeyink and van de Panne (2004): repeatedly take the region of least measure,
merge it across the highest saddle it shares with a neighbour, add its measure to the
neighbour's. The highest edge leaving a connected union of cells is an edge of the
cell graph's maximum spanning forest (the cut property; the sweep order is strict),
and those edges are exactly the merge events' (source, target) pairs: the pruning runs
on the events alone. Each region keeps its events in a pairing heap keyed by sweep
order (a lower event index is a higher saddle); an event whose two ends already share
a region is dropped when it reaches the top. The regions wait in one binary heap
indexed by region, keyed by measure: a merge raises the keeper's key in place and
takes the other region out, so the heap never holds a stale entry.

The measures are non-negative, so the pruned measures never decrease: pruned to the
end once, the order and the measure at each merge (its *extinction*) hold every cut,
a count k as a prefix of the order, a threshold t as the events whose extinction is
below t.
"""

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


@numba.njit(cache=True, nogil=True, inline="always")
def _before(a, b, measure):
    """Region a is pruned before b: a smaller measure, on a tie the larger id."""
    return measure[a] < measure[b] or (measure[a] == measure[b] and a > b)


@numba.njit(cache=True, nogil=True)
def _sift_up(i, regions, pos, measure):
    r = regions[i]
    while i > 0:
        up = (i - 1) // 2
        if not _before(r, regions[up], measure):
            break
        regions[i] = regions[up]
        pos[regions[i]] = i
        i = up
    regions[i] = r
    pos[r] = i


@numba.njit(cache=True, nogil=True)
def _sift_down(i, regions, n, pos, measure):
    r = regions[i]
    while True:
        c = 2 * i + 1
        if c >= n:
            break
        if c + 1 < n and _before(regions[c + 1], regions[c], measure):
            c += 1
        if not _before(regions[c], r, measure):
            break
        regions[i] = regions[c]
        pos[regions[i]] = i
        i = c
    regions[i] = r
    pos[r] = i


@numba.njit(cache=True, nogil=True)
def _remove(r, regions, n, pos, measure):
    """Take region r out of the binary heap `regions[:n]`; returns the new size."""
    i = pos[r]
    n -= 1
    pos[r] = -1
    if i < n:
        moved = regions[n]
        regions[i] = moved
        pos[moved] = i
        _sift_down(i, regions, n, pos, measure)
        _sift_up(pos[moved], regions, pos, measure)
    return n


def prune(source, target, n_max, base, order, extinction):
    """Prune to the end: order[i] is the i-th event merged, extinction[e] the measure
    of the region pruned across event e. `base` (n_max,) is each cell's measure.

    Ties of measure: the region whose highest maximum is lower (larger id) first,
    the rest of the Morse stage's order. Returns the number of merges (every event).
    The pairing heaps' links are int32 when they fit: 24 bytes per event, not 48.
    """
    n_ev = len(source)
    link = np.int32 if 2 * n_ev + 1 < 2 ** 31 else np.int64
    return prune_events(source, target, n_max, base, order, extinction,
                        np.full(2 * n_ev, -1, dtype=link), np.full(2 * n_ev, -1, dtype=link),
                        np.empty(2 * n_ev + 1, dtype=link))


@numba.njit(cache=True, nogil=True)
def prune_events(source, target, n_max, base, order, extinction, child, sibling, stack):
    """`prune` with the pairing heaps' link arrays given: child and sibling (2E,) all
    -1, stack (2E + 1,)."""
    n_ev = len(source)
    heap_of = np.full(n_max, -1, dtype=np.int64)
    for e in range(n_ev):             # entry 2e at the source's end, 2e + 1 the target's
        heap_of[source[e]] = _meld(heap_of[source[e]], 2 * e, child, sibling)
        heap_of[target[e]] = _meld(heap_of[target[e]], 2 * e + 1, child, sibling)
    parent = np.arange(n_max)
    measure = base.copy()
    regions = np.empty(n_max, dtype=np.int64)
    pos = np.full(n_max, -1, dtype=np.int64)
    n = 0
    for m in range(n_max):
        if heap_of[m] >= 0:
            regions[n] = m
            pos[m] = n
            n += 1
    for i in range((n - 2) // 2, -1, -1):
        _sift_down(i, regions, n, pos, measure)
    n_merged = 0
    while n:
        r = regions[0]
        h = heap_of[r]
        while h >= 0 and find_root(parent, source[h // 2]) == find_root(parent, target[h // 2]):
            h = _pop(h, child, sibling, stack)          # an edge inside the region
        heap_of[r] = h
        if h < 0:                                       # a whole component: nothing left
            n = _remove(r, regions, n, pos, measure)
            continue
        e = h // 2
        other = find_root(parent, source[e])
        if other == r:
            other = find_root(parent, target[e])
        value = measure[r]
        order[n_merged] = e
        extinction[e] = value
        n_merged += 1
        keep, gone = min(r, other), max(r, other)
        parent[gone] = keep
        heap_of[keep] = _meld(heap_of[r], heap_of[other], child, sibling)
        n = _remove(gone, regions, n, pos, measure)
        measure[keep] = value + measure[other]          # never smaller: sift down
        _sift_down(pos[keep], regions, n, pos, measure)
    return n_merged


@numba.njit(cache=True, nogil=True, inline="always")
def _term(cells, field, saddles, unit, hypervolume, i):
    """The int64 term of vertex i inside the mask: 1 (size), or floor((f - s) / unit)
    above s = its cell's highest saddle, else 0 (hypervolume)."""
    if not hypervolume:
        return np.int64(1)
    above = field[i] - saddles[cells[i]]
    return np.int64(np.floor(above / unit)) if above > 0 else np.int64(0)


@numba.njit(cache=True, nogil=True)
def cell_sums(cells, field, saddles, unit, hypervolume, out):
    """out[c] += the terms of cell c's vertices (cells < 0: outside the mask), in one
    pass: no per-vertex temporaries."""
    for i in range(len(cells)):
        if cells[i] >= 0:
            out[cells[i]] += _term(cells, field, saddles, unit, hypervolume, i)


@numba.njit(cache=True, nogil=True, inline="always")
def _slot(keys, key, bits):
    """The slot of `key` in an open-addressing table of 2^bits int64 keys (-1 empty)."""
    mask = (1 << bits) - 1
    h = np.int64((np.uint64(key) * np.uint64(0x9E3779B97F4A7C15)) >> np.uint64(64 - bits))
    while keys[h] >= 0 and keys[h] != key:
        h = (h + 1) & mask
    return h


@numba.njit(cache=True, nogil=True)
def block_sums(cells, field, saddles, unit, hypervolume):
    """(ids, sums) of a block: its distinct cells (any order) and the sums of their
    terms, through a hash table (no sort of the block; a run of one cell along the
    fastest axis is one lookup)."""
    bits = 10
    keys = np.full(1 << bits, -1, dtype=np.int64)
    sums = np.zeros(1 << bits, dtype=np.int64)
    used, last, slot = 0, -1, 0
    for i in range(len(cells)):
        c = cells[i]
        if c < 0:
            continue
        if c != last:
            if 2 * (used + 1) > len(keys):              # grow at half full
                bits += 1
                grown = np.full(1 << bits, -1, dtype=np.int64)
                grown_sums = np.zeros(1 << bits, dtype=np.int64)
                for k in range(len(keys)):
                    if keys[k] >= 0:
                        at = _slot(grown, keys[k], bits)
                        grown[at] = keys[k]
                        grown_sums[at] = sums[k]
                keys, sums = grown, grown_sums
            slot = _slot(keys, c, bits)
            if keys[slot] < 0:
                keys[slot] = c
                used += 1
            last = c
        sums[slot] += _term(cells, field, saddles, unit, hypervolume, i)
    taken = keys >= 0
    return keys[taken], sums[taken]


@numba.njit(cache=True, nogil=True)
def masked_range(cells, field):
    """(min, max) of the field over the vertices inside the mask; (inf, -inf) if none."""
    low, high = np.inf, -np.inf
    for i in range(len(cells)):
        if cells[i] >= 0:
            low = min(low, field[i])
            high = max(high, field[i])
    return low, high
