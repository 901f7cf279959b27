"""The cells' measures of a lazy (Dask) hierarchy, summed on the workers: each block's
distinct cells, their counts and hypervolume sums, joined per maximum. The same
fixed-point integers as in memory (`volseg.morse._measures`), so the totals are equal
bit for bit whatever the chunking."""

from __future__ import annotations

import numpy as np

from .. import _basins, _prune
from .._measures import (
    Fixed,
    _cell_saddles,
    _Events,
    get_measure,
    range_of,
    scale_of,
    unit_of,
)
from ._cells import block_cells, block_counts, gathered
from ._objects import per_block

__all__ = ["lazy_cell_measures", "computed_range", "cell_measures_of_dask"]


def cell_measures_of_dask(hierarchy, measure: str):
    """`volseg.morse._measures.cell_measures` of a hierarchy whose cells are lazy."""
    import dask

    # The events' three arrays as one shared task, sent once to the worker that
    # makes the saddles.
    events = dask.delayed(_Events(hierarchy.source, hierarchy.target,
                                  hierarchy.saddle_value), pure=True)
    lazy = lazy_cell_measures(hierarchy.cells, hierarchy._field, len(hierarchy.maxima),
                              hierarchy.vertex_weight, events, (measure,),
                              lambda d: dask.compute(d)[0])
    return dask.compute(lazy)[0][measure]


def lazy_cell_measures(cells, field, n_max: int, weight, events, measures, compute, *,
                       ids=None, low_high=None, place=None, keep=None) -> dict:
    """`cell_measures` of lazy cells, {measure: Delayed (M,)} for each of `measures`,
    every step on the workers and no array of every maximum sent to a block's task
    (`_block_cells`): each block's distinct cells, their counts (the size), the cells'
    saddles (one task, where `events` are) gathered for each block's cells, each
    block's hypervolume sums (one task per block reading its cells and its field: Dask
    fuses the reads into it), and each measure's total (one task: it receives about 12
    bytes per cell of each block, the client nothing). `events`: a Delayed of anything
    with the hierarchy's ``source``, ``target`` and ``saddle_value`` (a
    `MorseHierarchy`, or `_Events`); `weight`: None or a number.

    `ids`: `_block_cells.block_cells(cells)`, if made already (a cut's labels read
    them too). `low_high`: the field's (min, max) over the cells, when known (the
    blockwise build's ascent has it); else, for the hypervolume, it is computed first
    by ``compute(array) -> value``: a pass of its own, as in the graph of the sums every
    block would wait in memory for the last one's range. ``place(*lazy) -> lazy``
    computes the tasks that read a whole per-maximum array where that array is, and
    keeps them there; ``keep(*lazy) -> lazy`` computes per-block tasks and keeps them
    where they are, so that the next graph holds the next step alone. Neither given:
    one lazy graph."""
    import dask

    def unchanged(*lazy):
        return lazy

    place, keep = place or unchanged, keep or unchanged
    field = field.rechunk(cells.chunks)
    if ids is None:
        ids, = keep(block_cells(cells))
    out = {}
    for name in measures:
        if get_measure(name).watershed:              # per (cell, rank): `_basins`
            if low_high is None:
                low_high = computed_range(cells, field, compute)
            out[name] = _basins_of(cells, field, events, low_high, weight)
            continue
        if not get_measure(name).by_height:                   # a count per vertex
            sizes, = keep(block_counts(cells))
            out[name] = _total(n_max, weight, 1.0, ids, sizes)
            continue
        if low_high is None:
            low_high = computed_range(cells, field, compute)
        unit = unit_of(*low_high)
        saddles = dask.delayed(_cell_saddles)(events, n_max, low_high[0])
        saddles, = place(gathered(ids, saddles))
        sums, = keep(per_block(_block_hypervolumes, cells, field, ids, saddles, unit=unit))
        out[name] = _total(n_max, weight, unit, ids, sums)
    return out


def _basins_of(cells, field, events, low_high, weight):
    """Delayed `_basins.Basins` of lazy cells: each block's records (one task per
    block, given the events' saddles as one shared task), summed in one task."""
    import dask

    unit = unit_of(*low_high)
    negated = dask.delayed(_negated_saddles, pure=True)(events)
    parts = per_block(_block_basins, cells, field, negated=negated, low=low_high[0],
                      unit=unit)
    parts = list(parts.to_delayed(optimize_graph=False).ravel())
    n_events = dask.delayed(len, pure=True)(negated)
    return dask.delayed(_joined_basins, pure=True)(n_events, low_high[0], unit,
                                                   scale_of(weight, 1.0), *parts)


def _negated_saddles(events) -> np.ndarray:
    return -np.asarray(events.saddle_value, np.float64)


def _block_basins(cells, field, block_id, negated, low, unit):
    return _basins.block_records(np.ascontiguousarray(cells).ravel(),
                                 np.ascontiguousarray(field, np.float64).ravel(), negated,
                                 low, unit)


def _joined_basins(n_events, low, unit, scale, *parts):
    return _basins.joined([p.flat[0] for p in parts], n_events, low, unit, scale)


def _total(n_max, weight, unit, ids, sums):
    """Delayed (M,) of a measure from each block's `ids` and `sums` (aligned)."""
    import dask

    # Each block as a Delayed of the graph as it is: an optimized graph (or an array
    # passed whole to `delayed`) names persisted blocks by key and drops their futures,
    # so the blocks could be released before this task runs.
    ids = list(ids.to_delayed(optimize_graph=False).ravel())
    sums = list(sums.to_delayed(optimize_graph=False).ravel())
    return dask.delayed(_summed, pure=True)(n_max, weight, unit, len(ids), *ids, *sums)


def _block_hypervolumes(cells, field, ids, saddles, block_id, unit):
    """The int64 hypervolume sums of one block's cells (aligned with its `ids`), from
    its share of the cells' `saddles`."""
    ids, saddles = ids.flat[0], saddles.flat[0]
    out = np.zeros(len(ids), dtype=np.int64)
    _prune.block_hypervolumes(cells.ravel(), field.ravel(), ids, saddles, unit, out)
    return out


def _summed(n_max, weight, unit, n_blocks, *parts) -> Fixed:
    """The (M,) measure from the blocks' ids and then their sums (1x1x1 object
    blocks)."""
    total = np.zeros(n_max, dtype=np.int64)
    for ids, sums in zip(parts[:n_blocks], parts[n_blocks:], strict=True):
        total[ids.flat[0]] += sums.flat[0]                  # a block's ids are distinct
    return Fixed(total, scale_of(weight, unit))


def _block_range(cells, field, block_id):
    return _prune.masked_range(cells.ravel(), field.ravel())


def computed_range(cells, field, compute) -> tuple:
    """The field's (min, max) over the cells of lazy `cells`, in a pass of its own
    (``compute(array) -> value``); `field` in the cells' chunks."""
    return range_of(*compute(per_block(_block_range, cells, field)).ravel())


