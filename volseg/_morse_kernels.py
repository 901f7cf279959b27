"""Compiled passes for `volseg.morse`: flat, checked arrays, no defaults.

Neighbours come either from flat offsets on a padded grid (``grid=True``; the pad
holds -inf, so it is never higher than a real vertex) or from a CSR adjacency.
"Higher" is simulation of simplicity: (f(u), u) > (f(v), v).

The elder-rule sweep runs on the cell graph, not on every vertex: inside a
descending cell the superlevel set is connected through the cell's maximum (steepest
ascent stays above), so components merge only across edges between cells, and
Kruskal over those edges, ordered by their lower endpoint, is the vertex sweep.
`cross_edges` gathers them in memory order keeping (mostly) the highest edge per
cell pair (only that one can ever join two components); `kruskal` then runs a
union-find over maxima. Sweeping the cell-boundary vertices in value order instead
was 3x slower at 256^3 (random access into the whole field).
"""

import numba
import numpy as np


@numba.njit(cache=True, nogil=True, inline="always")
def _higher(values, u, v):
    return values[u] > values[v] or (values[u] == values[v] and u > v)


@numba.njit(cache=True, parallel=True)
def steepest_ascent(values, vertices, grid, offsets, indptr, indices, up):
    """up[v] = v's highest neighbour if higher than v, else v (a maximum)."""
    for n in numba.prange(len(vertices)):
        v = vertices[n]
        best = v
        if grid:
            for t in range(len(offsets)):
                u = v + offsets[t]
                if _higher(values, u, best):
                    best = u
        else:
            for e in range(indptr[v], indptr[v + 1]):
                u = indices[e]
                if _higher(values, u, best):
                    best = u
        up[v] = best


@numba.njit(cache=True, nogil=True)
def resolve_cells(vertices, up, cell):
    """cell[v] = the maximum reached from v by following `up` (path compression)."""
    for n in range(len(vertices)):
        v = vertices[n]
        root = v
        while up[root] != root:
            root = up[root]
        x = v
        while up[x] != root and x != root:
            nxt = up[x]
            up[x] = root
            x = nxt
        cell[v] = root


@numba.njit(cache=True, parallel=True)
def relabel(vertices, cell, ids):
    """cell[v] = ids[cell[v]] (root vertex -> maximum id)."""
    for n in numba.prange(len(vertices)):
        v = vertices[n]
        cell[v] = ids[cell[v]]


@numba.njit(cache=True, nogil=True, inline="always")
def find_root(parent, x):
    """Root of x in a union-find forest, halving the path on the way (shared with
    `_star_kernels`)."""
    while parent[x] != x:
        parent[x] = parent[parent[x]]
        x = parent[x]
    return x


_TABLE_BITS = 12


@numba.njit(cache=True, nogil=True, inline="always")
def _emit(out_a, out_b, out_v, start, n, capacity, a, b, v):
    """Write edge number n of a chunk if it fits; return n + 1 (the count goes on)."""
    if n < capacity:
        out_a[start + n] = a
        out_b[start + n] = b
        out_v[start + n] = v
    return n + 1


