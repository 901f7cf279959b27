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
    saddles = unit = None
    if measure == "hypervolume":
        low, high = _field_range(hierarchy)
        unit = (high - low) / STEPS if high > low else 1.0
        saddles = _cell_saddles(hierarchy, n_max, low)
    if per_vertex:       # a mesh: in memory, float sums
        cells = hierarchy.cells.ravel()
        inside = cells >= 0
        terms = np.asarray(weight, dtype=np.float64)[inside]
        if measure == "hypervolume":
            f = hierarchy._field.ravel()[inside]
            terms = terms * np.maximum(f - saddles[cells[inside]], 0.0)
        return np.bincount(cells[inside], weights=terms, minlength=n_max)
    sums = np.zeros(n_max, dtype=np.int64)
    if type(hierarchy.cells).__module__.startswith("dask."):
        for ids, part in _block_sums(hierarchy, saddles, unit):
            _prune.cell_sums(ids, part, sums)
    else:
        cells = hierarchy.cells.ravel()
        _prune.cell_sums(cells, _terms(cells, hierarchy._field.ravel(), saddles, unit), sums)
    scale = (1.0 if weight is None else float(weight)) * (1.0 if unit is None else unit)
    return sums.astype(np.float64) * scale


def _terms(cells, field, saddles, unit):
    """int64 term of each vertex: 1 (size), or f - s above the saddle in steps of
    `unit` (hypervolume); any value outside the mask (cells < 0)."""
    if saddles is None:
        return np.ones(len(cells), dtype=np.int64)
    s = saddles[np.maximum(cells, 0)]
    above = np.where(cells >= 0, np.maximum(field - s, 0.0), 0.0)
    return np.floor(above / unit).astype(np.int64)


def _block_sums(hierarchy, saddles, unit) -> list:
    """Per block of lazy cells: (cell ids present, their int64 sums)."""
    import dask

    def sums_of(cells, field, saddles):
        cells = cells.ravel()
        ids, where = np.unique(cells, return_inverse=True)
        out = np.zeros(len(ids), dtype=np.int64)
        _prune.cell_sums(where.ravel(), _terms(cells, field.ravel(), saddles, unit), out)
        keep = ids >= 0
        return ids[keep], out[keep]

    field = hierarchy._field.rechunk(hierarchy.cells.chunks)
    # The saddles (8 B per maximum) as one shared task, sent once to each worker that
    # needs them, not inside every block's task (a closure, pickled with each).
    saddles = None if saddles is None else dask.delayed(saddles, pure=True)
    parts = [dask.delayed(sums_of)(c, f, saddles) for c, f in zip(
        hierarchy.cells.to_delayed().ravel(), field.to_delayed().ravel(), strict=True)]
    return dask.compute(*parts)


def _field_range(hierarchy) -> tuple:
    """(min, max) of the field over the vertices that took part."""
    cells, field = hierarchy.cells, hierarchy._field
    if type(cells).__module__.startswith("dask."):
        import dask
        import dask.array as da

        inside = da.where(cells >= 0, field.rechunk(cells.chunks), np.nan)
        low, high = dask.compute(da.nanmin(inside), da.nanmax(inside))
        return float(low), float(high)
    inside = field[cells >= 0]
    return float(inside.min()), float(inside.max())


def _cell_saddles(hierarchy, n_max, low) -> np.ndarray:
    """(M,) the highest saddle value among each cell's events (its first merge sweeping
    down); `low` for a cell with none (alone in its component)."""
    out = np.full(n_max, -np.inf)
    np.maximum.at(out, hierarchy.source, hierarchy.saddle_value)
    np.maximum.at(out, hierarchy.target, hierarchy.saddle_value)
    out[out == -np.inf] = low
    return out
