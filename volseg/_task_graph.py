"""`TaskGraph`: a Dask graph written task by task, for the reductions over block groups.

`dask.delayed` merges the graphs of a call's arguments at every call, so a graph of
n calls over one large collection takes O(n x its size) to build (minutes for a few
thousand calls over a 1024^3 volume's blocks). Here the tasks go into one dict, and
one `HighLevelGraph` layer joins it to the collections it reads.

Each task's key is named for its function (``("pruned_leaf-morse-prune-<token>", i)``):
the scheduler keeps its duration estimates per key prefix, and with one prefix for a
whole graph a 20-microsecond `getitem` had the mean duration of the pruning's leaves.
Such getitems ran away from the tuple they read, which then moved whole (at 512^3 on
two workers, 324 of the 958 MB the pruning moved were such tuples; none with keys
named for their function, and 30 % less moved in that stage).
"""

from __future__ import annotations

import itertools
import operator

__all__ = ["TaskGraph"]

_names = itertools.count()


class TaskGraph:
    """Tasks ``(function, *args)`` in one layer over `dependencies` (Dask collections
    whose keys, and this graph's own keys, may appear in the arguments, also inside
    lists; tuples that are not keys are passed as they are)."""

    def __init__(self, label: str, dependencies=()):
        from dask.base import tokenize

        self.label = label
        self.token = tokenize(*dependencies, next(_names))
        self.name = f"volseg-{label}-{self.token}"
        self.tasks = {}
        self.dependencies = list(dependencies)

    def __call__(self, function, *args):
        """The key of a new task ``function(*args)``, named for `function`."""
        named = getattr(function, "__name__", "task").strip("_")
        key = (f"{named}-{self.label}-{self.token}", len(self.tasks))
        self.tasks[key] = (function, *args)
        return key

    def item(self, key, index):
        """The key of ``key's result[index]``."""
        return self(operator.getitem, key, index)

    def delayed(self, keys) -> list:
        """Delayed objects of `keys`, in one graph."""
        from dask.delayed import Delayed
        from dask.highlevelgraph import HighLevelGraph

        graph = HighLevelGraph.from_collections(self.name, self.tasks,
                                                dependencies=self.dependencies)
        return [Delayed(key, graph, layer=self.name) for key in keys]

    def object_array(self, keys: dict, numblocks):
        """A Dask object array of the block grid `numblocks` (chunks of one), holding
        the result of ``keys[block index]`` in each block."""
        import dask.array as da
        import numpy as np
        from dask.highlevelgraph import HighLevelGraph

        for index, key in keys.items():
            self.tasks[(self.name, *index)] = (_one_object, key, len(numblocks))
        graph = HighLevelGraph.from_collections(self.name, self.tasks,
                                                dependencies=self.dependencies)
        return da.Array(graph, self.name, chunks=tuple((1,) * n for n in numblocks),
                        dtype=object, meta=np.empty((0,) * len(numblocks), object))


def _one_object(item, ndim: int):
    """`item` as the one element of an object block of `ndim` dimensions."""
    import numpy as np

    out = np.empty((1,) * ndim, dtype=object)
    out[(0,) * ndim] = item
    return out
