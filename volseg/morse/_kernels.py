"""Compiled passes for `volseg.morse`: flat, checked arrays, no defaults.

Neighbours come either from flat offsets on a padded grid (``grid=True``; the pad
holds -inf, so it is never higher than a real vertex) or from a CSR adjacency.
"Higher" is simulation of simplicity: (f(u), u) > (f(v), v).

The elder-rule sweep runs on the cell graph, not on every vertex: inside a
descending cell the superlevel set is connected through the cell's maximum (steepest
ascent stays above), so components merge only across edges between cells, and
Kruskal over those edges, ordered by their lower endpoint, is the vertex sweep.
`cell_pairs` (with `two_sided` where it walks each edge once) keeps exactly the
highest edge per pair of adjacent cells (only that one can ever join two
components); `kruskal` then runs a union-find over maxima. Sweeping the
cell-boundary vertices in value order instead was 3x slower at 256^3 (random access
into the whole field).
"""

import numba
import numpy as np

from .._union_find import find_root


@numba.njit(cache=True, nogil=True, inline="always")
def _higher(values, u, v):
    return values[u] > values[v] or (values[u] == values[v] and u > v)


#: Grid neighbourhoods of at most this many offsets are walked by a loop of exactly
#: this length (`unrolled`: the offsets padded by 0, the vertex itself, which never
#: wins against the best so far): a loop of known length is unrolled, 4x faster
#: steepest ascent at 256^3 (Kuhn's 14 offsets).
UNROLLED = 16


def unrolled(offsets) -> tuple[np.ndarray, bool]:
    """(steps, whether the loop over them is of the known length `UNROLLED`): `offsets`
    (flat, int64) padded to `UNROLLED` entries by 0 (the vertex itself, which never
    wins), or as they are if longer (18 and 26 neighbours take the loop of unknown
    length). The one place that choice is made, for both ascents."""
    offsets = np.asarray(offsets, dtype=np.int64)
    if len(offsets) > UNROLLED:
        return offsets, False
    return np.concatenate([offsets, np.zeros(UNROLLED - len(offsets), dtype=np.int64)]), True


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


@numba.njit(cache=True, parallel=True)
def steepest_ascent_unrolled(values, vertices, offsets, up):
    """`steepest_ascent` on a grid, `offsets` padded by `unrolled`."""
    for n in numba.prange(len(vertices)):
        v = vertices[n]
        best = v
        best_value = values[v]
        for t in range(UNROLLED):
            u = v + offsets[t]
            x = values[u]
            if x >= best_value:          # rarely taken: a neighbour as high as the best
                if x > best_value or u > best:
                    best = u
                    best_value = x
        up[v] = best


@numba.njit(cache=True, nogil=True)
def _resolve_run(vertices, up, cell, lo, hi):
    """`resolve_cells` for vertices[lo:hi]."""
    for n in range(lo, hi):
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


#: Runs of vertices the path compression is cut into.
_RESOLVE_RUNS = 64


