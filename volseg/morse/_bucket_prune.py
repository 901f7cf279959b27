"""A size or hypervolume cut where the hierarchy's buckets are (`_buckets`): the
measure pruning decided in a tree of groups spread over the workers, so that no task
holds every maximum or event (issue 30).

1. Each cell's measure, in its bucket (`cell_measures`): a size sums the blocks' cell
   counts there; a hypervolume first finds each cell's highest saddle there (each
   event sends its saddle value to the buckets of its two cells), gives each block
   its cells' saddles (as a cut gives its labels, `_bucket_cut.block_labels`) and
   sums the blocks' fixed-point terms there (`_measures`: integers, exact in any
   order).
2. The leaves (`leaf_grid`, `leaf_states`): the grid in cubes, each maximum in the
   cube of its voxel. Each bucket asks the buckets of its events' two cells for their
   leaves and measures (one exchange), then sends each leaf its maxima and the events
   touching them, with their sweep keys: a leaf orders its edges by the sweep key
   (`_prune_groups.GroupState`), as no event has a global index here.
3. The tree (`_group_tree.block_tree` over the leaves): each leaf prunes what its
   outside cannot change, each group joins what its two halves passed up and prunes
   again (`_prune_groups.GroupState.pruned`); the root leaves nothing. What a group
   passes up lies near its faces (measured: 1.7 % of the maxima reach the root at
   256^3), so the groups high in the tree stay small.
4. Each decided merge goes to the bucket of the larger id of its two regions, the
   one that is never a region again (`Merges`, aligned with the bucket's maxima). A
   cut reads them as a persistence cut reads a `Bucket` (`_bucket_cut`): the cut
   merges a prefix of the pruning's order (the extinctions never decrease along it),
   and following the larger id to the smaller over those merges gives every maximum
   its region's lowest id, its highest maximum.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._task_graph import TaskGraph
from . import _measures, _merge_groups, _prune_groups
from ._block_objects import per_block
from ._bucket_cut import block_labels
from ._buckets import batches, by_bucket
from ._group_tree import block_tree

__all__ = []


@dataclass
class Merges:
    """How a size measure's pruning merges the maxima ``first`` to ``first + len - 1``
    (module docstring, step 4): `target` the smaller region id each one's region
    merged into (-1: its region never merges, the lowest id of its component); `key`
    the extinction in fixed point (steps of `scale`) and `tie` the id of the region
    pruned: the pruning's order is increasing (key, -tie)."""

    first: int
    target: np.ndarray
    key: np.ndarray
    tie: np.ndarray
    scale: float
    measure: str

    def __len__(self):
        return len(self.target)

    @property
    def dies(self) -> np.ndarray:
        return self.target >= 0

    def extinction(self) -> np.ndarray:
        """(n,) float64, as `MorseHierarchy.extinction` gives it; inf for no merge."""
        return np.where(self.dies, self.key.astype(np.float64) * self.scale, np.inf)

    def order(self) -> tuple:
        return self.key, self.tie


def _saddle_pieces(bucket, firsts) -> list:
    """Its events' saddle values, sent to the buckets of their two cells:
    [(cells sorted, values)] per bucket."""
    dies = bucket.dies
    ends = np.concatenate([bucket.source[dies], bucket.target[dies]]).astype(np.int64)
    values = np.tile(bucket.saddle_value[dies], 2)
    order = np.argsort(ends, kind="stable")
    return by_bucket(firsts, ends[order], values[order])


def _highest_saddles(bucket, pieces: list, low: float) -> tuple:
    """(first, (n,) each cell's highest saddle value; `low` for a cell with none), as
    `_measures._cell_saddles`."""
    return bucket.first, _measures.highest_saddles(
        len(bucket), [(ends - bucket.first, values) for ends, values in pieces], low)


def _values_asked(state: tuple, questions: list) -> list:
    first, values = state
    return [values[q - first] for q in questions]


def cell_saddles(buckets: list, firsts, ids, low: float):
    """Lazy: each block's cells' highest saddles, aligned with its `ids` (an object
    array of the block grid), from the buckets' events."""
    graph = TaskGraph("morse-cut-saddles", [*buckets, firsts])
    pieces = [graph(_saddle_pieces, b.key, firsts.key) for b in buckets]
    saddles = graph.delayed([graph(_highest_saddles, b.key, [graph.item(p, j) for p in pieces],
                                   low) for j, b in enumerate(buckets)])
    return block_labels(saddles, firsts, ids, _values_asked, "morse-cut-block-saddles")


def block_hypervolumes(cells, field, ids, saddles, unit: float):
    """Lazy: each block's int64 hypervolume sums, aligned with its `ids`."""
    return per_block(_measures._block_hypervolumes, cells, field.rechunk(cells.chunks), ids,
                     saddles, unit=unit)


