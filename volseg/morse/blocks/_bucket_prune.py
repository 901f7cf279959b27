"""A size or hypervolume cut where the hierarchy's buckets are (`_buckets`): the
measure pruning decided in a tree of groups spread over the workers, so that no task
holds every maximum or event (issue 30).

1. Each cell's measure, in its bucket (`cell_measures`): a size sums the blocks' cell
   counts there; a hypervolume first finds each cell's highest saddle there (each
   event sends its saddle value to the buckets of its two cells), gives each block
   its cells' saddles (as a cut gives its labels, `_bucket_cut.block_labels`) and
   sums the blocks' fixed-point terms there (`_measures`: integers, exact in any
   order).
2. The leaves (`leaf_grid`, `leaf_state`): the grid in cubes, each maximum in the
   cube of its voxel. Each bucket asks the buckets of its events' two cells for their
   leaves and measures (one exchange), then sends each leaf its maxima and the events
   touching them, with their sweep keys: a leaf orders its edges by the sweep key
   (`_prune_groups.GroupState`), as no event has a global index here.
3. The tree (`_group_tree.block_tree` over the leaves): each leaf prunes what its
   outside cannot change, each group joins what its two halves passed up and prunes
   again (`_prune_groups.GroupState.pruned`); the root leaves nothing. What a group
   passes up lies near its faces (measured: 1.7 % of the maxima reach the root at
   256^3), so the groups high in the tree stay small. The keys found (extinction,
   pruned id) go back down the same tree (`_keys_down`): each group sends each half
   the keys of the events that half passed up, so that each leaf, which kept its
   edges, knows all its keys without a second exchange with the buckets. A second
   pass up the tree names each merge's regions as the sequential order does
   (`_merge_groups`).
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

from ..._distinct import distinct, positions
from ..._sizes import SizedByArrays
from ..._task_graph import TaskGraph
from .. import _measures, _prune_groups
from .._edges import _saddle_order
from .._group_tree import block_tree
from . import _merge_groups
from ._bucket_cut import block_labels
from ._buckets import batches, by_bucket
from ._measures import _block_hypervolumes
from ._objects import per_block

__all__ = []


@dataclass
class Merges(SizedByArrays):
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
    return per_block(_block_hypervolumes, cells, field.rechunk(cells.chunks), ids,
                     saddles, unit=unit)


#: The smallest leaf edge in voxels (`_prune_groups.LEAF_EDGE`); tests make it smaller.
MIN_LEAF_EDGE = _prune_groups.LEAF_EDGE


#: Leaves allowed whatever the buckets' count: a leaf's pruning costs more than in
#: proportion to its maxima (512^3, 8 M maxima, two workers: 8 leaves took 16.1 s of
#: CPU, 64 leaves 9.8 s), and 64 leaves x 8 buckets is still a small exchange.
MIN_LEAVES = 64


def leaf_grid(shape, n_buckets: int, min_edge: int | None = None) -> tuple:
    """(edge, grid): cubes of `edge` voxels, `min_edge` doubled until there are at most
    twice as many as buckets (or `MIN_LEAVES`), so that the exchange with the buckets
    stays about buckets^2 pieces."""
    edge = int(min_edge or MIN_LEAF_EDGE)
    while True:
        grid = tuple(max(-(-int(n) // edge), 1) for n in shape)
        if int(np.prod(grid)) <= max(2 * n_buckets, MIN_LEAVES) or edge >= max(shape):
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
    return by_bucket(firsts, distinct(np.concatenate([bucket.source[dies],
                                                       bucket.target[dies]])))


def _ends_answered(placed: tuple, questions: list) -> list:
    first, leaf, sums = placed
    return [(leaf[q - first], sums[q - first]) for q in questions]


def _leaf_pieces(bucket, placed: tuple, asked: list, replies: list, n_leaves: int) -> list:
    """What a bucket sends each leaf: (its maxima there, their measures) and the events
    with an end there, as (young, near end, far end, far end's leaf and measure, the
    saddle value, the saddle): the sweep key's two ends are the near and far ends,
    ordered in `leaf_state`. Maximum ids in the buckets' id type (int32 where they
    fit: the pieces are most of what the pruning moves, and all of them are held at
    once, as each leaf reads a piece of every bucket)."""
    first, leaf, sums = placed
    index = bucket.target.dtype
    ids = first + np.arange(len(bucket), dtype=index)
    known = np.concatenate(asked)
    known_leaf = np.concatenate([r[0] for r in replies])
    known_sum = np.concatenate([r[1] for r in replies])
    dies = np.flatnonzero(bucket.dies)
    s, t = bucket.source[dies], bucket.target[dies]
    at_s, at_t = positions(known, np.stack([s, t]))         # one table for both ends
    ls, lt = known_leaf[at_s], known_leaf[at_t]
    other = lt != ls
    both = np.concatenate([np.arange(len(dies)), np.flatnonzero(other)])
    near = np.concatenate([s, t[other]])
    far = np.concatenate([t, s[other]])
    near_leaf = np.concatenate([ls, lt[other]])
    far_leaf = np.concatenate([lt, ls[other]]).astype(np.int32)
    far_sum = np.concatenate([known_sum[at_t], known_sum[at_s][other]])
    columns = (ids[dies][both], near, far, far_leaf, far_sum,
               bucket.saddle_value[dies][both], bucket.saddle[dies][both].astype(np.int64))
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
    rid, key, young, near, far, far_leaf, far_sum, value, saddle = (
        np.concatenate([p[k] for p in pieces]) for k in range(len(pieces[0])))
    sweep = (value, saddle, np.minimum(near, far), np.maximum(near, far))
    order = np.argsort(rid, kind="stable")
    by = _saddle_order(*sweep)[::-1]          # decreasing (value, saddle, pair)
    inside = far_leaf[by] == g
    far = far[by]
    return _with_local(_prune_groups.GroupState(
        rid[order], key[order], young[by], near[by], np.where(inside, far, -1),
        np.where(inside, 0, far_sum[by]), np.where(inside, -1, far),
        tuple(c[by] for c in sweep)))


def _with_local(state: _prune_groups.GroupState) -> _prune_groups.GroupState:
    """`state` with its edges' ends as places among its regions (-1 outside), by a
    hash table (`_merge_groups.local_ends`, which this path compiles anyway) instead
    of `GroupState.pruned`'s binary search per end."""
    state.local = _merge_groups.local_ends(state)
    return state


