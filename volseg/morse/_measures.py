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

import numpy as np

from . import _prune

__all__ = ["MEASURES", "STEPS", "check_measure", "cell_measures"]

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
    per_vertex = weight is not None and np.ndim(weight) > 0
    hypervolume = measure == "hypervolume"
    saddles, unit = np.zeros(0), 1.0          # a size: every term is 1, no saddle read
    if hypervolume:
        low, high = _field_range(hierarchy)
        unit = (high - low) / STEPS if high > low else 1.0
        saddles = _cell_saddles(hierarchy, n_max, low)
    if per_vertex:       # a mesh: in memory, float sums
        cells = hierarchy.cells.ravel()
        inside = cells >= 0
        terms = np.asarray(weight, dtype=np.float64)[inside]
        if hypervolume:
            f = hierarchy._field.ravel()[inside]
            terms = terms * np.maximum(f - saddles[cells[inside]], 0.0)
        return np.bincount(cells[inside], weights=terms, minlength=n_max)
    sums = np.zeros(n_max, dtype=np.int64)
    if type(hierarchy.cells).__module__.startswith("dask."):
        # The saddles (8 B per maximum) as one shared task, sent once to each worker
        # that needs them, not inside every block's task (a closure, pickled with each).
        import dask

        parts = _per_block(_block_sums, hierarchy, dask.delayed(saddles, pure=True), unit,
                           hypervolume)
        for ids, part in parts:
            sums[ids] += part                                   # a block's ids are distinct
    else:
        _prune.cell_sums(hierarchy.cells.ravel(), hierarchy._field.ravel(), saddles, unit,
                         hypervolume, sums)
    scale = (1.0 if weight is None else float(weight)) * unit
    return sums.astype(np.float64) * scale


def _block_sums(cells, field, saddles, unit, hypervolume):
    """(cell ids present, their int64 sums) of one block of lazy cells."""
    return _prune.block_sums(cells.ravel(), field.ravel(), saddles, unit, hypervolume)


def _field_range(hierarchy) -> tuple:
    """(min, max) of the field over the vertices that took part (one pass; per block
    for lazy cells)."""
    if type(hierarchy.cells).__module__.startswith("dask."):
        def range_of(cells, field):
            return _prune.masked_range(cells.ravel(), field.ravel())

        parts = _per_block(range_of, hierarchy)
        return float(min(p[0] for p in parts)), float(max(p[1] for p in parts))
    low, high = _prune.masked_range(hierarchy.cells.ravel(), hierarchy._field.ravel())
    return float(low), float(high)


def _per_block(function, hierarchy, *shared) -> tuple:
    """function(cells, field, *shared) of each block of the lazy cells, computed."""
    import dask

    cells = hierarchy.cells
    field = hierarchy._field.rechunk(cells.chunks)
    return dask.compute(*[dask.delayed(function)(c, f, *shared) for c, f in zip(
        cells.to_delayed().ravel(), field.to_delayed().ravel(), strict=True)])


def _cell_saddles(hierarchy, n_max, low) -> np.ndarray:
    """(M,) the highest saddle value among each cell's events (its first merge sweeping
    down); `low` for a cell with none (alone in its component)."""
    out = np.full(n_max, -np.inf)
    np.maximum.at(out, hierarchy.source, hierarchy.saddle_value)
    np.maximum.at(out, hierarchy.target, hierarchy.saddle_value)
    out[out == -np.inf] = low
    return out
