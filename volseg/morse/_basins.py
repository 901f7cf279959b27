"""The watershed hierarchy's measures (docs/design.md sections 12 and 13): the area or
volume of the two regions each merge event joins, read at its saddle, and the event's
*saliency*, the smaller of the two, as in higra's ``watershed_hierarchy_by_area`` and
``_by_volume`` (extinction values: Vachier and Meyer 1995, Najman and Schmitt 1996).

At an event's saddle value s, the region on each side is the superlevel-set component
{f >= s} holding its maximum: the vertices at or above s of the cells already joined
to it by higher events (a vertex of a cell at or above s reaches the cell's maximum
without going below s). Its area is their count (times the vertex weight), its volume
the sum of f(v) - s over them. A vertex joins at the first event whose saddle is at or
below it, its *rank* (the count of events with a higher saddle). `records` sums the
vertices per (cell, rank), block by block, in fixed point on a grid (`STEPS` per range
of the field, `volseg.morse._measures`), so the blocks' sums add up to the in-memory
ones bit for bit; in memory on a grid `records` orders the vertices by rank instead
(`RankedVertices`) and the sweep reads their cells and values where they are.
`saliency` then sweeps the events once, adding each rank's records (or vertices) to
its region and reading both sides before joining them.

A cut by saliency keeps the k - 1 events of largest saliency and merges the rest
across their saddle edges (source, target): the regions are connected, and a larger
threshold merges more (nested cuts), as a horizontal cut of higra's hierarchy.
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numba
import numpy as np

from .._distinct import index_type, slot_of
from .._sizes import SizedByArrays
from .._union_find import find_root
from ._kernels import by_key, counting_sort, key_counts, key_starts
from ._prune import masked_range

__all__ = ["Basins", "RankedVertices", "BASINS", "records", "block_records", "joined",
           "saliency", "merge_order"]


@dataclass(frozen=True)
class Basins(SizedByArrays):
    """The vertices of a field summed per (cell, rank), as the blocks give them (one
    record per vertex on a mesh): `cell`, `rank` (R,) of one integer type (`_index`),
    `count` (R,) (vertices, or their weights on a mesh), `sums` (R,) of the vertices'
    values in fixed point (`low` + `unit` x steps; on a mesh, weight x value as
    floats), `scale` what one step of area x `unit` counts (the vertex weight)."""

    cell: np.ndarray
    rank: np.ndarray
    count: np.ndarray
    sums: np.ndarray
    low: float
    unit: float
    scale: float

    @property
    def values(self) -> np.ndarray:
        """(M,) each cell's area, as `MorseHierarchy.cell_measure` reports it."""
        n = int(self.cell.max(initial=-1)) + 1
        return np.bincount(self.cell, weights=self.count, minlength=n) * self.scale


@dataclass(frozen=True)
class RankedVertices(SizedByArrays):
    """The vertices of a field in memory on a grid, in the order the sweep adds them:
    `order` (V,) the flat indices of the vertices inside the mask by rank, rank r's
    being order[start[r]:start[r + 1]] (`start` (E + 2,)); the sweep reads their
    cells and values in `cells` and `field` (flat views of the hierarchy's own, not
    copies), the values' steps in fixed point (`low` + `unit` x steps) as `Basins`'
    are. 4 bytes a vertex (a `Basins` record took 16, and its sweep 4 more).
    `areas` (M,): each cell's vertex count; `scale`: what one counts."""

    cells: np.ndarray
    field: np.ndarray
    order: np.ndarray
    start: np.ndarray
    areas: np.ndarray
    low: float
    unit: float
    scale: float

    @property
    def values(self) -> np.ndarray:
        """(M,) each cell's area, as `MorseHierarchy.cell_measure` reports it."""
        return self.areas * self.scale


def _index(cell_max: int, n_events: int):
    """The type of a `Basins`' cells and ranks (and of the ranks `records` takes in
    memory): int32 where they fit, else int64; the same rule for blocks and meshes, so
    `_sweep` compiles once."""
    return index_type(max(cell_max, n_events) + 1)


@numba.njit(cache=True, nogil=True)
def _rank(negated, value):
    """The rank of a vertex of value `value`: the count of events with a saddle above
    it, ``np.searchsorted(negated, -value, side="left")`` on the negated saddles (in
    sweep order, so increasing). A branchless lower bound: about 1.5x numpy's on
    random queries; the one spelling of a rank, in memory and blockwise."""
    q = -value
    n = len(negated)
    base, m = 0, n
    while m > 1:
        half = m >> 1
        base = base + half if negated[base + half] < q else base
        m -= half
    return base + 1 if n > 0 and negated[base] < q else base


@numba.njit(cache=True, nogil=True)
def _steps(value, low, unit):
    """A value in the fixed point's steps: floor((value - low) / unit), as int64 (the
    saddles' levels are `_levels`, the same arithmetic in numpy)."""
    return np.int64(np.floor((value - low) / unit))


