"""`HierarchyOnWorkers`: the blockwise build's hierarchy, kept on the workers.

The maxima and their events (about 40 bytes per maximum) stay in buckets of
consecutive maximum ids (`_buckets`), each bucket a task's result on some worker. A
cut runs where the buckets are (`cut_in_buckets`, `_bucket_cut`, the components that
``min_component`` drops found there too): by persistence directly; by size or
hypervolume once the cells' measures are summed in the buckets and the pruning is
decided in a tree of groups of leaves (`pruned_in_buckets`, `_bucket_prune`). No task
holds every maximum. Only a count above `volseg.cuts.MAX_COUNT_IN_BUCKETS`, or a
mesh's per-vertex weights, joins the buckets in one task (`core`, on a cluster one
worker's memory, about 64 bytes per maximum) and runs the cut beside it (`run`):
the same functions as in memory on a `MorseHierarchy`, each block sent its own
cells' share of the result (`_block_cells`). Either way only the cut's small result
(O(regions) and a thinned curve) reaches the client (issue 30).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from ..._block_hooks import BlockHooks
from .. import _measures
from .._curve import CurveSample, sample_ranks
from .._hierarchy import MorseHierarchy, checked_weight, region_table
from . import _bucket_cut as in_buckets
from . import _bucket_prune as pruning
from ._cells import block_counts, gathered, looked_up
from ._measures import cell_measures_of_dask, computed_range, lazy_cell_measures

__all__ = ["HierarchyOnWorkers"]

#: Attributes of the handle itself, never looked up in the fetched hierarchy.
_OWN = ("_fetched", "_blocks", "_joined", "_counts", "_merges")


@dataclass(eq=False)
class HierarchyOnWorkers:
    """A blockwise `MorseHierarchy` whose per-maximum arrays stay on the workers.

    `buckets` are Delayed (persisted) `_buckets.Bucket`s, `firsts` their first ids;
    `core` a lazy Delayed of the hierarchy without cells, field or mask, joined from
    them (persisted where the hierarchy is, on first need); `cells` the lazy cells.
    `cut_in_buckets` cuts by persistence where the buckets are, `run` where `core` is;
    reading anything else of `MorseHierarchy` (``maxima``, ``segment``, ...) fetches
    it whole to the client, once (`fetch`), so the handle is a `MorseHierarchy` to a
    caller that needs one. `field_range`: the field's (min, max) in the mask, as the
    ascent found it. `_blocks`: each block's distinct cells (`_block_cells`).
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
    buckets: list | None = None
    firsts: object = None
    _fetched: MorseHierarchy | None = None
    _blocks: object = None
    _joined: object = None
    _counts: object = None
    _merges: dict | None = None

    def fetch(self) -> MorseHierarchy:
        """The whole hierarchy on the client (computed once)."""
        if self._fetched is None:
            joined = self.core if self._joined is None else self._joined
            core, = self.hooks.compute(joined, stage="Morse: the hierarchy, to the client")
            self._fetched = dataclasses.replace(
                core, cells=self.cells, mask=self.mask, _field=self._field,
                _connectivity=self._connectivity, timings=self.timings,
                vertex_weight=self.vertex_weight, _pruned={},
                _measure_cells=cell_measures_of_dask)
        return self._fetched

    def __getattr__(self, name):
        if name.startswith("__") or name in _OWN:       # copy, pickle
            raise AttributeError(name)
        return getattr(self.fetch(), name)

    def with_vertex_weight(self, weight) -> HierarchyOnWorkers:
        """`MorseHierarchy.with_vertex_weight`, kept on the workers."""
        return dataclasses.replace(self, vertex_weight=checked_weight(weight, self.shape),
                                   _fetched=None, _merges=None)

    def _hierarchy(self):
        """`core` persisted where the hierarchy is, once: the events joined (`_buckets.joined`)."""
        if self._joined is None:
            self._joined, = self.hooks.persist(self.core, stage="Morse: the events joined in "
                                               "sweep order", hierarchy=True)
        return self._joined

    def cut_of(self, cut) -> tuple:
        """(lazy labels 1..k, `volseg.morse.cuts.CutReport`) of `cut`, made where the
        hierarchy is kept (`_cut.cut_of`)."""
        from . import _cut

        return _cut.cut_of(self, cut)

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
            self.cells, self._field, self.n_maxima, self.vertex_weight, self._hierarchy(), measures,
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
        task = dask.delayed(_run, pure=True)(self._hierarchy(), self.vertex_weight, masked,
                                             function, args, tuple(totals), *totals.values())
        task, = persist(task, stage="Morse: the cut, where the hierarchy is", hierarchy=True)
        regions, = persist(gathered(ids, task[0]), stage="Morse: each block's regions, where "
                           "the hierarchy is", hierarchy=True)
        result, = self.hooks.compute(task[1], stage="Morse: the cut's result")
        return looked_up(self.cells, ids, regions, np.int32), result

    def head(self, length: int, dropped=None, merges=None) -> in_buckets.Head:
        """The events' `Head` (`_bucket_cut`): the `length` largest extinctions and the
        counts, from the buckets (nothing joined), without the maxima `dropped`
        (`dropped_components`); persistences, or a size measure's by its `merges`
        (`pruned_in_buckets`)."""
        return in_buckets.heads(self.buckets if merges is None else merges, length,
                                self.hooks, dropped)

    def dropped_components(self, min_share: float) -> list:
        """Each bucket's maxima (persisted) in the components of the graph holding less
        than `min_share` of its vertices: what ``min_component`` drops."""
        return in_buckets.dropped_maxima(self.buckets, self.firsts, self._bucket_sizes(),
                                         min_share, self.hooks)

    def pruned_in_buckets(self, measure: str) -> list:
        """Each bucket's `_bucket_prune.Merges` of the pruning by `measure` (``size`` or
        ``hypervolume``), persisted once: the cells' measures summed in the buckets, the
        pruning decided in a tree of groups of leaves (`_bucket_prune`), no task
        holding every maximum."""
        if self._merges is None:
            self._merges = {}
        if measure not in self._merges:
            persist = self.hooks.persist
            ids = self._block_cells()
            if not _measures.get_measure(measure).by_height:
                unit, totals = 1.0, self._bucket_sizes()
            else:
                low, high = self._field_range()
                unit = _measures.unit_of(low, high)
                saddles, = persist(pruning.cell_saddles(self.buckets, self.firsts, ids, low),
                                   stage="Morse: each block's cells' saddles, from the buckets")
                sums, = persist(pruning.block_hypervolumes(self.cells, self._field, ids,
                                                           saddles, unit),
                                stage="Morse: each block's cells' hypervolumes")
                totals = persist(*in_buckets.summed(self.buckets, self.firsts, ids, sums,
                                                    "morse-cell-measures"),
                                 stage=f"Morse: the cells' {measure}, in the buckets")
            self._merges[measure] = list(persist(*pruning.pruned(
                self.buckets, self.firsts, totals, self.shape,
                _measures.scale_of(self.vertex_weight, unit), measure),
                stage=f"Morse: the pruning by {measure}, in a tree of groups"))
        return self._merges[measure]

    def _field_range(self) -> tuple:
        """The field's (min, max) over the cells, as the ascent found it or computed."""
        if self.field_range is not None:
            return self.field_range
        return computed_range(
            self.cells, self._field.rechunk(self.cells.chunks),
            lambda d: self.hooks.compute(d, stage="Morse: the field's range")[0])

    def _bucket_sizes(self) -> list:
        """Each bucket's cells' vertex counts (`_bucket_cut.summed` of the blocks'
        `_block_cells.block_counts`), kept: what ``min_component`` and a size cut read."""
        if self._counts is None:
            counts, = self.hooks.persist(block_counts(self.cells),
                                         stage="Morse: each block's cell sizes")
            self._counts = list(self.hooks.persist(
                *in_buckets.summed(self.buckets, self.firsts, self._block_cells(), counts,
                                   "morse-cell-sizes"),
                stage="Morse: the cells' sizes, in the buckets"))
        return self._counts

    def cut_in_buckets(self, head: in_buckets.Head, threshold=None, n_regions=None,
                       dropped=None, merges=None) -> tuple:
        """A cut where the buckets are (`_bucket_cut`): no task holds every maximum.
        Returns (lazy labels 1..k, 0 in `dropped` components, (voxel, value,
        persistence) of each region's highest maximum, the extinctions' `CurveSample`);
        `head` from `head` with the same `dropped` and `merges`, long enough for
        `n_regions`. `merges`: `pruned_in_buckets` for a size measure's cut, None for
        persistence."""
        merges = self.buckets if merges is None else merges
        rule = in_buckets.rule_of(head, threshold, n_regions)
        states = in_buckets.regions(merges, self.firsts, rule, self.hooks, dropped)
        ids = self._block_cells()
        labels, = self.hooks.persist(in_buckets.block_labels(states, self.firsts, ids),
                                     stage="Morse: each block's regions, from the buckets")
        top = in_buckets.tops(states, self.buckets, self.hooks)
        ranks = sample_ranks(head.n_positive)
        curve = CurveSample(in_buckets.curve_values(merges, ranks, self.hooks, dropped),
                            ranks, head.n_positive, head.n_components)
        return looked_up(self.cells, ids, labels, np.int32), top, curve

    def _block_cells(self):
        """Each block's distinct cells, kept on the workers (persisted by the build from
        the blocks' tables, `_block_cells.table_cells`)."""
        return self._blocks


def _run(core, weight, masked, function, args, names, *sums) -> tuple:
    hierarchy = dataclasses.replace(core, vertex_weight=weight).with_cell_measures(
        dict(zip(names, sums, strict=True)))
    region, result = function(hierarchy, masked, *args)
    return region_table(region, masked), result
