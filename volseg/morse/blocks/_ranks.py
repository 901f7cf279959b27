"""The maxima's ids of the blockwise build (their ranks by decreasing (value, gid), as in
memory) by a sample sort on the workers: no process sorts them all.

1. Each block sorts its own maxima and gives `_SAMPLES` of them.
2. One small task picks ``buckets - 1`` splitters from the samples.
3. Each block splits its sorted maxima at the splitters and counts each bucket.
4. One small task turns the counts (blocks x buckets) into each bucket's first rank.
5. Each bucket sorts what the blocks put in it: its maxima's ranks are its first rank
   plus their position. The buckets' sorted maxima, in bucket order, are the whole
   sorted list (`maxima`, `values` of the hierarchy).
6. Each block gathers its maxima's ranks from the buckets.

The order is strict (the gid breaks ties), so the ranks are exactly the in-memory ids
whatever the samples. Everything is one lazy graph: the client asks nothing in between.
"""

from __future__ import annotations

import numpy as np

__all__ = []

#: Maxima per block that choose the splitters.
_SAMPLES = 16


def _key_order(values, gids):
    """Argsort by decreasing (value, gid): the in-memory ids' order."""
    return np.lexsort((gids, values))[::-1]


def _before(values, gids, value, gid):
    """For each splitter (value, gid): how many of the sorted (decreasing) maxima come
    before it, i.e. are higher."""
    # decreasing values: search the negated (increasing) values, then the gids in the run
    negated = -values
    lo = np.searchsorted(negated, -value, side="left")
    hi = np.searchsorted(negated, -value, side="right")
    out = lo.copy()
    for s in np.flatnonzero(hi > lo):
        run = gids[lo[s]:hi[s]][::-1]                   # increasing gids in the run
        out[s] = hi[s] - np.searchsorted(run, gid[s], side="right")
    return out


def sorted_block(maxima, values):
    """Step 1: a block's maxima sorted by decreasing (value, gid), and its samples."""
    order = _key_order(values, maxima)
    gids, values = maxima[order], values[order]
    pick = np.unique(np.linspace(0, len(gids) - 1, _SAMPLES).astype(np.int64)) if len(gids) \
        else np.zeros(0, np.int64)
    return gids, values, (values[pick], gids[pick])


def splitters(samples, buckets: int):
    """Step 2: ``buckets - 1`` splitters (values, gids), decreasing, from every block's
    samples."""
    values = np.concatenate([s[0] for s in samples])
    gids = np.concatenate([s[1] for s in samples])
    order = _key_order(values, gids)
    values, gids = values[order], gids[order]
    if not len(values):
        return values, gids
    pick = np.unique(np.linspace(0, len(values), buckets + 1)[1:-1].astype(np.int64))
    pick = pick[pick < len(values)]
    return values[pick], gids[pick]


def bucket_bounds(block, cut):
    """Step 3: where the block's sorted maxima split at the splitters (bucket b holds
    positions bounds[b]:bounds[b + 1])."""
    gids, values = block[0], block[1]
    inner = _before(values, gids, cut[0], cut[1])
    return np.concatenate([[0], inner, [len(gids)]]).astype(np.int64)


def first_ranks(bounds: list):
    """Step 4: each bucket's first rank, from every block's bounds (blocks x buckets)."""
    counts = np.array([np.diff(b) for b in bounds]).reshape(len(bounds), -1)
    return np.concatenate([[0], np.cumsum(counts.sum(axis=0))]).astype(np.int64)


def piece(block, bounds, bucket: int):
    """A block's maxima in one bucket (gids, values)."""
    lo, hi = bounds[bucket], bounds[bucket + 1]
    return block[0][lo:hi], block[1][lo:hi]


def bucket(pieces: list, first):
    """Step 5: the bucket's maxima sorted (gids, values) and, per block, the ranks of its
    piece's maxima (in the piece's order)."""
    gids = np.concatenate([p[0] for p in pieces])
    values = np.concatenate([p[1] for p in pieces])
    order = _key_order(values, gids)
    ranks = np.empty(len(gids), dtype=np.int64)
    ranks[order] = first + np.arange(len(gids), dtype=np.int64)
    sizes = np.cumsum([0] + [len(p[0]) for p in pieces])
    return (gids[order], values[order]), [ranks[sizes[i]:sizes[i + 1]] for i in range(len(pieces))]


def block_ranks(block, parts: list):
    """Step 6: (the block's maxima by gid, their ranks): its pieces' ranks joined."""
    gids = block[0]
    ranks = np.concatenate(parts) if parts else np.zeros(0, np.int64)
    order = np.argsort(gids)
    return gids[order], ranks[order]


def ranks_of(graph, blocks: list, buckets: int):
    """Steps 1-6 added to `graph` (a `TaskGraph`) over the keys of the blocks' (maxima
    gids, values): (per block, the key of (gids sorted, ranks); the key of the total
    count; per bucket, the key of its sorted (gids, values))."""
    sorted_blocks = [graph(_sorted_pair, b) for b in blocks]
    cut = graph(splitters, [graph.item(s, 2) for s in sorted_blocks], buckets)
    bounds = [graph(bucket_bounds, s, cut) for s in sorted_blocks]
    firsts = graph(first_ranks, bounds)
    maxima, per_bucket = [], []   # fewer splitters than asked (few maxima): last buckets empty
    for j in range(buckets):
        pieces = [graph(_piece_or_empty, s, b, j) for s, b in zip(sorted_blocks, bounds,
                                                                  strict=True)]
        out = graph(bucket, pieces, graph(_first_or_end, firsts, j))
        maxima.append(graph.item(out, 0))
        per_bucket.append(graph.item(out, 1))
    per_block = [graph(block_ranks, s, [graph.item(p, i) for p in per_bucket])
                 for i, s in enumerate(sorted_blocks)]
    return per_block, graph(_total, firsts), maxima


def _sorted_pair(pair):
    return sorted_block(*pair)


def _total(firsts):
    return int(firsts[-1])


def _piece_or_empty(block, bounds, j):
    if j + 1 >= len(bounds):
        return block[0][:0], block[1][:0]
    return piece(block, bounds, j)


def _first_or_end(firsts, j):
    return firsts[min(j, len(firsts) - 1)]