#: The smallest leaf edge in voxels (`_prune_groups.LEAF_EDGE`); tests make it smaller.
MIN_LEAF_EDGE = _prune_groups.LEAF_EDGE


def leaf_grid(shape, n_buckets: int, min_edge: int | None = None) -> tuple:
    """(edge, grid): cubes of `edge` voxels, `min_edge` doubled until there are at most
    twice as many as buckets, so that the exchange with the buckets stays about
    buckets^2 pieces."""
    edge = int(min_edge or MIN_LEAF_EDGE)
    while True:
        grid = tuple(max(-(-int(n) // edge), 1) for n in shape)
        if int(np.prod(grid)) <= max(2 * n_buckets, 1) or edge >= max(shape):
            return edge, grid
        edge *= 2


def _placed(bucket, sums, shape, grid, edge) -> tuple:
    """(first, each maximum's leaf, its cell's measure)."""
    leaf = _prune_groups._leaf_of(np.asarray(bucket.gids, np.int64), np.array(shape, np.int64),
                                  np.array(grid, np.int64), edge)
    return bucket.first, leaf.astype(np.int32), sums


def _ends_asked(bucket, firsts) -> list:
    """The distinct cells of its events, split by bucket."""
    dies = bucket.dies
    return by_bucket(firsts, np.unique(np.concatenate([bucket.source[dies],
                                                       bucket.target[dies]])))


def _ends_answered(placed: tuple, questions: list) -> list:
    first, leaf, sums = placed
    return [(leaf[q - first], sums[q - first]) for q in questions]


def _leaf_pieces(bucket, placed: tuple, asked: list, replies: list, n_leaves: int,
                 keys=None) -> list:
    """What a bucket sends each leaf: (its maxima there, their measures) and the events
    with an end there, as (young, near end, far end, far end's leaf and measure, *the
    order's key): the sweep's (saddle value, saddle, lower end, higher end), or with
    the pruning's `keys` ((n,) extinction and pruned id by young), the merge order's
    (-extinction, pruned id). Maximum ids in the buckets' id type (int32 where they
    fit: the pieces are most of what the pruning moves)."""
    first, leaf, sums = placed
    index = bucket.target.dtype
    ids = first + np.arange(len(bucket), dtype=index)
    known = np.concatenate(asked)
    known_leaf = np.concatenate([r[0] for r in replies])
    known_sum = np.concatenate([r[1] for r in replies])
    dies = np.flatnonzero(bucket.dies)
    s, t = bucket.source[dies], bucket.target[dies]
    at_s, at_t = np.searchsorted(known, s), np.searchsorted(known, t)
    ls, lt = known_leaf[at_s], known_leaf[at_t]
    other = lt != ls
    both = np.concatenate([np.arange(len(dies)), np.flatnonzero(other)])
    near = np.concatenate([s, t[other]])
    far = np.concatenate([t, s[other]])
    near_leaf = np.concatenate([ls, lt[other]])
    far_leaf = np.concatenate([lt, ls[other]]).astype(np.int32)
    far_sum = np.concatenate([known_sum[at_t], known_sum[at_s][other]])
    young = ids[dies][both]
    if keys is None:
        sweep = (bucket.saddle_value[dies][both], bucket.saddle[dies][both].astype(np.int64),
                 np.minimum(s, t)[both], np.maximum(s, t)[both])
    else:
        sweep = (-keys[0][dies][both], keys[1][dies][both].astype(index))
    columns = (young, near, far, far_leaf, far_sum, *sweep)
    by_max = np.argsort(leaf, kind="stable")
    max_bounds = np.searchsorted(leaf[by_max], np.arange(n_leaves + 1))
    by_edge = np.argsort(near_leaf, kind="stable")
    edge_bounds = np.searchsorted(near_leaf[by_edge], np.arange(n_leaves + 1))
    out = []
    for g in range(n_leaves):
        m = by_max[max_bounds[g]:max_bounds[g + 1]]
        e = by_edge[edge_bounds[g]:edge_bounds[g + 1]]
        out.append((ids[m], sums[m], *(c[e] for c in columns)))
    return out


def leaf_state(g: int, pieces: list) -> _prune_groups.GroupState:
    """Leaf `g`'s `GroupState` from the buckets' pieces: its maxima, and its edges in
    sweep order."""
    rid, key, young, near, far, far_leaf, far_sum, *sweep = (
        np.concatenate([p[k] for p in pieces]) for k in range(len(pieces[0])))
    order = np.argsort(rid, kind="stable")
    by = np.lexsort(sweep[::-1])[::-1]
    inside = far_leaf[by] == g
    far = far[by]
    return _prune_groups.GroupState(
        rid[order], key[order], young[by], near[by], np.where(inside, far, -1),
        np.where(inside, 0, far_sum[by]), np.where(inside, -1, far),
        tuple(c[by] for c in sweep))


def _pruned_leaf(g: int, pieces: list) -> tuple:
    return leaf_state(g, pieces).pruned()


def _pruned_node(low, high) -> tuple:
    """(decided, up) of a group from what its two halves passed up."""
    return _prune_groups.GroupState.joined([low, high]).pruned()


def _merged_leaf(g: int, pieces: list) -> tuple:
    return _merge_groups.decided(leaf_state(g, pieces))


def _merged_node(low, high) -> tuple:
    return _merge_groups.decided(_prune_groups.GroupState.joined([low, high]))


def _root(step, *args) -> tuple:
    """`step` at the root group, which must leave no event undecided."""
    decided, up = step(*args)
    if len(up.event):
        raise RuntimeError("the root group of the pruning left events undecided")
    return decided, up


def _tree(graph, tree, grid, pieces, leaf, node) -> list:
    """The keys of each group's (decided, up), children before parents (`tree`): `leaf`
    at the leaves from the buckets' `pieces`, `node` above from what the halves pass."""
    nodes = []
    for i, (lo, _, _, low, high) in enumerate(tree):
        args = ((leaf, int(np.ravel_multi_index(lo, grid)),
                 [graph.item(p, int(np.ravel_multi_index(lo, grid))) for p in pieces])
                if low is None else (node, graph.item(nodes[low], 1), graph.item(nodes[high], 1)))
        nodes.append(graph(_root, *args) if i == len(tree) - 1 else graph(*args))
    return [graph.item(n, 0) for n in nodes]


def _by_bucket_of(firsts, results: list, column: int) -> list:
    """Some groups' decided merges (tuples of columns) sorted and split by the bucket of
    the id in `column`."""
    columns = [np.concatenate([r[k] for r in results]) for k in range(len(results[0]))]
    order = np.argsort(columns[column], kind="stable")
    columns = [c[order] for c in columns]
    return by_bucket(firsts, columns[column], *(c for k, c in enumerate(columns) if k != column))


def _keys(bucket, pieces: list) -> tuple:
    """((n,) extinction, (n,) pruned id) of each of its maxima's events, by young."""
    ext = np.zeros(len(bucket), np.int64)
    tie = np.full(len(bucket), -1, np.int64)
    for young, extinction, pruned in pieces:
        ext[young - bucket.first], tie[young - bucket.first] = extinction, pruned
    return ext, tie


def _merges(bucket, pieces: list, scale: float, measure: str) -> Merges:
    n = len(bucket)
    out = Merges(bucket.first, np.full(n, -1, np.int64), np.zeros(n, np.int64),
                 np.full(n, -1, np.int64), scale, measure)
    for gone, keep, extinction, pruned in pieces:
        at = gone - bucket.first
        out.target[at], out.key[at], out.tie[at] = keep, extinction, pruned
    return out


def pruned(buckets: list, firsts, sums: list, shape, scale: float, measure: str) -> list:
    """Lazy: each bucket's `Merges` of the pruning by a measure whose cells' int64
    `sums` are in the buckets (Delayed, aligned with them): steps 2-4, one graph."""
    edge, grid = leaf_grid(shape, len(buckets))
    n_leaves = int(np.prod(grid))
    tree = block_tree(grid)
    graph = TaskGraph("morse-prune", [*buckets, firsts, *sums])
    placed = [graph(_placed, b.key, s.key, shape, grid, edge)
              for b, s in zip(buckets, sums, strict=True)]
    asked = [graph(_ends_asked, b.key, firsts.key) for b in buckets]
    answers = [graph(_ends_answered, p, [graph.item(q, j) for q in asked])
               for j, p in enumerate(placed)]
    replies = [[graph.item(a, i) for a in answers] for i in range(len(buckets))]
    # The pruning's keys, decided in the tree of groups.
    pieces = [graph(_leaf_pieces, b.key, placed[j], asked[j], replies[j], n_leaves)
              for j, b in enumerate(buckets)]
    decided = _tree(graph, tree, grid, pieces, _pruned_leaf, _pruned_node)
    split = [graph(_by_bucket_of, firsts.key, part, 0) for part in batches(decided, len(buckets))]
    keys = [graph(_keys, b.key, [graph.item(s, j) for s in split]) for j, b in enumerate(buckets)]
    # The merges' region ids, decided in the same tree.
    pieces = [graph(_leaf_pieces, b.key, placed[j], asked[j], replies[j], n_leaves, keys[j])
              for j, b in enumerate(buckets)]
    decided = _tree(graph, tree, grid, pieces, _merged_leaf, _merged_node)
    split = [graph(_by_bucket_of, firsts.key, part, 0) for part in batches(decided, len(buckets))]
    return graph.delayed([graph(_merges, b.key, [graph.item(s, j) for s in split], scale,
                                measure) for j, b in enumerate(buckets)])
