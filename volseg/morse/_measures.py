"""Measures of the hierarchy's regions beside persistence (DESIGN.md section 12): each
cell's size and hypervolume, additive over the cells of a region.

- ``size``: the cell's vertices (voxels), times the vertex weight (a voxel's volume
  from the spacing, a mesh vertex's share of its star);
- ``hypervolume``: the sum over the cell's vertices of f(v) - s for those above s,
  where s is the cell's highest saddle (the first one it meets sweeping down, where
  Carr et al. prune a leaf), times the vertex weight.

On a grid the terms are integers (a count; the hypervolume in fixed point, `STEPS`
steps per range of the field), so the sums are exact in any order: a blockwise sum
of per-block sums equals the in-memory one bit for bit, whatever the chunking.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._sizes import SizedByArrays
from . import _prune
from ._block_cells import block_cells, block_counts, gathered
from ._block_objects import per_block

__all__ = ["MEASURES", "STEPS", "Fixed", "check_measure", "cell_measures", "lazy_cell_measures"]

#: The cut measures; ``persistence`` is the height of DESIGN.md section 5.
MEASURES = ("persistence", "size", "hypervolume")
#: Fixed-point steps of a hypervolume term per range (max - min) of the field:
#: 2^-32 of the range, while a cell of 2^31 voxels still sums within int64.
STEPS = 2.0 ** 32


@dataclass(frozen=True)
class Fixed:
    """A measure of every cell in fixed point: `sums` (M,) int64 steps of `scale`. The
    pruning adds the integers (exact in any order, so a pruning decided in groups
    equals the sequential one, `_prune_groups`); `values` are what it reports."""

    sums: np.ndarray
    scale: float

    @property
    def values(self) -> np.ndarray:
        """(M,) float64: the measure itself."""
        return self.sums.astype(np.float64) * self.scale


def check_measure(measure) -> str:
    """The checked measure name (one of `MEASURES`)."""
    if not isinstance(measure, str) or measure not in MEASURES:
        raise ValueError(f"unknown `measure` {measure!r}; choose one of "
                         + ", ".join(repr(m) for m in MEASURES))
    return measure


def cell_measures(hierarchy, measure: str) -> Fixed | np.ndarray:
    """`measure` of each maximum's cell (``size`` or ``hypervolume``): `Fixed` on a grid
    or with a scalar vertex weight, (M,) float64 sums with a mesh's weights."""
    n_max = len(hierarchy.maxima)
    weight = hierarchy.vertex_weight
    hypervolume = measure == "hypervolume"
    if type(hierarchy.cells).__module__.startswith("dask."):
        import dask

        # The events' three arrays as one shared task, sent once to the worker that
        # makes the saddles.
        events = dask.delayed(_Events(hierarchy.source, hierarchy.target,
                                      hierarchy.saddle_value), pure=True)
        lazy = lazy_cell_measures(hierarchy.cells, hierarchy._field, n_max, weight, events,
                                  (measure,), lambda d: dask.compute(d)[0])
        return dask.compute(lazy)[0][measure]
    saddles, unit = np.zeros(0), 1.0          # a size: every term is 1, no saddle read
    if hypervolume:
        low, high = _prune.masked_range(hierarchy.cells.ravel(), hierarchy._field.ravel())
        unit = _unit(low, high)
        saddles = _cell_saddles(hierarchy, n_max, low)
    if weight is not None and np.ndim(weight) > 0:      # a mesh: in memory, float sums
        cells = hierarchy.cells.ravel()
        inside = cells >= 0
        terms = np.asarray(weight, dtype=np.float64)[inside]
        if hypervolume:
            f = hierarchy._field.ravel()[inside]
            terms = terms * np.maximum(f - saddles[cells[inside]], 0.0)
        return np.bincount(cells[inside], weights=terms, minlength=n_max)
    sums = np.zeros(n_max, dtype=np.int64)
    _prune.cell_sums(hierarchy.cells.ravel(), hierarchy._field.ravel(), saddles, unit,
                     hypervolume, sums)
    return _scaled(sums, weight, unit)


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
    if "size" in measures:
        sizes, = keep(block_counts(cells))
        out["size"] = _total(n_max, weight, 1.0, ids, sizes)
    if "hypervolume" in measures:
        if low_high is None:
            low_high = computed_range(cells, field, compute)
        unit = _unit(*low_high)
        saddles = dask.delayed(_cell_saddles)(events, n_max, low_high[0])
        saddles, = place(gathered(ids, saddles))
        sums, = keep(per_block(_block_hypervolumes, cells, field, ids, saddles, unit=unit))
        out["hypervolume"] = _total(n_max, weight, unit, ids, sums)
    return out


def _total(n_max, weight, unit, ids, sums):
    """Delayed (M,) of a measure from each block's `ids` and `sums` (aligned)."""
    import dask

    # Each block as a Delayed of the graph as it is: an optimized graph (or an array
    # passed whole to `delayed`) names persisted blocks by key and drops their futures,
    # so the blocks could be released before this task runs.
    ids = list(ids.to_delayed(optimize_graph=False).ravel())
    sums = list(sums.to_delayed(optimize_graph=False).ravel())
    return dask.delayed(_summed, pure=True)(n_max, weight, unit, len(ids), *ids, *sums)


@dataclass(frozen=True)
class _Events(SizedByArrays):
    """The three event arrays `_cell_saddles` reads."""

    source: np.ndarray
    target: np.ndarray
    saddle_value: np.ndarray


def _unit(low, high) -> float:
    """A hypervolume term's fixed-point step: `STEPS` per range of the field."""
    return (float(high) - float(low)) / STEPS if high > low else 1.0


def scale_of(weight, unit: float) -> float:
    """A fixed-point measure's step: the vertex weight (None: 1) times the term's unit."""
    return (1.0 if weight is None else float(weight)) * unit


def _scaled(sums, weight, unit) -> Fixed:
    return Fixed(sums, scale_of(weight, unit))


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
    return _scaled(total, weight, unit)


def _block_range(cells, field, block_id):
    return _prune.masked_range(cells.ravel(), field.ravel())


def computed_range(cells, field, compute) -> tuple:
    """The field's (min, max) over the cells of lazy `cells`, in a pass of its own
    (``compute(array) -> value``); `field` in the cells' chunks."""
    return range_of(*compute(per_block(_block_range, cells, field)).ravel())


def range_of(*parts) -> tuple:
    """(min, max) of the field over the vertices that took part, from the blocks'."""
    return float(min(p[0] for p in parts)), float(max(p[1] for p in parts))


def _cell_saddles(hierarchy, n_max, low) -> np.ndarray:
    """(M,) the highest saddle value among each cell's events (its first merge sweeping
    down); `low` for a cell with none (alone in its component)."""
    return highest_saddles(n_max, [(hierarchy.source, hierarchy.saddle_value),
                                   (hierarchy.target, hierarchy.saddle_value)], low)


def highest_saddles(n: int, pairs, low: float) -> np.ndarray:
    """(n,) the highest of the saddle values given to each of n cells (`pairs` of
    (cells, values)); `low` for a cell given none."""
    out = np.full(n, -np.inf)
    for cells, values in pairs:
        np.maximum.at(out, cells, values)
    out[out == -np.inf] = low
    return out
