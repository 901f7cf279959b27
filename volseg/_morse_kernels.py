"""Compiled passes for `volseg.morse`: flat, checked arrays, no defaults.

Neighbours come either from flat offsets on a padded grid (``grid=True``; the pad
holds -inf, so it is never higher than a real vertex) or from a CSR adjacency.
"Higher" is simulation of simplicity: (f(u), u) > (f(v), v).

The elder-rule sweep runs on the cell graph, not on every vertex: inside a
descending cell the superlevel set is connected through the cell's maximum (steepest
ascent stays above), so components merge only across edges between cells, and
Kruskal over those edges, ordered by their lower endpoint, is the vertex sweep.
Only cell-boundary vertices are sorted and swept; the union-find is over maxima.
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


@numba.njit(cache=True, parallel=True)
def boundary_mask(values, vertices, grid, offsets, indptr, indices, cell, mask):
    """mask[n]: vertices[n] has a higher neighbour in another cell (a saddle candidate)."""
    for n in numba.prange(len(vertices)):
        v = vertices[n]
        found = False
        if grid:
            for t in range(len(offsets)):
                u = v + offsets[t]
                if _higher(values, u, v) and cell[u] != cell[v]:
                    found = True
                    break
        else:
            for e in range(indptr[v], indptr[v + 1]):
                u = indices[e]
                if _higher(values, u, v) and cell[u] != cell[v]:
                    found = True
                    break
        mask[n] = found


@numba.njit(cache=True, nogil=True, inline="always")
def _find(parent, x):
    while parent[x] != x:
        parent[x] = parent[parent[x]]
        x = parent[x]
    return x


@numba.njit(cache=True, nogil=True)
def merge_sweep(values, order, grid, offsets, indptr, indices, cell, n_max,
                ev_young, ev_elder, ev_target, ev_saddle):
    """Elder-rule merges over cells, saddle candidates from order[-1] down to order[0].

    Maximum ids are by decreasing value, so a component's root is its lowest id.
    Event e: maximum ev_young[e] dies into the component of ev_elder[e] at vertex
    ev_saddle[e]; ev_target[e] is the cell across that saddle edge. Returns the
    number of events.
    """
    parent = np.arange(n_max)
    n_ev = 0
    for idx in range(len(order) - 1, -1, -1):
        v = order[idx]
        count = len(offsets) if grid else indptr[v + 1] - indptr[v]
        for t in range(count):
            u = v + offsets[t] if grid else indices[indptr[v] + t]
            if cell[u] == cell[v] or not _higher(values, u, v):
                continue
            ru = _find(parent, cell[u])
            rv = _find(parent, cell[v])
            if ru == rv:
                continue
            if ru < rv:
                young, elder, target = rv, ru, cell[u]
            else:
                young, elder, target = ru, rv, cell[v]
            ev_young[n_ev] = young
            ev_elder[n_ev] = elder
            ev_target[n_ev] = target
            ev_saddle[n_ev] = v
            n_ev += 1
            parent[young] = elder
    return n_ev