def _pruned_leaf(g: int, pieces: list) -> tuple:
    """(decided, up, what the leaf's second pass reads: its maxima and its edges'
    (young, near end, far end or -1 outside))."""
    state = leaf_state(g, pieces)
    decided, up = state.pruned()
    return decided, up, (state.rid, state.event, state.a, state.b)


def _pruned_node(low, high) -> tuple:
    """(decided, up, the events each half passed up) of a group."""
    decided, up = _with_local(_prune_groups.GroupState.joined([low, high])).pruned()
    return decided, up, (low.event, high.event)


def _known_keys(decided: tuple, known: tuple) -> tuple:
    """(events, their extinctions, their pruned ids) of a group, each event once, in no
    order (`_looked_up` finds them by a hash table): what it decided and what the group
    above sent it for the events it passed up."""
    return tuple(np.concatenate([decided[k], known[k]]) for k in range(3))


def _looked_up(keys: tuple, events) -> tuple:
    """The keys of `events`, every one of which `keys` must hold."""
    event, ext, tie = keys
    at = positions(event, events, required="the pruning's tree lost the key of an event")
    return ext[at], tie[at]


def _keys_down(decided: tuple, sides: tuple, known: tuple) -> tuple:
    """For each half of a group, the keys of the events it passed up: (events,
    extinctions, pruned ids), from what the group decided and `known`."""
    keys = _known_keys(decided, known)
    return tuple((events, *_looked_up(keys, events)) for events in sides)


def _nothing_known() -> tuple:
    return np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0, np.int64)


