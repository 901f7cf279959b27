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

from . import _prune
from ._block_objects import per_block

__all__ = ["MEASURES", "STEPS", "check_measure", "cell_measures", "lazy_cell_measures"]

#: The cut measures; ``persistence`` is the height of DESIGN.md section 5.
MEASURES = ("persistence", "size", "hypervolume")
#: Fixed-point steps of a hypervolume term per range (max - min) of the field:
#: 2^-32 of the range, while a cell of 2^31 voxels still sums within int64.
STEPS = 2.0 ** 32


def check_measure(measure) -> str:
    """The checked measure name (one of `MEASURES`)."""
    if not isinstance(measure, str) or measure not in MEASURES:
        raise ValueError(f"unknown `measure` {measure!r}; choose one of "
                         + ", ".join(repr(m) for m in MEASURES))
    return measure


def cell_measures(hierarchy, measure: str) -> np.ndarray:
    """(M,) float64: `measure` of each maximum's cell (``size`` or ``hypervolume``)."""
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


def lazy_cell_measures(cells, field, n_max: int, weight, events, measures, compute,
                       place=None, low_high=None, keep=None) -> dict:
    """`cell_measures` of lazy cells, {measure: Delayed (M,)} for each of `measures`,
    every step on the workers: the cells' saddles (hypervolume), each block's sums (one
    task per block reading its cells and, for the hypervolume, its field: Dask fuses
    the reads into it), and their total (one task: it receives about 12 bytes per cell
    of each block, the client nothing). `events`: a Delayed of anything with the
    hierarchy's ``source``, ``target`` and ``saddle_value`` (a `MorseHierarchy`, or
    `_Events`); `weight`: None or a number.

    `low_high`: the field's (min, max) over the cells, when known (the blockwise
    build's ascent has it); else, for the hypervolume, it is computed first by
    ``compute(array) -> value``: a pass of its own, as in the graph of the sums every
    block would wait in memory for the last one's range. ``place(delayed) -> delayed``,
    if given, computes the one task that reads the whole `events` (the cells' saddles)
    where they are, and keeps it there; ``keep(*arrays) -> arrays``, if given, computes
    the blocks' sums (Dask arrays) and keeps them where they are, so that the totals'
    graph holds the totals alone (and a cluster may run them where the hierarchy is)."""
    if "hypervolume" in measures and low_high is None:
        ranges = compute(per_block(_block_range, cells, field.rechunk(cells.chunks)))
        low_high = range_of(*ranges.ravel())
    parts, units = {}, {}
    for m in measures:
        parts[m], units[m] = _lazy_block_sums(cells, field, n_max, events,
                                              low_high if m == "hypervolume" else None, place)
    if keep is not None and parts:
        parts = dict(zip(parts, keep(*parts.values()), strict=True))
    return {m: _total(n_max, weight, units[m], parts[m]) for m in measures}


def _lazy_block_sums(cells, field, n_max, events, low_high, place) -> tuple:
    """(each block's sums as a Dask object array of the block grid, their unit) of one
    measure: the hypervolume with the field's `low_high`, the size (cells alone)
    without."""
    import dask

    if low_high is None:
        return per_block(_block_sizes, cells, n_max=n_max), 1.0
    unit = _unit(*low_high)
    saddles = dask.delayed(_cell_saddles)(events, n_max, low_high[0])
    if place is not None:
        saddles = place(saddles)
    return per_block(_block_hypervolumes, cells, field.rechunk(cells.chunks), n_max=n_max,
                     saddles=saddles, unit=unit), unit


def _total(n_max, weight, unit, parts):
    import dask

    return dask.delayed(_summed, pure=True)(n_max, weight, unit, parts)


@dataclass(frozen=True)
class _Events:
    """The three event arrays `_cell_saddles` reads."""

    source: np.ndarray
    target: np.ndarray
    saddle_value: np.ndarray


def _unit(low, high) -> float:
    """A hypervolume term's fixed-point step: `STEPS` per range of the field."""
    return (float(high) - float(low)) / STEPS if high > low else 1.0


def _scaled(sums, weight, unit) -> np.ndarray:
    return sums.astype(np.float64) * ((1.0 if weight is None else float(weight)) * unit)


def _block_sizes(cells, block_id, n_max):
    """(cell ids present, their int64 vertex counts) of one block of lazy cells."""
    return _ids_fitted(_prune.block_sums(cells.ravel(), np.zeros(0), np.zeros(0), 1.0,
                                         False), n_max)


def _block_hypervolumes(cells, field, block_id, n_max, saddles, unit):
    """(cell ids present, their int64 hypervolume sums) of one block of lazy cells."""
    return _ids_fitted(_prune.block_sums(cells.ravel(), field.ravel(), saddles, unit, True),
                       n_max)


def _ids_fitted(ids_sums, n_max) -> tuple:
    """A block's sums with int32 cell ids where every id fits (12 bytes per cell sent
    to the total, not 16)."""
    ids, sums = ids_sums
    return (ids.astype(np.int32) if n_max < 2**31 else ids), sums


def _summed(n_max, weight, unit, parts) -> np.ndarray:
    """The (M,) measure from the blocks' sums (an object array of them)."""
    sums = np.zeros(n_max, dtype=np.int64)
    for ids, part in parts.flat:
        sums[ids] += part                                   # a block's ids are distinct
    return _scaled(sums, weight, unit)


def _block_range(cells, field, block_id):
    return _prune.masked_range(cells.ravel(), field.ravel())


def range_of(*parts) -> tuple:
    """(min, max) of the field over the vertices that took part, from the blocks'."""
    return float(min(p[0] for p in parts)), float(max(p[1] for p in parts))


def _cell_saddles(hierarchy, n_max, low) -> np.ndarray:
    """(M,) the highest saddle value among each cell's events (its first merge sweeping
    down); `low` for a cell with none (alone in its component)."""
    out = np.full(n_max, -np.inf)
    np.maximum.at(out, hierarchy.source, hierarchy.saddle_value)
    np.maximum.at(out, hierarchy.target, hierarchy.saddle_value)
    out[out == -np.inf] = low
    return out