@numba.njit(cache=True, nogil=True)
def _grown(keys, counts, sums, bits):
    grown = np.full(1 << bits, -1, dtype=np.int64)
    grown_counts = np.zeros(1 << bits, dtype=np.int64)
    grown_sums = np.zeros(1 << bits, dtype=np.int64)
    for k in range(len(keys)):
        if keys[k] >= 0:
            at = slot_of(grown, grown, keys[k], bits)
            grown[at], grown_counts[at], grown_sums[at] = keys[k], counts[k], sums[k]
    return grown, grown_counts, grown_sums


@numba.njit(cache=True, nogil=True)
def block_records(cells, field, negated_saddles, low, unit):
    """(keys, counts, sums) of one block's vertices (flat; cells < 0 outside the mask):
    key = cell x (E + 1) + rank, the vertex count and the fixed-point value sum per key,
    through a hash table that doubles before it is half full."""
    n_ranks = np.int64(len(negated_saddles) + 1)
    bits = 10
    keys = np.full(1 << bits, -1, dtype=np.int64)
    counts = np.zeros(1 << bits, dtype=np.int64)
    sums = np.zeros(1 << bits, dtype=np.int64)
    used = 0
    for i in range(len(cells)):
        c = cells[i]
        if c < 0:
            continue
        key = np.int64(c) * n_ranks + _rank(negated_saddles, field[i])
        slot = slot_of(keys, keys, key, bits)
        if keys[slot] < 0:
            if 2 * (used + 1) > len(keys):
                bits += 1
                keys, counts, sums = _grown(keys, counts, sums, bits)
                slot = slot_of(keys, keys, key, bits)
            keys[slot] = key
            used += 1
        counts[slot] += 1
        sums[slot] += _steps(field[i], low, unit)
    taken = keys >= 0
    return keys[taken], counts[taken], sums[taken]


