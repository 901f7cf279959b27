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


def lazy_cell_measures(cells, field, n_max: int, weight, events, measures,
                       compute, place=None) -> dict:
    """`cell_measures` of lazy cells, {measure: Delayed (M,)} for each of `measures`,
    every step on the workers: the cells' saddles (hypervolume), each block's sums, and
    their total (one task: it receives about 12 bytes per cell of each block, the
    client nothing). For the hypervolume, the field's range is computed first, by
    ``compute(delayed) -> value``: a pass of its own, as in the graph of the sums
    every block would wait in memory for the last one's range. `events`: a Delayed of
    anything with the hierarchy's ``source``, ``target`` and ``saddle_value`` (a
    `MorseHierarchy`, or `_Events`); `weight`: None or a number. ``place(delayed) ->
    delayed``, if given, computes the one task that reads the whole `events` (the
    cells' saddles) where they are, and keeps it there."""
    import dask

    low_high = None
    if "hypervolume" in measures:
        low_high = compute(dask.delayed(_range_of)(*[dask.delayed(_block_range)(c, f)
                                                     for c, f in _blocks(cells, field)]))
    return {m: _lazy_sums(cells, field, n_max, weight, events,
                          low_high if m == "hypervolume" else None, place)
            for m in measures}


def _lazy_sums(cells, field, n_max, weight, events, low_high, place):
    """One measure's Delayed sums: the hypervolume with the field's `low_high`, the
    size without."""
    import dask

    hypervolume = low_high is not None
    saddles, unit = np.zeros(0), 1.0
    if hypervolume:
        unit = _unit(*low_high)
        saddles = dask.delayed(_cell_saddles)(events, n_max, low_high[0])
        if place is not None:
            saddles = place(saddles)
    parts = [dask.delayed(_block_sums)(c, f, saddles, unit, hypervolume)
             for c, f in _blocks(cells, field)]
    return dask.delayed(_summed)(n_max, weight, unit, *parts)


def _blocks(cells, field) -> list:
    """(cells, field) Delayed of each block of the lazy cells."""
    field = field.rechunk(cells.chunks)
    return list(zip(cells.to_delayed().ravel(), field.to_delayed().ravel(), strict=True))


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


def _block_sums(cells, field, saddles, unit, hypervolume):
    """(cell ids present, their int64 sums) of one block of lazy cells."""
    return _prune.block_sums(cells.ravel(), field.ravel(), saddles, unit, hypervolume)


def _summed(n_max, weight, unit, *parts) -> np.ndarray:
    sums = np.zeros(n_max, dtype=np.int64)
    for ids, part in parts:
        sums[ids] += part                                   # a block's ids are distinct
    return _scaled(sums, weight, unit)


def _block_range(cells, field):
    return _prune.masked_range(cells.ravel(), field.ravel())


def _range_of(*parts) -> tuple:
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