@numba.njit(cache=True, nogil=True)
def _chunk_edges(values, vertices, lo, hi, grid, offsets, indptr, indices, cell,
                 out_a, out_b, out_v, start, capacity):
    """Cross-cell edges of vertices[lo:hi], deduplicated per cell pair.

    For each vertex v and each higher neighbour u in another cell, the candidate
    saddle of the cell pair {cell[v], cell[u]} (stored smaller id first) is v. A small direct-mapped table keeps
    the highest candidate per pair; an evicted entry is emitted, and the table is
    flushed at the end. Duplicates of a pair may be emitted (they are harmless to
    Kruskal: only the highest one of a pair can join two components). Writes the
    first `capacity` edges from out_*[start]; returns how many there were in all.
    """
    size = 1 << _TABLE_BITS
    mask = size - 1
    tab_a = np.full(size, -1, dtype=np.int64)
    tab_b = np.zeros(size, dtype=np.int64)
    tab_v = np.zeros(size, dtype=np.int64)
    n = 0
    for k in range(lo, hi):
        v = vertices[k]
        cv = cell[v]
        count = len(offsets) if grid else indptr[v + 1] - indptr[v]
        for t in range(count):
            u = v + offsets[t] if grid else indices[indptr[v] + t]
            cu = cell[u]
            if cu == cv or not _higher(values, u, v):
                continue
            a, b = (cv, cu) if cv < cu else (cu, cv)
            slot = (a * 1000003 + b * 7919) & mask
            if tab_a[slot] == a and tab_b[slot] == b:
                if _higher(values, v, tab_v[slot]):
                    tab_v[slot] = v
                continue
            if tab_a[slot] >= 0:  # evict the entry in the way
                n = _emit(out_a, out_b, out_v, start, n, capacity,
                          tab_a[slot], tab_b[slot], tab_v[slot])
            tab_a[slot] = a
            tab_b[slot] = b
            tab_v[slot] = v
    for slot in range(size):
        if tab_a[slot] >= 0:
            n = _emit(out_a, out_b, out_v, start, n, capacity,
                      tab_a[slot], tab_b[slot], tab_v[slot])
    return n


@numba.njit(cache=True, parallel=True)
def cross_edges(values, vertices, bounds, chunks, grid, offsets, indptr, indices, cell,
                out_a, out_b, out_v, starts, capacity, counts):
    """`_chunk_edges` over vertices[bounds[c]:bounds[c + 1]] for c in `chunks`, in parallel.

    The i-th chunk writes at most capacity[i] edges from starts[i] and reports its full
    count in counts[i]; the caller reruns the chunks that overflowed. Chunking is
    fixed, so the output does not depend on the thread count.
    """
    for i in numba.prange(len(chunks)):
        c = chunks[i]
        counts[i] = _chunk_edges(values, vertices, bounds[c], bounds[c + 1], grid, offsets,
                                 indptr, indices, cell, out_a, out_b, out_v, starts[i],
                                 capacity[i])


@numba.njit(cache=True, nogil=True)
def kruskal(order, edge_a, edge_b, edge_v, n_max, ev_young, ev_elder, ev_target, ev_saddle):
    """Elder-rule merges over cross-cell edges, order[-1] (highest saddle) first.

    Maximum ids are by decreasing value, so a component's root is its lowest id.
    Event e: maximum ev_young[e] dies into the component of ev_elder[e] at vertex
    ev_saddle[e]; ev_target[e] is the cell of the edge's pair on the elder's side.
    Returns the number of events.
    """
    parent = np.arange(n_max)
    n_ev = 0
    for idx in range(len(order) - 1, -1, -1):
        e = order[idx]
        ca = edge_a[e]
        cb = edge_b[e]
        ra = find_root(parent, ca)
        rb = find_root(parent, cb)
        if ra == rb:
            continue
        if ra < rb:
            young, elder, target = rb, ra, ca
        else:
            young, elder, target = ra, rb, cb
        ev_young[n_ev] = young
        ev_elder[n_ev] = elder
        ev_target[n_ev] = target
        ev_saddle[n_ev] = edge_v[e]
        n_ev += 1
        parent[young] = elder
        if n_ev == n_max - 1:
            break
    return n_ev


@numba.njit(cache=True, nogil=True)
def break_ties(order, ranked, saddle):
    """Within each run of equal `ranked` values, sort `order` by saddle vertex index.

    `order` sorts the values (`ranked` = values[order]) in any tie order; afterwards it
    sorts by (value, vertex) exactly, so the result does not depend on the sort used.
    """
    n = len(order)
    start = 0
    while start < n:
        stop = start + 1
        while stop < n and ranked[stop] == ranked[start]:
            stop += 1
        if stop - start > 32:
            run = order[start:stop].copy()
            order[start:stop] = run[np.argsort(saddle[run])]
        elif stop - start > 1:  # short runs (often one vertex's edges): insertion sort
            for i in range(start + 1, stop):
                item = order[i]
                key = saddle[item]
                j = i - 1
                while j >= start and saddle[order[j]] > key:
                    order[j + 1] = order[j]
                    j -= 1
                order[j + 1] = item
        start = stop
