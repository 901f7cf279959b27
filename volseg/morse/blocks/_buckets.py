"""The blockwise hierarchy in buckets of maximum ids, so that no process needs every
maximum or event (issue 30).

The maxima's sample sort (`_ranks`) leaves them in buckets of consecutive ids: bucket
j holds the ids ``first[j]`` to ``first[j + 1] - 1``, with their voxels and values.
A maximum dies at most once, as the young maximum of one event, so the events split
by their young maximum's bucket make columns aligned with the maxima: a `Bucket`
holds, for each of its maxima, its voxel and value and, if it dies, that event's
target, source, saddle and saddle value (target -1: it never dies).

The groups of the union-find tree (`_group_tree`) send their decided events to the
buckets in batches of groups, so the pieces are about buckets^2 whatever the groups'
count. What needs the whole hierarchy joins the buckets in one task (`joined`: the
in-memory order of the events, with their elders); a persistence cut reads them
where they are (`_bucket_cut`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..._sizes import SizedByArrays
from ..._task_graph import TaskGraph
from .. import _group_tree
from .._hierarchy import MorseHierarchy
from .._measures import PERSISTENCE

__all__ = []


@dataclass
class Bucket(SizedByArrays):
    """The maxima ``first`` to ``first + len - 1`` and how each dies (module
    docstring): `gids` its voxel, `values`; `target` (-1: never dies), `source`,
    `saddle` (voxel) and `saddle_value` of its event."""

    first: int
    gids: np.ndarray
    values: np.ndarray
    target: np.ndarray
    source: np.ndarray
    saddle: np.ndarray
    saddle_value: np.ndarray

    def __len__(self):
        return len(self.gids)

    @property
    def dies(self) -> np.ndarray:
        return self.target >= 0

    def events(self) -> tuple:
        """(young, target, source, saddle, saddle value) of its maxima that die, as
        the union-find's groups decided them (`_group_tree.assembled` joins them)."""
        young = np.flatnonzero(self.dies)
        return (young + self.first, self.target[young], self.source[young], self.saddle[young],
                self.saddle_value[young])

    def persistence(self) -> np.ndarray:
        """(n,) each maximum's persistence; inf for those that never die."""
        return np.where(self.dies, self.values - self.saddle_value, np.inf)

    # How a persistence cut merges the maxima (`_bucket_cut.head_of`): each one that
    # dies into its target, ordered by its persistence, ties the lower id kept first.
    measure = PERSISTENCE.name

    def extinction(self) -> np.ndarray:
        return self.persistence()

    def order(self) -> tuple:
        """(key, tie) of each maximum's merge in the cut's order (`_bucket_cut`)."""
        return self.persistence(), self.first + np.arange(len(self), dtype=np.int64)


def bucketed(sorted_buckets: list, decided: list, id_type) -> tuple:
    """(a Delayed `Bucket` per bucket, a Delayed of the buckets' first ids (B + 1,)):
    the maxima's sorted buckets (`_ranks`, Delayed (gids, values)) and the events each
    group of the union-find tree decided (Delayed (young, target, source, saddle,
    saddle value)), one lazy graph."""
    graph = TaskGraph("morse-buckets", [*sorted_buckets, *decided])
    firsts = graph(first_ids, [graph(len, graph.item(b.key, 0)) for b in sorted_buckets])
    splits = [graph(split, firsts, [d.key for d in part])
              for part in batches(decided, len(sorted_buckets))]
    buckets = [graph(bucket, b.key, firsts, j, [graph.item(s, j) for s in splits], id_type)
               for j, b in enumerate(sorted_buckets)]
    return graph.delayed(buckets), graph.delayed([firsts])[0]


def batches(items: list, n_buckets: int) -> list:
    """`items` (the groups, the blocks) in consecutive batches, about one per bucket,
    so that an exchange with the buckets is about buckets^2 pieces."""
    size = -(-len(items) // n_buckets)
    return [items[i:i + size] for i in range(0, len(items), size)]


def first_ids(lengths) -> np.ndarray:
    return np.concatenate([[0], np.cumsum(lengths)]).astype(np.int64)


def owner(firsts, ids) -> np.ndarray:
    """The bucket of each maximum id."""
    return np.searchsorted(firsts, ids, side="right") - 1


def by_bucket(firsts, ids, *columns) -> list:
    """Sorted maximum `ids` (and `columns` aligned with them) split by bucket: a list of
    ``ids`` slices, or of ``(ids, *columns)`` tuples, one per bucket."""
    bounds = np.searchsorted(owner(firsts, ids), np.arange(len(firsts)))
    out = [tuple(c[bounds[k]:bounds[k + 1]] for c in (ids, *columns))
           for k in range(len(firsts) - 1)]
    return out if columns else [o[0] for o in out]


def split(firsts, decided: list) -> list:
    """Events of some groups (`decided`), by the bucket of their young maximum: a list
    of (young, target, source, saddle, saddle value) per bucket."""
    columns = [np.concatenate([d[k] for d in decided]) for k in range(5)]
    order = np.argsort(columns[0], kind="stable")
    return by_bucket(firsts, *(c[order] for c in columns))


def bucket(maxima, firsts, j: int, pieces: list, id_type) -> Bucket:
    """Bucket `j` from its sorted maxima (gids, values) and the events of its maxima."""
    gids, values = maxima
    first, n = int(firsts[j]), len(gids)
    young, target, source, saddle, value = (np.concatenate([p[k] for p in pieces])
                                            for k in range(5))
    at = young - first
    out = Bucket(first, gids, values, np.full(n, -1, id_type), np.full(n, -1, id_type),
                 np.full(n, -1, np.int64), np.full(n, np.nan))
    out.target[at], out.source[at], out.saddle[at], out.saddle_value[at] = (
        target, source, saddle, value)
    return out


def joined(shape, *buckets: Bucket) -> MorseHierarchy:
    """The hierarchy without cells, field or mask, in one task: the maxima in id order
    and the events in the in-memory sweep order with their elders."""
    n_maxima = sum(len(b) for b in buckets)
    young, elder, target, source, saddle, saddle_values = _group_tree.assembled(
        [b.events() for b in buckets], n_maxima)
    return MorseHierarchy(
        shape=shape, cells=None, maxima=np.concatenate([b.gids for b in buckets]),
        values=np.concatenate([b.values for b in buckets]), young=young, elder=elder,
        target=target, source=source, saddle=saddle, saddle_value=saddle_values, mask=None,
        _field=None)
