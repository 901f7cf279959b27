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
ones bit for bit (in memory, one record per vertex); `saliency` then sweeps the events
once, adding each rank's records (a counting sort) to its region and reading both sides
before joining them.

A cut by saliency keeps the k - 1 events of largest saliency and merges the rest
across their saddle edges (source, target): the regions are connected, and a larger
threshold merges more (nested cuts), as a horizontal cut of higra's hierarchy.
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numba
import numpy as np

from .._distinct import counts, index_type, slot_of
from .._sizes import SizedByArrays
from .._union_find import find_root
from ._kernels import counting_sort
from ._prune import masked_range

__all__ = ["Basins", "records", "block_records", "joined", "saliency", "merge_order"]


@dataclass(frozen=True)
class Basins(SizedByArrays):
    """The vertices of a field summed per (cell, rank): `cell`, `rank` (R,) of one
    integer type (`_index`), `count` (R,) (vertices, or their weights on a mesh; empty
    when every record is one vertex, as in memory on a grid), `sums` (R,) of the
    vertices' values in fixed point (`low` + `unit` x steps; on a mesh, weight x value
    as floats), `scale` what one step of area x `unit` counts (the vertex weight)."""

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
        if len(self.count) == 0:                        # one vertex per record
            return counts(self.cell, n) * self.scale
        return np.bincount(self.cell, weights=self.count, minlength=n) * self.scale


def _index(cell_max: int, n_events: int):
    """The type of a `Basins`' cells and ranks: int32 where they fit (half the memory
    of one record per vertex), else int64; the same rule in memory and blockwise, so
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
        sums[slot] += np.int64(np.floor((field[i] - low) / unit))
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


def records(cells, field, saddle_value, weight, unit_of, scale_of) -> Basins:
    """`Basins` of a field in memory: one record per vertex (no table: the sweep's
    counting sort by rank is the grouping), fixed point on a grid (`weight` None or a
    number; the step ``unit_of(low, high)``, an area step ``scale_of(weight, 1)``),
    float sums weighted per vertex on a mesh (`weight` one per vertex).

    On a grid a record is its cell and rank (`_index`: int32 where they fit) and its
    int64 steps, 16 bytes a vertex, filled chunk by chunk (`RECORD_CHUNK`) with no
    temporaries (at 512^3 the records and their temporaries took 40 bytes a voxel or
    more)."""
    cells, field = np.ravel(cells), np.ravel(field)
    index = _index(int(cells.max(initial=0)), len(saddle_value))
    negated = -np.asarray(saddle_value, np.float64)
    if weight is not None and np.ndim(weight) > 0:
        cell, rank, _ = _filled(cells, field, negated, 0.0, np.inf, index)
        inside = cells >= 0
        w = np.asarray(weight, np.float64)[inside]
        return Basins(cell, rank, w, w * field[inside], 0.0, 1.0, 1.0)
    low, high = masked_range(cells, field)
    unit = unit_of(low, high)
    cell, rank, sums = _filled(cells, field, negated, low, unit, index)
    return Basins(cell, rank, np.zeros(0, np.int64), sums, low, unit, scale_of(weight, 1.0))


def _filled(cells, field, negated, low, unit, index):
    """(cell, rank, steps) of the vertices inside the mask, `_records_into` chunk by
    chunk (`RECORD_CHUNK`) into arrays made once."""
    starts = range(0, len(cells), RECORD_CHUNK)
    taken = [int(np.count_nonzero(cells[a:a + RECORD_CHUNK] >= 0)) for a in starts]
    at = np.concatenate([[0], np.cumsum(taken, dtype=np.int64)])
    cell, rank, sums = (np.empty(at[-1], index), np.empty(at[-1], index),
                        np.empty(at[-1], np.int64))

    def fill(k):
        a = starts[k]
        _records_into(cells[a:a + RECORD_CHUNK], field[a:a + RECORD_CHUNK], negated, low,
                      unit, cell, rank, sums, at[k])

    # The kernel releases the GIL: chunks side by side on numba's threads (random
    # reads of the saddles, bound by memory latency: 1.4-1.6x on 2 cores). An
    # interrupt cancels the chunks not started (`Executor.map` does) rather than
    # waiting for them.
    with ThreadPoolExecutor(max(1, min(numba.get_num_threads(), len(starts)))) as pool:
        list(pool.map(fill, range(len(starts))))
    return cell, rank, sums


@numba.njit(cache=True, nogil=True)
def _records_into(cells, field, negated, low, unit, cell, rank, sums, at):
    """The records of a chunk's vertices inside the mask (cell >= 0), from index `at`:
    the cell, the rank (`_rank`) and the fixed-point steps (all 0 for `unit` inf:
    the ranks alone)."""
    for i in range(len(cells)):
        if cells[i] < 0:
            continue
        f = field[i]
        cell[at] = cells[i]
        rank[at] = _rank(negated, f)
        sums[at] = np.int64(np.floor((f - low) / unit))
        at += 1


def saliency(basins: Basins, source, target, saddle_value, n_max: int,
             volume: bool) -> np.ndarray:
    """(E,) each event's saliency: the smaller area (or volume) of the two regions it
    joins, at its saddle; int64 steps on a grid (times `basins.scale`, and `unit` for
    a volume, to read it), float on a mesh."""
    saddle_value = np.asarray(saddle_value, np.float64)
    if basins.sums.dtype == np.int64:
        level = np.floor((saddle_value - basins.low) / basins.unit).astype(np.int64)
    else:
        level = saddle_value
    out = np.empty(len(source), dtype=basins.sums.dtype)
    order = np.empty(len(basins.rank), dtype=index_type(len(basins.rank)))
    _sweep(basins.cell, basins.rank, basins.count, basins.sums,
           np.asarray(source, np.int64), np.asarray(target, np.int64), level, n_max,
           volume, order, out)
    return out


@numba.njit(cache=True, nogil=True)
def _sweep(cell, rank, count, sums, source, target, level, n_max, volume, order, out):
    """`saliency`'s sweep; `count` empty: one vertex per record."""
    parent = np.arange(n_max)
    area = np.zeros(n_max, dtype=count.dtype)
    total = np.zeros(n_max, dtype=sums.dtype)
    ones = len(count) == 0
    start = counting_sort(rank, len(source) + 1, order)
    for e in range(len(source)):
        for t in range(start[e], start[e + 1]):
            i = order[t]
            r = find_root(parent, cell[i])
            area[r] += 1 if ones else count[i]
            total[r] += sums[i]
        a, b = find_root(parent, source[e]), find_root(parent, target[e])
        if volume:
            left, right = total[a] - level[e] * area[a], total[b] - level[e] * area[b]
        else:
            left, right = area[a], area[b]
        out[e] = min(left, right)
        parent[a] = b
        area[b] += area[a]
        total[b] += total[a]


def merge_order(saliency_of_events) -> np.ndarray:
    """(E,) the events in the order a cut merges them: least saliency first, on a tie
    the lower saddle (the later event) first, so a cut into k regions keeps the k - 1
    last (docs/design.md section 12)."""
    events = np.arange(len(saliency_of_events))
    return np.lexsort((-events, saliency_of_events))
