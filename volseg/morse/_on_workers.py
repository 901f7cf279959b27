"""`HierarchyOnWorkers`: the blockwise build's hierarchy, kept where it was assembled.

The per-maximum arrays (maxima, values, events: about 64 bytes per maximum) stay in
the task that joined them (on a cluster, in one worker's memory), and a cut runs in a
task beside them (`run`): the cells' measures summed on the workers, the pruning, the
region of every maximum and its relabelling table made there, each block sent its own
cells' share of it (`_block_cells`: no block worker receives an array of every maximum),
and only the cut's small result (O(regions) and a thinned curve) sent to the client
(issue 30). The same functions run in memory
on a `MorseHierarchy`: one cut, written once.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from .._block_hooks import BlockHooks
from ._block_cells import block_cells, gathered, looked_up
from ._hierarchy import MorseHierarchy, checked_weight, region_table
from ._measures import lazy_cell_measures

__all__ = ["HierarchyOnWorkers"]


@dataclass(eq=False)
class HierarchyOnWorkers:
    """A blockwise `MorseHierarchy` whose per-maximum arrays stay on the workers.

    `core` is a Delayed (persisted) of the hierarchy without cells, field or mask;
    `cells` the lazy cells. `run` cuts it where it is; reading anything else of
    `MorseHierarchy` (``maxima``, ``segment``, ...) fetches it whole to the client,
    once (`fetch`), so the handle is a `MorseHierarchy` to a caller that needs one.
    `field_range`: the field's (min, max) in the mask, as the ascent found it.
    """

    core: object
    n_maxima: int
    shape: tuple
    cells: object
    mask: object
    _field: object
    _connectivity: object
    timings: dict
    hooks: BlockHooks
    vertex_weight: object = None
    field_range: tuple | None = None
    _fetched: MorseHierarchy | None = None
    _blocks: object = None

    def fetch(self) -> MorseHierarchy:
        """The whole hierarchy on the client (computed once)."""
        if self._fetched is None:
            core, = self.hooks.compute(self.core, stage="Morse: the hierarchy, to the client")
            self._fetched = dataclasses.replace(
                core, cells=self.cells, mask=self.mask, _field=self._field,
                _connectivity=self._connectivity, timings=self.timings,
                vertex_weight=self.vertex_weight, _pruned={})
        return self._fetched

    def __getattr__(self, name):
        if name.startswith("__") or name in ("_fetched", "_blocks"):   # copy, pickle
            raise AttributeError(name)
        return getattr(self.fetch(), name)

    def with_vertex_weight(self, weight) -> HierarchyOnWorkers:
        """`MorseHierarchy.with_vertex_weight`, kept on the workers."""
        return dataclasses.replace(self, vertex_weight=checked_weight(weight, self.shape),
                                   _fetched=None)

    def run(self, function, *args, measures=()) -> tuple:
        """(lazy labels, result) of ``function(hierarchy, masked, *args) -> (region,
        result)`` run in one task where the hierarchy is: `region` (the region of each
        maximum, as `MorseHierarchy.region_of_maximum` gives) becomes the labels'
        table there and stays on the workers, each block given its own cells' share of
        it (`_block_cells`); `result` (small) comes to the client. The hierarchy is
        given the cells' `measures` first (`with_cell_measures`, summed on the
        workers), so that it reads no cell."""
        import dask

        masked = self.mask is not None
        persist = self.hooks.persist
        ids = self._block_cells()
        totals = lazy_cell_measures(
            self.cells, self._field, self.n_maxima, self.vertex_weight, self.core, measures,
            lambda d: self.hooks.compute(d, stage="Morse: the field's range")[0],
            ids=ids, low_high=self.field_range,
            place=lambda *lazy: persist(*lazy, stage="Morse: the cells' saddles, where "
                                        "the hierarchy is", hierarchy=True),
            keep=lambda *lazy: persist(*lazy, stage="Morse: the cells' measures"))
        # The totals (per maximum) where the hierarchy is, and the blocks' sums let go
        # before the cut's pruning runs beside them.
        if totals:
            totals = dict(zip(totals, persist(*totals.values(), stage="Morse: the cells' "
                                              "measures summed, where the hierarchy is",
                                              hierarchy=True), strict=True))
        task = dask.delayed(_run, pure=True)(self.core, self.vertex_weight, masked, function,
                                             args, tuple(totals), *totals.values())
        task, = persist(task, stage="Morse: the cut, where the hierarchy is", hierarchy=True)
        regions, = persist(gathered(ids, task[0]), stage="Morse: each block's regions, where "
                           "the hierarchy is", hierarchy=True)
        result, = self.hooks.compute(task[1], stage="Morse: the cut's result")
        return looked_up(self.cells, ids, regions, np.int32), result

    def _block_cells(self):
        """Each block's distinct cells (`_block_cells.block_cells`), found once and kept
        on the workers."""
        if self._blocks is None:
            self._blocks, = self.hooks.persist(block_cells(self.cells),
                                               stage="Morse: each block's cells")
        return self._blocks


def _run(core, weight, masked, function, args, names, *sums) -> tuple:
    hierarchy = dataclasses.replace(core, vertex_weight=weight).with_cell_measures(
        dict(zip(names, sums, strict=True)))
    region, result = function(hierarchy, masked, *args)
    return region_table(region, masked), result