def joined(parts, n_events: int, low: float, unit: float, scale: float) -> Basins:
    """`Basins` from blocks' `block_records` (keys, counts, sums), side by side: a key
    may come from several blocks; the sweep adds its records in any order, in
    integers (exact)."""
    n_ranks = np.int64(n_events + 1)
    top = max((int(p[0].max()) for p in parts if len(p[0])), default=0)
    index = _index(top // int(n_ranks), n_events)
    # Each part's keys split into its share of cell and rank: no int64 copy of them all.
    n = sum(len(p[0]) for p in parts)
    cell, rank = np.empty(n, index), np.empty(n, index)
    at = 0
    for keys, _, _ in parts:
        cell[at:at + len(keys)] = keys // n_ranks
        rank[at:at + len(keys)] = keys % n_ranks
        at += len(keys)
    counts = np.concatenate([p[1] for p in parts]) if parts else np.zeros(0, np.int64)
    sums = np.concatenate([p[2] for p in parts]) if parts else np.zeros(0, np.int64)
    return Basins(cell, rank, counts, sums, low, unit, scale)


#: Vertices per chunk of `records` (the unit its threads share out).
RECORD_CHUNK = 1 << 22


def records(cells, field, saddle_value, weight, unit_of, scale_of):
    """What the sweep of a field in memory reads: on a grid (`weight` None or a
    number) its `RankedVertices`, the step ``unit_of(low, high)`` and an area step
    ``scale_of(weight, 1)``; on a mesh (`weight` one per vertex) `Basins` of one
    record per vertex inside the mask, with float sums weighted per vertex.

    The ranks are taken chunk by chunk (`RECORD_CHUNK`) on threads into one array of
    the cells' integer type (4 bytes a voxel, let go once the vertices are ordered).
    At 512^3 the records of one per vertex took 16 bytes a voxel, and the sweep's
    order 4 more."""
    cells, field = np.ravel(cells), np.ravel(field)
    n_cells = int(cells.max(initial=-1)) + 1
    index = _index(max(n_cells - 1, 0), len(saddle_value))
    rank = _ranks(cells, field, -np.asarray(saddle_value, np.float64), index)
    if weight is not None and np.ndim(weight) > 0:
        inside = cells >= 0
        w = np.asarray(weight, np.float64)[inside]
        return Basins(cells[inside].astype(index), rank[inside], w, w * field[inside],
                      0.0, 1.0, 1.0)
    low, high = masked_range(cells, field)
    start = key_starts(rank, len(saddle_value) + 1)
    order = np.empty(start[-1], index_type(len(cells)))
    by_key(rank, start, order)
    del rank
    areas = key_counts(cells, n_cells)
    return RankedVertices(cells, field, order, start, areas, low, unit_of(low, high),
                          scale_of(weight, 1.0))


def _ranks(cells, field, negated, index):
    """(N,) each vertex's rank (`_rank`), -1 outside the mask, `_ranks_into` chunk by
    chunk (`RECORD_CHUNK`)."""
    rank = np.empty(len(cells), index)
    starts = range(0, len(cells), RECORD_CHUNK)

    def fill(a):
        b = a + RECORD_CHUNK
        _ranks_into(cells[a:b], field[a:b], negated, rank[a:b])

    # The kernel releases the GIL: chunks side by side on numba's threads (random
    # reads of the saddles, bound by memory latency: 1.4-1.6x on 2 cores). An
    # interrupt cancels the chunks not started (`Executor.map` does) rather than
    # waiting for them.
    with ThreadPoolExecutor(max(1, min(numba.get_num_threads(), len(starts)))) as pool:
        list(pool.map(fill, starts))
    return rank


@numba.njit(cache=True, nogil=True)
def _ranks_into(cells, field, negated, rank):
    """rank[i]: the rank of vertex i (`_rank`), -1 outside the mask (cell < 0)."""
    for i in range(len(cells)):
        rank[i] = _rank(negated, field[i]) if cells[i] >= 0 else -1


def saliency(basins, source, target, saddle_value, n_max: int, volume: bool) -> np.ndarray:
    """(E,) each event's saliency: the smaller area (or volume) of the two regions it
    joins, at its saddle, from `Basins` or `RankedVertices`; int64 steps on a grid
    (times `scale`, and `unit` for a volume, to read it), float on a mesh."""
    saddle_value = np.asarray(saddle_value, np.float64)
    source, target = np.asarray(source, np.int64), np.asarray(target, np.int64)
    if isinstance(basins, RankedVertices):
        out = np.empty(len(source), dtype=np.int64)
        _sweep_vertices(basins.cells, basins.field, basins.order, basins.start, basins.low,
                        basins.unit, source, target, _levels(basins, saddle_value), n_max,
                        volume, out)
        return out
    if basins.sums.dtype == np.int64:
        level = _levels(basins, saddle_value)
    else:
        level = saddle_value
    out = np.empty(len(source), dtype=basins.sums.dtype)
    order = np.empty(len(basins.rank), dtype=index_type(len(basins.rank)))
    _sweep(basins.cell, basins.rank, basins.count, basins.sums, source, target, level, n_max,
           volume, order, out)
    return out


def _levels(basins, saddle_value):
    """The saddles' values in the steps of the fixed point."""
    return np.floor((saddle_value - basins.low) / basins.unit).astype(np.int64)


@numba.njit(cache=True, nogil=True)
def _sweep(cell, rank, count, sums, source, target, level, n_max, volume, order, out):
    """`saliency`'s sweep of `Basins`."""
    parent = np.arange(n_max)
    area = np.zeros(n_max, dtype=count.dtype)
    total = np.zeros(n_max, dtype=sums.dtype)
    start = counting_sort(rank, len(source) + 1, order)
    for e in range(len(source)):
        for t in range(start[e], start[e + 1]):
            i = order[t]
            r = find_root(parent, cell[i])
            area[r] += count[i]
            total[r] += sums[i]
        _joined_at(e, parent, area, total, source, target, level, volume, out)


@numba.njit(cache=True, nogil=True)
def _sweep_vertices(cells, field, order, start, low, unit, source, target, level, n_max,
                    volume, out):
    """`saliency`'s sweep of `RankedVertices`: each vertex's cell and value read
    where they are, the value in steps (`_steps`) as a block's records sum them."""
    parent = np.arange(n_max)
    area = np.zeros(n_max, dtype=np.int64)
    total = np.zeros(n_max, dtype=np.int64)
    for e in range(len(source)):
        for t in range(start[e], start[e + 1]):
            v = order[t]
            r = find_root(parent, cells[v])
            area[r] += 1
            total[r] += _steps(field[v], low, unit)
        _joined_at(e, parent, area, total, source, target, level, volume, out)


@numba.njit(cache=True, nogil=True)
def _joined_at(e, parent, area, total, source, target, level, volume, out):
    """Event e of a sweep: its saliency, the smaller side's area (or volume, above
    its saddle) into out[e], then the two regions joined."""
    a, b = find_root(parent, source[e]), find_root(parent, target[e])
    if volume:
        left, right = total[a] - level[e] * area[a], total[b] - level[e] * area[b]
    else:
        left, right = area[a], area[b]
    out[e] = min(left, right)
    parent[a] = b
    area[b] += area[a]
    total[b] += total[a]


#: What `saliency` sweeps: the watershed measures' cell base.
BASINS = (Basins, RankedVertices)


def merge_order(saliency_of_events) -> np.ndarray:
    """(E,) the events in the order a cut merges them: least saliency first, on a tie
    the lower saddle (the later event) first, so a cut into k regions keeps the k - 1
    last (docs/design.md section 12)."""
    events = np.arange(len(saliency_of_events))
    return np.lexsort((-events, saliency_of_events))