def _merged_leaf(decided: tuple, kept: tuple, known: tuple) -> tuple:
    """The second pass at a leaf: its edges in the merge order of their keys (what it
    decided in the first pass, or what came down the tree), `_merge_groups.decided`."""
    rid, young, near, far = kept
    ext, tie = _looked_up(_known_keys(decided, known), young)
    by = np.lexsort((tie, -ext))[::-1]
    return _merge_groups.decided(_merge_groups.state(rid, young[by], near[by], far[by],
                                                     ext[by], tie[by]))


def _merged_node(low, high) -> tuple:
    return _merge_groups.decided(_prune_groups.GroupState.joined([low, high]))


def _root(step, *args) -> tuple:
    """`step` at the root group, which must leave no event undecided."""
    result = step(*args)
    if len(result[1].event):
        raise RuntimeError("the root group of the pruning left events undecided")
    return result


def _up(graph, tree, leaves: dict, node) -> list:
    """The keys of each group's result, children before parents (`tree`): the task
    `leaves[i]` ((function, *args)) at leaf group i, `node` above from what its
    halves pass up (their results' item 1)."""
    nodes = []
    for i, (_, _, _, low, high) in enumerate(tree):
        args = leaves[i] if low is None else (node, graph.item(nodes[low], 1),
                                              graph.item(nodes[high], 1))
        nodes.append(graph(_root, *args) if i == len(tree) - 1 else graph(*args))
    return nodes


def _down(graph, tree, nodes: list) -> dict:
    """The keys of each group's known keys (`_keys_down`), parents before children:
    what comes down to it for the events it passed up."""
    known = {len(tree) - 1: graph(_nothing_known)}
    for i in range(len(tree) - 1, -1, -1):
        low, high = tree[i][3:]
        if low is not None:
            split = graph(_keys_down, graph.item(nodes[i], 0), graph.item(nodes[i], 2),
                          known[i])
            known[low], known[high] = graph.item(split, 0), graph.item(split, 1)
    return known


def _by_bucket_of(firsts, results: list) -> list:
    """Some groups' decided merges (tuples of columns, the merged id first) sorted and
    split by the bucket of that id."""
    columns = [np.concatenate([r[k] for r in results]) for k in range(len(results[0]))]
    order = np.argsort(columns[0], kind="stable")
    return by_bucket(firsts, *(c[order] for c in columns))


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
    leaves = {i: int(np.ravel_multi_index(g[0], grid)) for i, g in enumerate(tree)
              if g[3] is None}
    graph = TaskGraph("morse-prune", [*buckets, firsts, *sums])
    placed = [graph(_placed, b.key, s.key, shape, grid, edge)
              for b, s in zip(buckets, sums, strict=True)]
    asked = [graph(_ends_asked, b.key, firsts.key) for b in buckets]
    answers = [graph(_ends_answered, p, [graph.item(q, j) for q in asked])
               for j, p in enumerate(placed)]
    pieces = [graph(_leaf_pieces, b.key, placed[j], asked[j],
                    [graph.item(a, j) for a in answers], n_leaves)
              for j, b in enumerate(buckets)]
    # The pruning's keys, decided in the tree of groups, then sent back down it to the
    # leaves, which kept their edges.
    first = _up(graph, tree, {i: (_pruned_leaf, g, [graph.item(p, g) for p in pieces])
                              for i, g in leaves.items()}, _pruned_node)
    known = _down(graph, tree, first)
    # The merges' region ids, decided in the same tree.
    second = _up(graph, tree, {i: (_merged_leaf, graph.item(first[i], 0),
                                   graph.item(first[i], 2), known[i]) for i in leaves},
                 _merged_node)
    decided = [graph.item(n, 0) for n in second]
    split = [graph(_by_bucket_of, firsts.key, part) for part in batches(decided, len(buckets))]
    return graph.delayed([graph(_merges, b.key, [graph.item(s, j) for s in split], scale,
                                measure) for j, b in enumerate(buckets)])