@numba.njit(cache=True, parallel=True)
def resolve_cells(vertices, up, cell):
    """cell[v] = the maximum reached from v by following `up`, with path compression,
    in parallel runs of vertices (`cell` may be `up` itself: it then holds the roots).
    Two runs may compress the same path at once: each writes into up[x] only the one
    root x's path reaches, and never into a root, so every order of the writes leaves
    every path leading to its own root: the same cells and the same maxima (`roots`)."""
    n = len(vertices)
    for r in numba.prange(_RESOLVE_RUNS):
        _resolve_run(vertices, up, cell, n * r // _RESOLVE_RUNS, n * (r + 1) // _RESOLVE_RUNS)


@numba.njit(cache=True, parallel=True)
def relabel_roots(vertices, cell, maxima):
    """cell[v] = i for every vertex v whose root (`cell[v]`, fully compressed) is
    maxima[i], in place: the roots hold -(i + 1) while the others read them (a root's
    own entry is rewritten last), so no root -> id table of the nodes' size."""
    for i in numba.prange(len(maxima)):
        cell[maxima[i]] = -(i + 1)
    for n in numba.prange(len(vertices)):
        v = vertices[n]
        root = cell[v]
        if root >= 0:
            cell[v] = -cell[root] - 1
    for i in numba.prange(len(maxima)):
        cell[maxima[i]] = i


@numba.njit(cache=True, parallel=True)
def take(table, cells, out):
    """out[i] = table[cells[i]], a negative cell counted from the table's end (-1: its
    last entry): numpy's ``take`` on every core. A whole cut of 256^3 cells took
    11-17 ms with it on 2 cores, against 55-130 ms with numpy's ``table[cells]``."""
    n = len(table)
    for i in numba.prange(len(cells)):
        c = cells[i]
        out[i] = table[c if c >= 0 else n + c]


@numba.njit(cache=True, nogil=True)
def regions_of_cut(young, target, merged, region):
    """region[m] for each maximum m of a cut: the events with `merged` join the young
    maximum to its target; each resulting component is numbered by its lowest maximum
    id (its highest maximum), in increasing order. Returns the number of regions."""
    n = len(region)
    parent = np.arange(n)
    for e in range(len(young)):
        if merged[e]:
            a = find_root(parent, young[e])
            b = find_root(parent, target[e])
            if a < b:
                parent[b] = a
            elif b < a:
                parent[a] = b
    count = 0
    for m in range(n):        # a root is its component's lowest id: numbered first
        r = find_root(parent, m)
        if r == m:
            region[m] = count
            count += 1
        else:
            region[m] = region[r]
    return count


@numba.njit(cache=True, nogil=True)
def spanning_edges(edge_a, edge_b, order, parent, keep):
    """The blockwise build's per-block forest (`_edges.spanning_forest`): keep[e] =
    True for the edges of the maximum spanning forest, Kruskal from the last of
    `order` (the highest edge) down, over the union-find `parent` (cells 0..n-1,
    updated: a second call goes on with lower edges). An edge left out closes a cycle
    of higher edges of the same block, so it merges nothing in the whole graph
    either: the forest of the union of the blocks' forests is the whole graph's (the
    order is strict, so that forest is unique)."""
    for k in range(len(order) - 1, -1, -1):
        e = order[k]
        x = find_root(parent, edge_a[e])
        y = find_root(parent, edge_b[e])
        if x != y:
            parent[max(x, y)] = min(x, y)
            keep[e] = True


@numba.njit(cache=True, nogil=True)
def apart(edge_a, edge_b, edges, parent):
    """The `edges` whose two cells are in different components of `parent`."""
    out = np.empty(len(edges), dtype=np.int64)
    m = 0
    for k in range(len(edges)):
        e = edges[k]
        if find_root(parent, edge_a[e]) != find_root(parent, edge_b[e]):
            out[m] = e
            m += 1
    return out[:m]


@numba.njit(cache=True, parallel=True)
def gather(order, edge_a, edge_b, edge_v, out_a, out_b, out_v):
    """out_*[i] = edge_*[order[i]]: the edges in sweep order, in parallel, so that the
    union-find reads them sequentially."""
    for i in numba.prange(len(order)):
        e = order[i]
        out_a[i] = edge_a[e]
        out_b[i] = edge_b[e]
        out_v[i] = edge_v[e]


@numba.njit(cache=True, nogil=True)
def kruskal(edge_a, edge_b, edge_v, n_max, ev_young, ev_elder, ev_target, ev_source,
            ev_saddle):
    """Elder-rule merges over cross-cell edges sorted by increasing saddle: the last
    (highest saddle) first.

    Maximum ids are by decreasing value, so a component's root is its lowest id.
    Event e: maximum ev_young[e] dies into the component of ev_elder[e] at vertex
    ev_saddle[e]; ev_target[e] and ev_source[e] are the cells of the edge's pair on
    the elder's and on the young's side (the events' pairs are the edges of the cell
    graph's maximum spanning forest). Returns the number of events.
    """
    parent = np.arange(n_max)
    n_ev = 0
    for e in range(len(edge_a) - 1, -1, -1):
        ca = edge_a[e]
        cb = edge_b[e]
        ra = find_root(parent, ca)
        rb = find_root(parent, cb)
        if ra == rb:
            continue
        if ra < rb:
            young, elder, target, source = rb, ra, ca, cb
        else:
            young, elder, target, source = ra, rb, cb, ca
        ev_young[n_ev] = young
        ev_elder[n_ev] = elder
        ev_target[n_ev] = target
        ev_source[n_ev] = source
        ev_saddle[n_ev] = edge_v[e]
        n_ev += 1
        parent[young] = elder
        if n_ev == n_max - 1:
            break
    return n_ev


@numba.njit(cache=True, nogil=True)
def elders(young, target, n_max, elder):
    """elder[e]: the highest maximum of target[e]'s component when young[e] dies into
    it, from the events in sweep order (each young is its own component's highest
    then, so the roots here are always the components' highest maxima)."""
    parent = np.arange(n_max)
    for e in range(len(young)):
        elder[e] = find_root(parent, target[e])
        parent[young[e]] = elder[e]


@numba.njit(cache=True, nogil=True, inline="always")
def _before(i, j, saddle, edge_a, edge_b):
    """Edge i before edge j among equal saddle values: by (saddle vertex, a, b)."""
    if saddle[i] != saddle[j]:
        return saddle[i] < saddle[j]
    if edge_a[i] != edge_a[j]:
        return edge_a[i] < edge_a[j]
    return edge_b[i] < edge_b[j]


@numba.njit(cache=True, nogil=True)
def break_ties(order, values, saddle, edge_a, edge_b):
    """Within each short run of equal values, sort `order` by (saddle vertex, a, b);
    returns the long runs (more than 32 edges) as (K, 2) start, stop, left to the
    caller (`_edges._saddle_order`, by numpy: numba's own argsort took 2 CPU-s to
    compile).

    `order` sorts `values` in any tie order; with the long runs sorted too it sorts by
    (value, vertex, cell pair) exactly, so the result does not depend on the sort
    used, nor on the order in which the edges were found (several edges can share a
    saddle vertex, and which merges first decides the events' targets). The values
    are read through `order` (no sorted copy: one array of the edges less at the
    client's peak).
    """
    n = len(order)
    long_runs = np.empty(32, dtype=np.int64)   # start, stop, start, ...: grown by a loop
    n_long = 0                                   # (numba's concatenate: 0.24 s to compile)
    start = 0
    while start < n:
        stop = start + 1
        first = values[order[start]]
        while stop < n and values[order[stop]] == first:
            stop += 1
        if stop - start > 32:
            if 2 * n_long == len(long_runs):
                grown = np.empty(2 * len(long_runs), dtype=np.int64)
                for k in range(len(long_runs)):
                    grown[k] = long_runs[k]
                long_runs = grown
            long_runs[2 * n_long], long_runs[2 * n_long + 1] = start, stop
            n_long += 1
        elif stop - start > 1:  # short runs (often one vertex's edges): insertion sort
            for i in range(start + 1, stop):
                item = order[i]
                j = i - 1
                while j >= start and _before(item, order[j], saddle, edge_a, edge_b):
                    order[j + 1] = order[j]
                    j -= 1
                order[j + 1] = item
        start = stop
    return long_runs[:2 * n_long].reshape(n_long, 2)


@numba.njit(cache=True, nogil=True)
def group_by_cell_of_nodes(cell, n_cells, starts, members):
    """`group_by_cell` when the vertices are exactly the nodes with a cell (cell >= 0):
    the same members, read off `cell` alone, so the vertex list can be freed first."""
    for c in range(n_cells + 1):
        starts[c] = 0
    for v in range(len(cell)):
        if cell[v] >= 0:
            starts[cell[v] + 1] += 1
    for c in range(n_cells):
        starts[c + 1] += starts[c]
    fill = starts[:-1].copy()
    for v in range(len(cell)):
        c = cell[v]
        if c >= 0:
            members[fill[c]] = v
            fill[c] += 1


@numba.njit(cache=True, nogil=True)
def group_by_cell(vertices, cell, n_cells, starts, members):
    """Counting sort of the vertices by cell: members[starts[c]:starts[c + 1]] are cell
    c's vertices, in increasing order."""
    for c in range(n_cells + 1):
        starts[c] = 0
    for n in range(len(vertices)):
        starts[cell[vertices[n]] + 1] += 1
    for c in range(n_cells):
        starts[c + 1] += starts[c]
    fill = starts[:-1].copy()
    for n in range(len(vertices)):
        v = vertices[n]
        c = cell[v]
        members[fill[c]] = v
        fill[c] += 1


@numba.njit(cache=True, nogil=True)
def _pairs_of_cells(values, members, starts, visit, lo, hi, grid, offsets, indptr, indices,
                    cell, degree, one_sided, out_a, out_b, out_v, start, capacity, table_size):
    """Unique cell pairs (a, b), a in visit[lo:hi] and b > a, each with its highest saddle;
    with `one_sided`, each cell a with every other cell b its vertices' forward edges
    reach instead (to a neighbour u > v; a grid's `offsets` are then its positive
    ones), so a pair may come out once from each side (`two_sided` merges them).

    For every vertex of cell a and every neighbour u in a cell b > a (any b != a when
    one-sided), the edge's saddle is its lower end. a's partners are found through a
    small open-addressing table (`table[slot]` = 1 + index into part_*, 0 if free)
    sized for a's vertex count, so it stays in cache; only the slots a used are
    cleared afterwards. Writes the first `capacity` entries from out_*[start]; returns
    how many there were. The table and its columns are made here, not in
    `cell_pairs`' parallel loop: numba compiles a loop body with allocations of its
    own for longer.
    """
    room = table_size // 2
    table = np.zeros(table_size, dtype=np.int32)
    part_b = np.empty(room, dtype=cell.dtype)
    part_v = np.empty(room, dtype=members.dtype)
    part_f = np.empty(room, dtype=np.float64)
    part_slot = np.empty(room, dtype=np.int64)
    n = 0
    n_cells = len(starts) - 1
    for p in range(lo, hi):
        a = visit[p]
        floor = 0 if one_sided else a + 1   # partners b >= floor, b != a
        bound = min(degree * (starts[a + 1] - starts[a]), n_cells)
        size = 16
        while size < 2 * bound:
            size *= 2
        mask = size - 1
        m = 0
        for idx in range(starts[a], starts[a + 1]):
            v = members[idx]
            fv = values[v]
            lowest = v if one_sided else -1     # one-sided: backward edges come from u
            count = len(offsets) if grid else indptr[v + 1] - indptr[v]
            for t in range(count):
                u = v + offsets[t] if grid else indices[indptr[v] + t]
                b = cell[u]
                # the same cell, off the vertices (-1), a smaller one seen from there
                # or a backward edge walked from its other end: one branch for all
                if (b < floor) | (b == a) | (u < lowest):
                    continue
                fu = values[u]
                v_higher = (fv > fu) | ((fv == fu) & (v > u))
                low = u if v_higher else v              # selects: the order is a coin flip
                fl = fu if v_higher else fv
                slot = (b * 2654435761) & mask
                while True:
                    k = table[slot]
                    if k == 0:
                        table[slot] = m + 1
                        part_b[m] = b
                        part_v[m] = low
                        part_f[m] = fl
                        part_slot[m] = slot
                        m += 1
                        break
                    if part_b[k - 1] == b:
                        f, w = part_f[k - 1], part_v[k - 1]
                        better = (fl > f) | ((fl == f) & (low > w))
                        part_v[k - 1] = low if better else w
                        part_f[k - 1] = fl if better else f
                        break
                    slot = (slot + 1) & mask
        for q in range(m):
            table[part_slot[q]] = 0
            if n < capacity:
                out_a[start + n] = a
                out_b[start + n] = part_b[q]
                out_v[start + n] = part_v[q]
            n += 1
    return n


@numba.njit(cache=True, nogil=True)
def two_sided(a, b, v, values, n_cells):
    """Merge the pairs a one-sided `_pairs_of_cells` found from both sides (each cell's
    entries contiguous): an entry (a, b) with b < a is folded into b's entry for a,
    keeping the higher saddle (by value, then index), or becomes (b, a) where b has
    none. Returns keep (bool): the entries left, exactly one per pair, all a < b."""
    first = np.full(n_cells, -1, dtype=np.int64)
    count = np.zeros(n_cells, dtype=np.int64)
    for i in range(len(a)):
        if first[a[i]] < 0:
            first[a[i]] = i
        count[a[i]] += 1
    keep = np.ones(len(a), dtype=np.bool_)
    for i in range(len(a)):
        x, y = a[i], b[i]
        if y > x:
            continue
        found = -1
        if first[y] >= 0:
            for j in range(first[y], first[y] + count[y]):
                if b[j] == x:
                    found = j
                    break
        if found < 0:
            a[i], b[i] = y, x
            continue
        if _higher(values, v[i], v[found]):
            v[found] = v[i]
        keep[i] = False
    return keep


@numba.njit(cache=True, parallel=True)
def cell_pairs(values, members, starts, visit, bounds, chunks, grid, offsets, indptr, indices,
               cell, degree, one_sided, table_sizes, out_a, out_b, out_v, out_starts, capacity,
               counts):
    """`_pairs_of_cells` over cells visit[bounds[c]:bounds[c + 1]] for c in `chunks`, in
    parallel (one partner table per chunk, `table_sizes[c]` slots: room for the largest
    cell's bound). Chunking is fixed, so the output does not depend on the thread
    count; the caller reruns the chunks that overflowed."""
    for i in numba.prange(len(chunks)):
        c = chunks[i]
        counts[i] = _pairs_of_cells(values, members, starts, visit, bounds[c], bounds[c + 1],
                                    grid, offsets, indptr, indices, cell, degree, one_sided,
                                    out_a, out_b, out_v, out_starts[i], capacity[i],
                                    table_sizes[c])


@numba.njit(cache=True, nogil=True)
def roots(vertices, up):
    """The vertices v with up[v] == v (the maxima), in the order of `vertices`, without
    the two field-sized temporaries of the numpy expression."""
    n = 0
    for k in range(len(vertices)):
        if up[vertices[k]] == vertices[k]:
            n += 1
    out = np.empty(n, dtype=vertices.dtype)
    n = 0
    for k in range(len(vertices)):
        v = vertices[k]
        if up[v] == v:
            out[n] = v
            n += 1
    return out


@numba.njit(cache=True, nogil=True)
def key_counts(keys, n_keys):
    """(n_keys,) how many of `keys` hold each key in 0..n_keys-1; keys below 0 are
    left out."""
    count = np.zeros(n_keys, dtype=np.int64)
    for i in range(len(keys)):
        if keys[i] >= 0:
            count[keys[i]] += 1
    return count


@numba.njit(cache=True, nogil=True)
def key_starts(keys, n_keys):
    """(n_keys + 1,) where each key's indices start in a counting sort of `keys`
    (`by_key`); the last entry counts the keys not below 0."""
    count = key_counts(keys, n_keys)
    start = np.zeros(n_keys + 1, dtype=np.int64)
    for k in range(n_keys):
        start[k + 1] = start[k] + count[k]
    return start


@numba.njit(cache=True, nogil=True)
def by_key(keys, start, order):
    """The scatter of a stable counting sort: fills `order` (start[-1] long, its type
    the caller's) with the indices of `keys` by key, increasing within a key, key k's
    at order[start[k]:start[k + 1]]; keys below 0 are left out."""
    fill = start[:-1].copy()
    for i in range(len(keys)):
        k = keys[i]
        if k >= 0:
            order[fill[k]] = i
            fill[k] += 1


@numba.njit(cache=True, nogil=True)
def counting_sort(keys, n_keys, order):
    """A stable counting sort of `keys` (each in 0..n_keys-1, or below 0 to leave
    out): fills `order` with the indices by key (`by_key`) and returns each key's
    start (n_keys + 1,)."""
    start = key_starts(keys, n_keys)
    by_key(keys, start, order)
    return start
