"""A cut where the hierarchy's buckets are (`_buckets`): no process holds every maximum
or event (issue 30). Written for persistence below; a size measure's cut runs the same
steps on its pruning's `_bucket_prune.Merges` (each maximum's merge into a smaller
region id, ordered by extinction) in place of the buckets' events.

1. `head`: each bucket's events by decreasing persistence (ties: the lower young id)
   up to a length, and its counts, merged in a task: what a count or ``auto`` cut
   reads and the report's listed persistences, O(the regions asked) to the client.
2. A rule marks the merged events: persistence below a threshold, or after the
   count's last kept event in that order (as `_hierarchy._all_but_most_persistent`).
   Each merged maximum points to its target; the others are roots. A persistence cut
   merges a maximum only with lower-persistence maxima below it on its way (docs/design.md
   section 5), so each root is the highest maximum of its region, and region i + 1 is
   the i-th root in id order, as `_kernels.regions_of_cut` numbers them.
3. Pointer jumping: each bucket follows its maxima's pointers inside itself, then
   asks the buckets that hold the others, round after round (each at least doubles
   how far a pointer has come), until every maximum holds its region.
4. Each block's cells are given their regions by the buckets (`block_labels`; the
   blocks in batches, so about buckets^2 + blocks pieces).
5. The curve: the positive persistences sorted by the maxima's sample sort
   (`_ranks`), only a `CurveSample`'s ranks sent to the client.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..._distinct import distinct, positions
from ..._sizes import SizedByArrays
from ..._task_graph import TaskGraph
from .._hierarchy import events_kept, gap_evidence, midpoint_threshold, widest_gap_count
from . import _ranks
from ._buckets import Bucket, batches, by_bucket, first_ids

__all__ = []

#: Pointer-jumping rounds after which a cut is taken to be broken (a cycle): 2^64
#: maxima are more than any volume has.
MAX_ROUNDS = 64


@dataclass(frozen=True)
class Head(SizedByArrays):
    """The events a cut reads, last merged first: the first `values` (extinctions),
    `keys` (the order's exact key: the extinction, in fixed point for a size measure)
    and `ties` of `n_events`, by decreasing key, ties the lower `ties` first (the young
    maximum for persistence, the pruned region for a size measure); `n_components`
    that never merge; `n_maxima` (all); `n_positive` events of extinction above 0.
    Without the components that `min_component` drops when made with them
    (`head_of`). Answers what `volseg.segment.CutRequest.of` asks of a hierarchy for
    a cut by its `measure`."""

    measure: str
    n_maxima: int
    n_events: int
    n_components: int
    n_positive: int
    values: np.ndarray
    keys: np.ndarray
    ties: np.ndarray

    def _enough(self, rank: int):
        if rank >= len(self.values) and len(self.values) < self.n_events:
            raise ValueError(f"the head holds {len(self.values)} events; rank {rank} "
                             "was asked")

    def _same(self, measure):
        if measure != self.measure:
            raise ValueError(f"this head orders the events by {self.measure}, not {measure!r}")

    def largest_gap(self, region_range, measure="persistence", min_component=0.0,
                    fallback=None) -> int:
        self._same(measure)
        self._enough(region_range[1])
        return widest_gap_count(self.values, self.n_events, self.n_components,
                                region_range, self.n_maxima, fallback)

    def gap_evidence(self, region_range, measure="persistence", min_component=0.0) -> dict:
        self._same(measure)
        self._enough(region_range[1])
        return gap_evidence(self.values, self.n_events, self.n_components,
                            tuple(region_range))

    def threshold_for(self, n_regions, measure="persistence", min_component=0.0) -> float:
        self._same(measure)
        self._enough(n_regions)
        return midpoint_threshold(self.values, self.n_events, self.n_components, n_regions)


def head_of(merges, length: int, dropped=None) -> Head:
    """A bucket's `Head` of at most `length` events, without the maxima `dropped`.
    `merges`: a `_buckets.Bucket` (persistence) or a `_bucket_prune.Merges`: how each
    of its maxima merges (``dies``, ``extinction()``, ``order()``)."""
    kept = np.ones(len(merges), dtype=bool) if dropped is None else ~dropped
    at = np.flatnonzero(merges.dies & kept)
    value = merges.extinction()[at]
    key, tie = (c[at] for c in merges.order())
    order = np.lexsort((tie, -key))[:length]
    return Head(merges.measure, len(merges), len(at),
                int(np.count_nonzero(~merges.dies & kept)), int(np.count_nonzero(value > 0)),
                value[order], key[order], tie[order])


def merged_heads(heads, length: int) -> Head:
    """The buckets' heads as one `Head` of at most `length` events."""
    key, tie = (np.concatenate([getattr(h, c) for h in heads]) for c in ("keys", "ties"))
    order = np.lexsort((tie, -key))[:length]
    return Head(heads[0].measure,
                *(sum(getattr(h, name) for h in heads)
                  for name in ("n_maxima", "n_events", "n_components", "n_positive")),
                np.concatenate([h.values for h in heads])[order], key[order], tie[order])


def rule_of(head: Head, threshold=None, n_regions=None) -> tuple:
    """Which events the cut merges, as a rule a bucket applies alone (`merged`):
    ("below", threshold), ("after", key, tie) of the last event kept, or ("all",) /
    ("none",). `n_regions` warns as `MorseHierarchy.segment` does."""
    if n_regions is None:
        return ("below", 0.0 if threshold is None else float(threshold))
    keep = events_kept(n_regions, head.n_maxima, head.n_components, stacklevel=4)
    if keep <= 0:
        return ("all",)
    if keep >= head.n_events:
        return ("none",)
    head._enough(keep - 1)
    return ("after", head.keys[keep - 1].item(), int(head.ties[keep - 1]))


def merged(merges, at, rule) -> np.ndarray:
    """True for the events of the maxima `at` of a bucket's `merges` that `rule`
    merges."""
    kind = rule[0]
    if kind == "below":
        return merges.extinction()[at] < rule[1]
    if kind in ("all", "none"):
        return np.full(len(at), kind == "all")
    key, tie = (c[at] for c in merges.order())
    last_key, last_tie = rule[1], rule[2]
    return ~((key > last_key) | ((key == last_key) & (tie <= last_tie)))


@dataclass(frozen=True)
class Pointers(SizedByArrays):
    """A bucket's maxima during the pointer jumping: `pointer` a maximum id on the way
    to the region, or the region index where `known` (-1: a dropped component);
    `root`: the regions' highest maxima."""

    first: int
    pointer: np.ndarray
    known: np.ndarray
    root: np.ndarray


def pointers(merges, rule, dropped=None) -> Pointers:
    """Step 2: each maximum's pointer, its target where merged (every event of a
    `dropped` component is), itself otherwise; a dropped component's highest maximum
    is known at once, as region -1. `merges` as for `head_of`."""
    ids = merges.first + np.arange(len(merges), dtype=np.int64)
    dies = merges.dies
    joins = np.zeros(len(merges), dtype=bool)
    joins[dies] = merged(merges, np.flatnonzero(dies), rule)
    gone = np.zeros(len(merges), dtype=bool) if dropped is None else dropped & ~joins
    joins |= dies & gone
    pointer = np.where(joins, merges.target.astype(np.int64), ids)
    gone &= ~dies
    pointer[gone] = -1
    return Pointers(merges.first, pointer, gone, ~joins & ~gone)


def root_count(state: Pointers) -> int:
    return int(np.count_nonzero(state.root))


def numbered(state: Pointers, offsets, j: int) -> Pointers:
    """The roots given their regions (`offsets`: each bucket's first region), and the
    pointers that stay in the bucket followed."""
    pointer = state.pointer.copy()
    pointer[state.root] = offsets[j] + np.arange(root_count(state))
    return _inside(Pointers(state.first, pointer, state.known | state.root, state.root))


def _inside(state: Pointers) -> Pointers:
    """Every pointer followed while it stays in the bucket and leads to no region yet
    (doubling: each pass reads the pointers as they were before it)."""
    pointer, known, first, n = state.pointer, state.known, state.first, len(state.pointer)
    for _ in range(MAX_ROUNDS):
        ask = np.flatnonzero(~known & (pointer >= first) & (pointer < first + n))
        if not len(ask):
            return state
        at = pointer[ask] - first
        pointer[ask], known[ask] = pointer[at], known[at]
    raise RuntimeError("the cut's pointers inside a bucket form a cycle")


def asked(state: Pointers, firsts) -> list:
    """What the bucket asks each bucket: the sorted distinct maxima its unknown
    pointers lead to, split by their bucket."""
    return by_bucket(firsts, distinct(state.pointer[~state.known]))


def answers(state: Pointers, questions: list) -> list:
    """The bucket's (pointer, known) at the maxima each bucket asked of it."""
    return [(state.pointer[q - state.first], state.known[q - state.first]) for q in questions]


def answered(state: Pointers, questions: list, replies: list) -> Pointers:
    """One round: each unknown pointer replaced by its target's, then followed inside."""
    at = positions(np.concatenate(questions), state.pointer[~state.known],
                   required="a region pointer's target was not asked for")
    pointer, known = state.pointer.copy(), state.known.copy()
    open_ = np.flatnonzero(~known)
    pointer[open_] = np.concatenate([r[0] for r in replies])[at]
    known[open_] = np.concatenate([r[1] for r in replies])[at]
    return _inside(Pointers(state.first, pointer, known, state.root))


def unknown_count(state: Pointers) -> int:
    return int(np.count_nonzero(~state.known))


def regions(buckets: list, firsts, rule, hooks, dropped=None) -> list:
    """Steps 2-3: each bucket's `Pointers` with every region known (persisted);
    `dropped`: each bucket's maxima in the components `min_component` drops."""
    graph = TaskGraph("morse-cut-roots", [*buckets, firsts, *(dropped or ())])
    states = [graph(pointers, b.key, rule, _key(dropped, j)) for j, b in enumerate(buckets)]
    offsets = graph(first_ids, [graph(root_count, s) for s in states])
    states = [graph(numbered, s, offsets, j) for j, s in enumerate(states)]
    states = hooks.persist(*graph.delayed(states),
                           stage="Morse: the cut's regions, inside each bucket")
    for round_ in range(MAX_ROUNDS):
        counts = TaskGraph("morse-cut-count", states)
        if not sum(hooks.compute(*counts.delayed([counts(unknown_count, s.key) for s in states]),
                                 stage="Morse: the cut's regions, counted")):
            return list(states)
        graph = TaskGraph("morse-cut-jump", [*states, firsts])
        questions = [graph(asked, s.key, firsts.key) for s in states]
        replies = [graph(answers, s.key, [graph.item(q, j) for q in questions])
                   for j, s in enumerate(states)]
        states = hooks.persist(*graph.delayed(
            [graph(answered, s.key, questions[j], [graph.item(r, j) for r in replies])
             for j, s in enumerate(states)]),
            stage=f"Morse: the cut's regions, pointer jumping round {round_ + 1}")
    raise RuntimeError(f"the cut's pointers were not resolved in {MAX_ROUNDS} rounds")


def heads(buckets: list, length: int, hooks, dropped=None) -> Head:
    """Step 1: the buckets' `Head`s of at most `length` events, merged in a task: the
    client receives one `Head`."""
    graph = TaskGraph("morse-cut-head", [*buckets, *(dropped or ())])
    parts = [graph(head_of, b.key, length, _key(dropped, j)) for j, b in enumerate(buckets)]
    head, = hooks.compute(*graph.delayed([graph(merged_heads, parts, length)]),
                          stage="Morse: the events' largest extinctions (the head)")
    return head


def _key(delayed_list, j):
    """The key of the j-th of a list of Delayed, or None for no list."""
    return None if delayed_list is None else delayed_list[j].key


def dropped_maxima(buckets: list, firsts, sizes: list, min_share: float, hooks) -> list:
    """Each bucket's maxima in the components of the graph that hold less than
    `min_share` of its vertices (`MorseHierarchy.small_components`), persisted: the
    components by pointer jumping over every event, the cells' vertex counts in the
    buckets (`sizes`, as `summed` gives them) added per component, then across the
    buckets in one task (O(components))."""
    components = regions(buckets, firsts, ("all",), hooks)
    graph = TaskGraph("morse-cut-components", [*components, *sizes])
    per_component = [graph(component_sizes, c.key, s.key)
                     for c, s in zip(components, sizes, strict=True)]
    small = graph(small_components, per_component, min_share)
    return list(hooks.persist(*graph.delayed([graph(_dropped, c.key, small)
                                              for c in components]),
                              stage="Morse: the components too small to keep"))


def batch_sizes(firsts, id_blocks: list, count_blocks: list) -> list:
    """Some blocks' cell sizes (or any int64 sums aligned with their cells) summed per
    cell, split by bucket: [(ids, sums)]."""
    ids = np.concatenate([b.flat[0] for b in id_blocks])
    counts = np.concatenate([b.flat[0] for b in count_blocks])
    cells, where = np.unique(ids, return_inverse=True)
    sums = np.zeros(len(cells), dtype=np.int64)
    np.add.at(sums, where, counts)              # int64: exact for fixed-point sums too
    return by_bucket(firsts, cells, sums)


def bucket_sums(bucket, pieces: list) -> np.ndarray:
    """(n,) int64: a bucket's maxima's sums from the batches' (ids, sums) pieces."""
    out = np.zeros(len(bucket), dtype=np.int64)
    for ids, sums in pieces:
        np.add.at(out, ids - bucket.first, sums)
    return out


def summed(buckets: list, firsts, ids, sums, label: str) -> list:
    """Lazy: each bucket's (n,) int64 sums of the blocks' `sums` (object arrays of the
    block grid, aligned with the blocks' cells `ids`), routed in batches of blocks."""
    graph = TaskGraph(label, [*buckets, firsts, ids, sums])
    pieces = [graph(batch_sizes, firsts.key, [(ids.name, *b) for b in part],
                    [(sums.name, *b) for b in part])
              for part in batches(list(np.ndindex(ids.numblocks)), len(buckets))]
    return graph.delayed([graph(bucket_sums, b.key, [graph.item(p, j) for p in pieces])
                          for j, b in enumerate(buckets)])


def component_sizes(components: Pointers, per_maximum) -> tuple:
    """(components, their vertex counts) of a bucket's maxima (`per_maximum`: each
    one's cell's count)."""
    which, where = np.unique(components.pointer, return_inverse=True)
    return which, np.bincount(where, weights=per_maximum, minlength=len(which))


def small_components(sizes: list, min_share: float) -> np.ndarray:
    """(C,) True for the components of less than `min_share` of the vertices (the
    sums exact: integers below 2^53)."""
    which = np.concatenate([s[0] for s in sizes])
    total = np.bincount(which, weights=np.concatenate([s[1] for s in sizes]))
    return total < min_share * total.sum()


def _dropped(components: Pointers, small) -> np.ndarray:
    return small[components.pointer]


def block_labels(states: list, firsts, ids, reply=None, label="morse-cut-labels"):
    """Step 4, lazy: each block's labels (region + 1) aligned with its distinct cells
    `ids` (`_block_cells.block_cells`), as an object array of the block grid. Any other
    per-maximum values kept in buckets the same way: ``reply(state, questions) ->
    [values at each question's maxima]`` (default `labels_of`)."""
    graph = TaskGraph(label, [*states, firsts, ids])
    parts = batches(list(np.ndindex(ids.numblocks)), len(states))
    questions = [graph(batch_questions, firsts.key, [(ids.name, *b) for b in part])
                 for part in parts]
    replies = [graph(reply or labels_of, s.key,
                     [graph.item(graph.item(q, 0), j) for q in questions])
               for j, s in enumerate(states)]
    out = {}
    for i, part in enumerate(parts):
        labels = graph(batch_labels, questions[i], [graph.item(r, i) for r in replies])
        out.update({b: graph.item(labels, k) for k, b in enumerate(part)})
    return graph.object_array(out, ids.numblocks)


def batch_questions(firsts, blocks: list) -> tuple:
    """(the distinct cells of some blocks split by bucket, each block's cells' place in
    them, each block's cell count)."""
    ids = [b.flat[0] for b in blocks]
    cells, where = np.unique(np.concatenate(ids), return_inverse=True)
    return by_bucket(firsts, cells), where, [len(i) for i in ids]


def labels_of(state: Pointers, questions: list) -> list:
    """The labels (region + 1) of the maxima each batch asked of the bucket."""
    if unknown_count(state):
        raise RuntimeError("a bucket's regions are asked before they are known")
    return [(state.pointer[q - state.first] + 1).astype(np.int32) for q in questions]


def batch_labels(question, replies: list) -> list:
    """Each block's labels of its cells, from the buckets' replies to its batch."""
    _, where, sizes = question
    labels = np.concatenate(replies)[where]
    return np.split(labels, np.cumsum(sizes)[:-1])


def tops(states: list, buckets: list, hooks) -> tuple:
    """(voxel, value, persistence) of each region's highest maximum, in region order."""
    graph = TaskGraph("morse-cut-tops", [*states, *buckets])
    parts = hooks.compute(*graph.delayed([graph(_tops, s.key, b.key)
                                          for s, b in zip(states, buckets, strict=True)]),
                          stage="Morse: the regions' highest maxima")
    return tuple(np.concatenate([p[k] for p in parts]) for k in range(3))


def _tops(state: Pointers, bucket: Bucket) -> tuple:
    return (bucket.gids[state.root].astype(np.int64), bucket.values[state.root],
            bucket.persistence()[state.root])


def curve_values(buckets: list, ranks, hooks, dropped=None) -> np.ndarray:
    """Step 5: the positive persistences sorted decreasing, at `ranks` (increasing),
    without the `dropped` maxima's."""
    graph = TaskGraph("morse-cut-curve", [*buckets, *(dropped or ())])
    positive = [graph(_positive, b.key, _key(dropped, j)) for j, b in enumerate(buckets)]
    _, _, in_order = _ranks.ranks_of(graph, positive, len(buckets))
    firsts = graph(first_ids, [graph(len, graph.item(s, 0)) for s in in_order])
    picks = [graph(_picked, s, firsts, j, ranks) for j, s in enumerate(in_order)]
    parts = hooks.compute(*graph.delayed(picks), stage="Morse: the cut's curve, sampled")
    return np.concatenate(parts) if parts else np.zeros(0)


def _positive(merges, dropped=None) -> tuple:
    p = merges.extinction()
    at = np.flatnonzero(merges.dies & (p > 0) & (True if dropped is None else ~dropped))
    return at + merges.first, p[at]


def _picked(in_order, firsts, j: int, ranks) -> np.ndarray:
    lo, hi = firsts[j], firsts[j + 1]
    return in_order[1][ranks[(ranks >= lo) & (ranks < hi)] - lo]
